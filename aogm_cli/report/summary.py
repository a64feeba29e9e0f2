"""The summary of a comparison over its logs: per world and over all logs, each mode's metrics as count, mean,
standard deviation and a Student-t 95% confidence interval of the mean, and for each pair of modes the paired
difference on the logs both have (the same estimate, and wins, ties and losses); runtime as the ratio to the same
log's standard map."""

from __future__ import annotations

import dataclasses
import functools
import math
import statistics
from dataclasses import dataclass

from aogm_cli.core.occupancy_map import MODES
from aogm_cli.core.scores import METRIC_KEYS, PLANNER_KEYS, SCORE_KEYS
from aogm_cli.io.results import ModeResult
from aogm_cli.report.table import checks_passed, relative_runtimes

INTERVAL = "Student t, 95%, two-sided: mean +- t(0.975, n-1) sd / sqrt(n); none for n < 2"
CONFIDENCE = 0.95
RUNTIME_RATIO = "runtime_ratio"  # runtime / the standard map's of the same log
# the metrics summarized, in the order printed; held-out counts (readings, scans) are sizes, not scores
SUMMARY_METRICS = (*METRIC_KEYS, "checks_passed", *PLANNER_KEYS, "holdout_auc", "holdout_auc_band", "holdout_loglik",
                   RUNTIME_RATIO)
HIGHER_IS_BETTER = frozenset({"accuracy", "occupied_precision", "occupied_recall", "occupied_f1", "surface_recall",
                              "checks_passed", "walls_kept", "holdout_auc", "holdout_auc_band", "holdout_loglik"})
ALL = "all"  # the group of every log


def metric_values(result: ModeResult, ratio: float | None = None) -> dict[str, float | None]:
    """The values a gate or the summary can name for one (log, mode): metrics, runtime (and ``ratio``, its ratio to
    the standard map of the same log), checks_passed, what a planner sees, the held-out scores (None: not computed)."""
    values: dict[str, float | None] = {k: (result.metrics or {}).get(k) for k in METRIC_KEYS}
    values["runtime"] = result.runtime_s
    values[RUNTIME_RATIO] = ratio
    values["checks_passed"] = checks_passed(result.metrics)
    values.update({k: (result.planner or {}).get(k) for k in PLANNER_KEYS})
    for k in SCORE_KEYS:
        values[k] = None if result.holdout is None else result.holdout[k]
    return values


def known(v: float | None) -> bool:
    """Whether a value counts in the summary: measured and finite (NaN: nothing to measure)."""
    return v is not None and math.isfinite(v)


def log_values(results: list[ModeResult]) -> dict[str, dict[tuple[str, str], float | None]]:
    """Per log, in order of first mention: {(mode, metric): value} of every result of that log."""
    ratios = relative_runtimes(results)
    by_log: dict[str, dict[tuple[str, str], float | None]] = {}
    for r in results:
        values = by_log.setdefault(r.log, {})
        for metric, v in metric_values(r, ratios[(r.log, r.mode)]).items():
            values[(r.mode, metric)] = v
    return by_log


@dataclass(frozen=True)
class Estimate:
    """A mean over ``n`` values with its standard deviation (n - 1 in the denominator) and ``INTERVAL``'s bounds
    (None for n < 2), and the values' median, least and greatest."""

    n: int
    mean: float
    sd: float | None
    ci_low: float | None
    ci_high: float | None
    median: float
    min: float
    max: float

    def as_dict(self) -> dict:
        return {"n": self.n, "mean": self.mean, "sd": self.sd, "ci_low": self.ci_low, "ci_high": self.ci_high,
                "median": self.median, "min": self.min, "max": self.max}


@functools.cache
def t_quantile(n: int) -> float:
    """t(0.975, n - 1): the two-sided 95% quantile of Student's t with n - 1 degrees of freedom."""
    from scipy.special import stdtrit  # scipy.stats' t.ppf, without importing scipy.stats (seconds)

    return float(stdtrit(n - 1, 0.5 + CONFIDENCE / 2))


def estimate(values: list[float]) -> Estimate:
    """The ``Estimate`` of ``values`` (at least one)."""
    n = len(values)
    mean = math.fsum(values) / n
    spread = {"median": statistics.median(values), "min": min(values), "max": max(values)}
    if n < 2:
        return Estimate(n, mean, None, None, None, **spread)
    sd = math.sqrt(math.fsum((v - mean) ** 2 for v in values) / (n - 1))
    half = t_quantile(n) * sd / math.sqrt(n)
    return Estimate(n, mean, sd, mean - half, mean + half, **spread)


