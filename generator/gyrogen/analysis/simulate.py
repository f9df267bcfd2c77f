"""Simulate a scene: generate, build, integrate with scipy's solve_ivp through
the compiled RHS, check the invariants with the numpy reference (witness), and
write the trajectory (CSV, npz), a summary and a figure, all or nothing.

Invariants, all relative (see `Invariants`): |H| in N is constant (and so is
the vector H); the energy balance K(t) - K(0) - int_0^t P dt with
P = T (u4 - u2) + M g u7 is 0; and u4(t) - u4(0) - int_0^t T dt / J is 0
(J u4' = T). The integrals are Gauss-Legendre sums, QUAD_NODES nodes inside
each output interval, sampled from solve_ivp's dense output along with the
grid: a trapezoid on the grid alone is off by ~(dt/tau)^2 wherever the torque
changes on a time scale tau near dt (the speed controller: 1e-2). A transient
much shorter than dt (stiff_wheel's 1e-5 s) is not resolved either way.

Between solver steps the output comes from solve_ivp's dense output, which is
less accurate than the steps themselves: in a long DOP853 step it can be off
by far more than rtol (speed_controlled: 1e-7 mid-step), and the residuals
show it. They measure the trajectory as written, not only the steps.
"""

from __future__ import annotations

import io
import json
import time
from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

from gyrogen import methods
from gyrogen.abi import ODE_CODES, STATES, message
from gyrogen.errors import GyrogenError, SceneError
from gyrogen.files import make_dir, write_atomic
from gyrogen.oracle import scene_view
from gyrogen.runtime.compiled import Compiled, Language, controls
from gyrogen.runtime.rhs import RawRhs
from gyrogen.runtime.scene_build import build_scene
from gyrogen.runtime.segment import integrate_segments
from gyrogen.scene import Scene

MAX_NFEV = 10**7
"""RHS calls before giving up: a run that blows up can crawl for hours
without solve_ivp ever failing (its steps shrink as the state grows)."""
QUAD_NODES = 3
QUADRATURE = f"Gauss-Legendre, {QUAD_NODES} nodes per output interval, on solve_ivp's dense output"
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(QUAD_NODES)
Advance = Callable[[int], None]
"""Told how many more percent of the simulated time are done."""
Progress = Callable[[str], AbstractContextManager[Advance]]
"""label -> a context holding an Advance (a progress bar)."""


def _no_progress(label: str) -> AbstractContextManager[Advance]:
    return nullcontext(lambda n: None)


@dataclass(frozen=True)
class Settings:
    t_end: float
    dt: float
    method: str = "DOP853"
    plot: bool = True
    max_nfev: int = MAX_NFEV


@dataclass(frozen=True)
class Trajectory:
    t: np.ndarray
    """(n,) the output grid."""
    x: np.ndarray
    """(n, nx) states in the scene's order."""
    t_nodes: np.ndarray
    """(n - 1, QUAD_NODES) Gauss-Legendre nodes inside each output interval."""
    x_nodes: np.ndarray
    """(n - 1, QUAD_NODES, nx) the states there."""
    nfev: int
    wall: float
    """Seconds spent in solve_ivp."""


@dataclass(frozen=True)
class Invariants:
    h: np.ndarray
    """(n, 3) angular momentum about AB* in N."""
    kinetic: np.ndarray
    power: np.ndarray
    """T (u4 - u2) + M g u7: dK/dt."""
    h_drift: np.ndarray
    """(|H| - |H(0)|) / |H(0)|."""
    h_vector_drift: np.ndarray
    """|H - H(0)| / |H(0)|: also sees errors of the attitude, which |H| does not."""
    energy: np.ndarray
    """(K - K(0) - int P dt) / max |K|."""
    u4: np.ndarray
    """(u4 - u4(0) - int T dt / J) / max |u4|."""

    def worst(self) -> dict[str, float]:
        return {
            "H_norm_relative_drift": _peak(self.h_drift),
            "H_vector_relative_drift": _peak(self.h_vector_drift),
            "energy_balance_relative_residual": _peak(self.energy),
            "u4_relative_residual": _peak(self.u4),
        }


