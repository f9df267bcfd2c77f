"""`gyrogen check`'s cases for reaction-wheel clusters, variants of the
rw4_pyramid scene: torque-free, stiff speed controllers, saturating motors,
nearly parallel axes (warned, then refused).

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

from gyrogen.analysis.check_engine import Case
from gyrogen.errors import SceneError
from gyrogen.scene import Scene, builtin_text, load, validate

PYRAMID_START = {"u1": 0.3, "u2": -0.2, "u3": 0.5, "w1": 90.0, "w2": -40.0, "w3": 60.0, "w4": 30.0}
WHEEL_J = 0.045
"""rw4_pyramid's axial inertia: the controller gains are multiples of it."""


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
    out = [Case("cluster torque-free (rw4, |H|)", coasting(), {}, start, 20.0, "pass")]
    refs = {f"w_ref_{k}": v for k, v in zip(range(1, 5), (100.0, -50.0, 80.0, 30.0), strict=True)}
    for ratio in (1e1, 1e5) if quick else (1e1, 1e3, 1e5):
        gains = {f"k_{k}": ratio * WHEEL_J for k in range(1, 5)}
        name = f"cluster speed controllers k/J={ratio:g}"
        out.append(Case(name, controlled(), {**gains, **refs}, start, 2.0, "pass"))
    # rw4_pyramid as built in: w1 starts 10 rad/s below w_ref_1, so its motor
    # sits at +tau_max for the first ~2 s, then leaves the clamp.
    sat = {"w_ref_1": 100.0, "w_ref_2": -50.0, "w_ref_3": 80.0, "w_ref_4": 30.0}
    name = "cluster wheel saturation (clamp, energy)"
    out.append(Case(name, load("rw4_pyramid"), sat, start, 10.0, "pass", samples=200,
                    quadrature=True))  # fmt: skip
    out += _parallel()
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
        out.append(Case(f"cluster ~parallel: {label}", scene, {}, start, 1.0, expect,
                        refused_by=refused))  # fmt: skip
    return out
