"""`gyrogen check`: numerical stability on stiff and extreme cases.

Each case is a scene with parameter values and an initial state. For it:
does setup accept it, and how well conditioned is the mass matrix; how stiff
is the system (eigenvalues of the generated Jacobian at the start and along
the run) and so which method it calls for; then an integration with the
compiled integrators at rtol = 1e-12, watching the invariants of NOTES.md:
|H| in N (always constant), the energy balance and u4 = u4(0) + T t / J
(exact forms for a constant torque), and non-finite values.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gyrogen.abi import (
    AXES_SPAN_WARN,
    ODE_ATTITUDE_SINGULAR,
    ODE_CODES,
    WARN_CONDITION,
    message,
    setup_codes_of,
)
from gyrogen.analysis.check import stiffness
from gyrogen.analysis.simulate import invariants
from gyrogen.analysis.simulate.trajectory import Trajectory
from gyrogen.oracle import gimbal_view, scene_view
from gyrogen.oracle.cluster_reference import clamp_margins
from gyrogen.physics import LUMPED_FROM, lumped_inertias
from gyrogen.runtime.compiled import Compiled, Controls, controls
from gyrogen.runtime.segment import integrate_segments, resampled
from gyrogen.scene import Scene
from gyrogen.scene.rotors import unit_axes

TOL = 1e-12
"""rtol and atol of every case's integration."""
DRIFT_BAR = 1e-10
"""The invariants' relative drift allowed at rtol TOL."""


@dataclass(frozen=True)
class Extreme:
    """What makes a case extreme, as its figure shows it: a quantity along
    the run (values(case, states) -> one value per state), or, where
    nothing varies in time, a fixed one stated in words (values None)."""

    label: str
    values: Callable[[Case, np.ndarray], np.ndarray] | None = None
    log: bool = False
    """Plot |values| on a log axis."""
    marks: tuple[tuple[float, str], ...] = ()
    """Horizontal lines (value, what it is): a threshold the run is judged by."""


@dataclass(frozen=True)
class Case:
    name: str
    scene: Scene
    params: dict[str, float]
    initial: dict[str, float]
    t_end: float
    expect: str
    """'pass', 'refused', 'singular' (the angles fail: gimbal lock), 'stable' or 'unstable'."""
    method: str | None = None
    """None: the method the stiffness analysis recommends."""
    steps: int = 0
    """For method 'rk4': the number of steps."""
    samples: int = 20
    extreme: Extreme | None = None
    """None: the figure states the scene's description instead."""
    quadrature: bool = False
    """Judge the energy balance and the first rotor's rate by quadrature
    along the run (any torque law: a clamp, friction) rather than in closed
    form, on the run's dense output (simulate/trajectory.py)."""
    refused_by: str = ""
    """The scene's own validation refused the case's values (folded into the
    code, they are checked when it is generated): its one line. Nothing is
    built or run; scene is the nearest valid one."""


@dataclass
class Result:
    case: Case
    verdict: str = "pass"
    setup_code: int = 0
    condition: float = math.nan
    stiffness: float = math.nan
    """Largest decay rate (1/s) times the time span, at the start and along the run."""
    recommended: str = ""
    method: str = ""
    drift: dict[str, float] = field(default_factory=dict)
    stats: dict[str, Any] = field(default_factory=dict)
    code: int = 0
    diagnosis: str = ""
    trajectory: np.ndarray | None = None
    times: np.ndarray | None = None
    intervals: tuple[dict[str, Any], ...] = ()
    """Each output interval's integrator statistics, a failed one last."""
    drift_series: dict[str, np.ndarray] = field(default_factory=dict)
    """Each invariant's relative drift at the times (drift holds the peaks)."""
    stopped: np.ndarray | None = None
    """A failed run's last good state, at stats["t"]."""

    @property
    def passed(self) -> bool:
        return self.verdict == self.case.expect


def _vector(values: dict[str, float], names: tuple[str, ...], fill: float) -> np.ndarray:
    return np.array([values.get(n, fill) for n in names], dtype=float)


