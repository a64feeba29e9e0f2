"""aogm's compiled kernels loaded from numba's on-disk cache without numba's full start-up
(``load_lean``): with only what their machine code links to, numba's runtime."""

from __future__ import annotations

_installed: list[bool] = []

# Before it loads any cached kernel, numba initialises its whole CPU target (``BaseContext.refresh``:
# every typing and lowering registry, numba.np.*, numba.cpython.*), which only compiling needs and
# which takes longer than the rest of ``aogm map`` of a small log. ``load_lean`` loads aogm's own
# kernels (functions of ``aogm_cli`` modules) with numba's runtime (the NRT) alone; compiling still
# initialises the target in full (numba's compiler does so itself), other packages' kernels load as
# numba loads them, and a kernel that fails to load this way is loaded numba's way.


def load_lean() -> None:
    """Install the lean loading of aogm's cached kernels (once; nothing when numba's cache
    has not the shape it was written for: ``Cache.load_overload``, ``_load_overload``)."""
    if _installed:
        return
    _installed.append(True)
    try:
        from numba.core.caching import Cache
        from numba.core.runtime import nrt
    except ImportError:
        return
    numba_way = getattr(Cache, "load_overload", None)
    if numba_way is None or not hasattr(Cache, "_load_overload") or not hasattr(nrt, "rtsys"):
        return

    def load_overload(self, sig, target_context):
        module = getattr(getattr(self, "_py_func", None), "__module__", None) or ""
        if not module.startswith("aogm_cli."):
            return numba_way(self, sig, target_context)
        try:
            nrt.rtsys.initialize(target_context)
            with self._guard_against_spurious_io_errors():
                return self._load_overload(sig, target_context)
        except Exception:  # noqa: BLE001 - then numba's own way, which initialises everything
            pass
        try:
            return numba_way(self, sig, target_context)
        except (ImportError, AttributeError):
            # an index written before a kernel it calls moved to another module (numba keys its
            # cache on the kernel's own source only): dropped, so that it compiles and writes anew
            _drop_index(self)
            return None

    Cache.load_overload = load_overload


def _drop_index(cache) -> None:
    """Remove a numba cache's index file (its entries are then compiled again and saved)."""
    import os

    path = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
    if path:
        try:
            os.remove(path)
        except OSError:
            pass
