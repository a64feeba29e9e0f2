"""A run against a baseline run (``aogm compare --baseline OLD.json``): every log, mode and metric present in both
compared within its tolerance, a change beyond it a regression or an improvement; logs matched by file name and
content, the runtime as the ratio to the same run's standard map, and each world's means compared alike."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from aogm_cli.core.errors import InputError
from aogm_cli.core.occupancy_map import MODES
from aogm_cli.io.results import ModeResult
from aogm_cli.report import summary

OPTION = "--tolerance"
RUNTIME = "runtime"  # its tolerance is a factor on the runtime's ratio to the standard map
# what each metric may move by, in the worse direction, before it is a regression: absolute for the scores,
# a factor for the runtime ratio; checks_passed may not drop at all
TOLERANCES = {
    "accuracy": 0.005, "occupied_precision": 0.02, "occupied_recall": 0.02, "occupied_f1": 0.02, "brier": 0.005,
    "ece": 0.01, "checks_passed": 0.0, "leak": 0.01, "block": 0.01, "surface_recall": 0.02, "walls_kept": 0.01,
    "leak_vs_standard": 0.01, "far_leak": 0.005, "holdout_auc": 0.005, "holdout_auc_band": 0.005,
    "holdout_loglik": 0.01, RUNTIME: 1.25,
}


def parse_tolerances(text: str | None) -> dict[str, float]:
    """``TOLERANCES`` with ``text``'s ``metric=value,...`` over them; InputError (key --tolerance) when malformed."""
    out = dict(TOLERANCES)
    for part in (text or "").split(","):
        if not part.strip():
            continue
        name, sep, value = part.partition("=")
        name = name.strip()
        if not sep or name not in TOLERANCES:
            raise InputError(f"{part.strip()!r}: expected METRIC=VALUE with METRIC one of {', '.join(TOLERANCES)}",
                             key=OPTION)
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        low = 1.0 if name == RUNTIME else 0.0
        if not math.isfinite(number) or number < low:
            what = "a factor >= 1" if name == RUNTIME else "a number >= 0"
            raise InputError(f"{part.strip()!r}: expected {what}, got {value.strip()!r}", key=OPTION)
        out[name] = number
    return out


@dataclass(frozen=True)
class Change:
    """One value beyond its tolerance: of a log (``where`` its file name) or of a world's mean (``where``
    "world W, mean of N logs")."""

    where: str
    mode: str
    metric: str
    old: float
    new: float

    def as_dict(self) -> dict:
        return {"where": self.where, "mode": self.mode, "metric": self.metric, "old": self.old, "new": self.new}


@dataclass
class BaselineReport:
    """What ``compare_to_baseline`` found: regressions and improvements, the (log, mode) pairs on one side only,
    the logs whose content changed (not compared), and how many values were compared."""

    baseline: str
    tolerances: dict[str, float]
    regressions: list[Change] = field(default_factory=list)
    improvements: list[Change] = field(default_factory=list)
    only_in_baseline: list[tuple[str, str]] = field(default_factory=list)
    only_in_run: list[tuple[str, str]] = field(default_factory=list)
    changed_logs: list[str] = field(default_factory=list)
    compared: int = 0

    def as_dict(self) -> dict:
        return {"file": self.baseline, "tolerances": self.tolerances, "compared": self.compared,
                "regressions": [c.as_dict() for c in self.regressions],
                "improvements": [c.as_dict() for c in self.improvements],
                "only_in_baseline": [{"log": log, "mode": mode} for log, mode in self.only_in_baseline],
                "only_in_run": [{"log": log, "mode": mode} for log, mode in self.only_in_run],
                "changed_logs": self.changed_logs}


def verdict(metric: str, old: float, new: float, tolerance: float) -> int:
    """-1: ``new`` is a regression of ``old`` beyond ``tolerance``; 1: an improvement beyond it; 0: within."""
    if metric == summary.RUNTIME_RATIO:  # a factor, lower is better
        if old <= 0 or new <= 0:
            return 0
        return -1 if new > old * tolerance else (1 if new * tolerance < old else 0)
    sign = 1 if metric in summary.HIGHER_IS_BETTER else -1
    moved = sign * (new - old)
    return -1 if moved < -tolerance else (1 if moved > tolerance else 0)


