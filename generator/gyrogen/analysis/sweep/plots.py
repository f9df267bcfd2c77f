"""The figures of a sweep: histograms of its metrics, and for a 2-D grid a
map of one metric over the grid, with a boundary overlaid when the sweep
has a criterion. Bare matplotlib Figures (Agg, no pyplot)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from gyrogen.analysis.simulate.plots import png_bytes
from gyrogen.analysis.sweep.columns import Histogram, log_scale

Scale = Callable[[Any], Any]


def histograms_png(title: str, histograms: dict[str, Histogram]) -> bytes:
    """One panel per histogram, on a log axis when it was binned so."""
    n = max(1, len(histograms))
    cols = min(3, n)
    rows = -(-n // cols)
    fig = Figure(figsize=(4.5 * cols, 3.2 * rows), dpi=100, layout="constrained")
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    for ax, (name, h) in zip(axes, histograms.items(), strict=False):
        if h.counts.size:
            ax.stairs(h.counts, h.edges, fill=True)
        if h.log:
            ax.set_xscale("log")
        ax.set(title=f"{name} ({h.finite:,} finite of {h.total:,})", ylabel="trajectories")
        ax.grid(True, alpha=0.3)
    for ax in axes[len(histograms) :]:
        ax.axis("off")
    fig.suptitle(title)
    return png_bytes(fig)


@dataclass(frozen=True)
class MapData:
    """A metric over a 2-D grid: z[i, j] at (x[j], y[i])."""

    title: str
    x_name: str
    x: np.ndarray
    y_name: str
    y: np.ndarray
    z_name: str
    z: np.ndarray
    boundary: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    """(X, Y, F) on a fine mesh: the boundary is F = 0."""
    boundary_label: str = ""
    second_y: tuple[str, Scale, Scale] | None = None
    """(label, forward, inverse): a second scale for the y axis."""


def map_png(data: MapData) -> bytes:
    fig = Figure(figsize=(9.0, 7.0), dpi=100, layout="constrained")
    ax = fig.subplots()
    finite = data.z[np.isfinite(data.z)]
    norm = LogNorm(finite.min(), finite.max()) if log_scale(finite.min(), finite.max()) else None
    mesh = ax.pcolormesh(data.x, data.y, data.z, shading="nearest", norm=norm, cmap="viridis")
    fig.colorbar(mesh, ax=ax, label=data.z_name)
    if data.boundary is not None:
        X, Y, F = data.boundary
        ax.contour(X, Y, F, levels=[0.0], colors="red", linewidths=1.5)
        ax.legend([Line2D([], [], color="red")], [data.boundary_label], loc="upper right")
    if data.second_y is not None:
        label, forward, inverse = data.second_y
        ax.secondary_yaxis("right", functions=(forward, inverse)).set_ylabel(label)
    ax.set(xlabel=data.x_name, ylabel=data.y_name, title=data.title)
    return png_bytes(fig)
