"""The results file of ``aogm compare --json`` (format "aogm-compare", version 1): ``ModeResult``,
the record of one (log, mode) it holds, written as JSON (``results_json``), read back key by key
(``read_results_file``) and merged (``merge_results_files``) without mapping again.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from aogm_cli import __version__
from aogm_cli.core.errors import InputError
from aogm_cli.core.occupancy_map import MODES, OccupancyMap
from aogm_cli.core.scores import (
    CONSISTENCY_KEYS,
    LATER_METRIC_KEYS,
    LEARNED_KEYS,
    METRIC_KEYS,
    SCORE_KEYS,
    STANDARD_KEYS,
    TRUTH_KEYS,
)

RESULTS_FORMAT = "aogm-compare"  # the "format" of a --json file; "format_version" RESULTS_FORMAT_VERSION
RESULTS_FORMAT_VERSION = 1


@dataclass
class ModeResult:
    """One (log, mode): the map, its runtime, its metrics (None without truth), where it came
    from, and for a log without truth its consistency with the log (``evaluation.consistency``).
    ``planner``: what a planner sees (``evaluation.planner``): leak, block and surface_recall with
    truth, walls_kept, leak_vs_standard and far_leak without (a result read back from an older
    file may lack them all, or far_leak alone). A result read back from a --json file
    (``read_results_file``) has no map."""

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
    holdout: dict | None = None  # with a held-out split: ``evaluation.holdout.holdout_scores``
    params: dict = field(default_factory=dict)  # the parameters the map records
    calibration: dict | None = None  # the map's stats["calibration"]: the forward model it learned
    results_file: str | None = None  # the --json file it was read back from
    planner: dict | None = None  # ``core.scores.PLANNER_KEYS`` -> value (NaN: nothing to measure)
    log_content: str | None = None  # ``io.provenance.content_sha256`` of the log: what --baseline matches logs by

    @property
    def truth(self) -> bool:
        """Whether the log has truth (and so the truth metrics and checks)."""
        return self.metrics is not None


# --- the JSON written by --json -------------------------------------------------------------------

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


def results_json(results: list[ModeResult], holdout: dict | None = None, provenance: dict | None = None,
                 extra: dict | None = None) -> dict:
    """``{"aogm_version", "results": [{log, world, mode, runtime_s, metrics}]}`` as in CONTRACT.md,
    plus ``format`` ("aogm-compare") and ``format_version`` (1) for reading it back
    (``read_results_file``), and ``provenance`` when given. Each result also has ``truth``
    (whether its log has truth), ``params`` (the parameters the map records), ``detector``
    (``{"path", "sha256"}`` for an adaptive map, else null) and ``calibration`` (the map's
    ``stats["calibration"]``: the forward model it learned, per round and ``final``, else null).

    A result of a log with truth has in ``metrics`` also what a planner sees (leak, block,
    surface_recall); one of a log without truth has there walls_kept, leak_vs_standard and far_leak only,
    and a ``consistency`` object beside it (``evaluation.consistency``: method, readings,
    endpoint_occupied, endpoint_occupied_8, endpoint_free, free_cells, free_contradicted).

    With held-out scores, each result's ``metrics`` also holds ``core.scores.SCORE_KEYS`` (and
    without truth only those), its ``params["holdout"]`` the split, and the top level the
    ``holdout`` object given: the split and the fixed reference the scores use
    (``report.compare.holdout_object``), or as read back (``read_results_file``).
    """
    out = []
    for r in results:
        item = {"log": r.log, "world": r.world, "mode": r.mode, "truth": r.truth, "runtime_s": _finite(float(r.runtime_s)),
                "metrics": metrics_json(r.metrics, r.holdout, r.planner), "params": r.params, "detector": r.detector,
                "calibration": r.calibration}
        if r.consistency is not None:
            item["consistency"] = consistency_json(r.consistency)
        if r.log_content is not None:
            item["log_content"] = r.log_content
        out.append(item)
    doc = {"format": RESULTS_FORMAT, "format_version": RESULTS_FORMAT_VERSION, "aogm_version": __version__,
           "results": out}
    if holdout is not None:
        doc["holdout"] = holdout
    if provenance is not None:
        doc["provenance"] = provenance
    doc.update(extra or {})  # the summary over the logs, the baseline's findings
    return doc


def json_bytes(results: list[ModeResult], holdout: dict | None = None, provenance: dict | None = None,
               extra: dict | None = None) -> bytes:
    """``results_json`` as the bytes of ``--json`` (committed with the command's other outputs)."""
    doc = results_json(results, holdout, provenance, extra)
    return (json.dumps(doc, indent=2, allow_nan=False) + "\n").encode("utf-8")


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
    auc = (split.get("reference") or {}).get("auc") if isinstance(split.get("reference"), dict) else None
    protocol = f" (AUC: {auc})" if isinstance(auc, str) else ""
    return f"held-out scores of --holdout {split.get('fraction')} --seed {split.get('seed')}{protocol}"


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


BAND_AUC = "holdout_auc_band"  # ``evaluation.holdout``: the held-out AUC's earlier definition
BANDED = "holdout_auc not measured (a file written before the axis protocol; its AUC is holdout_auc_band)"


def _axis_auc(holdout: dict) -> bool:
    """Whether a results file's ``holdout`` object records the AUC's protocol (its reference's
    ``auc``, ``evaluation.holdout.AUC_PROTOCOL``): files written before scored ``holdout_auc`` as
    ``holdout_auc_band`` is scored now, and are read back so (``holdout_auc`` then NaN)."""
    reference = holdout.get("reference")
    return isinstance(reference, dict) and "auc" in reference


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
        banded = holdout is not None and not _axis_auc(holdout)
        results = [self.result(item, f"results[{i}]", holdout is not None, banded) for i, item in enumerate(items)]
        if banded:  # as read back, so that it is written again as it now reads
            reference = holdout.get("reference") if isinstance(holdout.get("reference"), dict) else {}
            holdout = {**holdout, "reference": {**reference, "auc": BANDED}}
        return results, holdout

    def result(self, item, where: str, holdout: bool, banded: bool = False) -> ModeResult:

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
                      for k in SCORE_KEYS if not (banded and k == BAND_AUC)}
            if banded:  # written before the axis protocol: its holdout_auc is what holdout_auc_band is now
                scores[BAND_AUC], scores["holdout_auc"] = scores["holdout_auc"], math.nan
        truth_metrics = self.truth_metrics(metrics, f"{where}.metrics") if truth else None
        # what a planner sees: optional key by key, as files written before it was measured lack it
        # (and those written before far_leak lack far_leak alone)
        found = {k: get(metrics, k, f"{where}.metrics", _number_or_null, "a number or null")
                 for k in (TRUTH_KEYS if truth else STANDARD_KEYS) if k in (metrics or {})}
        content = get(item, "log_content", where, lambda v: isinstance(v, str), "a sha256 (hex)", required=False)
        return ModeResult(log, world, mode, _nan(runtime), truth_metrics, None, consistency=consistency,
                          detector=detector, holdout=scores, params=params, calibration=calibration,
                          results_file=self.path, planner={k: _nan(v) for k, v in found.items()} or None,
                          log_content=content)

    def truth_metrics(self, metrics: dict, where: str) -> dict:
        out = {k: _nan(self.get(metrics, k, where, _number_or_null, "a number or null",
                                required=k not in LATER_METRIC_KEYS)) for k in METRIC_KEYS}
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
