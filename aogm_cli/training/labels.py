"""Training labels from simulation truth: y = 1 where the region a reading sweeps is erroneous or
cluttered, by three rules (the comment below): (a) a wrong reading, (b) a cone across a depth edge of
the truth, (c) an occupied arc where the log's standard map is wrong. Pure functions on arrays."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.core.frames import sensor_poses
from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import CAUSE_ECHO, CAUSE_NO_ECHO, Log
from aogm_cli.sensor_models.inverse_model import InverseModelConfig
from aogm_cli.sensor_models.readings import cone_bands, cone_templates, readings_of

SCANS_PER_BLOCK = 16  # scans per block of sub-ray sampling (bounds the memory of sub_ray_depths)
# Rule (c)'s map: (probability float32, observed bool) (H, W), the standard map of a simulated log
# on its truth grid at the default inverse model. Training runs no mapper: the caller passes one
# in (``mapping.standard.truth_grid_map``).
StandardMapOf = Callable[[Log], tuple[np.ndarray, np.ndarray]]


# A reading (scan t, sonar j) gets y = 1 when
# (a) erroneous: its truth cause is random (2) or specular/multipath (3); or it has no echo (1)
#     although a surface lies in the cone (finite ideal range); or its range differs from the ideal
#     range by more than ``range_tolerance`` (a finite range where the ideal is +inf counts). A no-echo
#     reading with nothing in range is correct and is not flagged.
# (b) depth edge: ``sub_rays`` rays evenly across the cone are walked through the truth occupancy grid
#     (samples every half cell out to max_range); two adjacent rays whose first hits differ by more
#     than ``edge_factor`` x the nearer + ``edge_margin``, with the nearer hit within ``edge_reach``,
#     mean the cone covers an obstacle's side and the free space beside it: a door frame, a gap between
#     objects, an opening narrower than the cone's arc. There the standard inverse model smears the
#     near hit across the whole arc and closes openings. Smooth walls seen obliquely change depth
#     gradually from ray to ray and are not edges.
# (c) standard map wrong: the log's own standard map (default parameters, truth grid: ``StandardMapOf``,
#     passed in) is compared with the truth grid; a cell is wrong when p > 0.5 on a truth-free cell or
#     p < 0.5 on a truth-occupied one (observed cells only). The reading's occupied arc is the cells of
#     its cone (the standard mapper's templates) whose range lies within alpha/2 of the reading, in
#     template ranges as the standard mapper uses them (``readings.readings_of``). y = 1 when at least
#     ``arc_wrong_min`` arc cells are wrong: the readings whose arcs draw walls too thick towards the
#     robot (oblique cones), close openings or miss surfaces -- where EM should decide instead.
#     ``arc_wrong_min = 0`` turns the rule off. Max-range and invalid readings have no arc.
@dataclass(frozen=True)
class LabelDefinition:
    """The parameters of the label rules above; written as JSON to the detector file (``labels``)."""

    range_tolerance: float = 0.3  # m: |range - ideal_range| above this is an erroneous reading
    sub_rays: int = 31  # rays across the cone for the depth-edge test (1 degree apart for 30 degrees)
    edge_factor: float = 1.2  # adjacent rays form an edge when far > edge_factor * near + edge_margin
    edge_margin: float = 0.3  # m
    edge_reach: float = 2.5  # m: only edges whose near side is this close count
    arc_wrong_min: int = 3  # rule (c): wrong standard-map cells on the occupied arc that flag a reading (0 = off)

    def __post_init__(self):
        if not self.range_tolerance > 0:
            raise InputError(f"expected a positive number, got {self.range_tolerance!r}", key="labels.range_tolerance")
        if isinstance(self.sub_rays, bool) or not isinstance(self.sub_rays, int) or self.sub_rays < 2:
            raise InputError(f"expected an integer >= 2, got {self.sub_rays!r}", key="labels.sub_rays")
        if not self.edge_factor >= 1.0:
            raise InputError(f"expected a number >= 1, got {self.edge_factor!r}", key="labels.edge_factor")
        if not self.edge_margin >= 0.0:
            raise InputError(f"expected a non-negative number, got {self.edge_margin!r}", key="labels.edge_margin")
        if not self.edge_reach > 0:
            raise InputError(f"expected a positive number, got {self.edge_reach!r}", key="labels.edge_reach")
        if isinstance(self.arc_wrong_min, bool) or not isinstance(self.arc_wrong_min, int) or self.arc_wrong_min < 0:
            raise InputError(f"expected a non-negative integer, got {self.arc_wrong_min!r}", key="labels.arc_wrong_min")

    def describe(self) -> str:
        """One paragraph, for the detector file and ``aogm train --help``."""
        return (
            "y = 1 when the reading is erroneous (truth cause random or specular/multipath; no echo although a "
            f"surface is in the cone; or |range - ideal_range| > {self.range_tolerance:g} m) or when its cone "
            f"straddles a depth edge of the truth map: two adjacent of {self.sub_rays} sub-rays whose first hits "
            f"differ by more than {self.edge_factor:g} x nearer + {self.edge_margin:g} m, the nearer within "
            f"{self.edge_reach:g} m (door frames, gaps between objects, openings narrower than the cone's arc)"
            + (
                f"; or when the standard map of the same log (default parameters) is wrong against the truth on at "
                f"least {self.arc_wrong_min} cell(s) of the reading's occupied arc (its cone's cells within alpha/2 "
                "of the range; wrong: p > 0.5 on a free cell or p < 0.5 on an occupied one)."
                if self.arc_wrong_min
                else "."
            )
        )

    def as_dict(self) -> dict:
        """The parameters and the rule in words (JSON-able)."""
        return asdict(self) | {"definition": self.describe()}


def erroneous(ranges: np.ndarray, cause: np.ndarray, ideal_range: np.ndarray, tolerance: float) -> np.ndarray:
    """(T, S) bool: readings that are wrong (rule (a) of the comment above ``LabelDefinition``)."""
    r = np.asarray(ranges, dtype=np.float64)
    ideal = np.asarray(ideal_range, dtype=np.float64)
    cause = np.asarray(cause)
    wrong = (cause != CAUSE_ECHO) & (cause != CAUSE_NO_ECHO)
    wrong |= (cause == CAUSE_NO_ECHO) & np.isfinite(ideal)
    both = np.isfinite(r) & np.isfinite(ideal)
    with np.errstate(invalid="ignore"):
        wrong |= both & (np.abs(r - ideal) > tolerance)
    wrong |= np.isfinite(r) & np.isposinf(ideal)
    return wrong


def sub_ray_depths(
    occupancy: np.ndarray,
    grid: GridSpec,
    poses: np.ndarray,
    beam_width: float,
    max_range: float,
    sub_rays: int,
) -> np.ndarray:
    """(T, S, K) distance of the first occupied truth cell along each of K rays across each cone.

    ``poses`` (T, S, 3) are the sensors' world poses (``frames.sensor_poses``). Each ray is
    sampled every half cell from half a cell out to max_range; the first sample in an occupied
    cell gives the depth, +inf if none. Samples outside the grid count as free.
    """
    poses = np.asarray(poses, dtype=np.float64)
    occ = np.asarray(occupancy) > 0
    offsets = np.linspace(-beam_width / 2.0, beam_width / 2.0, sub_rays)
    step = grid.resolution / 2.0
    dist = np.arange(1, int(np.ceil(max_range / step)) + 1) * step
    dist = dist[dist <= max_range + 1e-9]
    n_scans, n_sensors = poses.shape[:2]
    out = np.full((n_scans, n_sensors, sub_rays), np.inf)
    for a in range(0, n_scans, SCANS_PER_BLOCK):
        p = poses[a : a + SCANS_PER_BLOCK]
        heading = p[:, :, 2, None] + offsets  # (B, S, K)
        x = p[:, :, 0, None, None] + np.cos(heading)[..., None] * dist
        y = p[:, :, 1, None, None] + np.sin(heading)[..., None] * dist
        row, col = grid.world_to_cell(x, y)
        inside = grid.contains(row, col)
        hit = np.zeros(x.shape, dtype=bool)
        hit[inside] = occ[row[inside], col[inside]]
        first = np.argmax(hit, axis=-1)
        out[a : a + SCANS_PER_BLOCK] = np.where(hit.any(axis=-1), dist[first], np.inf)
    return out


def depth_edge(depths: np.ndarray, factor: float, margin: float, reach: float) -> np.ndarray:
    """(T, S) bool from (T, S, K) depths: some adjacent rays differ by > factor*near + margin, near <= reach."""
    d = np.asarray(depths, dtype=np.float64)
    near = np.minimum(d[..., 1:], d[..., :-1])
    far = np.maximum(d[..., 1:], d[..., :-1])
    with np.errstate(invalid="ignore"):
        return ((far > factor * near + margin) & (near <= reach)).any(axis=-1)


def standard_wrong(probability: np.ndarray, observed: np.ndarray, truth_occupancy: np.ndarray) -> np.ndarray:
    """(H, W) bool: observed cells where a map disagrees with the truth (p > 0.5 on a free cell,
    p < 0.5 on an occupied one; p = 0.5 counts as neither)."""
    p = np.asarray(probability, dtype=np.float64)
    occ = np.asarray(truth_occupancy) > 0
    return np.asarray(observed, dtype=bool) & (((p > 0.5) & ~occ) | ((p < 0.5) & occ))


def standard_map_wrong_arcs(log: Log, min_wrong: int, standard_map_of: StandardMapOf) -> np.ndarray:
    """(T, S) bool, rule (c): the log's standard map (``standard_map_of(log)``: default parameters,
    truth grid) is wrong on at least ``min_wrong`` cells of the reading's occupied arc."""
    truth = log.truth
    grid, sensor = truth.grid, log.sensor
    templates = cone_templates(grid, sensor)
    ranges = np.asarray(log.ranges, dtype=np.float32)
    probability, observed = standard_map_of(log)
    wrong = standard_wrong(probability, observed, truth.occupancy)
    cones = readings_of(log.pose, ranges, sensor, grid, templates)
    half = 0.5 * InverseModelConfig().alpha
    _, counts = cone_bands(grid, templates, cones, half, half, wrong)
    return (counts >= min_wrong).reshape(ranges.shape)


