"""A map in the making: the ``State`` the stages pass along and the parts it holds. Types only: the stages
(``stages``) fill it, the runner (``runner``) checks what each stage reads and writes of it."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from aogm_cli.mapping.learned import Learned
from aogm_cli.mapping.params import MapParams
from aogm_cli.mapping.plan import Plan

if TYPE_CHECKING:
    from aogm_cli.core.grid import GridSpec
    from aogm_cli.core.log import Log
    from aogm_cli.mapping.em import EMOutcome, EMProblem, ProblemFor
    from aogm_cli.mapping.pipeline import Progress, TimedSource
    from aogm_cli.mapping.standard import ExactPass
    from aogm_cli.sensor_models.readings import LaidOutReadings


@dataclass(frozen=True)
class StandardMap:
    """A log-odds map and its observed cells (H, W); once thinned, the exact model's ``evidence`` and Elfes' map."""

    log_odds: np.ndarray
    observed: np.ndarray
    evidence: np.ndarray | None = None
    elfes: np.ndarray | None = None


@dataclass(frozen=True)
class Clusters:
    """Where the adaptive mode runs EM: cluster ids (H, W), 0 outside, and their count."""

    ids: np.ndarray
    count: int


class EMRegion(NamedTuple):
    """What EM works on: its problems under a map, and the readings calibration fits on (None: all)."""

    problems: ProblemFor
    fitted_readings: Callable[[], np.ndarray | None]


class View(NamedTuple):
    probability: np.ndarray
    observed: np.ndarray  # the map file's layers, (H, W)


@dataclass(frozen=True)
class State:
    """A map in the making: what it was given (``GIVEN``), then what the stages add (None until written)."""

    params: MapParams
    source: TimedSource
    grid: GridSpec
    plan: Plan
    detector: object = None  # anything with ``flag(ranges, max_range)``
    detector_record: dict | None = None  # what the map's params record of it
    progress: Progress | None = None
    learned: Learned = Learned()  # a model given, then what the stages learn
    whole: Log | None = None  # the scans in memory
    readings: LaidOutReadings | None = None
    standard: StandardMap | None = None
    echo_walls: np.ndarray | None = None  # (H, W): the standard map with the walls echoes alone make (``walls``)
    exact: ExactPass | None = None  # the exact inverse model's pass the lobe's walls were thinned with
    flags: np.ndarray | None = None  # (readings,) bool: the detector's
    clusters: Clusters | None = None
    region: EMRegion | None = None  # None: EM has nothing to work on
    occupied: np.ndarray | None = None  # flat bool: EM's binary map, updated in place
    problem: EMProblem | None = None
    candidates: np.ndarray | None = None  # flat ids of the cells EM may flip
    em: EMOutcome | None = None
    final_evidence: np.ndarray | None = None  # (H, W): each cell's evidence at the final map (``decided``)
    view: View | None = None

    def but(self, **changes) -> State:
        return dataclasses.replace(self, **changes)

    @property
    def in_use(self) -> MapParams:
        """The configured parameters with the forward model learned so far: what the mappers are handed."""
        forward = self.learned.model(self.params.em.forward)
        return dataclasses.replace(self.params, em=dataclasses.replace(self.params.em, forward=forward))


GIVEN = ("params", "source", "grid", "plan", "detector", "detector_record", "progress")  # not a stage's to write
MADE = tuple(f.name for f in dataclasses.fields(State) if f.name not in GIVEN)  # what stages add
