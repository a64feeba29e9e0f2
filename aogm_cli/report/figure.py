"""The comparison figure of ``aogm compare``, laid out like the paper's: one row per log, panels truth |
standard | em | adaptive (clusters outlined), each titled with its accuracy, leak and runtime and tinted
where a planner reaches in it (``evaluation.planner``), red beyond the truth's reach."""

from __future__ import annotations

from aogm_cli.evaluation.planner import ROBOT_RADIUS, map_reach, truth_reach
from aogm_cli.io.logfile import LogReader
from aogm_cli.io.results import ModeResult
from aogm_cli.report.picture import draw_map, draw_reach, draw_truth, figure_png
from aogm_cli.report.scoring import ScoredLog

PANEL_WIDTH = 4.0  # inches


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def panel_title(result: ModeResult) -> str:
    """``em  acc 0.973  leak 0.012  0.21 s``; accuracy omitted without truth, and leak there
    leak_vs_standard (``lvs``) and far_leak (``far``)."""
    parts = [result.mode]
    if result.metrics is not None:
        parts.append(f"acc {result.metrics['accuracy']:.3f}")
    planner = result.planner or {}
    for key, short in (("leak", "leak"), ("leak_vs_standard", "lvs"), ("far_leak", "far")):
        if planner.get(key) is not None:
            parts.append(f"{short} {planner[key]:.3f}")
    parts.append(f"{result.runtime_s:.3g} s")
    return "  ".join(parts)


def comparison_figure_png(entries: list[ScoredLog], results: list[ModeResult], labels: dict[str, str],
                          robot_radius: float = ROBOT_RADIUS) -> bytes:
    """The PNG: a truth panel and one panel per mode for every log; each map tinted where the
    planner of a robot of ``robot_radius`` reaches, leaked cells (truth logs) in red."""
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
            with LogReader(e.path) as reader:
                pose = reader.poses()
            in_truth = None
            if e.truth is not None:
                in_truth = truth_reach(e.truth.grid, e.truth.occupancy, pose, robot_radius)
                draw_truth(row[0], e.truth.grid, e.truth.occupancy, pose, e.truth.checks, title=f"{label}: truth")
            else:
                row[0].set_axis_off()
                row[0].text(0.5, 0.5, f"{label}\n(no truth)", ha="center", va="center", transform=row[0].transAxes)
            mode_results = by_log.get(e.path, [])
            for ax, r in zip(row[1:], mode_results, strict=False):
                m = r.map
                draw_map(ax, m.grid, m.probability, m.observed, m.clusters, title=panel_title(r))
                reach = map_reach(m.grid, m.probability, m.observed, pose, robot_radius)
                draw_reach(ax, m.grid, reach, None if in_truth is None else reach & ~in_truth)
            for ax in row[1 + len(mode_results):]:
                ax.set_axis_off()
        fig.tight_layout()
    except BaseException:
        plt.close(fig)
        raise
    return figure_png(fig)
