"""Error against run time: every way of integrating a scene, measured.

For one scene: a reference solution (DOP853 in C at rtol = atol = 1e-13,
cross-checked against scipy and, for the torque-free scene, the closed form),
then each method at a ladder of tolerances (step counts for RK4): the
compiled integrators in C and Fortran, scipy's solve_ivp with the numpy
reference and with the compiled RHS through cffi, and PyDy's cython RHS when
it is installed. Wall times are the best of several repeats, compilation
excluded. workprec_report.py writes the tables and the figure.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

from gyrogen import methods
from gyrogen.abi import ODE_CODES, STATES, message
from gyrogen.analysis.bench.timing import best_time
from gyrogen.errors import GyrogenError
from gyrogen.oracle import scene_view
from gyrogen.oracle.compare import scaled_error
from gyrogen.runtime.compiled import Compiled, Controls, controls
from gyrogen.runtime.rhs import RawRhs
from gyrogen.runtime.segment import integrate_segments
from gyrogen.scene import Scene

REF_TOL = 1e-13
SLOW = 2.0
"""A scipy run slower than this (s) is timed once."""
TOO_SLOW = 20.0
"""After a scipy run slower than this (s), tighter tolerances are skipped."""


@dataclass(frozen=True)
class Config:
    tolerances: tuple[float, ...]
    rk4_steps: tuple[int, ...]
    scipy_tolerances: tuple[float, ...]
    repeats: int
    max_calls: int
    """Give a scipy run up after this many RHS calls (RK45 on a stiff scene)."""
    fortran: bool


FULL = Config(
    tolerances=tuple(10.0 ** (-k / 2) for k in range(4, 29)),  # 1e-2 .. 1e-14, half decades
    rk4_steps=(100, 200, 400, 800, 1600, 3200, 6400, 12800, 25600, 51200),
    scipy_tolerances=tuple(10.0**-k for k in range(3, 13)),
    repeats=5,
    max_calls=1_000_000,
    fortran=True,
)
QUICK = Config(
    tolerances=(1e-3, 1e-5, 1e-7, 1e-9, 1e-11, 1e-12),
    rk4_steps=(200, 800, 3200, 12800),
    scipy_tolerances=(1e-3, 1e-6, 1e-9),
    repeats=2,
    max_calls=200_000,
    fortran=False,
)


@dataclass(frozen=True)
class Run:
    method: str
    backend: str
    setting: float
    """Tolerance (rtol = atol), or the number of steps for RK4."""
    error: float
    """Mixed error max_i |x_i - ref_i| / (atol/rtol + |ref_i|) at t1 (atol = rtol)."""
    seconds: float
    rhs_calls: int
    status: str = "ok"

    @property
    def label(self) -> str:
        return f"{self.method} ({self.backend})"

    @property
    def digits(self) -> float:
        return -math.log10(self.error) if self.error > 0 else 16.0


@dataclass
class Problem:
    scene: Scene
    compiled: dict[str, Compiled]
    p: np.ndarray
    c: np.ndarray
    x0: np.ndarray
    t1: float
    ref: np.ndarray = field(default_factory=lambda: np.zeros(0))
    checks: dict[str, float] = field(default_factory=dict)
    """Reference cross-checks: name -> mixed difference."""
    reference_name: str = f"DOP853 in C at rtol = atol = {REF_TOL:g}"
    notes: dict[str, str] = field(default_factory=dict)
    """What the report says beside its tables: set-up times (builds, JITs)."""

    @property
    def quadruple(self) -> bool:
        """Whether ref is the quadruple-precision one (errors below 1e-10 readable)."""
        return self.reference_name.startswith("heyoka")


def full_model(scene: Scene) -> bool:
    """The default scene, every state kept: the hand-written peer RHSs
    (PyDy's, the numba one of peers.py) integrate exactly its equations."""
    return scene.name == "gyrostat" and list(scene.states) == list(STATES)


def reference(prob: Problem, quadruple: bool = True) -> None:
    """DOP853 in C at 1e-13, checked against scipy at the same tolerance
    and the closed form; then, when quadruple, heyoka is installed and the scene's rhs
    expressible in it, heyoka's real128 integrator at 1e-32 (quadruple
    precision) is the reference, checked against a run of its own at 1e-28
    and against that DOP853."""
    comp = prob.compiled["C"]
    given = Controls(rtol=REF_TOL, atol=REF_TOL)
    seg = integrate_segments(comp, "dop853", prob.x0, prob.c, (0.0, prob.t1), given)
    if seg.code != 0:
        why = message(ODE_CODES, seg.code)
        raise GyrogenError(
            f"{prob.scene.name}: reference DOP853 failed at t = {seg.totals['t']:.6g} s: {why}"
        )
    prob.ref = x = seg.states[-1]
    rhs = RawRhs(comp, prob.c)
    sol = solve_ivp(rhs, (0.0, prob.t1), prob.x0, method="DOP853", rtol=REF_TOL, atol=REF_TOL)
    prob.checks["scipy DOP853 (compiled RHS) at 1e-13"] = scaled_error(sol.y[:, -1], x)
    if prob.scene.name == "torque_free":
        prob.checks["closed form (NOTES.md)"] = scaled_error(closed_form(prob), x)
    if quadruple:
        _quadruple(prob, x)
    else:
        prob.notes["reference"] = "DOP853 at 1e-13 (a stiff scene: no real128 Taylor reference)"


def _quadruple(prob: Problem, dop853: np.ndarray) -> None:
    from gyrogen.analysis.bench import heyoka_peer
    from gyrogen.codegen.generate import unit_of

    hy = heyoka_peer.module()
    if hy is None:
        prob.notes["reference"] = "DOP853 at 1e-13 (pip install heyoka for the real128 one)"
        return
    try:
        sys = heyoka_peer.system(hy, unit_of(prob.scene))
    except ValueError as exc:
        prob.notes["reference"] = f"DOP853 at 1e-13 (heyoka cannot take this scene: {exc})"
        return
    heyoka_peer.check(sys, prob.compiled["C"].rhs, prob.c, prob.x0, lambda line: None)
    ref, self_check = heyoka_peer.reference(sys, prob.x0, prob.c, prob.t1)
    prob.checks[f"DOP853 in C at {REF_TOL:g} against heyoka real128"] = scaled_error(dop853, ref)
    prob.checks[f"heyoka real128 at {heyoka_peer.QUAD_CHECK_TOL:g} against it"] = self_check
    prob.ref = ref
    prob.reference_name = f"heyoka real128 (quadruple precision) at tol {heyoka_peer.QUAD_TOL:g}"


def closed_form(prob: Problem) -> np.ndarray:
    """Axisymmetric, torque-free: u2, u4 constant, (u1, u3) rotating at lambda.
    Compared on the speeds only (the angles have no closed form here)."""
    v = scene_view.values(prob.scene, prob.p)
    i_t = v["I11"] + v["I"]
    idx = {s: i for i, s in enumerate(prob.scene.states)}
    u1, u2, u3, u4 = (prob.x0[idx[f"u{k}"]] for k in range(1, 5))
    lam = ((v["I22"] - i_t) * u2 + v["J"] * u4) / i_t
    t = prob.t1
    out = prob.ref.copy()
    out[idx["u1"]] = u1 * math.cos(lam * t) + u3 * math.sin(lam * t)
    out[idx["u3"]] = u3 * math.cos(lam * t) - u1 * math.sin(lam * t)
    out[idx["u2"]], out[idx["u4"]] = u2, u4
    return out


def compiled_runs(prob: Problem, cfg: Config, progress: Callable[[str], None]) -> list[Run]:
    runs = []
    for backend, comp in prob.compiled.items():
        for method in prob.scene.integrators:
            progress(f"{method} ({backend})")
            settings = cfg.rk4_steps if methods.get(method).fixed_step else cfg.tolerances
            for s in settings:
                runs.append(_compiled_run(prob, comp, backend, method, s, cfg.repeats))
    return runs


def _compiled_run(
    prob: Problem, comp: Compiled, backend: str, method: str, setting: float, repeats: int
) -> Run:
    kw = controls(method, steps=int(setting), rtol=setting, atol=setting, max_steps=10**8)
    seg = integrate_segments(comp, method, prob.x0, prob.c, (0.0, prob.t1), kw)
    calls = int(seg.totals["rhs_calls"])
    if seg.code != 0:
        return Run(method, backend, setting, math.inf, 0.0, calls, f"code {seg.code}")
    secs = best_time(raw_call(comp, method, prob.x0, prob.c, prob.t1, kw), repeats)
    return Run(method, backend, setting, scaled_error(seg.states[-1], prob.ref), secs, calls)


def raw_call(
    comp: Compiled, method: str, x0: np.ndarray, c: np.ndarray, t1: float, kw: Controls
) -> Callable[[], Any]:
    """One integration of x0 from 0 to t1 through cffi on preallocated
    buffers, as a program embedding the C would call it (Compiled.integrate
    adds about 1 us: a new state and stats struct per call, `make
    bench-call`); each call starts again from x0."""
    ffi = comp.ffi
    fn = comp.function(method)
    x = x0.copy()
    xb, cb = ffi.from_buffer("double[]", x), ffi.from_buffer("double[]", np.ascontiguousarray(c))
    stats = ffi.new("gyrogen_stats *")
    if methods.get(method).fixed_step:
        steps = kw["steps"]

        def run_rk4() -> Any:
            x[:] = x0
            return fn(0.0, t1, steps, xb, cb, stats)

        return run_rk4
    rtol, atol, max_steps = kw["rtol"], kw["atol"], kw["max_steps"]

    def run() -> Any:
        x[:] = x0
        return fn(0.0, t1, xb, cb, rtol, atol, 0.0, max_steps, stats)

    return run


class _GiveUp(Exception):
    pass


def scipy_runs(
    prob: Problem,
    backend: str,
    rhs: Callable[[float, np.ndarray], np.ndarray],
    cfg: Config,
    progress: Callable[[str], None],
    which: tuple[str, ...] = methods.SCIPY,
) -> list[Run]:
    runs = []
    for method in which:
        progress(f"solve_ivp {method} ({backend})")
        for tol in cfg.scipy_tolerances:
            run = _scipy_run(prob, backend, rhs, method, tol, cfg)
            runs.append(run)
            if run.status != "ok":
                break  # tighter tolerances only cost more (a stiff scene: as much again)
    return runs


def _scipy_run(
    prob: Problem,
    backend: str,
    rhs: Callable[[float, np.ndarray], np.ndarray],
    method: str,
    tol: float,
    cfg: Config,
) -> Run:
    calls = [0]

    def counted(t: float, x: np.ndarray) -> np.ndarray:
        calls[0] += 1
        if calls[0] > cfg.max_calls:
            raise _GiveUp
        return rhs(t, x)

    def solve() -> Any:
        calls[0] = 0
        return solve_ivp(counted, (0.0, prob.t1), prob.x0, method=method, rtol=tol, atol=tol)

    label = f"scipy {method}"
    t0 = time.perf_counter()
    try:
        sol = solve()
    except _GiveUp:
        return Run(label, backend, tol, math.inf, 0.0, calls[0], f"gave up after {calls[0]} calls")
    once = time.perf_counter() - t0
    if not sol.success:
        return Run(label, backend, tol, math.inf, 0.0, calls[0], f"failed: {sol.message}")
    n = calls[0]
    # Repeat only what is quick to repeat: a run of seconds is timed well enough once.
    secs = once if once > SLOW else best_time(solve, max(1, cfg.repeats // 2), min_total=0.0)
    status = "ok" if once <= TOO_SLOW else "ok, slow"
    return Run(
        label, backend, tol, scaled_error(sol.y[:, -1], prob.ref), min(secs, once), n, status
    )


def numpy_rhs(prob: Problem) -> Callable[[float, np.ndarray], np.ndarray]:
    scene, p = prob.scene, prob.p
    return lambda t, x: scene_view.rhs(scene, x[None, :], p, t)[0]


def compiled_rhs(prob: Problem) -> Callable[[float, np.ndarray], np.ndarray]:
    return RawRhs(prob.compiled["C"], prob.c)


def front(runs: list[Run]) -> list[Run]:
    """The work-precision front of one contender's runs: by time, each run
    more accurate than every faster one (a run both slower and less
    accurate than another says nothing of what the method costs)."""
    out: list[Run] = []
    for r in sorted((r for r in runs if r.status.startswith("ok") and r.error > 0),
                    key=lambda r: (r.seconds, r.error)):  # fmt: skip
        if not out or r.error < out[-1].error:
            out.append(r)
    return out


def seconds_at(runs: list[Run], level: float) -> float | None:
    """What one contender needs for an error of level, read along its front:
    interpolated in log-log between the two runs around level; a contender
    whose fastest run is already below level is charged that run (no
    extrapolation); None when no run reaches level."""
    pts = front(runs)
    if not pts or pts[-1].error > level:
        return None
    if pts[0].error <= level:
        return pts[0].seconds
    for slow, fast in zip(pts[1:], pts, strict=False):
        if slow.error <= level:
            w = math.log(fast.error / level) / math.log(fast.error / slow.error)
            return math.exp((1 - w) * math.log(fast.seconds) + w * math.log(slow.seconds))
    return None  # unreachable: pts[-1].error <= level
