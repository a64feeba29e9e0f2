"""One map of ``aogm compare``, made and scored: the job every task carries (``CompareJob``), the
task that maps a log in one mode and scores the map where it runs (``map_and_score``), and the
scores of a map at hand (``score_map``): truth metrics or consistency, held-out, planner's view.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field

from aogm_cli import map_files
from aogm_cli.core.budget import Limits
from aogm_cli.core.errors import InputError
from aogm_cli.core.log import Truth
from aogm_cli.core.occupancy_map import OccupancyMap
from aogm_cli.evaluation.consistency import map_consistency
from aogm_cli.evaluation.holdout import HoldoutSplit, holdout_scores, split_log
from aogm_cli.evaluation.metrics import evaluate
from aogm_cli.evaluation.planner import ROBOT_RADIUS, STANDARD_ITSELF, TRUTH_KEYS, against_standard, planner_metrics
from aogm_cli.io.detectorfile import detector_identity
from aogm_cli.io.logfile import LogReader
from aogm_cli.io.results import ModeResult
from aogm_cli.mapping.learned import Learned
from aogm_cli.mapping.params import MapParams


@dataclass(frozen=True)
class CompareJob:
    """How every map of a comparison is made and scored, built once (``aogm compare``) and passed
    whole to each task, so that a task is picklable and stands on its own (a worker process, a
    Dask worker): the mapping ``params``; ``detector``, the adaptive mode's detector as
    ``--detector`` names it (a detector file, a baseline "all" / "none", None for the packaged
    one); the ``holdout`` split (each map made from the kept scans and scored on the held-out
    ones); the ``limits`` (``core.budget``) every map is checked against before it is made; and
    the ``robot_radius`` of the disk robot whose planner's view is measured."""

    params: MapParams = field(default_factory=MapParams)
    detector: str | None = None
    holdout: HoldoutSplit | None = None
    limits: Limits = field(default_factory=Limits)
    robot_radius: float = ROBOT_RADIUS
    forward_model: str | None = None


@dataclass
class ScoredLog:
    """A log whose maps are scored: its path, the world's name, its truth (None: the maps are
    scored by their consistency with the log and against its standard map instead)."""

    path: str
    world: str
    truth: Truth | None


def map_one(job: CompareJob, path: str, mode: str, given: Learned | None = None) -> OccupancyMap:
    """Map the log at ``path`` in ``mode`` as ``job`` says (``given``: a forward model another map
    of the log learned; else ``job.forward_model``'s: ``map_files.sensor_model``): from the scans
    its holdout split keeps when it has one, refused before any work beyond its limits. The mapper
    measures ``runtime_s`` around the mapping work only, inside the process that maps."""
    if job.holdout is not None:
        return map_kept_scans(job, path, mode, given)
    return map_files.map_file(path, mode, job.params, job.detector, limits=job.limits,
                              model=given or job.forward_model)


def map_kept_scans(job: CompareJob, path: str, mode: str, given: Learned | None = None) -> OccupancyMap:
    """Map the scans of the log at ``path`` that ``job.holdout`` keeps (``evaluation.holdout.split_log``)
    through ``mapping.modes.map_source``, as ``map_file`` maps a whole log (budget, warm-up,
    timing). The map names the log as its source and records the split in ``params["holdout"]``."""
    with LogReader(path) as reader:
        kept, _held = split_log(reader, job.holdout)
    source = map_files.NamedSource(kept, str(path), {"holdout": job.holdout.as_dict()})
    return map_files.map_file(path, mode, job.params, job.detector, limits=job.limits,
                              model=given or job.forward_model, source=source)


def map_and_score(job: CompareJob, path: str, world: str, mode: str, identity: dict | None,
                  keep_map: bool) -> ModeResult:
    """One task of a comparison, in whichever process runs it: map the log at ``path`` in
    ``mode`` (``map_one``) and score the map there (``score_map``: the truth read from the log;
    a log without truth also gets its standard map made here for the planner's comparison).
    ``identity``: this run's detector (``io.detectorfile.detector_identity``). The map comes back
    only with ``keep_map``, so that a cluster's results are small records."""
    result = scored(job, path, world, mode, map_one(job, path, mode), identity)
    if not keep_map:
        result.map = None
    return result


def scored(job: CompareJob, path: str, world: str, mode: str, m: OccupancyMap, identity: dict | None) -> ModeResult:
    """``score_map`` of the map ``m`` made here of the log at ``path``, its truth read from the log."""
    with LogReader(path) as reader:
        truth = reader.truth()
    return score_map(ScoredLog(path, world, truth), mode, m, job, identity=identity)


