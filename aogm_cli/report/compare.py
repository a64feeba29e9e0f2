"""The library behind ``aogm compare``: collect logs and map files, map what is missing in each
mode (optionally in worker processes), evaluate against the truth, and build the JSON of
CONTRACT.md ("Metrics") and the CSV table. Maps of logs without truth are scored by their
consistency with the log instead (``aogm_cli.consistency``). With a ``HoldoutSplit`` every map
is made from the kept scans and also scored on the held-out ones (``evaluation.holdout``), truth
or not. Every map is also measured as a planner sees it (``evaluation.planner``): against the
truth, or without truth against the standard map of the same log and grid. Results JSON files
read back and merge (``merge_results_files``) without mapping again.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from aogm_cli import __version__
from aogm_cli.core import budget
from aogm_cli.core.budget import Limits
from aogm_cli.core.errors import InputError
from aogm_cli.core.executors import Failure, Task, run_tasks
from aogm_cli.core.log import Truth
from aogm_cli.core.occupancy_map import MODES, OccupancyMap
from aogm_cli.evaluation.consistency import map_consistency
from aogm_cli.evaluation.holdout import SCORE_KEYS, HoldoutSplit, holdout_scores, reference_json, split_log
from aogm_cli.evaluation.metrics import evaluate
from aogm_cli.evaluation.planner import (
    ROBOT_RADIUS,
    STANDARD_ITSELF,
    STANDARD_KEYS,
    TRUTH_KEYS,
    against_standard,
    planner_metrics,
)
from aogm_cli.io.detectorfile import detector_identity
from aogm_cli.io.h5file import open_input
from aogm_cli.io.logfile import LogReader
from aogm_cli.io.mapfile import FORMAT as MAP_FORMAT
from aogm_cli.io.mapfile import FORMAT_VERSION as MAP_FORMAT_VERSION
from aogm_cli.io.mapfile import is_map_file, map_bytes, read_map_file, read_map_header
from aogm_cli.io.provenance import file_sha256, read_provenance
from aogm_cli.mapping.params import MapParams

METRIC_KEYS = ("accuracy", "occupied_precision", "occupied_recall", "occupied_f1", "brier")
PLANNER_KEYS = (*TRUTH_KEYS, *STANDARD_KEYS)  # ``evaluation.planner``: with truth the first, without the others
CONSISTENCY_KEYS = ("method", "readings", "endpoint_occupied", "endpoint_occupied_8", "endpoint_free", "free_cells",
                    "free_contradicted")  # ``evaluation.consistency.summarize``
LEARNED_KEYS = ("sigma", "p_rand", "p_hit", "p_max")  # ``mapping.calibration.LEARNED``: stats["calibration"]["final"]
RESULTS_FORMAT = "aogm-compare"  # the "format" of a --json file; "format_version" RESULTS_FORMAT_VERSION
RESULTS_FORMAT_VERSION = 1


@dataclass
class LogEntry:
    """One log of the comparison: its path, world name, truth, and the map files given for it."""

    path: str  # as given on the command line, else as found from a map's source_log
    world: str
    truth: Truth | None
    maps: dict[str, str] = field(default_factory=dict)  # mode -> map file given
    given: bool = False  # the log itself was an argument

    @property
    def stem(self) -> str:
        return Path(self.path).stem


@dataclass
class ModeResult:
    """One (log, mode): the map, its runtime, its metrics (None without truth), where it came
    from, and for a log without truth its consistency with the log (``consistency.log_consistency``).
    ``planner``: what a planner sees (``evaluation.planner``): leak, block and surface_recall with
    truth, walls_kept and leak_vs_standard without (a result read back from an older file may
    lack them). A result read back from a --json file (``read_results_file``) has no map."""

    log: str
    world: str
    mode: str
    runtime_s: float
    metrics: dict | None
    map: OccupancyMap | None
    map_file: str | None = None  # the map file given, or the one written to --maps-dir
    reused: bool = False
    consistency: dict | None = None  # logs without truth only
    detector: dict | None = None  # adaptive only: {"path", "sha256"} of the detector used
    holdout: dict | None = None  # with a HoldoutSplit: ``evaluation.holdout.holdout_scores``
    params: dict = field(default_factory=dict)  # the parameters the map records
    calibration: dict | None = None  # the map's stats["calibration"]: the forward model it learned
    results_file: str | None = None  # the --json file it was read back from
    planner: dict | None = None  # PLANNER_KEYS -> value (NaN: nothing to measure)

    @property
    def truth(self) -> bool:
        """Whether the log has truth (and so the truth metrics and checks)."""
        return self.metrics is not None


def parse_modes(text: str) -> tuple[str, ...]:
    """``"standard,em"`` -> ("standard", "em"); InputError (key ``--modes``) on unknown or repeated modes."""
    modes = tuple(m.strip() for m in text.split(",") if m.strip())
    if not modes:
        raise InputError(f"expected a comma-separated list of {', '.join(MODES)}, got {text!r}", key="--modes")
    for m in modes:
        if m not in MODES:
            raise InputError(f"unknown mode {m!r}; expected a comma-separated list of {', '.join(MODES)}", key="--modes")
    if len(set(modes)) != len(modes):
        raise InputError(f"a mode is repeated in {text!r}", key="--modes")
    return modes


def world_name(truth: Truth | None, log_path: str) -> str:
    """The ``name`` of the world file inside the log's truth; else the log's file stem."""
    return (truth.world_name() if truth is not None else None) or Path(log_path).stem


def _find_log(source_log: str, map_path: str, given_logs: list[str]) -> str:
    """The log a map was made from: its source_log as a path (from here, then from the map's
    folder), else the file of that name in the map's folder or among the logs given."""
    if not source_log:
        raise InputError("empty; the map does not name the log it was made from", file=map_path, key="source_log")
    folder = Path(map_path).parent
    name = Path(source_log).name
    for candidate in (Path(source_log), folder / source_log, folder / name):
        if candidate.is_file():
            return str(candidate)
    same_name = [p for p in given_logs if Path(p).name == name]
    if len(same_name) == 1:
        return same_name[0]
    raise InputError(
        f"the log {source_log!r} it was made from was not found (also looked in {str(folder)!r}); "
        "expected the log file, with its truth, next to the map or among the arguments",
        file=map_path,
        key="source_log",
    )


