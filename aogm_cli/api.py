"""aogm from Python, re-exported at the package's top level and loaded on first use: load and save logs
and maps, simulate, map in any mode, evaluate, check, info, through the same library functions as the
commands. Results are numpy arrays or aogm's domain types; bad input raises ``InputError``."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from aogm_cli.core.log import Log
    from aogm_cli.core.occupancy_map import OccupancyMap
    from aogm_cli.report.log_check import LogCheck

__all__ = ["bundled_world", "check", "evaluate", "info", "load_log", "load_map", "map_log", "map_params", "save_log",
           "save_map", "simulate"]


def _keep_cone_templates() -> None:
    """Cone templates that take a while to build are kept on disk for the next process, as the
    commands keep them (``io.template_store``; the sensor models take the store, they write no file)."""
    from aogm_cli.io import template_store
    from aogm_cli.sensor_models import cone_build

    cone_build.use_store(template_store.STORE)


_keep_cone_templates()


def bundled_world(name: str) -> Path:
    """The path of a bundled world file, e.g. ``"corridor_door"``: the repository's ``worlds/``
    folder, which the package links in as ``data/worlds`` and the wheel carries, so that it is
    found from a checkout and after ``pip install`` alike; ``worlds/README.md`` describes them.

    Examples:

    >>> bundled_world("corridor_door").name
    'corridor_door.yaml'
    >>> bundled_world("corridor_door").is_file()
    True
    """
    import aogm_cli

    return Path(aogm_cli.__file__).parent / "data" / "worlds" / f"{name}.yaml"


def load_log(path: str | Path) -> Log:
    """The log at ``path`` (HDF5, CONTRACT.md), read whole and checked: a ``core.log.Log`` with
    ``time`` (T,), ``pose`` (T, 3), ``ranges`` (T, S), ``sensor`` and, for a simulated log, ``truth``.

    Examples:

    >>> import tempfile
    >>> log = simulate(bundled_world("corridor_door"), seed=1)
    >>> with tempfile.TemporaryDirectory() as d:
    ...     save_log(log, f"{d}/door.h5")
    ...     back = load_log(f"{d}/door.h5")
    >>> bool((back.ranges == log.ranges).all()), back.seed, back.truth is not None
    (True, 1, True)
    """
    from aogm_cli.io.logfile import read_log

    return read_log(path)


def save_log(log: Log, path: str | Path) -> None:
    """Write ``log`` to ``path`` (HDF5, CONTRACT.md), atomically, as ``aogm simulate`` and
    ``aogm import`` do; it reads back with ``load_log`` or any command.

    Examples:

    >>> import tempfile
    >>> log = simulate(bundled_world("corridor_door"), seed=2)
    >>> with tempfile.TemporaryDirectory() as d:
    ...     save_log(log, f"{d}/door.h5")
    ...     load_log(f"{d}/door.h5").n_scans == log.n_scans
    True
    """
    from aogm_cli.io.logfile import write_log

    write_log(path, log)


def load_map(path: str | Path) -> OccupancyMap:
    """The map at ``path`` (written by ``aogm map``, ``compare --maps-dir`` or ``save_map``): an
    ``OccupancyMap`` with ``probability``, ``observed``, ``log_odds``, ``clusters`` (H, W), its
    ``grid`` (``GridSpec``), ``mode``, ``params`` and ``stats``.

    Examples:

    >>> import tempfile
    >>> m = map_log(simulate(bundled_world("corridor_door"), seed=1), "standard")
    >>> with tempfile.TemporaryDirectory() as d:
    ...     save_map(m, f"{d}/door_map.h5")
    ...     back = load_map(f"{d}/door_map.h5")
    >>> back.mode, back.grid == m.grid, bool((back.probability == m.probability).all())
    ('standard', True, True)
    """
    from aogm_cli.io.mapfile import read_map_file

    return read_map_file(path)


def save_map(m: OccupancyMap, path: str | Path) -> None:
    """Write map ``m`` to ``path`` (HDF5, CONTRACT.md), atomically, as ``aogm map`` does; ``aogm
    render``, ``export``, ``info`` and ``compare`` read it.

    Examples:

    >>> import tempfile
    >>> m = map_log(simulate(bundled_world("corridor_door"), seed=1), "standard")
    >>> with tempfile.TemporaryDirectory() as d:
    ...     save_map(m, f"{d}/door_map.h5")
    ...     load_map(f"{d}/door_map.h5").grid.shape == m.grid.shape
    True
    """
    from aogm_cli.io.mapfile import write_map_file

    write_map_file(path, m)


def info(path: str | Path) -> dict:
    """What the log, map or detector file at ``path`` holds and what made it, as ``aogm info
    --json`` prints it (``io.summary.describe``; numpy values as read): ``kind`` ("log", "map" or
    "detector"), the kind's fields (shape, grid, parameters, stats, ...) and ``provenance``
    (None when none is recorded). A missing, damaged or non-aogm file: InputError.

    Examples:

    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     save_log(simulate(bundled_world("corridor_door"), seed=1), f"{d}/door.h5")
    ...     summary = info(f"{d}/door.h5")
    >>> summary["kind"], summary["seed"], summary["checks"][0]
    ('log', 1, 'door_passable')
    """
    from aogm_cli.io.summary import describe

    return describe(str(path))


def simulate(world_path: str | Path, seed: int = 0) -> Log:
    """Simulate the sonar of the world file ``world_path`` along its trajectory (``aogm
    simulate``): the log with its truth; the same seed gives identical arrays. Refused
    (``InputError``) before any work when its estimate exceeds the limits in force.

    Examples:

    >>> log = simulate(bundled_world("corridor_door"), seed=1)
    >>> log.ranges.shape == (log.n_scans, log.sensor.count), log.seed
    (True, 1)
    >>> bool((simulate(bundled_world("corridor_door"), seed=1).ranges == log.ranges).all())
    True
    """
    from aogm_cli.simulation.sonar import simulate as run_simulation
    from aogm_cli.world.simulation_cost import load_checked_world

    return run_simulation(load_checked_world(world_path), seed=seed)


def map_params(**params: Any):
    """``mapping.params.MapParams`` from keyword arguments: ``resolution=0.1`` and the sections of
    a ``--params`` file as dicts, ``inverse_model={...}``, ``em={...}``, ``adaptive={...}``,
    ``calibration={...}`` (``mapping.params.params_from``' overrides; what is not given keeps
    its default). An unknown section is a TypeError, an unknown key or bad value an InputError.

    Examples:

    >>> p = map_params(resolution=0.1, em={"sigma": 0.05}, calibration={"enabled": False})
    >>> p.resolution, p.em.forward.sigma, p.calibration.enabled
    (0.1, 0.05, False)
    """
    from aogm_cli.map_files import resolve_params
    from aogm_cli.mapping.params import SECTIONS

    for name, value in params.items():
        if name != "resolution" and name not in SECTIONS:
            raise TypeError(f"unknown mapping parameter {name!r}; expected resolution or one of "
                            f"{', '.join(SECTIONS)} (each a dict)")
        if name in SECTIONS and not isinstance(value, dict):
            raise TypeError(f"{name}= takes a dict of {', '.join(sorted(SECTIONS[name]))}, got {value!r}")
    return resolve_params(overrides={name: dict(value) if name in SECTIONS else value for name, value in params.items()})


def map_log(log_or_path: Log | str | Path, mode: str = "standard", detector: str | None = None,
            **params: Any) -> OccupancyMap:
    """Map a log (a ``Log`` or the path of a log file) in ``mode`` ("standard", "em" or
    "adaptive"), as ``aogm map`` does (``map_files.map_file``). ``detector``
    (adaptive): None for the packaged one, a detector file, or "all" / "none". ``params``: see
    ``map_params``, e.g. ``resolution=0.1, em={"prior_occupied": 0.2}, calibration={"enabled": False}``.
    A simulated log is mapped on its truth grid.

    Examples:

    >>> log = simulate(bundled_world("corridor_door"), seed=1)
    >>> m = map_log(log, "em", calibration={"enabled": False}, em={"max_sweeps": 5})
    >>> m.mode, m.grid == log.truth.grid, m.params["em"]["max_sweeps"]
    ('em', True, 5)
    >>> adaptive = map_log(log, "adaptive", calibration={"enabled": False})
    >>> adaptive.mode, adaptive.clusters.shape == adaptive.grid.shape
    ('adaptive', True)
    """
    from aogm_cli.map_files import map_file

    resolved = map_params(**params)
    if isinstance(log_or_path, str | Path):
        return map_file(log_or_path, mode, resolved, detector)
    return map_file(log_or_path.path or "(in memory)", mode, resolved, detector, source=log_or_path)


def _log(log_or_path: Log | str | Path) -> Log:
    return load_log(log_or_path) if isinstance(log_or_path, str | Path) else log_or_path


def evaluate(m: OccupancyMap, log: Log | str | Path, robot_radius: float | None = None) -> dict:
    """The metrics ``aogm compare`` reports for map ``m`` against the truth of its simulated
    ``log`` (a ``Log`` or a path): accuracy, occupied precision/recall/F1, brier, ece,
    observed_cells and the world's checks (``evaluation.metrics.evaluate``), and what a planner
    with a robot of ``robot_radius`` (default: compare's, 0.2 m) sees: leak, block and
    surface_recall (``evaluation.planner.planner_metrics``). A log without truth: ValueError.

    Examples:

    >>> log = simulate(bundled_world("corridor_door"), seed=1)
    >>> metrics = evaluate(map_log(log, "standard"), log)
    >>> [k for k in ("accuracy", "occupied_f1", "brier", "leak", "block", "surface_recall") if k in metrics]
    ['accuracy', 'occupied_f1', 'brier', 'leak', 'block', 'surface_recall']
    >>> 0.5 < metrics["accuracy"] <= 1.0
    True
    """
    from aogm_cli.evaluation.metrics import evaluate as map_metrics
    from aogm_cli.evaluation.planner import ROBOT_RADIUS, TRUTH_KEYS, planner_metrics

    log = _log(log)
    if log.truth is None:
        raise ValueError("the log has no truth (not simulated): aogm compare reports its consistency instead")
    metrics = map_metrics(m, log.truth)
    radius = ROBOT_RADIUS if robot_radius is None else robot_radius
    planner = planner_metrics(m.grid, m.probability, m.observed, log.truth.occupancy, log.poses(), radius)
    metrics.update({k: planner[k] for k in TRUTH_KEYS})
    return metrics


def check(log_or_path: Log | str | Path, **limits: Any) -> LogCheck:
    """What a log holds before it is mapped, as ``aogm check`` reports it
    (``report.log_check.check_log``): per-sensor shares, time and pose findings, the grid a
    map would need, and ``warnings`` (a list of dicts; empty for a clean log). ``limits``:
    ``CheckLimits``' fields (``max_speed``, ``max_turn``, ``gap_factor``, ``resolution``,
    ``max_memory``). ``.as_dict()`` is ``--json``'s output, ``.lines()`` the table's.

    Examples:

    >>> result = check(simulate(bundled_world("corridor_door"), seed=1))
    >>> result.warnings
    []
    >>> result.as_dict()["scans"] > 0
    True
    """
    from aogm_cli.report.log_check import CheckLimits, check_log

    checked = CheckLimits(**limits)
    if isinstance(log_or_path, str | Path):
        from aogm_cli.io.logfile import LogReader

        with LogReader(log_or_path) as reader:
            return check_log(reader, checked)
    return check_log(log_or_path, checked)
