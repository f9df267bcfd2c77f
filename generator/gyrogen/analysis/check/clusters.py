"""`gyrogen check`'s cases for reaction-wheel clusters, variants of the
rw4_pyramid scene: torque-free, stiff speed controllers, saturating motors,
nearly parallel axes (warned, then refused); and the control-moment gyros'
pyramid started at a singular gimbal set (its steering singularity measure
reported).

A cluster folds its mass properties into the code, so a value the scene's
own rules refuse (a numerically singular lumped inertia) is refused when the
scene is generated: that case carries the one line (Case.refused_by) and
nothing is built for it.
"""

from __future__ import annotations

import math
import tomllib
from functools import cache
from typing import Any

import numpy as np

from gyrogen.abi import AXES_SPAN_WARN
from gyrogen.analysis.check.engine import Case, Extreme
from gyrogen.errors import SceneError
from gyrogen.oracle import cluster_reference, gimbal_view
from gyrogen.scene import Scene, builtin_text, load, validate

PYRAMID_START = {"u1": 0.3, "u2": -0.2, "u3": 0.5, "w1": 90.0, "w2": -40.0, "w3": 60.0, "w4": 30.0}
WHEEL_J = 0.045
"""rw4_pyramid's axial inertia: the controller gains are multiples of it."""


def wheel_share(case: Case, xs: np.ndarray) -> np.ndarray:
    """|sum_k J_k (w_k - g_k.w_A) g_k| / |H|: the wheels' part of the
    angular momentum, which the carrier's tumbling trades with them."""
    v = cluster_reference.values(case.scene)
    mo = cluster_reference.motion(case.scene, xs, case.params)
    return np.linalg.norm((v.J * mo.rel) @ v.g, axis=1) / np.linalg.norm(mo.h, axis=1)


def wheel_slip(case: Case, xs: np.ndarray) -> np.ndarray:
    """max_k |w_k - g_k.w_A - w_ref_k|: the speed controllers' largest error."""
    rel = cluster_reference.motion(case.scene, xs, case.params).rel
    refs = np.array([case.params[f"w_ref_{k}"] for k in range(1, rel.shape[1] + 1)])
    return np.max(np.abs(rel - refs), axis=1)


def clamp_margin(case: Case, xs: np.ndarray) -> np.ndarray:
    """max_k |demanded torque_k| - tau_max_k: positive while a clamp holds a motor."""
    return np.max(cluster_reference.clamp_margins(case.scene, xs, case.params), axis=1)


SHARE = Extreme("wheels' share of |H|: |sum J_k (w_k - g_k.w_A) g_k| / |H|", wheel_share)
SLIP = Extreme("wheel slip max_k |w_k - g_k.w_A - w_ref_k| (rad/s)", wheel_slip, log=True)
CLAMP = Extreme(
    "clamp margin max_k |T_k demanded| - tau_max (N m)",
    clamp_margin,
    marks=((0.0, "above: the clamp holds a motor at tau_max"),),
)


STEERING = Extreme(
    "steering singularity det(A A^T), A = [g_g x g_s]",
    lambda case, xs: gimbal_view.steering_singularity(case.scene, xs),
    log=True,
)
SINGULAR_SET = (-90.0, 0.0, 90.0, 0.0)
"""cmg4_pyramid's gimbal angles (deg) where det(A A^T) = 0: its torque
directions g_g x g_s all lie in one plane."""


def singular_pyramid() -> Case:
    """cmg4_pyramid started at SINGULAR_SET, gimbals 1 and 3 held (rate_ref
    0), 2 and 4 turning at their -0.2 rad/s: the steering law's singularity
    is not the dynamics', which stay regular (energy balance, |H|)."""
    initial = {**tomllib.loads(builtin_text("cmg4_pyramid"))["simulate"]["initial"]}
    initial.update({f"gam{k}": math.radians(a) for k, a in enumerate(SINGULAR_SET, 1)})
    return Case("CMG pyramid at a singular gimbal set", load("cmg4_pyramid"),
                {"rate_ref_1": 0.0, "rate_ref_2": -0.2, "rate_ref_3": 0.0, "rate_ref_4": -0.2},
                initial, 10.0, "pass", samples=100,
                quadrature=True, extreme=STEERING)  # fmt: skip


def span_text(axes: list[Any], carrier: float) -> Extreme:
    """Where nothing varies in time: the axes' span (smallest over largest
    singular value of [g_1 .. g_N]) and the carrier's scale."""
    g = np.array(axes, dtype=float)
    sv = np.linalg.svd(g / np.linalg.norm(g, axis=1, keepdims=True), compute_uv=False)
    return Extreme(
        f"axes' span s_min / s_max of [g_1 .. g_N] = {sv[-1] / sv[0]:.3g}"
        f" (warned below {AXES_SPAN_WARN:g})\ncarrier inertia x{carrier:g}"
    )


