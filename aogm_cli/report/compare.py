"""The library behind ``aogm compare``: collect logs and map files, map what is missing in each
mode (optionally in worker processes), evaluate against the truth, and build the JSON of
CONTRACT.md ("Metrics"). Maps of logs without truth are scored by their consistency with
the log instead (``aogm_cli.consistency``). With a ``HoldoutSplit`` every map is made from the
kept scans and also scored on the held-out ones (``evaluation.holdout``), truth or not.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from aogm_cli import __version__
from aogm_cli.core.errors import InputError
from aogm_cli.core.interrupts import end_workers, worker_init
from aogm_cli.core.log import Truth
from aogm_cli.core.occupancy_map import MODES, OccupancyMap
from aogm_cli.evaluation.consistency import map_consistency
from aogm_cli.evaluation.holdout import SCORE_KEYS, HoldoutSplit, holdout_scores, reference_json, split_log
from aogm_cli.evaluation.metrics import evaluate
from aogm_cli.io.detectorfile import detector_identity
from aogm_cli.io.logfile import LogReader
from aogm_cli.io.mapfile import is_map_file, map_bytes, read_map_file, read_map_header
from aogm_cli.mapping.params import MapParams

METRIC_KEYS = ("accuracy", "occupied_precision", "occupied_recall", "occupied_f1", "brier")


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
    from, and for a log without truth its consistency with the log (``consistency.log_consistency``)."""

    log: str
    world: str
    mode: str
    runtime_s: float
    metrics: dict | None
    map: OccupancyMap
    map_file: str | None = None  # the map file given, or the one written to --maps-dir
    reused: bool = False
    consistency: dict | None = None  # logs without truth only
    detector: dict | None = None  # adaptive only: {"path", "sha256"} of the detector used
    holdout: dict | None = None  # with a HoldoutSplit: ``evaluation.holdout.holdout_scores``


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
    if truth is not None and truth.world:
        try:
            raw = yaml.safe_load(truth.world)
        except yaml.YAMLError:
            raw = None
        if isinstance(raw, dict) and isinstance(raw.get("name"), str) and raw["name"].strip():
            return raw["name"].strip()
    return Path(log_path).stem


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
            holdout: HoldoutSplit | None = None) -> OccupancyMap:
    """Map one log in one mode, from the scans ``holdout`` keeps when given. A top-level
    function, so that worker processes can run it; the mapper measures ``runtime_s`` around the
    mapping work only, inside the process that maps."""
    from aogm_cli.mapping.modes import map_file

    if holdout is not None:
        return map_kept_scans(path, mode, params, detector, holdout)
    return map_file(path, mode, params, detector)


def map_kept_scans(path: str, mode: str, params: MapParams, detector: str | None, holdout: HoldoutSplit) -> OccupancyMap:
    """Map the scans of the log at ``path`` that ``holdout`` keeps (``evaluation.holdout.split_log``),
    timed as ``mapping.modes.map_file`` times a log: compilation (the warm-up) and reading left
    out. The map names the log as its source and records the split in ``params["holdout"]``."""
    from aogm_cli.mapping.modes import map_log, resolve_detector, resolved_params, warm_up

    flagger, name = resolve_detector(detector) if mode == "adaptive" else (None, "")
    with LogReader(path) as reader:
        kept, _held = split_log(reader, holdout)
    params = resolved_params(kept, params)
    warm_up(kept.sensor, params, mode)
    m = map_log(kept, mode, params, flagger, name)
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
    on_map: Callable[[int, str, OccupancyMap], None] | None = None,
    holdout: HoldoutSplit | None = None,
) -> dict[tuple[int, str], OccupancyMap]:
    """Map each (log index, mode) of ``tasks`` (from the scans ``holdout`` keeps, when given);
    with ``jobs`` > 1 in that many worker processes.

    ``on_map`` is called in this process as each map is finished (in order of completion).
    """
    done: dict[tuple[int, str], OccupancyMap] = {}
    if jobs <= 1 or len(tasks) <= 1:
        for i, mode in tasks:
            m = map_one(entries[i].path, mode, params, detector, holdout)
            done[(i, mode)] = m
            if on_map:
                on_map(i, mode, m)
        return done
    from concurrent.futures import FIRST_EXCEPTION, ProcessPoolExecutor, wait

    pool = ProcessPoolExecutor(max_workers=min(jobs, len(tasks)), initializer=worker_init, initargs=(os.getpid(),))
    try:
        futures = {pool.submit(map_one, entries[i].path, mode, params, detector, holdout): (i, mode)
                   for i, mode in tasks}
        pending = set(futures)
        while pending:
            finished, pending = wait(pending, return_when=FIRST_EXCEPTION)
            for fut in finished:
                key = futures[fut]
                m = fut.result()  # re-raises a worker's error here
                done[key] = m
                if on_map:
                    on_map(key[0], key[1], m)
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        end_workers()  # the maps still running are not waited for
        raise
    pool.shutdown()
    return done


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


def evaluate_result(entry: LogEntry, mode: str, m: OccupancyMap, map_file: str | None, reused: bool,
                    detector: dict | None = None, holdout: HoldoutSplit | None = None) -> ModeResult:
    """Metrics against the truth; without truth, the map's consistency with its log instead;
    with ``holdout``, also the scores on the held-out scans (``evaluation.holdout.holdout_scores``).
    ``detector``: this run's detector identity (``detector_identity``)."""
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
    if holdout is not None:
        with LogReader(entry.path) as reader:
            scores = holdout_scores(reader, m, holdout)
    return ModeResult(entry.path, entry.world, mode, float(m.runtime_s), metrics, m, map_file, reused, consistency,
                      _map_detector(m, reused, detector), scores)