@dataclass(frozen=True)
class Result:
    scene: Scene
    out: Path
    language: str
    build_id: str
    settings: Settings
    trajectory: Trajectory
    invariants: Invariants
    files: tuple[Path, ...]


def _peak(a: np.ndarray) -> float:
    return float(np.max(np.abs(a))) if a.size else 0.0


def runtime_values(scene: Scene) -> np.ndarray:
    """simulate.parameters in p[] order; every runtime parameter needs one."""
    given = scene.simulate.parameters
    missing = [n for n in scene.runtime if n not in given]
    if missing:
        raise SceneError(
            f"{scene.name}: simulate.parameters: no value for runtime parameter "
            f"{', '.join(missing)} (set it under [simulate] parameters)"
        )
    return np.array([given[n] for n in scene.runtime], dtype=np.float64)


def output_grid(t_end: float, dt: float) -> np.ndarray:
    # Clipped: rounding in arange must not put the last point past t_end,
    # which solve_ivp refuses.
    return np.minimum(np.arange(0.0, t_end + dt / 2, dt), t_end)


def sample_times(grid: np.ndarray) -> np.ndarray:
    """The grid with the quadrature nodes of each interval between its
    points, in order: every (QUAD_NODES + 1)-th time is a grid point."""
    a, b = grid[:-1, None], grid[1:, None]
    nodes = 0.5 * (a + b) + 0.5 * (b - a) * _NODES
    return np.concatenate([np.column_stack([grid[:-1], nodes]).ravel(), grid[-1:]])


class _Exhausted(Exception):
    pass


class _Rhs(RawRhs):
    """The raw rhs for solve_ivp, advancing the progress bar by simulated
    time at most once per percent (the bookkeeping adds ~0.1 us a call), and
    giving up after budget calls."""

    def __init__(self, comp: Compiled, c: np.ndarray, t_end: float, advance: Advance, budget: int):
        super().__init__(comp, c)
        self.t_end, self.advance = t_end, advance
        self.shown, self.mark, self.t_max = 0, t_end / 100, 0.0
        self.calls, self.budget = 0, budget

    def __call__(self, t: float, x: np.ndarray) -> np.ndarray:
        out = super().__call__(t, x)
        self.calls += 1
        if self.calls > self.budget:
            raise _Exhausted
        if t > self.t_max:
            self.t_max = t
            if t >= self.mark:
                self._tick(t)
        return out

    def _tick(self, t: float) -> None:
        pct = min(int(100 * t / self.t_end), 100)
        self.advance(pct - self.shown)
        self.shown = pct
        self.mark = (pct + 1) * self.t_end / 100

    def finish(self) -> None:
        self.advance(100 - self.shown)
        self.shown = 100


def integrate_compiled(
    comp: Compiled,
    c: np.ndarray,
    x0: np.ndarray,
    settings: Settings,
    tol: tuple[float, float],
    advance: Advance,
) -> Trajectory:
    """The generated integrator from each sample time to the next: every
    output is a step end, so no interpolation error (rk4: 100 steps an
    interval)."""
    method = settings.method
    if method not in comp.manifest["integrators"]:
        raise SceneError(
            f"{comp.manifest['prefix']}: method {method} is not among the scene's integrators "
            f"({', '.join(comp.manifest['integrators']) or 'none'})"
        )
    grid = output_grid(settings.t_end, settings.dt)
    samples = sample_times(grid)
    shown = [0]

    def reached(t: float) -> None:
        pct = int(100 * t / grid[-1])
        advance(pct - shown[0])
        shown[0] = pct

    given = controls(method, steps=100, rtol=tol[0], atol=tol[1], max_steps=settings.max_nfev)
    t0 = time.perf_counter()
    seg = integrate_segments(comp, method, x0, c, samples, given, reached)
    wall = time.perf_counter() - t0
    if seg.code != 0:
        why = message(ODE_CODES, seg.code)
        raise GyrogenError(f"{method} failed at t = {seg.totals['t']:.6g} s: {why}")
    return _trajectory(grid, samples, seg.states, int(seg.totals["rhs_calls"]), wall)


