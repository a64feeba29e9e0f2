"""The summary over logs and the baseline's findings as ``aogm compare`` shows them: printed tables, rows of the
--csv table, and the Markdown of --markdown (for a CI job's summary page or a review comment)."""

from __future__ import annotations

from aogm_cli.report.baseline import BaselineReport, Change
from aogm_cli.report.summary import ALL, RUNTIME_RATIO, SUMMARY_METRICS, Estimate, GroupSummary, Summary

# the metrics of the printed and Markdown tables (the JSON and the CSV have every one of SUMMARY_METRICS)
SHOWN = ("accuracy", "occupied_f1", "ece", "leak", "block", "checks_passed", "walls_kept", "far_leak", "holdout_auc",
         RUNTIME_RATIO)
HEADERS = {"accuracy": "Accuracy", "occupied_f1": "Occ. F1", "ece": "ECE", "leak": "Leak", "block": "Block",
           "checks_passed": "Checks", "walls_kept": "Walls kept", "far_leak": "Far leak", "holdout_auc": "Held-out AUC",
           RUNTIME_RATIO: "vs standard"}
CSV_COLUMN = {RUNTIME_RATIO: "runtime_vs_standard"}  # a metric -> its column of --csv, when not its own name
STATISTICS = ("n", "mean", "sd", "ci_low", "ci_high", "median", "min", "max")
ALL_LABEL = "all logs"


def group_label(group: GroupSummary) -> str:
    return ALL_LABEL if group.name == ALL else group.name


def groups(summary: Summary) -> list[GroupSummary]:
    """The groups shown: each world's of two or more logs (one log's is its row of the table), then every log's
    when there are several worlds; a single log's when that is all there is."""
    shown = [g for g in summary.worlds if g.logs > 1]
    if len(summary.worlds) > 1:
        shown.append(summary.all)
    return shown or list(summary.worlds)


def shown_metrics(summary: Summary) -> list[str]:
    present = {k for g in groups(summary) for by in g.modes.values() for k in by}
    return [k for k in SHOWN if k in present]


def estimate_text(e: Estimate | None, n: int, signed: bool = False) -> str:
    """``mean ± half-width`` of an estimate (the mean alone for one value), ``(n=K)`` after it when it is of K
    values and not of the row's ``n``; "–" for none."""
    if e is None:
        return "–"
    text = f"{e.mean:+.4f}" if signed else f"{e.mean:.4f}"
    if e.ci_low is not None:
        text += f" ± {(e.ci_high - e.ci_low) / 2:.4f}"
    return text if e.n == n else f"{text} (n={e.n})"


def summary_rows(summary: Summary) -> tuple[list[str], list[list[str]], list[list[str]]]:
    """(metric columns, one row per group and mode, one row per group and pair of modes) as text."""
    metrics = shown_metrics(summary)
    per_mode, per_pair = [], []
    for g in groups(summary):
        for mode, by in g.modes.items():
            n = max(e.n for e in by.values())
            per_mode.append([group_label(g), mode, str(n), *(estimate_text(by.get(k), n) for k in metrics)])
        pairs = dict.fromkeys((d.mode, d.other) for d in g.differences)
        for mode, other in pairs:
            found = {d.metric: d for d in g.differences if (d.mode, d.other) == (mode, other)}
            n = max(d.estimate.n for d in found.values())
            per_pair.append([group_label(g), f"{mode} − {other}", str(n),
                             *(_difference_text(found.get(k), n) for k in metrics)])
    return metrics, per_mode, per_pair


def _difference_text(d, n: int) -> str:
    if d is None:
        return "–"
    return f"{estimate_text(d.estimate, n, signed=True)} {d.wins}/{d.ties}/{d.losses}"


def print_summary(summary: Summary, quiet: bool) -> None:
    """Print the summary: per group each mode's means with their 95% intervals, then the paired differences with
    wins/ties/losses."""
    import click
    from rich.console import Console
    from rich.table import Table

    console = Console()
    if not console.is_terminal:
        console = Console(width=max(console.width, 240), no_color=True, highlight=False)
    metrics, per_mode, per_pair = summary_rows(summary)
    for title, rows, first in (("summary over logs: mean ± 95% interval half-width (Student t)", per_mode, "Mode"),
                               ("paired differences on the same logs, and wins/ties/losses", per_pair, "Difference")):
        table = Table(title=None if quiet else title)
        for name in ("Logs", first, "n", *(HEADERS[k] for k in metrics)):
            table.add_column(name, justify="left" if name in ("Logs", first) else "right", no_wrap=True)
        previous = None
        for row in rows:
            if previous is not None and row[0] != previous:
                table.add_section()
            previous = row[0]
            table.add_row(*row)
        if rows:
            console.print(table)
    for line in check_lines(summary):
        click.echo(line)


