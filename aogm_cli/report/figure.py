"""The comparison figure of ``aogm compare``, laid out like the paper's: one row per log, panels
truth | standard | em | adaptive (clusters outlined), each map titled with its accuracy and runtime.
"""

from __future__ import annotations

from aogm_cli.io.logfile import LogReader
from aogm_cli.report.compare import LogEntry, ModeResult
from aogm_cli.report.picture import draw_map, draw_truth, figure_png

PANEL_WIDTH = 4.0  # inches


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def panel_title(result: ModeResult) -> str:
    """``em  acc 0.973  0.21 s``; accuracy omitted without truth."""
    parts = [result.mode]
    if result.metrics is not None:
        parts.append(f"acc {result.metrics['accuracy']:.3f}")
    parts.append(f"{result.runtime_s:.3g} s")
    return "  ".join(parts)


def comparison_figure_png(entries: list[LogEntry], results: list[ModeResult], labels: dict[str, str]) -> bytes:
    """The PNG: a truth panel and one panel per mode for every log."""
    plt = _pyplot()
    by_log: dict[str, list[ModeResult]] = {}
    for r in results:
        by_log.setdefault(r.log, []).append(r)
    n_cols = 1 + max((len(v) for v in by_log.values()), default=0)
    heights = []
    for e in entries:
        grid = by_log[e.path][0].map.grid if by_log.get(e.path) else (e.truth.grid if e.truth else None)
        aspect = grid.height / max(grid.width, 1) if grid is not None else 1.0
        heights.append(max(1.5, min(6.0, PANEL_WIDTH * aspect)) + 0.7)
    fig, axes = plt.subplots(
        len(entries), n_cols, figsize=(PANEL_WIDTH * n_cols, sum(heights)), squeeze=False,
        gridspec_kw={"height_ratios": heights},
    )
    try:
        for row, e in zip(axes, entries, strict=True):
            label = labels.get(e.path, e.world)
            if e.truth is not None:
                with LogReader(e.path) as reader:
                    pose = reader.poses()
                draw_truth(row[0], e.truth.grid, e.truth.occupancy, pose, e.truth.checks, title=f"{label}: truth")
            else:
                row[0].set_axis_off()
                row[0].text(0.5, 0.5, f"{label}\n(no truth)", ha="center", va="center", transform=row[0].transAxes)
            mode_results = by_log.get(e.path, [])
            for ax, r in zip(row[1:], mode_results, strict=False):
                m = r.map
                draw_map(ax, m.grid, m.probability, m.observed, m.clusters, title=panel_title(r))
            for ax in row[1 + len(mode_results):]:
                ax.set_axis_off()
        fig.tight_layout()
    except BaseException:
        plt.close(fig)
        raise
    return figure_png(fig)