def _trajectory(
    grid: np.ndarray, samples: np.ndarray, y: np.ndarray, nfev: int, wall: float
) -> Trajectory:
    """Split the states at the sample times into the output grid and the
    quadrature nodes inside each interval."""
    step, n = QUAD_NODES + 1, len(grid)
    inner = y[:-1].reshape(n - 1, step, -1)[:, 1:]  # drop the grid point opening each interval
    t_nodes = samples[:-1].reshape(n - 1, step)[:, 1:]
    return Trajectory(grid, y[::step], t_nodes, inner, nfev, wall)


def integrate(
    comp: Compiled,
    c: np.ndarray,
    x0: np.ndarray,
    settings: Settings,
    tol: tuple[float, float],
    advance: Advance,
) -> Trajectory:
    """solve_ivp from 0 to the grid's end, sampled on the grid and the
    quadrature nodes; a failure is one line with the time reached."""
    if settings.method in methods.NAMES:
        return integrate_compiled(comp, c, x0, settings, tol, advance)
    grid = output_grid(settings.t_end, settings.dt)
    f = _Rhs(comp, c, grid[-1], advance, settings.max_nfev)
    samples = sample_times(grid)
    t0 = time.perf_counter()
    try:
        sol = solve_ivp(f, (0.0, grid[-1]), x0, settings.method, samples, rtol=tol[0], atol=tol[1])
    except _Exhausted:
        sol = None
    wall = time.perf_counter() - t0
    check_solution(sol, settings.method, f.t_max, grid[-1], settings.max_nfev)
    f.finish()
    return _trajectory(grid, samples, np.ascontiguousarray(sol.y.T), int(sol.nfev), wall)


def check_solution(sol: Any, method: str, t_max: float, t_end: float, max_nfev: int) -> None:
    """One line for a run that gave up (sol None: the RHS budget ran out),
    failed, or left non-finite states behind; t_max: the latest time tried."""
    at = f"{method} failed at t = {t_max:.6g} s of {t_end:g}"
    if sol is None:
        raise GyrogenError(
            f"{at}: {max_nfev} RHS calls (--max-nfev) spent; "
            "the state may be blowing up, or the scene is stiff (try --method Radau)"
        )
    if sol.status < 0:
        raise GyrogenError(f"{at}: {sol.message}")
    bad = ~np.all(np.isfinite(sol.y), axis=0)
    if bad.any():
        raise GyrogenError(f"{method}: non-finite state at t = {sol.t[np.argmax(bad)]:.6g} s")


def _scale(a: np.ndarray) -> float:
    """The largest |a|, or 1 when a is all zero (then the residual is absolute)."""
    return float(np.max(np.abs(a))) or 1.0


