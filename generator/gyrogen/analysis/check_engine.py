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
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gyrogen.abi import (
    AXES_SPAN_WARN,
    ODE_ATTITUDE_SINGULAR,
    ODE_CODES,
    SETUP_CODES,
    WARN_CONDITION,
    message,
)
from gyrogen.analysis import invariants
from gyrogen.analysis.trajectory import QUAD_NODES, from_samples, sample_times
from gyrogen.oracle import scene_view
from gyrogen.oracle.cluster_reference import clamp_margins
from gyrogen.physics import lumped_inertias
from gyrogen.runtime.compiled import Compiled, Controls, controls
from gyrogen.runtime.segment import integrate_segments
from gyrogen.scene import Scene

STIFF = 1e3
"""Stiffness index (largest decay rate x time span) above which an explicit
method spends most of its steps on stability: implicit it is."""
DRIFT_BAR = 1e-10
"""The invariants' relative drift allowed at rtol 1e-12."""


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
    quadrature: bool = False
    """Judge the energy balance and the first rotor's rate by Gauss-Legendre
    quadrature along the run (any torque law: a clamp, friction) rather than
    in closed form; the run is sampled at the quadrature nodes too."""
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

    @property
    def passed(self) -> bool:
        return self.verdict == self.case.expect


def _vector(values: dict[str, float], names: tuple[str, ...], fill: float) -> np.ndarray:
    return np.array([values.get(n, fill) for n in names], dtype=float)


def stiffness(comp: Compiled, c: np.ndarray, xs: np.ndarray, span: float) -> tuple[float, str]:
    """max over the states of (largest decay rate) x span, and the method
    it calls for with the reason."""
    worst = 0.0
    for x in np.atleast_2d(xs):
        jac = comp.jacobian(x, c)
        rate = max(0.0, float(-np.min(np.linalg.eigvals(jac).real)))
        worst = max(worst, rate * span)
    if worst > STIFF:
        why = (
            f"implicit (rodas4): decay rates up to {worst / span:.3g} 1/s over {span:g} s "
            f"would hold an explicit method to steps of ~{3.0 * span / worst:.2g} s"
        )
        return worst, why
    return worst, f"explicit (dop853): stiffness index {worst:.3g} <= {STIFF:g}"


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
        res.diagnosis = f"setup refused the parameters: {message(SETUP_CODES, res.setup_code)}"
        return res
    res.condition = float(c[-1])
    res.stiffness, res.recommended = stiffness(comp, c, x0, case.t_end)
    res.method = case.method or ("rodas4" if res.stiffness > STIFF else "dop853")
    ts = np.linspace(0.0, case.t_end, case.samples + 1)
    steps = max(1, case.steps // case.samples)
    given = controls(res.method, steps=steps, rtol=1e-12, atol=1e-12, max_steps=10**8)
    if case.quadrature:
        ts = _with_clamp_switches(comp, res.method, (x0, c, p), ts, given, scene)
    times = sample_times(ts) if case.quadrature else ts
    seg = integrate_segments(comp, res.method, x0, c, times, given)
    res.stats, res.code = seg.totals, seg.code
    every = QUAD_NODES + 1 if case.quadrature else 1
    res.trajectory, res.times = seg.states[::every], ts[: len(seg.states[::every])]
    if case.quadrature and seg.code == 0:
        traj = from_samples(ts, times, seg.states, 0, 0.0)
        res.drift = invariants.by_quadrature(scene, p, traj)
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
        res.drift = invariants.at_samples(scene, p, xs, res.times)
    later, _ = stiffness(comp, c, xs[:: max(1, len(xs) // 5)], case.t_end)
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
    span = axes_span(scene)
    if span < AXES_SPAN_WARN:
        res.diagnosis = (res.diagnosis + "; " if res.diagnosis else "") + (
            f"warning: the wheel axes nearly fail to span space (singular values of "
            f"[g_1 .. g_N] in ratio {span:.2g} < {AXES_SPAN_WARN:g}): "
            "too little torque about some direction"
        )
    if _near_gimbal_lock(scene, xs).any() and not res.diagnosis:
        res.diagnosis = "passes near gimbal lock: quaternions would be cheaper"


def axes_span(scene: Scene) -> float:
    """Smallest over largest singular value of a cluster's axes [g_1 .. g_N]
    (1 below three wheels, which cannot span space anyway, and without rotors)."""
    if len(scene.rotors) < 3:
        return 1.0
    sv = np.linalg.svd(np.array([r.unit_axis for r in scene.rotors], dtype=float), compute_uv=False)
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


def spin_prediction(v: dict[str, float], omega: float, u4: float) -> str:
    """NOTES.md: stable iff (H_a - I_t1 Omega)(H_a - I_t3 Omega) > 0."""
    names = ("m_a", "m_b", "I11", "I22", "I33", "I13", "I", "l1", "l3")
    a11, a22, a33, a13 = lumped_inertias(*(v[n] for n in names))
    it1, it3 = np.linalg.eigvalsh([[a11, a13], [a13, a33]])
    h_a = a22 * omega + v["J"] * u4
    return "stable" if (h_a - it1 * omega) * (h_a - it3 * omega) > 0 else "unstable"


def plot(res: Result) -> bytes:
    """Invariant drift and the states along the run: one PNG per case."""
    from matplotlib.figure import Figure  # matplotlib: loaded only for plots

    from gyrogen.analysis.plots import png_bytes

    fig = Figure(figsize=(12, 4.5), dpi=100)
    a, b = fig.subplots(1, 2)
    if res.trajectory is not None and res.times is not None:
        for i, s in enumerate(res.case.scene.states):
            if s.startswith("u"):
                a.plot(res.times[: len(res.trajectory)], res.trajectory[:, i], label=s)
        a.set_xlabel("t (s)")
        a.set_ylabel("generalized speeds (rad/s, m/s)")
        a.legend(fontsize=8)
    b.axis("off")
    lines = [f"{res.case.name}: {res.verdict} (expected {res.case.expect})", res.recommended]
    lines += [f"{k}: {v:.2e}" for k, v in res.drift.items()] + [res.diagnosis]
    b.text(
        0.0,
        1.0,
        "\n".join(x for x in lines if x),
        va="top",
        family="monospace",
        fontsize=9,
        wrap=True,
    )
    fig.suptitle(f"gyrogen check: {res.case.name}")
    fig.tight_layout()
    return png_bytes(fig)