def check_lines(summary: Summary) -> list[str]:
    """One line per group: on how many of its logs each mode passes each world check."""
    lines = []
    for g in (g for g in groups(summary) if g.name != ALL):  # a check is a world's
        found = [f"{mode} {name} {p}/{n}" for mode, by in g.checks.items() for name, (p, n) in by.items()]
        if found:
            lines.append(f"checks passed, {group_label(g)}: {', '.join(found)}")
    return lines


def csv_rows(summary: Summary) -> list[dict]:
    """The summary as rows of --csv: log empty, world the group ("all logs" for every log), mode the mode or
    "MODE-OTHER" for a paired difference, ``statistic`` which number the metric columns hold."""
    rows = []
    for g in [*summary.worlds, summary.all]:
        for mode, by in g.modes.items():
            for stat in STATISTICS:
                rows.append(_csv_row(g, mode, stat, {k: getattr(e, stat) for k, e in by.items()}))
        pairs = dict.fromkeys((d.mode, d.other) for d in g.differences)
        for mode, other in pairs:
            found = [d for d in g.differences if (d.mode, d.other) == (mode, other)]
            for stat in (*STATISTICS, "wins", "ties", "losses"):
                values = {d.metric: (getattr(d, stat) if stat in ("wins", "ties", "losses") else getattr(d.estimate, stat))
                          for d in found}
                rows.append(_csv_row(g, f"{mode}-{other}", stat, values))
    return rows


def _csv_row(g: GroupSummary, mode: str, stat: str, values: dict) -> dict:
    row = {"log": "", "world": group_label(g), "mode": mode, "statistic": stat}
    row.update({CSV_COLUMN.get(k, k): v for k, v in values.items() if k in SUMMARY_METRICS})
    return row


def _change_row(c: Change) -> str:
    return f"| {c.where} | {c.mode} | {c.metric} | {c.old:.6g} | {c.new:.6g} |"


def print_baseline(report: BaselineReport) -> None:
    """Print the baseline's findings: each regression and improvement (old -> new), the logs and modes on one side
    only, the logs that changed, and a count."""
    import click

    for kind, changes in (("REGRESSION", report.regressions), ("improvement", report.improvements)):
        for c in changes:
            click.echo(f"{kind} {c.where} {c.mode}.{c.metric}: {c.old:.6g} -> {c.new:.6g}")
    for side, pairs in (("only in the baseline", report.only_in_baseline), ("only in this run", report.only_in_run)):
        for log, mode in pairs:
            click.echo(f"{side}: {log} ({mode})")
    for log in report.changed_logs:
        click.echo(f"changed: {log} (its content differs from the baseline's; not compared)")
    click.echo(f"baseline {report.baseline}: {report.compared} values compared, {len(report.regressions)} "
               f"regressions, {len(report.improvements)} improvements")


def markdown(summary: Summary, report: BaselineReport | None) -> str:
    """The summary (and the baseline's findings) as GitHub-flavoured Markdown tables."""
    metrics, per_mode, per_pair = summary_rows(summary)
    head = "| Logs | {} | n | " + " | ".join(HEADERS[k] for k in metrics) + " |"
    rule = "|" + "---|" * (3 + len(metrics))
    lines = ["## Summary over logs", "", "Mean ± half-width of the 95% interval (Student t), (n) logs.", "",
             head.format("Mode"), rule, *("| " + " | ".join(r) + " |" for r in per_mode), ""]
    if checks := check_lines(summary):
        lines += ["Logs on which each mode passes each world check:", "", *(f"* {c}" for c in checks), ""]
    if per_pair:
        lines += ["## Paired differences", "", "Mean difference on the same logs ± 95% half-width, then "
                  "wins/ties/losses of the first mode.", "", head.format("Difference"), rule,
                  *("| " + " | ".join(r) + " |" for r in per_pair), ""]
    if report is not None:
        lines += [f"## Against the baseline `{report.baseline}`", "",
                  f"{report.compared} values compared: {len(report.regressions)} regressions, "
                  f"{len(report.improvements)} improvements.", ""]
        for title, changes in (("Regressions", report.regressions), ("Improvements", report.improvements)):
            if changes:
                lines += [f"### {title}", "", "| Where | Mode | Metric | Old | New |", "|---|---|---|---|---|",
                          *(_change_row(c) for c in changes), ""]
        for title, pairs in (("Only in the baseline", report.only_in_baseline), ("Only in this run", report.only_in_run)):
            if pairs:
                lines += [f"### {title}", "", *(f"* {log} ({mode})" for log, mode in pairs), ""]
        if report.changed_logs:
            lines += ["### Logs that changed (not compared)", "", *(f"* {log}" for log in report.changed_logs), ""]
    return "\n".join(lines)