# the mode of a log whose map learns the forward model when ``aogm compare`` calibrates the log
# once, and the mode that takes it: adaptive fits on the readings that reach its clusters, which
# serves both (docs/algorithms.md, "Where the defaults come from")
CALIBRATES, TAKES = "adaptive", "em"


def map_and_score_calibrated_once(job: CompareJob, path: str, world: str, identity: dict | None,
                                  keep_map: bool) -> list[ModeResult]:
    """The em and the adaptive map of one log with one calibration (``aogm compare`` when it
    compares both with calibration on), [em, adaptive]: the ``CALIBRATES`` map learns the forward
    model (``map_and_score``), the ``TAKES`` map is made with what it learned, carried
    (``Learned.carried``): it records the model as made by that map, and counts the seconds
    learning it took there in its own runtime."""
    first = map_and_score(job, path, world, CALIBRATES, identity, True)
    learned = Learned.of_map(first.map.learned or {}, first.map.stats.get("calibration"))
    if learned.calibration is None:  # nothing learned (no reading to fit): calibrate as usual
        then = map_and_score(job, path, world, TAKES, identity, True)
    else:
        carried = learned.carried(CALIBRATES, first.map.stats["phase_seconds"].get("calibration", 0.0))
        then = scored(job, path, world, TAKES, map_one(job, path, TAKES, carried), identity)
    if not keep_map:
        first.map = then.map = None
    made = {CALIBRATES: first, TAKES: then}
    return [made["em"], made["adaptive"]]


def score_map(log: ScoredLog, mode: str, m: OccupancyMap, job: CompareJob, map_file: str | None = None,
              identity: dict | None = None, standard: OccupancyMap | None = None) -> ModeResult:
    """The ``ModeResult`` of map ``m`` of ``log`` in ``mode``: metrics against the truth; without
    truth, the map's consistency with its log instead; with ``job.holdout``, also the scores on
    the held-out scans (``evaluation.holdout.holdout_scores``); and what a planner sees
    (``planner_values``, against ``standard`` when at hand). ``map_file``: the file the map was
    given as (None: made by this job, whose detector is ``identity``)."""
    metrics = None
    consistency = None
    if log.truth is not None:
        try:
            metrics = evaluate(m, log.truth)
        except ValueError as exc:
            raise InputError(str(exc), file=map_file or log.path) from None
    else:
        consistency = map_consistency(log.path, m)
    scores = None
    with LogReader(log.path) as reader:
        poses = reader.poses()
        if job.holdout is not None:
            scores = holdout_scores(reader, m, job.holdout)
    planner = planner_values(log, mode, m, poses, job, standard, map_file)
    reused = map_file is not None
    return ModeResult(log.path, log.world, mode, float(m.runtime_s), metrics, m, map_file, reused, consistency,
                      _map_detector(m, reused, identity), scores, m.params, _plain(m.stats.get("calibration")),
                      planner=planner)


def planner_values(log: ScoredLog, mode: str, m: OccupancyMap, poses, job: CompareJob,
                   standard: OccupancyMap | None = None, map_file: str | None = None) -> dict:
    """What a planner with a robot of ``job.robot_radius`` sees in map ``m`` (``evaluation.planner``),
    starting at the log's ``poses``: leak, block and surface_recall against the log's truth;
    without truth, walls_kept, leak_vs_standard and far_leak against the standard map of the same
    log and grid (``standard`` when it is on that grid, else made here by ``job`` at the map's
    resolution, from the same scans), which itself has 1, 0 and 0."""
    if log.truth is not None:
        values = planner_metrics(m.grid, m.probability, m.observed, log.truth.occupancy, poses, job.robot_radius)
        return {k: values[k] for k in TRUTH_KEYS}
    if mode == "standard":
        return dict(STANDARD_ITSELF)
    if standard is None or standard.grid != m.grid:
        at_resolution = dataclasses.replace(job.params, resolution=m.grid.resolution)
        standard = map_one(dataclasses.replace(job, params=at_resolution, detector=None), log.path, "standard")
    if standard.grid != m.grid:
        raise InputError(f"grid {m.grid.height}x{m.grid.width} at {m.grid.origin} does not match the grid "
                         f"{standard.grid.height}x{standard.grid.width} at {standard.grid.origin} of the standard map "
                         f"of {log.path}, which the map is compared with", file=map_file or log.path,
                         key="/map/probability")
    return against_standard(m.grid, m.probability, m.observed, standard.probability, standard.observed, poses,
                            job.robot_radius)


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


def _plain(value):
    """``value`` as plain JSON types: numpy scalars of a fresh map's stats become Python numbers,
    NaN and infinities None."""
    if value is None:
        return None
    text = json.dumps(value, default=lambda v: v.item() if hasattr(v, "item") else str(v))
    return json.loads(text, parse_constant=lambda name: None)
