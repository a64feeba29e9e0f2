"""The library behind ``aogm compare``, orchestration only: sort the arguments into logs and map
files, take up given and resumable maps, run the rest as tasks (``report.scoring``) here, in
worker processes or on a Dask cluster, and gather their results (``io.results.ModeResult``).
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from aogm_cli.core.errors import InputError
from aogm_cli.core.executors import Failure, Task, run_tasks
from aogm_cli.core.log import Truth
from aogm_cli.core.occupancy_map import MODES, OccupancyMap
from aogm_cli.evaluation.holdout import HoldoutSplit, reference_json
from aogm_cli.io.detectorfile import detector_identity
from aogm_cli.io.h5file import open_input
from aogm_cli.io.logfile import LogReader
from aogm_cli.io.mapfile import FORMAT as MAP_FORMAT
from aogm_cli.io.mapfile import FORMAT_VERSION as MAP_FORMAT_VERSION
from aogm_cli.io.mapfile import is_map_file, map_bytes, read_map_file, read_map_header
from aogm_cli.io.provenance import content_sha256, file_sha256, read_provenance
from aogm_cli.io.results import ModeResult, json_bytes
from aogm_cli.mapping.params import MapParams
from aogm_cli.report.baseline import BaselineReport
from aogm_cli.report.scoring import CompareJob, ScoredLog, map_and_score, map_and_score_calibrated_once, score_map
from aogm_cli.report.summary import Summary
from aogm_cli.report.table import csv_bytes


@dataclass
class LogEntry(ScoredLog):
    """One log of the comparison: its ``path`` (as given on the command line, else as found from a
    map's source_log), world name and truth, and the map files given for it."""

    maps: dict[str, str] = field(default_factory=dict)  # mode -> map file given
    given: bool = False  # the log itself was an argument

    @property
    def stem(self) -> str:
        return Path(self.path).stem


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


SHARED = ("em", "adaptive")  # the modes one task maps with one calibration (``compute_maps``)


def run_comparison(entries: list[LogEntry], modes: tuple[str, ...], job: CompareJob, jobs: int = 1,
                   scheduler: str | None = None, maps_dir: str | None = None, keep_maps: bool = True,
                   on_map: Callable[[int, str, ModeResult], None] | None = None) -> tuple[list[ModeResult], list[Failure]]:
    """Every log in every mode, each map made and scored as ``job`` says: given maps reused, the
    others computed (``compute_maps``: here, in ``jobs`` processes or on the Dask cluster at
    ``scheduler``) and written to DIR/<logstem>_<mode>.h5 of ``maps_dir`` when set
    (``maps_dir_outputs`` gives their bytes, to commit with the command's other outputs); results
    per log, then per mode, and the tasks that failed (``Failure.key``: (log path, mode)), which
    have no result. With ``job.holdout``, every map is made from (or, given, must record) the
    kept scans and is scored on the held-out ones. Without ``keep_maps`` (and ``maps_dir``) the
    results of maps made here hold no map. A given map of a log without truth is compared with
    that log's standard map when it is at hand (given, or made here and kept)."""
    tasks = [(i, mode) for i, e in enumerate(entries) for mode in modes if mode not in e.maps]
    targets = maps_dir_targets(entries, modes, maps_dir) if maps_dir else {}
    given = load_given_maps(entries, modes, job.holdout)
    computed, failed = compute_maps(entries, tasks, job, jobs, scheduler, keep_maps or bool(maps_dir), on_map)
    results = []
    for i, e in enumerate(entries):
        for mode in modes:
            if (i, mode) in given:
                standard = given.get((i, "standard")) or getattr(computed.get((i, "standard")), "map", None)
                results.append(score_map(e, mode, given[(i, mode)], job, e.maps[mode], standard=standard))
            elif (i, mode) in computed:  # else failed
                result = computed[(i, mode)]
                result.log = e.path  # as given here (a worker may see the path otherwise)
                if (i, mode) in targets:
                    result.map_file = str(targets[(i, mode)])
                results.append(result)
    contents = {e.path: _content(e.path) for e in entries}
    for r in results:
        r.log_content = contents.get(r.log)
    order = {key: n for n, key in enumerate(tasks)}
    failures = [Failure((entries[f.key[0]].path, f.key[1]), f.message, f.bad_input)
                for f in sorted(failed, key=lambda f: order[f.key])]
    return results, failures


def _content(path: str) -> str | None:
    """``content_sha256`` of a log, None when it cannot be read (its maps failed, and say why)."""
    try:
        return content_sha256(path)
    except (OSError, KeyError, ValueError):
        return None


def compute_maps(entries: list[LogEntry], tasks: list[tuple[int, str]], job: CompareJob, jobs: int = 1,
                 scheduler: str | None = None, keep_maps: bool = True,
                 on_map: Callable[[int, str, ModeResult], None] | None = None,
                 ) -> tuple[dict[tuple[int, str], ModeResult], list[Failure]]:
    """Map and score each (log index, mode) of ``tasks`` as ``job`` says, each as one task of
    ``core.executors.run_tasks`` (``report.scoring.map_and_score``): here, in ``jobs`` local
    worker processes, or on the Dask cluster at ``scheduler``. A task takes the job, the log's
    path and world name and gives back its ``ModeResult``, scored where the map was made; the
    map itself comes back only with ``keep_maps`` (a figure or --maps-dir needs it). Returns the
    results and the tasks that failed (keyed (log index, mode)); a failed task does not stop the
    others. ``on_map`` is called in this process as each result comes in (in order of completion)."""
    identity = detector_identity(job.detector) if any(mode == "adaptive" for _, mode in tasks) else None
    # with calibration on, a log's em and adaptive maps are one task that calibrates once
    # (``map_and_score_calibrated_once``), keyed (log index, ("em", "adaptive"))
    calibrates = job.params.calibration.enabled and not job.forward_model
    once = {i for i, mode in tasks if mode == "em" and (i, "adaptive") in tasks} if calibrates else set()
    work = []
    for i, mode in tasks:
        e = entries[i]
        if i in once and mode == "em":
            work.append(Task((i, SHARED), map_and_score_calibrated_once, (job, e.path, e.world, identity, keep_maps)))
        elif not (i in once and mode == "adaptive"):
            work.append(Task((i, mode), map_and_score, (job, e.path, e.world, mode, identity, keep_maps)))

    def each(key, value):
        """(key, result) per mode of a task's outcome."""
        return list(zip(((key[0], m) for m in key[1]), value, strict=True)) if key[1] == SHARED else [(key, value)]

    def done(key, value):
        for (i, mode), result in each(key, value):
            on_map(i, mode, result)

    results, failed = run_tasks(work, jobs, scheduler, on_done=done if on_map else None)
    expanded = {k: v for key, value in results.items() for k, v in each(key, value)}
    failures = [dataclasses.replace(f, key=(f.key[0], m)) for f in failed
                for m in (f.key[1] if f.key[1] == SHARED else (f.key[1],))]
    return expanded, failures


def resume_maps(entries: list[LogEntry], modes: tuple[str, ...], maps_dir: str, job: CompareJob) -> list[str]:
    """``--resume``: take each DIR/<logstem>_<mode>.h5 of ``maps_dir`` that is complete and valid
    for its log (``resumable_map``) as a map given for that mode, so it is not made again; the
    others are mapped (and rewritten) as usual. Returns the map files taken."""
    targets = maps_dir_targets(entries, modes, maps_dir)
    wanted_detector = detector_identity(job.detector)["sha256"] if any(m == "adaptive" for _, m in targets) else None
    log_sha: dict[int, str | None] = {}
    taken = []
    for (i, mode), target in targets.items():
        if not target.is_file():
            continue
        e = entries[i]
        if i not in log_sha:
            log_sha[i] = file_sha256(e.path)
        if resumable_map(str(target), e, mode, job, log_sha[i], wanted_detector):
            e.maps[mode] = str(target)
            taken.append(str(target))
    return taken


def resumable_map(path: str, entry: LogEntry, mode: str, job: CompareJob, log_sha256: str | None,
                  detector_sha256: str | None) -> bool:
    """Whether the map file ``path`` is what ``job`` would make of ``entry`` in ``mode``: it
    reads back whole and valid (a truncated or damaged file does not), is of that mode, names a
    log of that file name whose sha256 its provenance records as the log's is now, on the truth
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
    if made != (None if job.holdout is None else job.holdout.as_dict()):
        return False
    if mode == "adaptive" and m.params.get("detector_sha256") != detector_sha256:
        return False
    origin = (m.learned or {}).get("origin", "")
    if mode != "standard" and (origin == f"file {job.forward_model}") != bool(job.forward_model):
        return False  # made with another sensor model file, or with one where this run learns its own
    return not params_differences(configured_params(m), job.params, entry.truth is not None)


def configured_params(m: OccupancyMap) -> dict:
    """The parameters a map was made with as configured: its ``params`` (a map that records what
    it learned apart); for a map written before that, whose ``params["em"]`` holds the learned
    values, the values it started from (``stats["calibration"]["initial"]``) in their place."""
    if m.learned is not None:
        return m.params
    initial = (m.stats.get("calibration") or {}).get("initial")
    if not isinstance(initial, dict) or not isinstance(m.params.get("em"), dict):
        return m.params
    return {**m.params, "em": {**m.params["em"], **initial}}


def maps_dir_outputs(results: list[ModeResult], provenance: dict | None = None) -> list[tuple[Path, bytes]]:
    """(path, bytes) of every map computed here that goes to --maps-dir, with ``provenance``
    (``io.provenance.provenance`` of the comparison's inputs)."""
    return [(Path(r.map_file), map_bytes(r.map, provenance)) for r in results if not r.reused and r.map_file is not None]


def output_files(results: list[ModeResult], provenance: dict | None, json_out: str | None = None,
                 csv_out: str | None = None, holdout: dict | None = None,
                 analysis: Analysis | None = None) -> list[tuple[Path, bytes]]:
    """(path, bytes) of the files a comparison writes but its figure, to commit together: the
    --maps-dir maps made here, the --json results file (``holdout``: the object merged results
    share, see ``holdout_object``), the --csv table and the --markdown page; ``analysis``: the summary
    over the logs and the baseline's findings they hold. The maps and the JSON record the
    ``provenance``; the CSV stays a plain table."""
    from aogm_cli.report.summary_table import csv_rows, markdown

    files = maps_dir_outputs(results, provenance)
    extra = {} if analysis is None else analysis.json()
    if json_out:
        files.append((Path(json_out), json_bytes(results, holdout_object(results, holdout), provenance, extra)))
    if csv_out:
        files.append((Path(csv_out), csv_bytes(results, None if analysis is None else csv_rows(analysis.summary))))
    if analysis is not None and analysis.markdown_out:
        files.append((Path(analysis.markdown_out), markdown(analysis.summary, analysis.baseline).encode("utf-8")))
    return files


@dataclasses.dataclass(frozen=True)
class Analysis:
    """What a comparison concludes over its logs: the ``report.summary.Summary``, the baseline's findings
    (``report.baseline.BaselineReport``, None without --baseline), and where --markdown writes them."""

    summary: Summary
    baseline: BaselineReport | None = None
    markdown_out: str | None = None

    def json(self) -> dict:
        out = {"summary": self.summary.as_dict()}
        if self.baseline is not None:
            out["baseline"] = self.baseline.as_dict()
        return out


def given_maps_differences(results: list[ModeResult], params: MapParams, resumed: set[str]) -> list[tuple[str, list[str]]]:
    """(map file, the parameter sections that differ) of every map given (not resumed) whose
    recorded parameters differ from ``params`` (``params_differences``): it is reported as it is."""
    found = []
    for r in results:
        differs = [] if r.map_file in resumed or not r.reused else params_differences(r.map.params, params,
                                                                                     r.metrics is not None)
        if differs:
            found.append((r.map_file, differs))
    return found


def holdout_object(results: list[ModeResult], holdout: dict | None = None) -> dict | None:
    """The top-level ``holdout`` object of the results file (``io.results.results_json``):
    ``holdout`` when given (merged results, as read back); else, when a result has held-out
    scores, the split its map records and the fixed reference the scores use
    (``evaluation.holdout.reference_json``); else None."""
    if holdout is not None:
        return holdout
    split = next((r.params.get("holdout") for r in results if r.holdout is not None), None)
    return None if split is None else {**split, "reference": reference_json()}
