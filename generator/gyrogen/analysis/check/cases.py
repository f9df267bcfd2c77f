"""The built-in stiff and extreme cases of `gyrogen check`.

Most are the full model (every parameter at run time, so one build serves
them all) with extreme values; the high-gain controller uses the
speed-controlled scene, and the gimbal-lock cases compare 3-1-2 angles with
Euler parameters.
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np

from gyrogen import methods
from gyrogen.abi import GIMBAL_LOCK_COS
from gyrogen.analysis.check import clusters
from gyrogen.analysis.check.engine import Case, Extreme, spin_prediction
from gyrogen.analysis.simulate import invariants
from gyrogen.errors import SceneError
from gyrogen.oracle.scene_view import quaternion_dcm
from gyrogen.physics import LUMPED_FROM, lumped_inertias
from gyrogen.scene import Scene, builtin_names, default, load

# A moderate spacecraft: lumped inertia about (12, 9.5, 15), rotor J = 0.03.
NOMINAL = {
    "m_a": 100.0, "m_b": 5.0, "I11": 12.0, "I22": 9.0, "I33": 15.0, "I13": 0.8,
    "I": 0.02, "J": 0.03, "l1": 0.2, "l3": -0.1, "g": 0.0, "T": 0.01,
}  # fmt: skip
SPIN = {  # NOTES.md: lumped inertia diag(3, 2, 4), J = 0.1
    "m_a": 10.0, "m_b": 1.0, "I11": 2.95, "I22": 2.0, "I33": 3.95, "I13": 0.0,
    "I": 0.05, "J": 0.1, "l1": 0.0, "l3": 0.0, "g": 0.0, "T": 0.0,
}  # fmt: skip
START = {"u1": 0.2, "u2": 1.0, "u3": -0.1, "u4": 50.0}
CLOSEST_APPROACH = 17.0
"""The gimbal-lock cases started eps below q2 = pi/2 come within about
17 eps^2 of |cos q2| = 0 (see _gimbal)."""
EXPLICIT = methods.EXPLICIT_CHOICE[0]
"""The method of the cases that name one (gimbal lock, spin stability): the
one simulate picks for a smooth scene that is not stiff."""


def _speeds(case: Case, xs: np.ndarray, *names: str) -> list[np.ndarray]:
    return [xs[:, case.scene.states.index(n)] for n in names]


def rotor_ratio(case: Case, xs: np.ndarray) -> np.ndarray:
    """J |u4| / |I~ w|: the rotor's axial momentum over the carrier's, with
    the lumped inertia I~ of carrier and rotor (NOTES.md)."""
    a11, a22, a33, a13 = lumped_inertias(*(case.params[n] for n in LUMPED_FROM))
    u1, u2, u3, u4 = _speeds(case, xs, "u1", "u2", "u3", "u4")
    carrier = np.linalg.norm([a11 * u1 + a13 * u3, a22 * u2, a13 * u1 + a33 * u3], axis=0)
    return case.params["J"] * np.abs(u4) / carrier


def cos_q2(case: Case, xs: np.ndarray) -> np.ndarray:
    """|cos q2| of the 3-1-2 angles, also from Euler parameters: the length
    of a2's projection on the n1-n2 plane, |(C21, C22)|; 0 at gimbal lock."""
    states = case.scene.states
    if case.scene.attitude == "euler312":
        return np.abs(np.cos(xs[:, states.index("q2")]))
    dcm = quaternion_dcm(xs[:, [states.index(e) for e in ("e0", "e1", "e2", "e3")]])
    return np.hypot(dcm[:, 1, 0], dcm[:, 1, 1])


def slip(case: Case, xs: np.ndarray) -> np.ndarray:
    """u4 - u2 - w_ref: the speed controller's error, which k/J drives to 0."""
    u2, u4 = _speeds(case, xs, "u2", "u4")
    return u4 - u2 - case.params["w_ref"]