def collect_inputs(paths: list[str]) -> list[LogEntry]:
    """Sort the arguments into logs and map files (``is_map_file``), each map attached to its
    log via ``source_log``; logs in order of first mention. InputError on a bad file or on two
    map files of one mode for one log."""
    for p in paths:
        if Path(p).suffix.lower() == ".json":
            raise InputError("a JSON file, not a log or map; to read back the results of aogm compare --json, "
                             "add --from-json", file=p)
    kinds = [(p, is_map_file(p)) for p in paths]
    given_logs = [p for p, is_map in kinds if not is_map]
    entries: dict[str, LogEntry] = {}

    def entry_for(log_path: str) -> LogEntry:
        key = os.path.realpath(log_path)
        if key not in entries:
            with LogReader(log_path) as reader:
                truth = reader.truth()
            entries[key] = LogEntry(path=log_path, world=world_name(truth, log_path), truth=truth)
        return entries[key]

    for path, is_map in kinds:
        if is_map:
            header = read_map_header(path)
            mode = header.mode
            entry = entry_for(_find_log(header.source_log, path, given_logs))
            other = entry.maps.get(mode)
            if other is not None and os.path.realpath(other) != os.path.realpath(path):
                raise InputError(f"a second {mode} map of the log {entry.path}; the first was {other}", file=path)
            entry.maps[mode] = path
        else:
            entry = entry_for(path)
            if not entry.given:
                entry.path, entry.given = path, True
                entry.world = world_name(entry.truth, path)
    return list(entries.values())


def default_modes(entries: list[LogEntry]) -> tuple[str, ...]:
    """All three modes when a log was given itself; with map files only, the modes they have."""
    if any(e.given for e in entries):
        return MODES
    present = {mode for e in entries for mode in e.maps}
    return tuple(m for m in MODES if m in present)


def map_one(path: str, mode: str, params: MapParams, detector: str | None = None,
            holdout: HoldoutSplit | None = None, limits: Limits | None = None) -> OccupancyMap:
    """Map one log in one mode, from the scans ``holdout`` keeps when given, under ``limits``
    (``core.budget``; a Dask worker does not inherit the client's). A top-level function, so that
    worker processes can run it; the mapper measures ``runtime_s`` around the mapping work only,
    inside the process that maps."""
    from aogm_cli.mapping.modes import map_file

    with budget.using(limits or budget.active_limits()):
        if holdout is not None:
            return map_kept_scans(path, mode, params, detector, holdout)
        return map_file(path, mode, params, detector)


def map_kept_scans(path: str, mode: str, params: MapParams, detector: str | None, holdout: HoldoutSplit) -> OccupancyMap:
    """Map the scans of the log at ``path`` that ``holdout`` keeps (``evaluation.holdout.split_log``)
    through ``mapping.modes.map_source``, as ``map_file`` maps a whole log (budget, warm-up,
    timing). The map names the log as its source and records the split in ``params["holdout"]``."""
    from aogm_cli.mapping.modes import map_source

    with LogReader(path) as reader:
        kept, _held = split_log(reader, holdout)
    m = map_source(kept, mode, params, detector, file=str(path))
    m.source_log = str(path)
    m.params["holdout"] = holdout.as_dict()
    return m


def maps_dir_targets(entries: list[LogEntry], modes: tuple[str, ...], maps_dir: str) -> dict[tuple[int, str], Path]:
    """DIR/<logstem>_<mode>.h5 for every map to compute; InputError when two logs share a stem."""
    targets: dict[tuple[int, str], Path] = {}
    owner: dict[Path, str] = {}
    for i, e in enumerate(entries):
        for mode in modes:
            if mode in e.maps:
                continue
            target = Path(maps_dir) / f"{e.stem}_{mode}.h5"
            if target in owner:
                raise InputError(f"two logs would write {target}: {owner[target]} and {e.path}; rename one", key="--maps-dir")
            owner[target] = e.path
            targets[(i, mode)] = target
    return targets


def params_differences(map_params: dict, params: MapParams, has_truth: bool = False) -> list[str]:
    """The parameter sections (resolution, inverse_model, em) in which a map's recorded
    parameters differ from ``params``; a log with truth decides its maps' resolution itself."""
    wanted = json.loads(json.dumps(params.as_dict()))
    if has_truth:
        wanted.pop("resolution")
    return [k for k, v in wanted.items() if k in map_params and map_params[k] != v]


