"""Pictures (PNG, matplotlib Agg): a log's truth and trajectory, and a map's probabilities (free white,
occupied black, unobserved pale blue so that unknown never looks like p = 0.5, clusters outlined in
orange; checks green or red; where a planner drives tinted green, red where it leaks)."""

from __future__ import annotations

import io

import numpy as np

from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import check_kind

UNKNOWN_RGB = (0.80, 0.87, 0.96)
CLUSTER_COLOUR = "#ff7f0e"
CHECK_COLOURS = {"passable": "#2ca02c", "blocked": "#d62728"}  # a world check's endpoints, by kind
REACH_RGBA = (0.17, 0.63, 0.17, 0.25)  # translucent green: cells the planner reaches
LEAK_RGBA = (0.84, 0.15, 0.16, 0.75)  # red: cells it reaches that the robot cannot reach in truth


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def map_rgb(probability: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """(H, W, 3) floats: grey 1 - p where observed, the unknown colour elsewhere; row 0 = lowest y."""
    grey = 1.0 - np.clip(np.asarray(probability, dtype=np.float64), 0.0, 1.0)
    rgb = np.repeat(grey[:, :, None], 3, axis=2)
    rgb[~np.asarray(observed, dtype=bool)] = UNKNOWN_RGB
    return rgb


def draw_map(ax, grid: GridSpec, probability, observed, clusters=None, title: str | None = None) -> None:
    """Draw one map into a matplotlib axis: grey probabilities, unknown tinted, clusters outlined."""
    extent = grid.extent
    ax.imshow(map_rgb(probability, observed), origin="lower", extent=extent, interpolation="nearest")
    if clusters is not None and np.any(clusters > 0):
        xs = grid.origin_x + (np.arange(grid.width) + 0.5) * grid.resolution
        ys = grid.origin_y + (np.arange(grid.height) + 0.5) * grid.resolution
        ax.contour(xs, ys, (clusters > 0).astype(float), levels=[0.5], colors=CLUSTER_COLOUR, linewidths=0.8)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal")
    if title:
        ax.set_title(title, fontsize=9)


def _figure_size(grid: GridSpec, panels: int = 1) -> tuple[float, float]:
    w_m = grid.width * grid.resolution
    h_m = grid.height * grid.resolution
    aspect = h_m / max(w_m, 1e-9)
    width = min(16.0, 5.0 * panels + 1.0) if panels > 1 else 8.0
    return width, max(2.5, min(12.0, width / panels * aspect + 1.2))


def figure_png(fig) -> bytes:
    """The PNG bytes of a matplotlib figure, which is closed (the caller commits them with the
    command's other outputs: ``io.atomic.write_files_atomically``)."""
    plt = _pyplot()
    try:
        buffer = io.BytesIO()
        fig.savefig(buffer, format="png", dpi=120, bbox_inches="tight")
        return buffer.getvalue()
    finally:
        plt.close(fig)


def map_png(grid: GridSpec, probability, observed, clusters=None, title: str | None = None) -> bytes:
    """A PNG of one map."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=_figure_size(grid))
    draw_map(ax, grid, probability, observed, clusters, title)
    return figure_png(fig)


def draw_truth(ax, grid: GridSpec, occupancy, pose=None, checks=(), title: str | None = None) -> None:
    """Draw the truth grid, the trajectory and the checks' endpoints into an axis."""
    occ = np.asarray(occupancy, dtype=np.float64)
    draw_map(ax, grid, occ, np.ones_like(occ, dtype=bool), title=title)
    if pose is not None and len(pose):
        ax.plot(pose[:, 0], pose[:, 1], "-", color="#1f77b4", linewidth=1.0, label="trajectory")
        ax.plot(pose[0, 0], pose[0, 1], "o", color="#1f77b4", markersize=4)
    for check in checks:
        kind = check_kind(check)
        colour = CHECK_COLOURS[kind]
        (x0, y0), (x1, y1) = check[kind]["from"], check[kind]["to"]
        ax.plot([x0, x1], [y0, y1], ":", color=colour, linewidth=1.0)
        ax.plot([x0, x1], [y0, y1], "s" if kind == "passable" else "x", color=colour, markersize=4)
        ax.annotate(check["name"], (x1, y1), fontsize=7, color=colour)


def draw_reach(ax, grid: GridSpec, reach, leaked=None) -> None:
    """Tint the cells a planner reaches (``planner.map_reach``) over a drawn map, and the cells of
    them that it cannot reach in truth (``leaked``) in another colour."""
    rgba = np.zeros((*grid.shape, 4))
    rgba[np.asarray(reach, dtype=bool)] = REACH_RGBA
    if leaked is not None:
        rgba[np.asarray(leaked, dtype=bool)] = LEAK_RGBA
    ax.imshow(rgba, origin="lower", extent=grid.extent, interpolation="nearest")


def truth_png(log, title: str | None = None) -> bytes:
    """A PNG of a simulated log's truth grid, trajectory and checks."""
    plt = _pyplot()
    truth = log.truth
    fig, ax = plt.subplots(figsize=_figure_size(truth.grid))
    draw_truth(ax, truth.grid, truth.occupancy, log.pose, truth.checks, title=title)
    return figure_png(fig)