def transverse_rate(case: Case, xs: np.ndarray) -> np.ndarray:
    """|(u1, u3)|: the nutation about the spin axis a2, which grows if unstable."""
    u1, u3 = _speeds(case, xs, "u1", "u3")
    return np.hypot(u1, u3)


ROTOR = Extreme("rotor to carrier momentum J |u4| / |I~ w|", rotor_ratio, log=True)
GIMBAL = Extreme(
    "|cos q2| (3-1-2 angles; 0 at gimbal lock)",
    cos_q2,
    log=True,
    marks=((GIMBAL_LOCK_COS, "GIMBAL_LOCK_COS: the angles' integrators stop"),),
)
SLIP = Extreme("controller slip |u4 - u2 - w_ref| (rad/s)", slip, log=True)
NUTATION = Extreme("transverse rate |(u1, u3)| (rad/s)", transverse_rate, log=True)


def proportions(params: dict[str, float]) -> Extreme:
    """Where nothing varies in time: the mass ratio, the condition number of
    the lumped inertia's coupled block, and the rotor's share of it."""
    a11, a22, a33, a13 = lumped_inertias(*(params[n] for n in LUMPED_FROM))
    cond = np.linalg.cond([[a11, a13], [a13, a33]])
    return Extreme(
        f"m_b / m_a = {params['m_b'] / params['m_a']:.3g}\n"
        f"cond [[I~11, I~13], [I~13, I~33]] = {cond:.3g}\n"
        f"J / I~22 = {params['J'] / a22:.3g}"
    )


@cache
def quaternion_scene() -> Scene:
    data = default().model_dump()
    data.update(
        name="gyrostat_quat",
        attitude="quaternion",
        integrators=[methods.EXPLICIT_CHOICE[0], methods.STIFF_CHOICE[0]],
    )
    data["description"] = "the full model with Euler parameters for the attitude"
    start = data["simulate"]["initial"]
    data["simulate"]["initial"] = {k: v for k, v in start.items() if k not in ("q1", "q2", "q3")}
    return Scene.model_validate(data)


def _with(**changes: float) -> dict[str, float]:
    return {**NOMINAL, **changes}


def _gimbal(eps: float, quaternion: bool) -> Case:
    """Start eps below q2 = pi/2, turning slowly about a1: the angles'
    kinematics q1' and q3' grow as 1/cos(q2) and the steps shrink to match;
    Euler parameters do not notice.

    a2 sweeps a cone of radius r ~ 0.03 rad through a point eps from n3, so
    it passes the pole at about eps^2 / (2 r) ~ 17 eps^2 in |cos q2|
    (measured 1.7e-3, 1.7e-7, 1.7e-11 for eps = 1e-2, 1e-4, 1e-6): below
    GIMBAL_LOCK_COS (eps = 1e-6, 1e-8) the angles' integrators stop with
    code 6, "singular"; above it (eps = 1e-2, 1e-4) they pass, at a cost."""
    q2 = math.pi / 2 - eps
    speeds = {"u1": 0.01, "u2": 0.3, "u3": 0.0, "u4": 50.0}
    initial = {"q2": q2, **speeds}
    if quaternion:
        half = q2 / 2  # 3-1-2 angles (0, q2, 0): a rotation q2 about a1
        initial = {"e0": math.cos(half), "e1": math.sin(half), **speeds}
    scene = quaternion_scene() if quaternion else default()
    kind = "quaternion" if quaternion else "3-1-2 angles"
    locks = not quaternion and CLOSEST_APPROACH * eps**2 < GIMBAL_LOCK_COS
    expect = "singular" if locks else "pass"
    name = f"gimbal lock eps={eps:g} ({kind})"
    return Case(name, scene, NOMINAL, initial, 2.0, expect, EXPLICIT, extreme=GIMBAL)