def labels(log: Log, definition: LabelDefinition | None = None, file: str | None = None,
           standard_map_of: StandardMapOf | None = None) -> np.ndarray:
    """(T, S) bool labels y of a simulated log (rules (a), (b) or (c) above ``LabelDefinition``);
    rule (c) (``arc_wrong_min`` > 0) needs ``standard_map_of``."""
    definition = definition or LabelDefinition()
    if log.truth is None:
        raise InputError("no /truth group: training needs a simulated log with its truth", file=file, key="/truth")
    truth = log.truth
    wrong = erroneous(log.ranges, truth.cause, truth.ideal_range, definition.range_tolerance)
    poses = sensor_poses(log.pose, log.sensor.mount)
    depths = sub_ray_depths(truth.occupancy, truth.grid, poses, log.sensor.beam_width, log.sensor.max_range, definition.sub_rays)
    edge = depth_edge(depths, definition.edge_factor, definition.edge_margin, definition.edge_reach)
    y = wrong | edge
    if definition.arc_wrong_min:
        if standard_map_of is None:
            raise ValueError("label rule (c) (arc_wrong_min > 0) compares the log's standard map with its truth: "
                             "pass standard_map_of (mapping.standard.truth_grid_map)")
        y |= standard_map_wrong_arcs(log, definition.arc_wrong_min, standard_map_of)
    return y