def load_given_maps(entries: list[LogEntry], modes: tuple[str, ...],
                    holdout: HoldoutSplit | None = None) -> dict[tuple[int, str], OccupancyMap]:
    """Read the map files given for the modes compared, and check each against its log's truth
    grid and against ``holdout``: a map made from every scan cannot be scored on held-out
    scans, nor one made from kept scans stand for a map of the whole log."""
    maps = {}
    for i, e in enumerate(entries):
        for mode in modes:
            if mode not in e.maps:
                continue
            path = e.maps[mode]
            m = read_map_file(path)
            if e.truth is not None and m.grid.shape != e.truth.grid.shape:
                raise InputError(
                    f"grid {m.grid.height}x{m.grid.width} does not match the truth grid "
                    f"{e.truth.grid.height}x{e.truth.grid.width} of {e.path}",
                    file=path,
                    key="/map/probability",
                )
            check_map_holdout(m, holdout, path)
            maps[(i, mode)] = m
    return maps


def check_map_holdout(m: OccupancyMap, holdout: HoldoutSplit | None, path: str) -> None:
    """InputError (key --holdout) unless map ``m`` (the file ``path``) was made from the scans
    ``holdout`` keeps (from every scan when None), as its ``params["holdout"]`` records."""
    made = m.params.get("holdout") if isinstance(m.params, dict) else None
    wanted = None if holdout is None else holdout.as_dict()
    if made == wanted:
        return
    if made is None:
        found = "made from every scan of its log"
    else:
        found = f"made from the scans kept by --holdout {made.get('fraction')} --seed {made.get('seed')}"
    expected = (f"a map made with --holdout {holdout.fraction:g} --seed {holdout.seed} (--maps-dir), or the log itself"
                if holdout else "a map made from every scan (without --holdout)")
    raise InputError(f"{found}; expected {expected}", file=path, key="--holdout")


def compute_maps(
    entries: list[LogEntry],
    tasks: list[tuple[int, str]],
    params: MapParams,
    detector: str | None = None,
    jobs: int = 1,
    on_map: Callable[[int, str, ModeResult], None] | None = None,
    holdout: HoldoutSplit | None = None,
    scheduler: str | None = None,
    keep_maps: bool = True,
    robot_radius: float = ROBOT_RADIUS,
) -> tuple[dict[tuple[int, str], ModeResult], list[Failure]]:
    """Map and evaluate each (log index, mode) of ``tasks`` (from the scans ``holdout`` keeps,
    when given), each as one task of ``core.executors.run_tasks``: here, in ``jobs`` local
    worker processes, or on the Dask cluster at ``scheduler``. A task takes the log's path and
    gives back its ``ModeResult``: metrics, consistency, held-out scores and what a planner with
    a robot of ``robot_radius`` sees are computed where the map was made, and the map itself
    comes back only with ``keep_maps`` (a figure or --maps-dir needs it), so that a cluster's
    results are small records. Returns the results and the tasks that failed (keyed (log index,
    mode)); a failed task does not stop the others.

    ``on_map`` is called in this process as each result comes in (in order of completion).
    """
    limits = budget.active_limits()
    identity = detector_identity(detector) if any(mode == "adaptive" for _, mode in tasks) else None
    work = [Task((i, mode), map_and_evaluate, (entries[i].path, entries[i].world, mode, params, detector, holdout,
                                               limits, identity, keep_maps, robot_radius)) for i, mode in tasks]
    return run_tasks(work, jobs, scheduler, on_done=(lambda key, r: on_map(key[0], key[1], r)) if on_map else None)


def map_and_evaluate(path: str, world: str, mode: str, params: MapParams, detector: str | None,
                     holdout: HoldoutSplit | None, limits: Limits | None, identity: dict | None,
                     keep_map: bool, robot_radius: float = ROBOT_RADIUS) -> ModeResult:
    """One task of ``compute_maps``, in whichever process runs it: map the log at ``path``
    (``map_one``), evaluate the map there (``evaluate_result``: the truth read from the log; a
    log without truth also gets its standard map made here for the planner's comparison), and
    drop the map from the result unless ``keep_map``."""
    m = map_one(path, mode, params, detector, holdout, limits)
    with LogReader(path) as reader:
        truth = reader.truth()
    result = evaluate_result(LogEntry(path, world, truth), mode, m, None, False, identity, holdout,
                             Planning(robot_radius, params, limits))
    if not keep_map:
        result.map = None
    return result


def _map_detector(m: OccupancyMap, reused: bool, identity: dict | None) -> dict | None:
    """The detector behind an adaptive map: this run's for a map made here, else the one its
    parameters record (hashed as the file is now)."""
    if m.mode != "adaptive":
        return None
    if not reused:
        return identity
    if "detector" not in m.params:
        return None
    recorded = m.params.get("detector_sha256")  # what the map was made with (older maps: the file as it is now)
    found = detector_identity(m.params["detector"])
    return found if recorded is None else {"path": found["path"], "sha256": recorded}


@dataclass(frozen=True)
class Planning:
    """How ``evaluate_result`` measures what a planner sees (``evaluation.planner``): the robot's
    radius, and for a log without truth how to make the standard map to compare with when none
    is at hand (``standard``): ``params`` (at the map's resolution) under ``limits``."""

    robot_radius: float = ROBOT_RADIUS
    params: MapParams = field(default_factory=MapParams)
    limits: Limits | None = None
    standard: OccupancyMap | None = None  # the standard map of the same log, scans and grid, when at hand