def run_comparison(
    entries: list[LogEntry],
    modes: tuple[str, ...],
    params: MapParams,
    detector: str | None = None,
    jobs: int = 1,
    maps_dir: str | None = None,
    on_map: Callable[[int, str, OccupancyMap], None] | None = None,
    holdout: HoldoutSplit | None = None,
) -> list[ModeResult]:
    """Every log in every mode: given maps reused, the others computed (and written to
    as DIR/<logstem>_<mode>.h5 of ``maps_dir`` when set: ``maps_dir_outputs`` gives their bytes,
    to commit with the command's other outputs); results per log, then per mode. With
    ``holdout``, every map is made from (or, given, must record) the kept scans and is scored
    on the held-out ones."""
    tasks = [(i, mode) for i, e in enumerate(entries) for mode in modes if mode not in e.maps]
    targets = maps_dir_targets(entries, modes, maps_dir) if maps_dir else {}
    given = load_given_maps(entries, modes, holdout)
    written: dict[tuple[int, str], str] = {}

    def finished(i: int, mode: str, m: OccupancyMap) -> None:
        if (i, mode) in targets:
            written[(i, mode)] = str(targets[(i, mode)])
        if on_map:
            on_map(i, mode, m)

    identity = detector_identity(detector) if any(mode == "adaptive" for _, mode in tasks) else None
    computed = compute_maps(entries, tasks, params, detector, jobs, finished, holdout)
    results = []
    for i, e in enumerate(entries):
        for mode in modes:
            if (i, mode) in given:
                results.append(evaluate_result(e, mode, given[(i, mode)], e.maps[mode], True, holdout=holdout))
            else:
                results.append(evaluate_result(e, mode, computed[(i, mode)], written.get((i, mode)), False, identity,
                                               holdout))
    return results


def maps_dir_outputs(results: list[ModeResult]) -> list[tuple[Path, bytes]]:
    """(path, bytes) of every map computed here that goes to --maps-dir."""
    return [(Path(r.map_file), map_bytes(r.map)) for r in results if not r.reused and r.map_file is not None]


def checks_passed(metrics: dict | None) -> float | None:
    """Fraction of the world's checks that pass (1.0 when it has none); None without truth."""
    if metrics is None:
        return None
    checks = metrics["checks"]
    return sum(c["passed"] for c in checks) / len(checks) if checks else 1.0


def metric_values(result: ModeResult) -> dict[str, float | None]:
    """The values a gate can name for one (log, mode): metrics, runtime, checks_passed and the
    held-out scores (None when not computed)."""
    values: dict[str, float | None] = {k: (None if result.metrics is None else result.metrics[k]) for k in METRIC_KEYS}
    values["runtime"] = result.runtime_s
    values["checks_passed"] = checks_passed(result.metrics)
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
    logs share a world name."""
    count: dict[str, int] = {}
    for e in entries:
        count[e.world] = count.get(e.world, 0) + 1
    return {e.path: e.world if count[e.world] == 1 else f"{e.world} ({e.stem})" for e in entries}


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


def metrics_json(metrics: dict | None, holdout: dict | None = None) -> dict | None:
    """The metrics object of CONTRACT.md (NaN, e.g. nothing observed, becomes null), plus the
    held-out scores when given; only those without truth, None with neither."""
    out = None
    if metrics is not None:
        out = {k: _finite(float(metrics[k])) for k in METRIC_KEYS}
        out["checks"] = [{"name": c["name"], "passed": bool(c["passed"])} for c in metrics["checks"]]
    if holdout is not None:
        out = out or {}
        out.update({k: _finite(holdout[k]) for k in SCORE_KEYS})
    return out


def consistency_json(consistency: dict | None) -> dict | None:
    """The consistency object of a log without truth (NaN becomes null)."""
    if consistency is None:
        return None
    return {k: _finite(float(v)) if isinstance(v, float) else v for k, v in consistency.items()}


def results_json(results: list[ModeResult]) -> dict:
    """``{"aogm_version", "results": [{log, world, mode, runtime_s, metrics}]}`` as in CONTRACT.md,
    each result also with ``params`` (the parameters the map records) and ``detector``
    (``{"path", "sha256"}`` for an adaptive map, else null).

    A result of a log without truth has ``metrics`` null and a ``consistency`` object beside
    it (``aogm_cli.consistency``: method, readings, endpoint_occupied, endpoint_occupied_8,
    endpoint_free, free_cells, free_contradicted).

    With held-out scores, each result's ``metrics`` also holds ``evaluation.holdout.SCORE_KEYS``
    (and without truth only those), its ``params["holdout"]`` the split, and the top level a
    ``holdout`` object: the split and the fixed reference the scores use
    (``evaluation.holdout.reference_json``).
    """
    out = []
    for r in results:
        item = {"log": r.log, "world": r.world, "mode": r.mode, "runtime_s": _finite(float(r.runtime_s)),
                "metrics": metrics_json(r.metrics, r.holdout), "params": r.map.params, "detector": r.detector}
        if r.consistency is not None:
            item["consistency"] = consistency_json(r.consistency)
        out.append(item)
    doc = {"aogm_version": __version__, "results": out}
    split = next((r.map.params.get("holdout") for r in results if r.holdout is not None), None)
    if split is not None:
        doc["holdout"] = {**split, "reference": reference_json()}
    return doc


def json_bytes(results: list[ModeResult]) -> bytes:
    """``results_json`` as the bytes of ``--json`` (committed with the command's other outputs)."""
    return (json.dumps(results_json(results), indent=2, allow_nan=False) + "\n").encode("utf-8")