def _pyramid(name: str, **rotor_changes: Any) -> dict[str, Any]:
    """rw4_pyramid's tables renamed, each rotor's keys changed as given."""
    data = tomllib.loads(builtin_text("rw4_pyramid"))
    data.update(name=name, description=f"check: {name.replace('_', ' ')}")
    data["rotors"] = [{**r, **rotor_changes} for r in data["rotors"]]
    keys = [key for key in ("k", "w_ref") if rotor_changes.get(key, "runtime") == "runtime"]
    given = data["simulate"]["parameters"]
    data["simulate"]["parameters"] = {
        f"{key}_{k}": given.get(f"{key}_{k}", 0.05) for key in keys for k in range(1, 5)
    }
    return data


@cache
def coasting() -> Scene:
    """Every wheel free (no torque, no friction), Euler parameters: |H| and
    the energy are constant."""
    data = _pyramid("rw4_coasting", torque="none", k=None, w_ref=None, tau_max=None, b=0.0)
    data["attitude"] = "quaternion"
    return validate(data, "rw4_coasting")


@cache
def controlled() -> Scene:
    """Speed controllers with the gain at run time (k_1..k_4, w_ref_1..4), no clamp."""
    data = _pyramid("rw4_gains", k="runtime", tau_max=None)
    return validate(data, "rw4_gains")


def _tilted(tilt: float, carrier: float) -> dict[str, Any]:
    """Four wheels at A*, their axes tilt (rad) from a3 in the pyramid's
    four directions: nearly parallel; the carrier's moments scaled by carrier."""
    data = _pyramid("rw4_parallel", torque="none", k=None, w_ref=None, tau_max=None, b=0.0)
    s, c = math.sin(tilt), math.cos(tilt)
    for rotor, (x, y) in zip(data["rotors"], ((1, 0), (0, 1), (-1, 0), (0, -1)), strict=True):
        rotor.update(axis=(s * x, s * y, c), position=(0.0, 0.0, 0.0))
    data["parameters"] = {
        **{n: v * carrier for n, v in data["parameters"].items() if n != "m_a"},
        "m_a": data["parameters"]["m_a"],
    }
    data["name"] = f"rw4_tilt_{tilt:g}_carrier_{carrier:g}".replace("-", "m").replace(".", "p")
    return data


def cases(quick: bool) -> list[Case]:
    """The cluster cases in table order."""
    start = PYRAMID_START
    free = Case(
        "cluster torque-free (rw4, |H|)", coasting(), {}, start, 20.0, "pass", extreme=SHARE
    )
    out = [free]
    refs = {f"w_ref_{k}": v for k, v in zip(range(1, 5), (100.0, -50.0, 80.0, 30.0), strict=True)}
    for ratio in (1e1, 1e5) if quick else (1e1, 1e3, 1e5):
        gains = {f"k_{k}": ratio * WHEEL_J for k in range(1, 5)}
        name = f"cluster speed controllers k/J={ratio:g}"
        out.append(Case(name, controlled(), {**gains, **refs}, start, 2.0, "pass", extreme=SLIP))
    # rw4_pyramid as built in: w1 starts 10 rad/s below w_ref_1, so its motor
    # sits at +tau_max for the first ~2 s, then leaves the clamp.
    sat = {"w_ref_1": 100.0, "w_ref_2": -50.0, "w_ref_3": 80.0, "w_ref_4": 30.0}
    name = "cluster wheel saturation (clamp, energy)"
    out.append(Case(name, load("rw4_pyramid"), sat, start, 10.0, "pass", samples=200,
                    quadrature=True, extreme=CLAMP))  # fmt: skip
    out += _parallel()
    out.append(singular_pyramid())
    return out


def _parallel() -> list[Case]:
    """Nearly parallel axes: on the real carrier the dynamics stays well
    conditioned (the carrier's inertia holds the common axis) and check
    warns about the axes' span; on a carrier of tiny inertia the lumped
    inertia about the common axis is sum I_k sin^2(tilt): warned as the
    single rotor is above WARN_CONDITION, refused above MAX_CONDITION."""
    start = {"u1": 0.01, "u2": 0.02, "u3": 0.03, "w1": 50.0, "w2": 40.0, "w3": 30.0, "w4": 20.0}
    out = []
    for label, tilt, carrier, expect in (
        ("tilt 0.01 deg", 1.75e-4, 1.0, "pass"),
        ("tilt 1e-5, carrier x1e-16", 1e-5, 1e-16, "pass"),
        ("tilt 1e-8, carrier x1e-18", 1e-8, 1e-18, "refused"),
    ):
        data = _tilted(tilt, carrier)
        try:
            scene, refused = validate(data, data["name"]), ""
        except SceneError as exc:
            scene, refused = coasting(), str(exc)
        span = span_text([r["axis"] for r in data["rotors"]], carrier)
        out.append(Case(f"cluster ~parallel: {label}", scene, {}, start, 1.0, expect,
                        refused_by=refused, extreme=span))  # fmt: skip
    return out