def evaluate_result(entry: LogEntry, mode: str, m: OccupancyMap, map_file: str | None, reused: bool,
                    detector: dict | None = None, holdout: HoldoutSplit | None = None,
                    planning: Planning | None = None) -> ModeResult:
    """Metrics against the truth; without truth, the map's consistency with its log instead;
    with ``holdout``, also the scores on the held-out scans (``evaluation.holdout.holdout_scores``);
    and what a planner sees (``planner_values``). ``detector``: this run's detector identity
    (``detector_identity``)."""
    metrics = None
    consistency = None
    if entry.truth is not None:
        try:
            metrics = evaluate(m, entry.truth)
        except ValueError as exc:
            raise InputError(str(exc), file=map_file or entry.path) from None
    else:
        consistency = map_consistency(entry.path, m)
    scores = None
    with LogReader(entry.path) as reader:
        poses = reader.poses()
        if holdout is not None:
            scores = holdout_scores(reader, m, holdout)
    planner = planner_values(entry, mode, m, poses, planning or Planning(), holdout, map_file)
    return ModeResult(entry.path, entry.world, mode, float(m.runtime_s), metrics, m, map_file, reused, consistency,
                      _map_detector(m, reused, detector), scores, m.params, _plain(m.stats.get("calibration")),
                      planner=planner)


def planner_values(entry: LogEntry, mode: str, m: OccupancyMap, poses, planning: Planning,
                   holdout: HoldoutSplit | None = None, map_file: str | None = None) -> dict:
    """What a planner with a robot of ``planning.robot_radius`` sees in map ``m`` (``evaluation.planner``),
    starting at the log's ``poses``: leak, block and surface_recall against the log's truth;
    without truth, walls_kept and leak_vs_standard against the standard map of the same log and
    grid (``planning.standard`` when it is on that grid, else made here from the same scans:
    ``holdout`` keeps the same ones), which itself has 1 and 0."""
    if entry.truth is not None:
        values = planner_metrics(m.grid, m.probability, m.observed, entry.truth.occupancy, poses, planning.robot_radius)
        return {k: values[k] for k in TRUTH_KEYS}
    if mode == "standard":
        return dict(STANDARD_ITSELF)
    standard = planning.standard
    if standard is None or standard.grid != m.grid:
        params = dataclasses.replace(planning.params, resolution=m.grid.resolution)
        standard = map_one(entry.path, "standard", params, None, holdout, planning.limits)
    if standard.grid != m.grid:
        raise InputError(f"grid {m.grid.height}x{m.grid.width} at {m.grid.origin} does not match the grid "
                         f"{standard.grid.height}x{standard.grid.width} at {standard.grid.origin} of the standard map "
                         f"of {entry.path}, which the map is compared with", file=map_file or entry.path,
                         key="/map/probability")
    return against_standard(m.grid, m.probability, m.observed, standard.probability, standard.observed, poses,
                            planning.robot_radius)


def _plain(value):
    """``value`` as plain JSON types: numpy scalars of a fresh map's stats become Python numbers,
    NaN and infinities None."""
    if value is None:
        return None
    text = json.dumps(value, default=lambda v: v.item() if hasattr(v, "item") else str(v))
    return json.loads(text, parse_constant=lambda name: None)


def run_comparison(
    entries: list[LogEntry],
    modes: tuple[str, ...],
    params: MapParams,
    detector: str | None = None,
    jobs: int = 1,
    maps_dir: str | None = None,
    on_map: Callable[[int, str, ModeResult], None] | None = None,
    holdout: HoldoutSplit | None = None,
    scheduler: str | None = None,
    keep_maps: bool = True,
    robot_radius: float = ROBOT_RADIUS,
) -> tuple[list[ModeResult], list[Failure]]:
    """Every log in every mode: given maps reused, the others computed (``compute_maps``: here,
    in ``jobs`` processes or on the Dask cluster at ``scheduler``) and written to
    DIR/<logstem>_<mode>.h5 of ``maps_dir`` when set (``maps_dir_outputs`` gives their bytes, to
    commit with the command's other outputs); results per log, then per mode, and the tasks that
    failed (``Failure.key``: (log path, mode)), which have no result. With ``holdout``, every map
    is made from (or, given, must record) the kept scans and is scored on the held-out ones.
    Without ``keep_maps`` (and ``maps_dir``) the results of maps made here hold no map. What a
    planner sees is measured for a robot of ``robot_radius``; a given map of a log without truth
    is compared with that log's standard map when it is at hand (given, or made here and kept)."""
    tasks = [(i, mode) for i, e in enumerate(entries) for mode in modes if mode not in e.maps]
    targets = maps_dir_targets(entries, modes, maps_dir) if maps_dir else {}
    given = load_given_maps(entries, modes, holdout)
    computed, failed = compute_maps(entries, tasks, params, detector, jobs, on_map, holdout, scheduler,
                                    keep_maps=keep_maps or bool(maps_dir), robot_radius=robot_radius)
    results = []
    for i, e in enumerate(entries):
        for mode in modes:
            if (i, mode) in given:
                standard = given.get((i, "standard")) or getattr(computed.get((i, "standard")), "map", None)
                planning = Planning(robot_radius, params, standard=standard)
                results.append(evaluate_result(e, mode, given[(i, mode)], e.maps[mode], True, holdout=holdout,
                                               planning=planning))
            elif (i, mode) in computed:  # else failed
                result = computed[(i, mode)]
                result.log = e.path  # as given here (a worker may see the path otherwise)
                if (i, mode) in targets:
                    result.map_file = str(targets[(i, mode)])
                results.append(result)
    order = {key: n for n, key in enumerate(tasks)}
    failures = [Failure((entries[f.key[0]].path, f.key[1]), f.message, f.bad_input)
                for f in sorted(failed, key=lambda f: order[f.key])]
    return results, failures