def cases(quick: bool = False) -> list[Case]:
    """Every case in table order; quick: fewer and shorter ones (for CI)."""
    return [
        Case("nominal", default(), NOMINAL, START, 10.0, "pass", extreme=ROTOR),
        *_fast_rotor(quick),
        *_attitude(quick),
        *_extreme_values(),
        *_speed_controller(quick),
        _long_run(quick),
        *_spin_stability(),
        *clusters.cases(quick),
    ]


def _fast_rotor(quick: bool) -> list[Case]:
    out = []
    for ratio in (1e2, 1e4) if quick else (1e2, 1e4, 1e6):
        # J u4 / (I~ |omega|) = ratio with I~ ~ 12 and |omega| ~ 1
        u4 = ratio * 12.0 / NOMINAL["J"]
        t_end = 0.05 if ratio > 1e3 else 1.0
        name = f"fast rotor J u4/(I|w|)={ratio:g}"
        initial = {**START, "u4": u4}
        out.append(Case(name, default(), NOMINAL, initial, t_end, "pass", extreme=ROTOR))
    return out


def _attitude(quick: bool) -> list[Case]:
    """Near and through gimbal lock, with 3-1-2 angles and with Euler parameters."""
    out = []
    for eps in (1e-2, 1e-6) if quick else (1e-2, 1e-4, 1e-6, 1e-8):
        out.append(_gimbal(eps, quaternion=False))
        out.append(_gimbal(eps, quaternion=True))
    # Turning about a1 (+ 0.05 a3) from q2 = 1.4: a2 passes n3 at 0.48 deg,
    # where q1 and q3 swing through ~pi in a fraction of a second; |cos q2|
    # stays above 0.008, far from GIMBAL_LOCK_COS, so the angles get there
    # with small steps rather than stop.
    through = {"q2": 1.4, "u1": 1.0, "u2": 0.0, "u3": 0.05, "u4": 0.0}
    name = "through q2 = pi/2"
    angles = Case(f"{name} (3-1-2 angles)", default(), NOMINAL, through, 1.0, "pass", EXPLICIT)
    half = 0.7  # q2 = 1.4: a rotation of 1.4 about a1
    quat = {"e0": math.cos(half), "e1": math.sin(half), "u1": 1.0, "u3": 0.05}
    scene = quaternion_scene()
    quaternions = Case(f"{name} (quaternion)", scene, NOMINAL, quat, 1.0, "pass", EXPLICIT)
    return out + [replace(c, extreme=GIMBAL) for c in (angles, quaternions)]


def _extreme_values() -> list[Case]:
    full = default()
    return [
        replace(case, extreme=proportions(case.params))
        for case in (
            Case("mass ratio m_b/m_a = 1e-9", full, _with(m_b=1e-7), START, 5.0, "pass"),
            Case("mass ratio m_b/m_a = 1e9", full, _with(m_a=5e-9), START, 5.0, "pass"),
            Case("rotor J = 1e-12", full, _with(J=1e-12, I=1e-12, T=1e-14), START, 5.0, "pass"),
            Case("inertias at 1e-9", full, _scaled(1e-9), START, 5.0, "pass"),
            Case("inertias at 1e9", full, _scaled(1e9), START, 5.0, "pass"),
            Case(
                "ill-conditioned lumped inertia (cond ~1e6)",
                full,
                _dumbbell(5e-6),
                START,
                1.0,
                "pass",
            ),
            # Above the warning level: setup multiplies the lumped products out
            # (optimize._multiplied_out), so the constants keep full accuracy.
            Case(
                "nearly singular lumped inertia (cond ~5e9)",
                full,
                _dumbbell(1e-9),
                START,
                1.0,
                "pass",
            ),
            Case(
                "numerically singular lumped inertia", full, _dumbbell(1e-15), START, 1.0, "refused"
            ),
            Case("negative mass", full, _with(m_a=-1.0), START, 1.0, "refused"),
        )
    ]


