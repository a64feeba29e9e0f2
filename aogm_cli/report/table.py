"""The tables of ``aogm compare``: the one printed (``print_table``) and the CSV of ``--csv``
(``csv_bytes``), with what they share: how a log is labelled, runtimes relative to the standard
map of the same log, the share of checks passed.
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

from aogm_cli.core.scores import CONSISTENCY_KEYS, LEARNED_KEYS, METRIC_KEYS, PLANNER_KEYS, SCORE_KEYS

if TYPE_CHECKING:
    from aogm_cli.io.results import ModeResult
    from aogm_cli.report.scoring import ScoredLog


def checks_passed(metrics: dict | None) -> float | None:
    """Fraction of the world's checks that pass (1.0 when it has none); None without truth."""
    if metrics is None:
        return None
    checks = metrics["checks"]
    return sum(c["passed"] for c in checks) / len(checks) if checks else 1.0


def log_labels(entries: list[ScoredLog]) -> dict[str, str]:
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


# --- the table printed --------------------------------------------------------------------------

# what a planner sees (``evaluation.planner``) -> its column: with truth, then without
PLANNER_COLUMNS = {"leak": "Leak", "block": "Block", "surface_recall": "Surface", "walls_kept": "Walls kept",
                   "leak_vs_standard": "Leak vs std", "far_leak": "Far leak"}


class Shown(NamedTuple):
    """Which optional columns the printed table has: the consistency of a log without truth, the
    held-out scores, and what a planner sees (``PLANNER_COLUMNS``' keys found; older JSON: none)."""

    consistency: bool
    holdout: bool
    planner: list[str]

    @classmethod
    def of(cls, results: list[ModeResult]) -> Shown:
        return cls(any(r.consistency is not None for r in results), any(r.holdout is not None for r in results),
                   [k for k in PLANNER_COLUMNS if any(k in (r.planner or {}) for r in results)])


def print_table(results: list[ModeResult], labels: dict[str, str], quiet: bool) -> None:
    """Print the results as a table on stdout, one section per log (``labels`` names them),
    titled unless ``quiet``; wide enough for every column when stdout is not a terminal."""
    from rich.console import Console
    from rich.table import Table

    shown = Shown.of(results)
    console = Console()
    if not console.is_terminal:  # wide enough for every column, the held-out ones too
        console = Console(width=max(console.width, (260 if shown.holdout else 200) + 12 * len(shown.planner)),
                          no_color=True, highlight=False)
    relative = relative_runtimes(results)
    table = Table(title=None if quiet else "aogm compare")
    for name, justify in table_columns(shown):
        table.add_column(name, justify=justify, no_wrap=name != "Map", overflow="fold")
    previous = None
    for r in results:
        label = labels[r.log]
        if previous is not None and label != previous:
            table.add_section()
        previous = label
        table.add_row(*table_row(r, label, relative[(r.log, r.mode)], shown))
    console.print(table)


def table_columns(shown: Shown) -> list[tuple[str, str]]:
    """(header, justification) of every column of the printed table."""
    columns = [("World", "left"), ("Mode", "left"), ("Accuracy", "right"), ("Occ. F1", "right"), ("Brier", "right"),
               ("ECE", "right"), ("Checks", "right")]
    if shown.consistency:
        columns += [("Ends on occ.", "right"), ("±1 cell", "right"), ("Free contra.", "right")]
    columns += [(PLANNER_COLUMNS[k], "right") for k in shown.planner]
    if shown.holdout:
        columns += [("Held-out AUC", "right"), ("AUC (band)", "right"), ("Held-out loglik", "right"),
                    ("Held-out readings", "right"), ("Held-out scans", "right")]
    return [*columns, ("Runtime (s)", "right"), ("vs standard", "right"), ("Map", "left")]


def table_row(r: ModeResult, label: str, relative: float | None, shown: Shown) -> list[str]:
    """The cells of one result's row of the printed table (``table_columns``)."""
    if r.metrics is None:
        acc = f1 = brier = ece = checks = "n/a"
    else:
        acc = f"{r.metrics['accuracy']:.4f}"
        f1 = f"{r.metrics['occupied_f1']:.4f}"
        brier = f"{r.metrics['brier']:.4f}"
        ece = _share(r.metrics.get("ece"))
        passed = sum(c["passed"] for c in r.metrics["checks"])
        checks = f"{passed}/{len(r.metrics['checks'])}"
    row = [label, r.mode, acc, f1, brier, ece, checks]
    if shown.consistency:
        c = r.consistency or {}
        row += [_share(c.get("endpoint_occupied")), _share(c.get("endpoint_occupied_8")),
                _share(c.get("free_contradicted"))]
    row += [_share((r.planner or {}).get(k)) for k in shown.planner]
    if shown.holdout:
        h = r.holdout or {}
        row += [_share(h.get("holdout_auc")), _share(h.get("holdout_auc_band")), _share(h.get("holdout_loglik")),
                str(h.get("holdout_readings", "n/a")), str(h.get("holdout_scans", "n/a"))]
    return [*row, f"{r.runtime_s:.3f}", "–" if relative is None else f"x{relative:.2f}", _source(r)]


def _share(v) -> str:
    return "n/a" if v is None or v != v else f"{v:.4f}"  # v != v: NaN


def _source(r: ModeResult) -> str:
    """Where a row's map came from: a file given, or mapped here (and written to --maps-dir); for
    a result read back with --from-json, that file."""
    if r.results_file is not None:
        return f"json {Path(r.results_file).name}"
    if r.reused:
        return f"file {Path(r.map_file).name}"
    return "mapped" if r.map_file is None else f"mapped -> {Path(r.map_file).name}"


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
    return [*CSV_COLUMNS, *checks, "statistic"], rows


def csv_cell(value) -> str:
    """A CSV cell: empty for None and NaN, true/false, floats in full (``repr``) precision."""
    if hasattr(value, "item"):  # numpy scalars
        value = value.item()
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value) if isinstance(value, float) else str(value)


def csv_bytes(results: list[ModeResult], summary_rows: list[dict] | None = None) -> bytes:
    """``csv_table`` as the bytes of ``--csv`` (header line, then one line per log and mode), then the summary's
    rows (``report.summary_table.csv_rows``: their ``statistic`` column says what they hold)."""
    columns, rows = csv_table(results)
    rows += summary_rows or []
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([csv_cell(row.get(c)) for c in columns])
    return buffer.getvalue().encode("utf-8")