def resume_maps(entries: list[LogEntry], modes: tuple[str, ...], maps_dir: str, params: MapParams,
                detector: str | None = None, holdout: HoldoutSplit | None = None) -> list[str]:
    """``--resume``: take each DIR/<logstem>_<mode>.h5 of ``maps_dir`` that is complete and valid
    for its log (``resumable_map``) as a map given for that mode, so it is not made again; the
    others are mapped (and rewritten) as usual. Returns the map files taken."""
    targets = maps_dir_targets(entries, modes, maps_dir)
    wanted_detector = detector_identity(detector)["sha256"] if any(m == "adaptive" for _, m in targets) else None
    log_sha: dict[int, str | None] = {}
    taken = []
    for (i, mode), target in targets.items():
        if not target.is_file():
            continue
        e = entries[i]
        if i not in log_sha:
            log_sha[i] = file_sha256(e.path)
        if resumable_map(str(target), e, mode, params, log_sha[i], holdout, wanted_detector):
            e.maps[mode] = str(target)
            taken.append(str(target))
    return taken


def resumable_map(path: str, entry: LogEntry, mode: str, params: MapParams, log_sha256: str | None,
                  holdout: HoldoutSplit | None, detector_sha256: str | None) -> bool:
    """Whether the map file ``path`` is what this comparison would make of ``entry`` in ``mode``:
    it reads back whole and valid (a truncated or damaged file does not), is of that mode, names
    a log of that file name whose sha256 its provenance records as the log's is now, on the truth
    grid, made with the same parameters (``params_differences``), the same --holdout split, and
    for adaptive the same detector (``params["detector_sha256"]``)."""
    try:
        m = read_map_file(path)
        with open_input(path, MAP_FORMAT, MAP_FORMAT_VERSION) as f:
            record = read_provenance(f, path) or {}
    except (InputError, OSError):
        return False
    if m.mode != mode or Path(m.source_log).name != Path(entry.path).name:
        return False
    if log_sha256 is None or log_sha256 not in {i.get("sha256") for i in record.get("inputs", []) if isinstance(i, dict)}:
        return False
    if entry.truth is not None and m.grid.shape != entry.truth.grid.shape:
        return False
    made = m.params.get("holdout")
    if made != (None if holdout is None else holdout.as_dict()):
        return False
    if mode == "adaptive" and m.params.get("detector_sha256") != detector_sha256:
        return False
    return not params_differences(configured_params(m), params, entry.truth is not None)


def configured_params(m: OccupancyMap) -> dict:
    """The parameters a map was made with as configured: for a map whose calibration learned its
    forward model (``params["em"]`` holds the learned values), the values it started from
    (``stats["calibration"]["initial"]``) in their place."""
    initial = (m.stats.get("calibration") or {}).get("initial")
    if not isinstance(initial, dict) or not isinstance(m.params.get("em"), dict):
        return m.params
    return {**m.params, "em": {**m.params["em"], **initial}}


def maps_dir_outputs(results: list[ModeResult], provenance: dict | None = None) -> list[tuple[Path, bytes]]:
    """(path, bytes) of every map computed here that goes to --maps-dir, with ``provenance``
    (``io.provenance.provenance`` of the comparison's inputs)."""
    return [(Path(r.map_file), map_bytes(r.map, provenance)) for r in results if not r.reused and r.map_file is not None]


def checks_passed(metrics: dict | None) -> float | None:
    """Fraction of the world's checks that pass (1.0 when it has none); None without truth."""
    if metrics is None:
        return None
    checks = metrics["checks"]
    return sum(c["passed"] for c in checks) / len(checks) if checks else 1.0


def metric_values(result: ModeResult) -> dict[str, float | None]:
    """The values a gate can name for one (log, mode): metrics, runtime, checks_passed, what a
    planner sees and the held-out scores (None when not computed)."""
    values: dict[str, float | None] = {k: (None if result.metrics is None else result.metrics[k]) for k in METRIC_KEYS}
    values["runtime"] = result.runtime_s
    values["checks_passed"] = checks_passed(result.metrics)
    values.update({k: (result.planner or {}).get(k) for k in PLANNER_KEYS})
    for k in SCORE_KEYS:
        values[k] = None if result.holdout is None else result.holdout[k]
    return values


def gate_values(results: list[ModeResult]) -> list[tuple[str, dict[tuple[str, str], float | None]]]:
    """Per log (in order): (log path, {(mode, metric): value})."""
    by_log: dict[str, dict[tuple[str, str], float | None]] = {}
    for r in results:
        values = by_log.setdefault(r.log, {})
        for metric, v in metric_values(r).items():
            values[(r.mode, metric)] = v
    return list(by_log.items())


def log_labels(entries: list[LogEntry]) -> dict[str, str]:
    """log path -> how tables and messages name it: the world name, plus the file stem when two
    logs share a world name (the whole path when they share the stem too)."""
    return labels_of([(e.path, e.world) for e in entries])