def run_case(case: Case, comp: Compiled | None) -> Result:
    """comp: the case's scene built (None when the case is refused_by its scene)."""
    res = Result(case)
    if case.refused_by or comp is None:
        res.verdict = "refused"
        res.diagnosis = f"generation refused the scene: {case.refused_by}"
        return res
    scene = case.scene
    p = _vector(case.params, scene.runtime, math.nan)
    x0 = np.array([{"e0": 1.0, **case.initial}.get(s, 0.0) for s in scene.states])
    res.setup_code, c = comp.setup_code(p)
    if res.setup_code != 0:
        res.verdict = "refused"
        why = message(setup_codes_of(bool(scene.rotors)), res.setup_code)
        res.diagnosis = f"setup refused the parameters: {why}"
        return res
    res.condition = float(c[-1])
    choice = stiffness.choose(comp, c, x0, case.t_end)
    res.stiffness, res.recommended = choice.stiffness, choice.why
    res.method = case.method or choice.method or ""
    ts = np.linspace(0.0, case.t_end, case.samples + 1)
    steps = max(1, case.steps // case.samples)
    given = controls(res.method, steps=steps, rtol=TOL, atol=TOL, max_steps=10**8)
    if case.quadrature:
        ts = _with_clamp_switches(comp, res.method, (x0, c, p), ts, given, scene)
    seg = integrate_segments(comp, res.method, x0, c, ts, given)
    res.stats, res.code, res.stopped = seg.totals, seg.code, seg.stopped
    res.intervals = tuple(dict(s) for s in seg.intervals)
    res.trajectory, res.times = seg.states, ts[: len(seg.states)]
    if case.quadrature and seg.code == 0:
        sample = resampled(comp, res.method, c, given, ts, seg.states)
        lengths = np.diff(ts) / np.maximum([s["accepted"] for s in seg.intervals], 1)
        traj = Trajectory(ts, seg.states, 0, 0.0, sample, (TOL, TOL), (ts, lengths))
        res.drift_series = invariants.by_quadrature(scene, p, traj)
    _judge(res, p, c, comp)
    return res


def _with_clamp_switches(
    comp: Compiled, method: str, start: tuple[np.ndarray, ...], ts: np.ndarray,
    given: Controls, scene: Scene,
) -> np.ndarray:  # fmt: skip
    """ts and the times a wheel's motor enters or leaves its clamp, found by
    bisection on the integrated state to rounding: the power's slope jumps
    there, and quadrature keeps its order only on either side of a jump."""
    x0, c, p = start
    if not any(r.tau_max is not None for r in scene.rotors):
        return ts
    runtime = scene_view.values(scene, p)
    xs = integrate_segments(comp, method, x0, c, ts, given).states
    held = clamp_margins(scene, xs, runtime) > 0
    switches = []
    for i, k in zip(*np.nonzero(held[1:] != held[:-1]), strict=True):
        a, b = float(ts[i]), float(ts[i + 1])
        while a < (mid := 0.5 * (a + b)) < b:
            x, _, _ = comp.integrate(method, xs[i], c, float(ts[i]), mid, **given)
            a, b = (
                (mid, b) if (clamp_margins(scene, x, runtime)[0, k] > 0) == held[i, k] else (a, mid)
            )
        switches.append(0.5 * (a + b))
    return np.union1d(ts, switches)


def _judge(res: Result, p: np.ndarray, c: np.ndarray, comp: Compiled) -> None:
    case, scene = res.case, res.case.scene
    xs = res.trajectory
    assert xs is not None and res.times is not None
    if res.code != 0:
        where = f"integrator code {res.code} at t = {res.stats.get('t', math.nan):.6g} s"
        if res.code == ODE_ATTITUDE_SINGULAR:  # the integrator saw gimbal lock itself
            res.verdict = "singular"
            res.diagnosis = f"{where}: {message(ODE_CODES, res.code)}"
        elif _near_gimbal_lock(scene, xs[-1]):  # another failure, near it
            res.verdict = "singular"
            res.diagnosis = f"{where} ({message(ODE_CODES, res.code)}) near gimbal lock: " + (
                'the 3-1-2 angles fail there, use attitude = "quaternion"'
            )
        else:
            res.verdict = "failed"
            res.diagnosis = f"{where}: {message(ODE_CODES, res.code)}"
        return
    if not case.quadrature:
        res.drift_series = invariants.series_at_samples(scene, p, xs, res.times)
    res.drift = {name: invariants.peak(values) for name, values in res.drift_series.items()}
    later = stiffness.index(comp, c, xs[:: max(1, len(xs) // 5)], case.t_end)
    res.stiffness = max(res.stiffness, later)
    if case.expect in ("stable", "unstable"):
        res.verdict = _spin_verdict(scene, xs)
    elif max(res.drift.values(), default=0.0) > DRIFT_BAR:
        res.verdict = "drift"
        res.diagnosis = f"an invariant drifted above {DRIFT_BAR:g}: tighten rtol or change method"
    if res.condition > WARN_CONDITION:
        res.diagnosis = (res.diagnosis + "; " if res.diagnosis else "") + (
            f"warning: mass matrix condition number {res.condition:.2g} > {WARN_CONDITION:g}"
        )
    span = axes_span(scene, dict(zip(scene.runtime, p, strict=True)))
    if span < AXES_SPAN_WARN and not gimbal_view.has_gimbals(scene):  # CMGs: the steering's
        res.diagnosis = (res.diagnosis + "; " if res.diagnosis else "") + (
            f"warning: the wheel axes nearly fail to span space (singular values of "
            f"[g_1 .. g_N] in ratio {span:.2g} < {AXES_SPAN_WARN:g}): "
            "too little torque about some direction"
        )
    if gimbal_view.has_gimbals(scene):
        given = dict(zip(scene.runtime, p, strict=True))
        measure = gimbal_view.steering_singularity(scene, xs, given)
        res.diagnosis = (res.diagnosis + "; " if res.diagnosis else "") + (
            f"steering singularity det({gimbal_view.steering_gram(scene)}) {measure[0]:.2g} "
            "at the start, "
            f"{measure.min():.2g} to {measure.max():.2g} along the run"
        )
    if _near_gimbal_lock(scene, xs).any() and not res.diagnosis:
        res.diagnosis = "passes near gimbal lock: quaternions would be cheaper"


def axes_span(scene: Scene, given: Mapping[str, float]) -> float:
    """Smallest over largest singular value of a cluster's axes [g_1 .. g_N]
    (1 below three wheels, which cannot span space anyway, and without
    rotors); a runtime axis's from the runtime values given."""
    if len(scene.rotors) < 3:
        return 1.0
    sv = np.linalg.svd(unit_axes(scene.rotors, given), compute_uv=False)
    return float(sv[-1] / sv[0])


def _near_gimbal_lock(scene: Scene, xs: np.ndarray) -> np.ndarray:
    if scene.attitude != "euler312":
        return np.zeros(len(np.atleast_2d(xs)), dtype=bool)
    q2 = np.atleast_2d(xs)[:, scene.states.index("q2")]
    return np.abs(np.cos(q2)) < 0.05  # within 3 degrees of the pole


def _spin_verdict(scene: Scene, xs: np.ndarray) -> str:
    """Unstable if the transverse rate grew a hundredfold."""
    idx = {s: i for i, s in enumerate(scene.states)}
    trans = np.hypot(xs[:, idx["u1"]], xs[:, idx["u3"]])
    return "unstable" if np.max(trans) > 100 * max(trans[0], 1e-300) else "stable"


def spin_axes(v: dict[str, Any], omega: Any, u4: Any) -> tuple[Any, Any, Any]:
    """NOTES.md's spin-stability terms: H_a / Omega (H_a = I~22 Omega + J
    u4) and the transverse inertias I_t1 <= I_t3, the eigenvalues of
    [[I~11, I~13], [I~13, I~33]]; numbers or numpy arrays alike."""
    a11, a22, a33, a13 = lumped_inertias(*(v[n] for n in LUMPED_FROM))
    block = np.stack(np.broadcast_arrays(a11, a13, a13, a33), axis=-1)
    it = np.linalg.eigvalsh(block.reshape((*block.shape[:-1], 2, 2)))
    return (a22 * omega + v["J"] * u4) / omega, it[..., 0], it[..., 1]


def spin_stable(v: dict[str, Any], omega: Any, u4: Any) -> Any:
    """NOTES.md: stable iff (H_a - I_t1 Omega)(H_a - I_t3 Omega) > 0."""
    sigma, it1, it3 = spin_axes(v, omega, u4)
    return (sigma - it1) * (sigma - it3) * omega**2 > 0


def spin_prediction(v: dict[str, float], omega: float, u4: float) -> str:
    """spin_stable as a check case's expected verdict."""
    return "stable" if spin_stable(v, omega, u4) else "unstable"