def _speed_controller(quick: bool) -> list[Case]:
    ctrl = load("speed_controlled")
    out = []
    for ratio in (1e1, 1e3, 1e6) if quick else (1e1, 1e2, 1e3, 1e4, 1e5, 1e6):
        params = {"k": ratio * 0.03, "w_ref": 150.0}
        initial = {"u2": 0.1, "u1": 0.02}
        name = f"speed controller k/J={ratio:g}"
        out.append(Case(name, ctrl, params, initial, 2.0, "pass", extreme=SLIP))
    return out


def _long_run(quick: bool) -> Case:
    """Fixed steps of 1e-4 s: the truncation error is negligible and what
    could drift is rounding, about eps per step with plain adds (4e-10
    after 1e7); the integrators sum their steps with compensation instead."""
    steps = 10**6 if quick else 10**7
    name = f"long run: {steps:.0e} RK4 steps"
    rounding = Extreme(
        f"{steps:.0e} fixed steps of 1e-4 s: plain adds of t and x would drift\n"
        f"by rounding, ~eps per step ({steps * 2.2e-16:.0e} after {steps:.0e})"
    )
    return Case(
        name, default(), NOMINAL, START, steps * 1e-4, "pass", "rk4", steps=steps, extreme=rounding
    )


def _spin_stability() -> list[Case]:
    out = []
    for u4 in (0.0, 15.0, 25.0, -40.0):
        initial = {"u1": 1e-4, "u2": 1.0, "u3": 0.0, "u4": u4}
        expect = spin_prediction(SPIN, 1.0, u4)
        name = f"spin stability u4={u4:g}: predicted {expect}"
        case = Case(name, default(), SPIN, initial, 200.0, expect, EXPLICIT, samples=400)
        out.append(replace(case, extreme=NUTATION))
    return out


def _scaled(s: float) -> dict[str, float]:
    """Masses, inertias and the torque times s: the same motion in units
    where mass is s times larger."""
    names = ("m_a", "m_b", "I11", "I22", "I33", "I13", "I", "J", "T")
    return _with(**{k: NOMINAL[k] * s for k in names})


def _dumbbell(tiny: float) -> dict[str, float]:
    """A tiny carrier and rotor far from A*: the lumped block tends to the
    rank-one mu (l3, -l1)(l3, -l1)^T."""
    return _with(I11=tiny, I22=tiny, I33=tiny, I13=0.0, I=tiny, J=tiny, l1=1.0, l3=1.0, T=0.0)


def is_scene(name: str) -> bool:
    return name in builtin_names() or (name.endswith(".toml") and Path(name).is_file())


def scene_case(name: str) -> Case:
    """A scene's own simulation ([simulate]) as a check case: it needs the C
    target, and an integrator of each kind the stiffness analysis may ask
    for (gyrogen.methods.EXPLICIT_CHOICE, STIFF_CHOICE)."""
    scene = load(name)
    pair = next(m for m in methods.EXPLICIT_CHOICE if methods.get(m).pair)  # offered anywhere
    kinds = {False: pair, True: methods.STIFF_CHOICE[0]}
    lacking = [m for stiff, m in kinds.items() if methods.pick(scene.integrators, stiff) is None]
    add = [] if "c" in scene.targets else ["c to targets"]
    add += [f"{', '.join(lacking)} to integrators"] if lacking else []
    if add:
        raise SceneError(
            f"{name}: gyrogen check needs the scene's C build with an explicit method "
            f"({' or '.join(methods.EXPLICIT_CHOICE)}) "
            f"and an implicit method "
            f"({' or '.join(methods.STIFF_CHOICE)}, with the Jacobian): add {' and '.join(add)}"
        )
    sim = scene.simulate
    quadrature = not invariants.in_closed_form(scene)  # a speed controller, a table, friction
    return Case(f"scene {scene.name}", scene, sim.parameters, sim.initial, sim.t_end, "pass",
                quadrature=quadrature)  # fmt: skip