def result_labels(results: list[ModeResult]) -> dict[str, str]:
    """``log_labels`` for results (read back from --json files, without their logs)."""
    return labels_of(list({r.log: (r.log, r.world) for r in results}.values()))


def labels_of(logs: list[tuple[str, str]]) -> dict[str, str]:
    """(log path, world) pairs -> {log path: label}; see ``log_labels``."""
    worlds: dict[str, int] = {}
    stems: dict[tuple[str, str], int] = {}
    for path, world in logs:
        worlds[world] = worlds.get(world, 0) + 1
        stems[(world, Path(path).stem)] = stems.get((world, Path(path).stem), 0) + 1
    labels = {}
    for path, world in logs:
        if worlds[world] == 1:
            labels[path] = world
        elif stems[(world, Path(path).stem)] == 1:
            labels[path] = f"{world} ({Path(path).stem})"
        else:
            labels[path] = f"{world} ({path})"
    return labels


def relative_runtimes(results: list[ModeResult]) -> dict[tuple[str, str], float | None]:
    """(log, mode) -> runtime / the standard map's runtime of the same log (None without one)."""
    standard = {r.log: r.runtime_s for r in results if r.mode == "standard"}
    out = {}
    for r in results:
        base = standard.get(r.log)
        out[(r.log, r.mode)] = r.runtime_s / base if base else None
    return out


def _finite(v):
    return None if isinstance(v, float) and not math.isfinite(v) else v


def metrics_json(metrics: dict | None, holdout: dict | None = None, planner: dict | None = None) -> dict | None:
    """The metrics object of CONTRACT.md (NaN, e.g. nothing observed, becomes null), plus what a
    planner sees and the held-out scores when given; only those without truth, None with none."""
    out = {}
    if metrics is not None:
        out = {k: _finite(float(metrics[k])) for k in METRIC_KEYS}
    out.update({k: _finite(float(v)) for k, v in (planner or {}).items()})
    if metrics is not None:
        out["checks"] = [{"name": c["name"], "passed": bool(c["passed"])} for c in metrics["checks"]]
    if holdout is not None:
        out.update({k: _finite(holdout[k]) for k in SCORE_KEYS})
    return out or None


def consistency_json(consistency: dict | None) -> dict | None:
    """The consistency object of a log without truth (NaN becomes null)."""
    if consistency is None:
        return None
    return {k: _finite(float(v)) if isinstance(v, float) else v for k, v in consistency.items()}


def results_json(results: list[ModeResult], holdout: dict | None = None, provenance: dict | None = None) -> dict:
    """``{"aogm_version", "results": [{log, world, mode, runtime_s, metrics}]}`` as in CONTRACT.md,
    plus ``format`` ("aogm-compare") and ``format_version`` (1) for reading it back
    (``read_results_file``), and ``provenance`` when given. Each result also has ``truth``
    (whether its log has truth), ``params`` (the parameters the map records), ``detector``
    (``{"path", "sha256"}`` for an adaptive map, else null) and ``calibration`` (the map's
    ``stats["calibration"]``: the forward model it learned, per round and ``final``, else null).

    A result of a log with truth has in ``metrics`` also what a planner sees (leak, block,
    surface_recall); one of a log without truth has there walls_kept and leak_vs_standard only,
    and a ``consistency`` object beside it (``aogm_cli.consistency``: method, readings,
    endpoint_occupied, endpoint_occupied_8, endpoint_free, free_cells, free_contradicted).

    With held-out scores, each result's ``metrics`` also holds ``evaluation.holdout.SCORE_KEYS``
    (and without truth only those), its ``params["holdout"]`` the split, and the top level a
    ``holdout`` object: the split and the fixed reference the scores use
    (``evaluation.holdout.reference_json``; ``holdout`` given: that object, as read back).
    """
    out = []
    for r in results:
        item = {"log": r.log, "world": r.world, "mode": r.mode, "truth": r.truth, "runtime_s": _finite(float(r.runtime_s)),
                "metrics": metrics_json(r.metrics, r.holdout, r.planner), "params": r.params, "detector": r.detector,
                "calibration": r.calibration}
        if r.consistency is not None:
            item["consistency"] = consistency_json(r.consistency)
        out.append(item)
    doc = {"format": RESULTS_FORMAT, "format_version": RESULTS_FORMAT_VERSION, "aogm_version": __version__,
           "results": out}
    split = next((r.params.get("holdout") for r in results if r.holdout is not None), None)
    if holdout is not None:
        doc["holdout"] = holdout
    elif split is not None:
        doc["holdout"] = {**split, "reference": reference_json()}
    if provenance is not None:
        doc["provenance"] = provenance
    return doc


def json_bytes(results: list[ModeResult], holdout: dict | None = None, provenance: dict | None = None) -> bytes:
    """``results_json`` as the bytes of ``--json`` (committed with the command's other outputs)."""
    return (json.dumps(results_json(results, holdout, provenance), indent=2, allow_nan=False) + "\n").encode("utf-8")


# --- the CSV table ------------------------------------------------------------------------------

