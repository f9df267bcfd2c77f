"""What `gyrogen linearize` writes and prints: linear.npz (A, B, C, D and
their names, the equilibrium, the eigenvalues), the modes in words, and
with --plot poles.png, the pole map."""

from __future__ import annotations

import io
import math
from pathlib import Path
from typing import Any

import numpy as np

from gyrogen.analysis.linearize import modes
from gyrogen.analysis.linearize.engine import RESIDUAL_BAR, Linear
from gyrogen.files import write_atomic

NPZ, PLOT = "linear.npz", "poles.png"


def arrays(lin: Linear) -> dict[str, np.ndarray]:
    """The .npz's arrays: the matrices, their names, x, p, the eigenvalues."""
    return {
        "A": lin.A,
        "B": lin.B,
        "C": lin.C,
        "D": lin.D,
        "states": np.array(lin.states, dtype=str),
        "inputs": np.array(lin.inputs, dtype=str),
        "outputs": np.array(lin.outputs, dtype=str),
        "dropped": np.array(lin.dropped, dtype=str),
        "x": lin.x,
        "x_names": np.array(lin.scene.states, dtype=str),
        "p": lin.p,
        "p_names": np.array(lin.scene.runtime, dtype=str),
        "eigenvalues": lin.eigenvalues,
        "residual": np.array(lin.residual),
    }


def npz_bytes(lin: Linear) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays(lin))  # type: ignore[arg-type]
    return buf.getvalue()


def warning(lin: Linear) -> str | None:
    """The one line a point that is no equilibrium gets, else None."""
    if lin.relative_residual <= RESIDUAL_BAR:
        return None
    share = lin.relative_residual
    why = (
        "which no state moves (its row of A is 0)"
        if math.isinf(share)
        else f"{share:.3g} of its row's |A| max(|x|, 1), above {RESIDUAL_BAR:g}"
    )
    return (
        f"warning: not an equilibrium: max |dx/dt| over the kept states is {lin.residual:.3g} "
        f"({lin.worst}' = {lin.worst_rate:.3g}, {why}); the model is about a moving point"
    )


def report(lin: Linear) -> list[str]:
    """The summary: the point, the sizes, the verdict and every mode in words."""
    found = modes.modes(lin.A, lin.states)
    x = ", ".join(f"{n} = {v:.9g}" for n, v in zip(lin.scene.states, lin.x, strict=True))
    lines = [
        f"scene {lin.scene.name}: {lin.found}",
        f"  at {x}",
        f"  max |dx/dt| over the kept states: {lin.residual:.3g}",
        f"  states ({len(lin.states)}): {', '.join(lin.states)}",
    ]
    if lin.dropped:
        lines.append(f"  left out (their rates do not vanish): {', '.join(lin.dropped)}")
    lines += [
        f"  inputs ({len(lin.inputs)}): {', '.join(lin.inputs) or 'none'}",
        f"  outputs ({len(lin.outputs)}): {', '.join(lin.outputs) or 'none'}",
        f"{modes.overall(found)}: {len(found)} modes (eigenvalues in 1/s, a pair once)",
    ]
    lines += [f"  {m.words()}" for m in found]
    return lines


def plot(lin: Linear) -> bytes:
    """The pole map: eigenvalues in the complex plane, by verdict."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4, 4.8))
    ax = fig.add_subplot()
    colors = {
        "stable": "tab:blue",
        "marginal": "tab:gray",
        "unstable": "tab:red",
        modes.CANNOT: "tab:orange",
    }
    found = modes.modes(lin.A, lin.states)
    for verdict, color in colors.items():
        pts = [
            v
            for m in found
            if m.verdict == verdict
            for v in (
                m.values
                or ((m.eigenvalue, m.eigenvalue.conjugate()) if m.oscillating else (m.eigenvalue,))
            )
        ]
        if pts:
            z = np.array(pts)
            ax.plot(z.real, z.imag, "x", ms=9, mew=2, color=color, label=verdict)
    ax.axvline(0.0, color="black", lw=0.6)
    ax.axhline(0.0, color="black", lw=0.6)
    ax.set_xlabel("Re lambda (1/s)")
    ax.set_ylabel("Im lambda (rad/s)")
    ax.set_title(f"{lin.scene.name}: poles of A ({len(lin.states)} states)")
    ax.legend(loc="best")
    ax.grid(alpha=0.3)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    return buf.getvalue()


def write(lin: Linear, out: Path, with_plot: bool) -> list[Path]:
    """linear.npz (and poles.png) in out, all or nothing."""
    files: dict[str, Any] = {NPZ: npz_bytes(lin)}
    if with_plot:
        files[PLOT] = plot(lin)
    write_atomic(out, files)
    return [out / name for name in files]
