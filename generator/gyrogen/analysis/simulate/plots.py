"""The trajectory figure of `gyrogen simulate`: one PNG, 2x2 panels.

Drawn on a bare matplotlib Figure (the Agg renderer, no pyplot): no display
is needed, and no global state is touched.
"""

from __future__ import annotations

import io
from collections.abc import Mapping

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from gyrogen.scene import Scene
from gyrogen.scene.rotors import gimbal_axes, unit_axes

SIZE_INCHES = (12.0, 8.0)
DPI = 100
PIXELS = (int(SIZE_INCHES[1] * DPI), int(SIZE_INCHES[0] * DPI))
"""(rows, columns) of the PNG."""
FLOOR = 1e-17
"""Smallest value shown on the log axis of the invariants (exact zeros at t = 0)."""


def _column(scene: Scene, x: np.ndarray, name: str) -> np.ndarray:
    return x[:, scene.states.index(name)]


def _body_rates(ax: Axes, scene: Scene, t: np.ndarray, x: np.ndarray) -> None:
    for name in ("u1", "u2", "u3"):
        ax.plot(t, _column(scene, x, name), label=name)
    ax.set(title="carrier angular velocity (A components)", ylabel="rad/s")


def _rotor(
    ax: Axes, scene: Scene, t: np.ndarray, x: np.ndarray, given: Mapping[str, float]
) -> None:
    if scene.rotors:
        _wheels(ax, scene, t, x, given)
        return
    u2, u4 = _column(scene, x, "u2"), _column(scene, x, "u4")
    ax.plot(t, u4, label="u4 (absolute)")
    ax.plot(t, u4 - u2, "--", label="u4 - u2 (relative to carrier)")
    ax.set(title="rotor rate about a2", ylabel="rad/s")


def _wheels(
    ax: Axes, scene: Scene, t: np.ndarray, x: np.ndarray, given: Mapping[str, float]
) -> None:
    """A cluster: each wheel's rate relative to the carrier, w_k - g_k . w_A
    (a runtime axis's g_k from the runtime values given); on a gimbal,
    relative to its gimbal: g_s turned by the gimbal angle gam_k."""
    w_a = np.column_stack([_column(scene, x, f"u{i}") for i in (1, 2, 3)])
    for k, (r, g) in enumerate(zip(scene.rotors, unit_axes(scene.rotors, given), strict=True), 1):
        along = w_a @ g
        if r.gimbal is not None:
            gam = _column(scene, x, f"gam{k}")
            turned = np.cross(gimbal_axes(r, k, given)[0], g)
            along = np.cos(gam) * along + np.sin(gam) * (w_a @ turned)
        ax.plot(t, _column(scene, x, f"w{k}") - along, label=f"w{k} - g{k}.w_A")
    ax.set(title="wheel rates relative to the carrier (or gimbal)", ylabel="rad/s")


def _attitude(ax: Axes, scene: Scene, t: np.ndarray, x: np.ndarray) -> None:
    if scene.attitude == "quaternion":
        for name in ("e0", "e1", "e2", "e3"):
            ax.plot(t, _column(scene, x, name), label=name)
        ax.set(title="Euler parameters of A in N", ylabel="dimensionless")
        return
    for name in ("q1", "q2", "q3"):
        ax.plot(t, np.degrees(_column(scene, x, name)), label=name)
    ax.set(title="3-1-2 Euler angles of A in N (unwrapped)", ylabel="deg")


def invariant_drifts(ax: Axes, t: np.ndarray, drifts: dict[str, np.ndarray]) -> None:
    top = FLOOR
    for label, values in drifts.items():
        shown = np.maximum(np.abs(values), FLOOR)
        ax.semilogy(t, shown, label=label, linewidth=0.9)
        top = max(top, float(shown.max()))
    # Three empty decades on top hold the legend clear of the curves.
    ax.set_ylim(FLOOR / 3, 10 ** (np.ceil(np.log10(top)) + 3))
    ax.legend(loc="upper right", ncol=2, fontsize="small")
    ax.set(title=f"invariants: |relative error| (floor {FLOOR:g})", ylabel="relative")


def trajectory_png(
    scene: Scene,
    t: np.ndarray,
    x: np.ndarray,
    drifts: dict[str, np.ndarray],
    given: Mapping[str, float] | None = None,
) -> bytes:
    """Body rates, rotor rate, attitude and the invariants' drifts (label ->
    relative error on t), as PNG bytes of exactly PIXELS; given: the runtime
    values by name (a runtime axis)."""
    fig = Figure(figsize=SIZE_INCHES, dpi=DPI, layout="constrained")
    (a, b), (c, d) = fig.subplots(2, 2, sharex=True)
    _body_rates(a, scene, t, x)
    _rotor(b, scene, t, x, given or {})
    _attitude(c, scene, t, x)
    invariant_drifts(d, t, drifts)
    for ax in (a, b, c):
        ax.ticklabel_format(axis="y", useOffset=False)  # 599.95, not 0.05 + 5.999e2
        ax.legend(loc="best", fontsize="small")
    for ax in (a, b, c, d):
        ax.grid(True, alpha=0.3)
    for ax in (c, d):
        ax.set_xlabel("t (s)")
    fig.suptitle(f"{scene.name}: {scene.description}")
    return png_bytes(fig)


def png_bytes(fig: Figure) -> bytes:
    """The figure as PNG at its own size and dpi (no bbox_inches="tight": the
    size stays fixed), for write_atomic."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=fig.dpi)
    return buf.getvalue()