# Every run writes these columns in this order (empty cells where a value does not apply), then one
# ``check:<name>`` column per world check, in order of first appearance.
CSV_COLUMNS = ("log", "world", "mode", "truth", "runtime_s", "runtime_vs_standard", *METRIC_KEYS, "checks_passed",
               *PLANNER_KEYS, *(f"consistency_{k}" for k in CONSISTENCY_KEYS), *SCORE_KEYS,
               *(f"learned_{k}" for k in LEARNED_KEYS), "learned_from_readings")


def csv_table(results: list[ModeResult]) -> tuple[list[str], list[dict]]:
    """(columns, one row per result {column: value, None where it does not apply}) of ``--csv``:
    ``CSV_COLUMNS`` (the truth metrics, what a planner sees, the consistency of a log without
    truth, the held-out scores, the forward model the map's calibration learned), then
    ``check:<name>`` columns."""
    relative = relative_runtimes(results)
    checks = list(dict.fromkeys(f"check:{c['name']}" for r in results if r.metrics for c in r.metrics["checks"]))
    rows = []
    for r in results:
        calibration = r.calibration or {}
        final = calibration.get("final") or {}
        row = {"log": r.log, "world": r.world, "mode": r.mode, "truth": r.truth, "runtime_s": r.runtime_s,
               "runtime_vs_standard": relative[(r.log, r.mode)], "checks_passed": checks_passed(r.metrics),
               **{k: (r.metrics or {}).get(k) for k in METRIC_KEYS},
               **{k: (r.planner or {}).get(k) for k in PLANNER_KEYS},
               **{f"consistency_{k}": (r.consistency or {}).get(k) for k in CONSISTENCY_KEYS},
               **{k: (r.holdout or {}).get(k) for k in SCORE_KEYS},
               **{f"learned_{k}": final.get(k) for k in LEARNED_KEYS},
               "learned_from_readings": calibration.get("readings_used")}
        row.update({f"check:{c['name']}": bool(c["passed"]) for c in (r.metrics or {}).get("checks", [])})
        rows.append(row)
    return [*CSV_COLUMNS, *checks], rows


def csv_cell(value) -> str:
    """A CSV cell: empty for None and NaN, true/false, floats in full (``repr``) precision."""
    if hasattr(value, "item"):  # numpy scalars
        value = value.item()
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value) if isinstance(value, float) else str(value)


def csv_bytes(results: list[ModeResult]) -> bytes:
    """``csv_table`` as the bytes of ``--csv`` (header line, then one line per log and mode)."""
    columns, rows = csv_table(results)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([csv_cell(row.get(c)) for c in columns])
    return buffer.getvalue().encode("utf-8")


# --- results read back from --json files ---------------------------------------------------------

EXPECTED_FILE = "a JSON file written by aogm compare --json"


@dataclass
class MergedResults:
    """The results of several --json files (``merge_results_files``) and the ``holdout`` object
    they share (None without held-out scores)."""

    results: list[ModeResult]
    holdout: dict | None

    @property
    def modes(self) -> tuple[str, ...]:
        present = {r.mode for r in self.results}
        return tuple(m for m in MODES if m in present)


def merge_results_files(paths: list[str]) -> MergedResults:
    """Read every --json file (``read_results_file``) and merge their results, grouped by log in
    order of first mention. InputError (exit 2) naming both files when one (log, mode) is in two
    of them, or when they hold scores of different --holdout splits (one with, one without too)."""
    results: list[ModeResult] = []
    seen: dict[tuple[str, str], str] = {}
    holdout = first = None
    for n, path in enumerate(paths):
        found, split = read_results_file(path)
        if n == 0:
            holdout, first = split, path
        elif split != holdout:
            raise InputError(f"{_split_text(split)}, but {first} has {_split_text(holdout)}; expected results of one "
                             "--holdout split (or none) in every file", file=path, key="holdout")
        for i, r in enumerate(found):
            where = f"{path} results[{i}]"
            if (r.log, r.mode) in seen:
                raise InputError(f"the {r.mode} result of the log {r.log} is also at {seen[(r.log, r.mode)]}; expected "
                                 "each log and mode in one file only (leave one out)", file=path, key=f"results[{i}]")
            seen[(r.log, r.mode)] = where
            results.append(r)
    order: dict[str, int] = {}
    for r in results:
        order.setdefault(r.log, len(order))
    return MergedResults(sorted(results, key=lambda r: order[r.log]), holdout)


def _split_text(split: dict | None) -> str:
    if split is None:
        return "no held-out scores"
    return f"held-out scores of --holdout {split.get('fraction')} --seed {split.get('seed')}"


def read_results_file(path: str) -> tuple[list[ModeResult], dict | None]:
    """The results of a --json file (``results_json``) and its ``holdout`` object (None when it
    has none). InputError (exit 2) naming the file and the key on anything else: not JSON, not
    of format "aogm-compare" version 1, a key missing or of the wrong type."""
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"no such file; expected {EXPECTED_FILE}", file=path) from None
    except UnicodeDecodeError:
        raise InputError(f"not JSON (not UTF-8 text); expected {EXPECTED_FILE}", file=path) from None
    except json.JSONDecodeError as exc:
        raise InputError(f"not JSON ({exc.msg}: line {exc.lineno} column {exc.colno}); expected {EXPECTED_FILE}",
                         file=path) from None
    except OSError as exc:
        raise InputError(f"cannot be read ({exc.strerror}); expected {EXPECTED_FILE}", file=path) from None
    return _ResultsReader(path).document(doc)


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _number_or_null(v) -> bool:
    return v is None or _is_number(v)


