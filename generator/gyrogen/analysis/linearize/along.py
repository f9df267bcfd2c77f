"""gyrogen linearize --along: the linearization along a trajectory, the
state transition matrix Phi(t) = dx(t)/dx0 (and dx(t)/dp for the scene's
sensitivities) on an output grid, from one integration of the scene's
variational system (Compiled.integrate_var_grid).

A scene without [sensitivities] is built with wrt = ["state"]; one that
declares them keeps its own (its parameters' columns after the state's)."""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gyrogen.abi import ODE_CODES, message
from gyrogen.analysis.simulate.engine import given_constants
from gyrogen.analysis.simulate.trajectory import output_grid
from gyrogen.errors import GyrogenError
from gyrogen.files import write_atomic
from gyrogen.runtime.scene_build import compiled, scene_sources
from gyrogen.scene import Scene, validate

NPZ, PLOT = "along.npz", "along.png"
STATE_COLUMNS = "state"


@dataclass(frozen=True)
class Along:
    """x and Phi on the grid, and what they were computed from."""

    scene: Scene
    method: str
    t: np.ndarray
    x: np.ndarray
    """(n, nx)."""
    phi: np.ndarray
    """(n, nx, ncol): the state's columns first (when wrt has "state")."""
    columns: tuple[str, ...]
    """Each column's name: x0's states, then the parameters of wrt."""
    p: np.ndarray
    tol: tuple[float, float]

    @property
    def state_columns(self) -> int:
        return sum(1 for c in self.columns if c in self.scene.states)

    def singular_values(self) -> np.ndarray:
        """(n, k) dx(t)/dx0's singular values, largest first (k = 0 when
        wrt has no "state")."""
        k = self.state_columns
        if not k:
            return np.zeros((len(self.t), 0))
        return np.linalg.svd(self.phi[:, :, :k], compute_uv=False)


def with_sensitivities(scene: Scene, method: str) -> Scene:
    """The scene built for --along: C, the one method, its sensitivities
    (wrt = ["state"] unless it declares its own)."""
    data = scene.model_dump(mode="json")
    data.setdefault("sensitivities", {"wrt": [STATE_COLUMNS]})
    data["targets"] = ["c"]
    data["integrators"] = [method]
    return validate(data, scene.name)


def along(
    scene: Scene,
    x0: np.ndarray,
    p: np.ndarray,
    method: str,
    t_end: float,
    dt: float,
) -> Along:
    """x and Phi from 0 to t_end every dt (the simulate grid's times)."""
    comp = compiled(scene_sources(with_sensitivities(scene, method)))
    c = given_constants(scene, comp, p)
    t = output_grid(t_end, dt)
    tol = (scene.simulate.rtol, scene.simulate.atol)
    x, phi, stats, code = comp.integrate_var_grid(method, x0, c, t, rtol=tol[0], atol=tol[1])
    if code:
        raise GyrogenError(
            f"{method} failed at t = {stats['t']:.6g} s along the trajectory with its state "
            f"transition matrix: {message(ODE_CODES, code)}"
        )
    columns = tuple(comp.manifest["variational"]["columns"])
    return Along(scene, method, t, x, phi, columns, p, tol)


def arrays(run: Along) -> dict[str, np.ndarray]:
    return {
        "t": run.t,
        "x": run.x,
        "Phi": run.phi,
        "x_names": np.array(run.scene.states, dtype=str),
        "columns": np.array(run.columns, dtype=str),
        "p": run.p,
        "p_names": np.array(run.scene.runtime, dtype=str),
        "singular_values": run.singular_values(),
    }


def report(run: Along) -> list[str]:
    """The run in words: the grid, the growth of dx/dx0, each parameter's
    largest sensitivity at the end."""
    n, end = len(run.t), float(run.t[-1])
    lines = [f"Phi = dx(t)/d({', '.join(_wrt(run))}) at {n} times from 0 to {end:g} s by "
             f"{run.method} (rtol {run.tol[0]:g}, atol {run.tol[1]:g})"]  # fmt: skip
    sv = run.singular_values()
    if sv.size:
        peak = int(np.argmax(sv[:, 0]))
        lines.append(
            f"  dx/dx0: largest singular value {sv[-1, 0]:.6g} at t = {end:g} s (peak "
            f"{sv[peak, 0]:.6g} at {run.t[peak]:g} s), smallest {sv[-1, -1]:.6g}; "
            f"det {np.linalg.det(run.phi[-1, :, : run.state_columns]):.6g}"
        )
    states = run.scene.states
    for j, name in enumerate(run.columns[run.state_columns :], run.state_columns):
        col = run.phi[-1, :, j]
        i = int(np.argmax(np.abs(col)))
        lines.append(f"  dx/d{name} at {end:g} s: largest d{states[i]}/d{name} = {col[i]:.6g}")
    return lines


def _wrt(run: Along) -> list[str]:
    return (["x0"] if run.state_columns else []) + list(run.columns[run.state_columns :])


def plot(run: Along) -> bytes:
    """The singular values of dx(t)/dx0 and each parameter column's norm
    over t, on a log scale: how perturbations grow along the run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    sv = run.singular_values()
    for k in range(sv.shape[1]):
        ax.semilogy(run.t, sv[:, k], color="tab:blue", lw=1, alpha=0.4 + 0.6 * (k == 0))
    if sv.size:
        ax.plot([], [], color="tab:blue", label="singular values of dx/dx0")
    for j, name in enumerate(run.columns[run.state_columns :], run.state_columns):
        ax.semilogy(run.t, np.linalg.norm(run.phi[:, :, j], axis=1), lw=1.5, label=f"|dx/d{name}|")
    ax.set_xlabel("t (s)")
    ax.set_title(f"{run.scene.name}: the state transition matrix along the trajectory")
    ax.grid(alpha=0.3, which="both")
    ax.legend(loc="best")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


def write(run: Along, out: Path, with_plot: bool) -> list[Path]:
    """along.npz (and along.png) in out, all or nothing."""
    buf = io.BytesIO()
    np.savez(buf, **arrays(run))  # type: ignore[arg-type]
    files: dict[str, Any] = {NPZ: buf.getvalue()}
    if with_plot:
        files[PLOT] = plot(run)
    write_atomic(out, files)
    return [out / name for name in files]
