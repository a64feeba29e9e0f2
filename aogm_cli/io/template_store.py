"""Cone templates kept on disk for the next process (``sensor_models.cone_build.use_store``): which files,
where (beside numba's cache of cone.py, else ~/.cache/aogm), written atomically and pruned to a few."""

from __future__ import annotations

import contextlib
import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aogm_cli.core import interrupts

# templates of this many entries are kept on disk: a 5 m sonar's at 0.05 m (430,000 entries,
# 10 MB) took 0.2 s to build and 0.01 s to load; smaller ones build fast, larger ones would fill
# the disk; at most STORE_FILES are kept in a folder (the oldest go)
STORE_ENTRIES = (100_000, 3_000_000)
STORE_FILES = 8


@dataclass(frozen=True)
class TemplateStore:
    """Templates built by the module at ``source`` (``sensor_models/cone_build.py``), kept as
    ``cone_templates-<digest>.npz`` in its package's ``__pycache__`` or the user's cache folder."""

    source: Path

    def paths(self, args: tuple) -> list[Path]:
        """Where templates of ``args`` are kept: beside numba's cache of the source module, else in
        the user's cache folder; the name holds a digest of the arguments, the module's source and
        numpy's version, so that a change of any of them builds anew."""
        key = hashlib.sha256(self.source.read_bytes() + repr((args, np.__version__)).encode()).hexdigest()[:24]
        folders = [self.source.parent / "__pycache__"]
        with contextlib.suppress(RuntimeError):  # no home folder
            folders.append(Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "aogm")
        return [folder / f"cone_templates-{key}.npz" for folder in folders]

    def load(self, args: tuple, dtypes: dict) -> dict | None:
        """The arrays kept by ``save`` for ``args``, named and typed as ``dtypes`` says ({name:
        dtype}), or None (none kept, or unreadable)."""
        for path in self.paths(args):
            try:
                with np.load(path, allow_pickle=False) as data:
                    arrays = {name: data[name] for name in dtypes}
            except Exception:  # noqa: BLE001 - missing, unreadable or not ours: built anew
                continue
            if all(arrays[name].dtype == dtype for name, dtype in dtypes.items()):
                return arrays
        return None

    def save(self, args: tuple, arrays: dict) -> None:
        """Keep ``arrays`` for the next process when they have ``STORE_ENTRIES`` entries
        (``arrays["ranges"]``): in the first folder of ``paths`` that can be written, through a
        temporary renamed into place (a signal waits for the rename); nothing when neither can."""
        if not STORE_ENTRIES[0] <= arrays["ranges"].size <= STORE_ENTRIES[1]:
            return
        for path in self.paths(args):
            temp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
            with interrupts.deferred():
                try:
                    path.parent.mkdir(parents=True, exist_ok=True)
                    with open(temp, "wb") as f:
                        np.savez(f, **arrays)
                    os.replace(temp, path)
                except OSError:
                    temp.unlink(missing_ok=True)
                    continue
            with contextlib.suppress(OSError):  # another process may prune at the same time
                kept = sorted(path.parent.glob("cone_templates-*.npz"), key=lambda p: p.stat().st_mtime)
                for old in kept[:-STORE_FILES]:
                    old.unlink(missing_ok=True)
            return


# aogm's store: ``cone_build.use_store(STORE)`` at the edges (the commands, the Python API, a compare
# task). The path is cone_build.py's as its own ``__file__`` gives it (io does not import the sensor models)
STORE = TemplateStore(Path(__file__).parent.parent / "sensor_models" / "cone_build.py")