def _nan(v) -> float | int:
    """A JSON number as read (null: NaN, as before ``metrics_json`` wrote it)."""
    return math.nan if v is None else v


def _shown(v) -> str:
    text = json.dumps(v)
    return text if len(text) <= 40 else text[:37] + "..."


class _ResultsReader:
    """Checks one --json document key by key; every error names the file and the key path."""

    def __init__(self, path: str):
        self.path = path

    def get(self, obj: dict, name: str, where: str, ok: Callable[[object], bool], expected: str, required: bool = True):
        key = f"{where}.{name}" if where else name
        if name not in obj:
            if required:
                raise InputError(f"missing; expected {expected}", file=self.path, key=key)
            return None
        if not ok(obj[name]):
            raise InputError(f"expected {expected}, got {_shown(obj[name])}", file=self.path, key=key)
        return obj[name]

    def document(self, doc) -> tuple[list[ModeResult], dict | None]:
        if not isinstance(doc, dict):
            raise InputError(f"expected a JSON object with format, format_version and results, got {_shown(doc)}; "
                             f"expected {EXPECTED_FILE}", file=self.path)
        self.get(doc, "format", "", lambda v: v == RESULTS_FORMAT, f'"{RESULTS_FORMAT}" ({EXPECTED_FILE})')
        self.get(doc, "format_version", "", lambda v: _is_number(v) and v == RESULTS_FORMAT_VERSION,
                 str(RESULTS_FORMAT_VERSION))
        self.get(doc, "aogm_version", "", lambda v: isinstance(v, str), "a version string")
        holdout = self.get(doc, "holdout", "", lambda v: isinstance(v, dict), "an object", required=False)
        items = self.get(doc, "results", "", lambda v: isinstance(v, list) and len(v) > 0, "a non-empty list")
        return [self.result(item, f"results[{i}]", holdout is not None) for i, item in enumerate(items)], holdout

    def result(self, item, where: str, holdout: bool) -> ModeResult:
        if not isinstance(item, dict):
            raise InputError(f"expected an object, got {_shown(item)}", file=self.path, key=where)
        get = self.get
        log = get(item, "log", where, lambda v: isinstance(v, str) and v != "", "the log's path")
        world = get(item, "world", where, lambda v: isinstance(v, str), "a string")
        mode = get(item, "mode", where, lambda v: v in MODES, f"one of {', '.join(MODES)}")
        truth = get(item, "truth", where, lambda v: isinstance(v, bool), "true or false")
        runtime = get(item, "runtime_s", where, _number_or_null, "a number of seconds")
        params = get(item, "params", where, lambda v: isinstance(v, dict), "an object")
        detector = get(item, "detector", where, lambda v: v is None or isinstance(v, dict), "an object or null")
        calibration = get(item, "calibration", where, lambda v: v is None or isinstance(v, dict), "an object or null")
        if calibration is not None:
            final = get(calibration, "final", f"{where}.calibration", lambda v: isinstance(v, dict), "an object")
            for k in LEARNED_KEYS:
                get(final, k, f"{where}.calibration.final", _is_number, "a number")
        consistency = get(item, "consistency", where, lambda v: isinstance(v, dict), "an object (the log has no truth)",
                          required=not truth)
        for k in CONSISTENCY_KEYS if consistency is not None else ():
            ok = (lambda v: isinstance(v, str)) if k == "method" else _number_or_null
            get(consistency, k, f"{where}.consistency", ok, "a string" if k == "method" else "a number or null")
        wanted = truth or holdout  # metrics hold the truth metrics, the held-out scores, or both
        metrics = get(item, "metrics", where, lambda v: isinstance(v, dict) or (v is None and not wanted),
                      "an object" if wanted else "an object or null (no truth and no held-out scores)")
        scores = None
        if holdout:
            scores = {k: _nan(get(metrics, k, f"{where}.metrics", _number_or_null, "a number or null"))
                      for k in SCORE_KEYS}
        truth_metrics = self.truth_metrics(metrics, f"{where}.metrics") if truth else None
        # what a planner sees: optional, as files written before it was measured lack it
        found = {k: get(metrics, k, f"{where}.metrics", _number_or_null, "a number or null")
                 for k in (TRUTH_KEYS if truth else STANDARD_KEYS) if k in (metrics or {})}
        return ModeResult(log, world, mode, _nan(runtime), truth_metrics, None, consistency=consistency,
                          detector=detector, holdout=scores, params=params, calibration=calibration,
                          results_file=self.path, planner={k: _nan(v) for k, v in found.items()} or None)

    def truth_metrics(self, metrics: dict, where: str) -> dict:
        out = {k: _nan(self.get(metrics, k, where, _number_or_null, "a number or null")) for k in METRIC_KEYS}
        checks = self.get(metrics, "checks", where, lambda v: isinstance(v, list), "a list of {name, passed}")
        out["checks"] = []
        for j, c in enumerate(checks):
            if not isinstance(c, dict):
                raise InputError(f"expected an object {{name, passed}}, got {_shown(c)}", file=self.path,
                                 key=f"{where}.checks[{j}]")
            name = self.get(c, "name", f"{where}.checks[{j}]", lambda v: isinstance(v, str), "a string")
            passed = self.get(c, "passed", f"{where}.checks[{j}]", lambda v: isinstance(v, bool), "true or false")
            out["checks"].append({"name": name, "passed": passed})
        return out