def _keyed(results: list[ModeResult]) -> dict[str, str]:
    """log path -> the name it is matched by: its file name, or its path where two logs share a file name."""
    names: dict[str, list[str]] = {}
    for r in results:
        if r.log not in names.setdefault(Path(r.log).name, []):
            names[Path(r.log).name].append(r.log)
    return {log: (name if len(logs) == 1 else log) for name, logs in names.items() for log in logs}


def _values(results: list[ModeResult]) -> tuple[dict[str, dict], dict[str, str | None], dict[str, str]]:
    """({name: {(mode, metric): value}}, {name: the log's content digest}, {name: world}) of ``results``."""
    keys = _keyed(results)
    by_log = summary.log_values(results)
    content = {keys[r.log]: r.log_content for r in results}
    world = {keys[r.log]: r.world for r in results}
    return {keys[log]: v for log, v in by_log.items()}, content, world


def compare_to_baseline(results: list[ModeResult], old: list[ModeResult], baseline: str,
                        tolerances: dict[str, float]) -> BaselineReport:
    """Compare ``results`` (this run) with ``old`` (the baseline file's, read back) within ``tolerances``."""
    report = BaselineReport(baseline, tolerances)
    new_values, new_content, world = _values(results)
    old_values, old_content, _ = _values(old)
    modes = {name: {m for m, _ in v} for name, v in new_values.items()}
    old_modes = {name: {m for m, _ in v} for name, v in old_values.items()}
    matched = []
    for name in old_values:
        if name not in new_values:
            report.only_in_baseline += [(name, m) for m in sorted(old_modes[name], key=MODES.index)]
        elif old_content[name] and new_content[name] and old_content[name] != new_content[name]:
            report.changed_logs.append(name)
        else:
            matched.append(name)
            report.only_in_baseline += [(name, m) for m in sorted(old_modes[name] - modes[name], key=MODES.index)]
            report.only_in_run += [(name, m) for m in sorted(modes[name] - old_modes[name], key=MODES.index)]
    report.only_in_run += [(name, m) for name in new_values if name not in old_values
                           for m in sorted(modes[name], key=MODES.index)]
    for name in matched:
        _compare_values(report, name, old_values[name], new_values[name])
    _compare_worlds(report, matched, world, old_values, new_values)
    return report


def _compare_values(report: BaselineReport, where: str, old: dict, new: dict) -> None:
    for (mode, metric), v in new.items():
        if metric == RUNTIME or (metric == summary.RUNTIME_RATIO and mode == "standard"):
            continue  # seconds differ between machines; the ratio is compared (and is 1 for standard)
        tolerance_name = RUNTIME if metric == summary.RUNTIME_RATIO else metric  # runtime's applies to the ratio
        if tolerance_name not in report.tolerances:
            continue
        before = old.get((mode, metric))
        if not (summary.known(before) and summary.known(v)):
            continue
        report.compared += 1
        found = verdict(metric, float(before), float(v), report.tolerances[tolerance_name])
        if found:
            (report.regressions if found < 0 else report.improvements).append(Change(where, mode, metric, before, v))


def _compare_worlds(report: BaselineReport, matched: list[str], world: dict[str, str], old_values: dict,
                    new_values: dict) -> None:
    """Each world's means over its matched logs (with two or more of them), compared as a log's values are."""
    worlds: dict[str, list[str]] = {}
    for name in matched:
        worlds.setdefault(world[name], []).append(name)
    for w, names in worlds.items():
        if len(names) < 2:
            continue
        means = [_means([values[n] for n in names]) for values in (old_values, new_values)]
        _compare_values(report, f"world {w}, mean of {len(names)} logs", *means)


def _means(logs: list[dict]) -> dict:
    """{(mode, metric): the mean over ``logs`` of the value}, for the values every log has."""
    out = {}
    for key in [k for k in logs[0] if all(k in v for v in logs)]:
        xs = [v[key] for v in logs]
        if all(summary.known(x) for x in xs):
            out[key] = math.fsum(xs) / len(xs)
    return out