def _rates(scene: Scene, p: np.ndarray, t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(m, 2): the power P = dK/dt and the torque T at times t (m,), states
    x (m, nx), from the scene's torque law as the reference applies it."""
    v = scene_view.values(scene, p)
    full = scene_view.full_states(scene, x)
    if scene.effects.torque == "table":  # scene_view.torque takes one t; the table needs each
        table = np.array(scene.effects.torque_table)
        torque = np.interp(t, table[:, 0], table[:, 1])
    else:
        torque = scene_view.torque(scene, v, full, 0.0)
    u2, u4, u7 = (full[:, STATES.index(s)] for s in ("u2", "u4", "u7"))
    power = torque * (u4 - u2) + (v["m_a"] + v["m_b"]) * v.get("g", 0.0) * u7
    return np.column_stack([power, torque])


def _integrals(scene: Scene, p: np.ndarray, traj: Trajectory) -> np.ndarray:
    """(n, 2): int_0^t of P and of T at each grid time, Gauss-Legendre per interval."""
    n1, q = traj.t_nodes.shape
    rates = _rates(scene, p, traj.t_nodes.ravel(), traj.x_nodes.reshape(n1 * q, -1))
    half = 0.5 * np.diff(traj.t)
    pieces = half[:, None] * np.einsum("iqk,q->ik", rates.reshape(n1, q, 2), _WEIGHTS)
    return np.vstack([np.zeros((1, 2)), np.cumsum(pieces, axis=0)])


def invariants(scene: Scene, p: np.ndarray, traj: Trajectory) -> Invariants:
    """From the numpy reference, never from the generated code under test."""
    x = traj.x
    h = scene_view.output(scene, "angular_momentum", x, p)
    k = scene_view.output(scene, "kinetic_energy", x, p)[:, 0]
    u4 = x[:, scene.states.index("u4")]
    work = _integrals(scene, p, traj)
    h_norm = np.linalg.norm(h, axis=1)
    h0 = h_norm[0] or _scale(h_norm)
    return Invariants(
        h=h,
        kinetic=k,
        power=_rates(scene, p, traj.t, x)[:, 0],
        h_drift=(h_norm - h_norm[0]) / h0,
        h_vector_drift=np.linalg.norm(h - h[0], axis=1) / h0,
        energy=(k - k[0] - work[:, 0]) / _scale(k),
        u4=(u4 - u4[0] - work[:, 1] / scene_view.values(scene, p)["J"]) / _scale(u4),
    )


COLUMNS = ("H_norm", "K", "H_drift", "H_vector_drift", "energy_residual", "u4_residual")
"""Invariant columns of trajectory.csv, after t and the states."""


def _columns(inv: Invariants) -> np.ndarray:
    h_norm = np.linalg.norm(inv.h, axis=1)
    cols = (h_norm, inv.kinetic, inv.h_drift, inv.h_vector_drift, inv.energy, inv.u4)
    return np.column_stack(cols)


def csv_text(scene: Scene, traj: Trajectory, inv: Invariants) -> str:
    buf = io.StringIO()
    data = np.column_stack([traj.t, traj.x, _columns(inv)])
    header = ",".join(("t", *scene.states, *COLUMNS))
    # %.17g: the CSV holds the same doubles as the npz.
    np.savetxt(buf, data, fmt="%.17g", delimiter=",", header=header, comments="")
    return buf.getvalue()


def npz_bytes(scene: Scene, traj: Trajectory, inv: Invariants) -> bytes:
    buf = io.BytesIO()
    np.savez(
        buf,
        t=traj.t,
        x=traj.x,
        names=np.array(scene.states),  # a str array: loads without allow_pickle
        H=inv.h,
        H_norm=np.linalg.norm(inv.h, axis=1),
        K=inv.kinetic,
        P=inv.power,
        H_drift=inv.h_drift,
        H_vector_drift=inv.h_vector_drift,
        energy_residual=inv.energy,
        u4_residual=inv.u4,
    )
    return buf.getvalue()


def summary(res: Result, p: np.ndarray) -> dict[str, Any]:
    s, traj = res.scene, res.trajectory
    return {
        "scene": s.name,
        "description": s.description,
        "build_id": res.build_id,
        "backend": res.language,
        "method": res.settings.method,
        "rtol": s.simulate.rtol,
        "atol": s.simulate.atol,
        "t_end": float(traj.t[-1]),
        "dt": res.settings.dt,
        "points": len(traj.t),
        "nfev": traj.nfev,
        "wall_time_s": traj.wall,
        "initial": dict(zip(s.states, s.initial_state(), strict=True)),
        "parameters": dict(zip(s.runtime, map(float, p), strict=True)),
        "invariants": res.invariants.worst(),
        "quadrature": QUADRATURE,
        "invariants_note": (
            "largest |value| over the output grid. H_norm_relative_drift: (|H| - |H(0)|)/|H(0)|, "
            "H about AB* in N; H_vector_relative_drift: |H - H(0)|/|H(0)|. "
            "energy_balance_relative_residual: (K - K(0) - int P dt)/max|K|, "
            "P = T (u4 - u2) + M g u7. u4_relative_residual: (u4 - u4(0) - int T dt/J)/max|u4|."
        ),
        "files": [f.name for f in res.files],
    }


def _prepare(scene: Scene, out: Path) -> tuple[Compiled, str]:
    """Sources into out/src (kept beside the trajectory they made), then the
    C backend, or Fortran when the scene builds no C."""
    language: Language = "c" if "c" in scene.targets else "fortran"
    unit, built = build_scene(scene, out / "src", [language])
    return built[language], unit.build_id


def run(
    scene: Scene,
    out: Path,
    settings: Settings,
    progress: Progress = _no_progress,
    echo: Callable[[str], None] = lambda s: None,
) -> Result:
    p = runtime_values(scene)  # first: a scene error must leave nothing behind
    make_dir(out)
    echo(f"generating and building {scene.name} in {out / 'src'} ...")
    comp, build_id = _prepare(scene, out)
    try:
        c = comp.setup(p)
    except ValueError as exc:
        raise SceneError(f"{scene.name}: simulate.parameters: {exc}") from exc
    tol = (scene.simulate.rtol, scene.simulate.atol)
    x0 = np.array(scene.initial_state())
    end = output_grid(settings.t_end, settings.dt)[-1]
    with progress(f"integrating {scene.name} to t = {end:g} s") as advance:
        traj = integrate(comp, c, x0, settings, tol, advance)
    inv = invariants(scene, p, traj)
    names = ["trajectory.csv", "trajectory.npz", "summary.json"]
    names += ["trajectory.png"] if settings.plot else []
    files = tuple(out / n for n in names)
    res = Result(scene, out, comp.language, build_id, settings, traj, inv, files)
    write_atomic(out, _contents(res, p))
    return res


def _contents(res: Result, p: np.ndarray) -> dict[str, bytes]:
    scene, traj, inv = res.scene, res.trajectory, res.invariants
    blobs = {
        "trajectory.csv": csv_text(scene, traj, inv).encode(),
        "trajectory.npz": npz_bytes(scene, traj, inv),
        "summary.json": (json.dumps(summary(res, p), indent=2) + "\n").encode(),
    }
    if res.settings.plot:
        from gyrogen.analysis import plots  # matplotlib: loaded only when a plot is wanted

        blobs["trajectory.png"] = plots.trajectory_png(scene, traj.t, traj.x, _drifts(inv))
    return blobs


def _drifts(inv: Invariants) -> dict[str, np.ndarray]:
    return {
        "|H| relative drift": inv.h_drift,
        "|H - H(0)| / |H(0)|": inv.h_vector_drift,
        "energy balance residual / max K": inv.energy,
        "u4 residual / max |u4|": inv.u4,
    }


_LANGUAGE = {"c": "C", "fortran": "Fortran"}


def summary_lines(res: Result) -> list[str]:
    traj, worst, s = res.trajectory, res.invariants.worst(), res.scene.simulate
    files = ", ".join(f.name for f in res.files)
    return [
        f"{res.scene.name}: {res.settings.method} (rtol {s.rtol:g}, atol {s.atol:g}) on the "
        f"{_LANGUAGE[res.language]} RHS, build {res.build_id}",
        f"  final time      {traj.t[-1]:g} s ({len(traj.t)} points, dt {res.settings.dt:g} s)",
        f"  nfev            {traj.nfev}",
        f"  wall time       {traj.wall:.3f} s "
        + ("(compiled integrator)" if res.settings.method in methods.NAMES else "(solve_ivp)"),
        f"  |H| in N        relative drift {worst['H_norm_relative_drift']:.2e} "
        f"(vector H: {worst['H_vector_relative_drift']:.2e})",
        f"  energy balance  K - K(0) - int P dt: {worst['energy_balance_relative_residual']:.2e}"
        " of max K (quadrature: Gauss-Legendre)",
        f"  u4 check        u4 - u4(0) - int T dt/J: {worst['u4_relative_residual']:.2e}"
        " of max |u4|",
        f"wrote {res.out}/ ({files}; sources in src/)",
    ]