@dataclass(frozen=True)
class Difference:
    """``better`` minus ``other`` on the logs both have: the ``Estimate`` of the differences, and on how many logs
    ``better`` is better (wins), equal (ties) or worse (losses), by the metric's direction (``HIGHER_IS_BETTER``)."""

    mode: str
    other: str
    metric: str
    estimate: Estimate
    wins: int
    ties: int
    losses: int

    def as_dict(self) -> dict:
        return {"mode": self.mode, "other": self.other, "metric": self.metric, **self.estimate.as_dict(),
                "wins": self.wins, "ties": self.ties, "losses": self.losses}


def difference(mode: str, other: str, metric: str, pairs: list[tuple[float, float]]) -> Difference:
    """The ``Difference`` of ``mode`` and ``other`` from (value of mode, value of other) per log."""
    d = [a - b for a, b in pairs]
    sign = 1 if metric in HIGHER_IS_BETTER else -1
    wins = sum(1 for x in d if sign * x > 0)
    losses = sum(1 for x in d if sign * x < 0)
    return Difference(mode, other, metric, estimate(d), wins, len(d) - wins - losses, losses)


@dataclass(frozen=True)
class GroupSummary:
    """The summary of one group of logs (a world's, or ``ALL``): per mode and metric an ``Estimate``, and the
    ``Difference`` of every pair of modes (the later mode of ``MODES`` minus the earlier) and metric."""

    name: str
    logs: int
    modes: dict[str, dict[str, Estimate]]
    differences: list[Difference]
    checks: dict[str, dict[str, tuple[int, int]]] = dataclasses.field(default_factory=dict)  # mode -> check ->
    # (logs where it passed, logs that have it)

    def as_dict(self) -> dict:
        return {"logs": self.logs,
                "modes": {m: {k: e.as_dict() for k, e in by.items()} for m, by in self.modes.items()},
                "differences": [d.as_dict() for d in self.differences],
                "checks": {m: {c: {"passed": p, "logs": n} for c, (p, n) in by.items()} for m, by in self.checks.items()}}


def summarize_group(name: str, logs: list[dict[tuple[str, str], float | None]]) -> GroupSummary:
    """The ``GroupSummary`` of ``logs`` (each ``log_values``' {(mode, metric): value}); a mode or metric no log has
    is left out."""
    columns: dict[tuple[str, str], dict[int, float]] = {}  # (mode, metric) -> {log index: value}
    for i, values in enumerate(logs):
        for key, v in values.items():
            if key[1] in SUMMARY_METRICS and known(v):
                columns.setdefault(key, {})[i] = v
    present = [m for m in MODES if any(key[0] == m for key in columns)]
    modes = {m: {k: estimate(list(columns[(m, k)].values())) for k in SUMMARY_METRICS if (m, k) in columns}
             for m in present}
    differences = []
    for i, other in enumerate(present):
        for mode in present[i + 1:]:
            for k in SUMMARY_METRICS:
                a, b = columns.get((mode, k), {}), columns.get((other, k), {})
                pairs = [(a[j], b[j]) for j in a if j in b]
                if pairs:
                    differences.append(difference(mode, other, k, pairs))
    return GroupSummary(name, len(logs), {m: by for m, by in modes.items() if by}, differences)


@dataclass(frozen=True)
class Summary:
    """A comparison's summary: one ``GroupSummary`` per world (logs of one world at several seeds), in order of
    first mention, and one of every log."""

    worlds: list[GroupSummary]
    all: GroupSummary

    def as_dict(self) -> dict:
        return {"interval": INTERVAL, "worlds": {g.name: g.as_dict() for g in self.worlds}, "all": self.all.as_dict()}


def check_counts(results: list[ModeResult]) -> dict[str, dict[str, tuple[int, int]]]:
    """mode -> world check -> (logs on which it passed, logs that have it), of ``results`` with truth."""
    out: dict[str, dict[str, list[int]]] = {}
    for r in sorted(results, key=lambda r: MODES.index(r.mode)):
        for c in (r.metrics or {}).get("checks", []):
            count = out.setdefault(r.mode, {}).setdefault(c["name"], [0, 0])
            count[0] += bool(c["passed"])
            count[1] += 1
    return {m: {c: (p, n) for c, (p, n) in by.items()} for m, by in out.items()}


def summarize(results: list[ModeResult]) -> Summary:
    """The ``Summary`` of a comparison's ``results``."""
    values = log_values(results)
    world_of = {r.log: r.world for r in results}
    worlds: dict[str, list] = {}
    for log, v in values.items():
        worlds.setdefault(world_of[log], []).append(v)
    groups = [dataclasses.replace(summarize_group(w, logs), checks=check_counts([r for r in results if r.world == w]))
              for w, logs in worlds.items()]
    return Summary(groups, dataclasses.replace(summarize_group(ALL, list(values.values())),
                                               checks=check_counts(results)))
