"""aogm: occupancy-grid maps from sonar readings (standard, EM and adaptive mappers), laid out along the
flow of data: world -> simulation -> log -> mapping -> map -> evaluation -> report, over ``core``
(domain types) and ``io`` (file formats)."""

__version__ = "0.1.0"

# aogm from Python (``aogm_cli.api``): load_log, save_log, load_map, save_map, simulate, map_log,
# evaluate, check, info. Loaded on first use, so that ``import aogm_cli`` (the CLI's start-up) stays cheap.
_API = ("bundled_world", "check", "evaluate", "info", "load_log", "load_map", "map_log", "map_params", "save_log",
        "save_map", "simulate")
__all__ = ["__version__", *_API]


def __getattr__(name: str):
    if name in _API:
        import importlib

        # by name, not ``from aogm_cli import api``: every module that imports aogm_cli (for
        # __version__) would otherwise depend on the top layer in the import graph
        return getattr(importlib.import_module("aogm_cli.api"), name)
    raise AttributeError(f"module 'aogm_cli' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_API])
