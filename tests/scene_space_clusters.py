"""The scene space of reaction-wheel clusters: a hypothesis strategy that
draws whole cluster scene files ([[rotors]] tables), for scene_space.check.

A draw: a carrier of any mass and full symmetric inertia tensor (principal
moments meeting the triangle inequality, turned by a random rotation), N = 1
to 6 rotors on random axes (unit vectors written to 17 digits; at times all
along the carrier's axes, or all in one plane) at random positions, each
with its own mass, inertias, friction, torque law (none, constant, speed
controller, a T(t) table; values folded or "runtime") and optional limit,
the carrier's mass and tensor (or its diagonal moments alone, beside folded
products of either sign) and each rotor's m, I, J, position (of either sign
when folded) and axis at times "runtime";
either attitude, the rotor angles or not, any outputs, integrators and
targets. One draw in four breaks one rotor on purpose (an axis of length 0
or 1.01, J > 2 I, a negative limit or friction): the validator must refuse
exactly those, each with one line.

With gimbals=True (control-moment gyros), N = 1 to 3 rotors, the first on a
gimbal and each other one in two: a gimbal axis anywhere perpendicular to
the rotor's spin axis, a frame of any principal inertias meeting the
triangle inequality and any mass (each at times "runtime"), its own torque
law (none, constant, rate servo, table; T, k and rate_ref at times
"runtime") and optional clamp, and a start angle and rate. One draw in
four breaks one gimbal (its axis along the spin axis, or its inertias past
the triangle inequality) or one rotor as above.
"""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st
from scene_space import INTEGRATOR_LISTS, TARGET_LISTS, Draw, offered, to_toml, toml_value

from gyrogen.abi_rotors import MAX_ROTORS

LAWS = ("none", "constant", "speed_controller", "table")
BREAKS = ("axis of length 0", "axis of length 1.01", "J > 2 I", "negative tau_max", "negative b")
GIMBAL_LAWS = ("none", "constant", "rate_servo", "table")
GIMBAL_BREAKS = ("gimbal axis along the spin axis", "gimbal inertias past the triangle")


def _carrier(rng: np.random.Generator) -> dict[str, float]:
    """m_a and I11..I23: principal moments a + b >= c, turned by a random rotation."""
    scale = 10.0 ** rng.uniform(-1, 3)
    a, b = rng.uniform(0.3, 1.0, 2) * scale
    c = rng.uniform(abs(a - b), a + b) if rng.random() < 0.9 else a + b  # a lamina at times
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    tensor = q @ np.diag([a, b, c]) @ q.T
    names = {"I11": (0, 0), "I22": (1, 1), "I33": (2, 2), "I12": (0, 1), "I13": (0, 2),
             "I23": (1, 2)}  # fmt: skip
    out = {"m_a": float(scale * rng.uniform(1, 10))}
    out.update({n: float(tensor[i, j]) for n, (i, j) in names.items()})
    return out


def _rotor(rng: np.random.Generator, scale: float, runtime: set[str], k: int) -> dict[str, object]:
    g = rng.normal(size=3)
    size = 10.0 ** rng.uniform(-3, -1) * scale
    inertia = float(size * rng.uniform(0.5, 1.0))
    rotor: dict[str, object] = {
        "m": float(10.0 ** rng.uniform(-1, 1)),
        "I": inertia,
        "J": float(inertia * rng.uniform(0.1, 2.0)),
        "axis": [float(x) for x in g / np.linalg.norm(g)],
        "position": [float(x) for x in rng.uniform(-1, 1, 3)],
    }
    if rng.random() < 0.5:
        rotor["b"] = float(10.0 ** rng.uniform(-6, -2))
    law = str(rng.choice(LAWS))
    rotor["torque"] = law
    values = {"T": float(rng.uniform(-1, 1) * size), "k": float(10.0 ** rng.uniform(-3, 0)),
              "w_ref": float(rng.uniform(-200, 200))}  # fmt: skip
    if law == "table":  # 2 to 6 points over the drawn scene's 1 s, and beyond it
        times = np.sort(rng.uniform(-0.2, 1.2, rng.integers(2, 7)))
        torques = rng.uniform(-1, 1, times.size) * size
        rotor["torque_table"] = [[float(t), float(v)] for t, v in zip(times, torques, strict=True)]
    for key in {"constant": ("T",), "speed_controller": ("k", "w_ref")}.get(law, ()):
        if rng.random() < 0.5:
            rotor[key] = "runtime"
            runtime.add(f"{key}_{k}")
        else:
            rotor[key] = values[key]
    if law != "none" and rng.random() < 0.5:
        rotor["tau_max"] = float(abs(values["T"]) + 10.0 ** rng.uniform(-3, 0))
    return rotor


LAYOUTS = ("random", "random", "carrier axes", "coplanar")
"""How the rotors' axes lie: anywhere, along the carrier's a1, a2, a3 (either
sign), or all in one plane (such clusters once failed `verify`)."""


def _lay_axes(rotors: list[dict[str, object]], layout: str, rng: np.random.Generator) -> None:
    normal = rng.normal(size=3)
    for rotor in rotors:
        if layout == "carrier axes":
            g = np.zeros(3)
            g[rng.integers(3)] = rng.choice([-1.0, 1.0])
        elif layout == "coplanar":
            v = rng.normal(size=3)
            g = v - normal * (v @ normal) / (normal @ normal)
            g /= np.linalg.norm(g)
        else:
            continue
        rotor["axis"] = [float(x) for x in g]


def _gimbal(
    rng: np.random.Generator, rotor: dict[str, object], inertia: float, runtime: set[str], k: int
) -> tuple[dict[str, object], dict[str, float]]:
    """A [rotors.gimbal] table for rotor (its axis folded; inertia its I),
    and the drawn values of the keys made "runtime" (by their names in p[])."""
    spin = np.array(rotor["axis"], dtype=float)
    v = rng.normal(size=3)
    g = v - spin * (v @ spin) / max(float(spin @ spin), 1e-300)
    size = inertia * 10.0 ** rng.uniform(0, 1)
    a, b = rng.uniform(0.3, 1.0, 2) * size
    c = rng.uniform(abs(a - b), a + b)
    law = str(rng.choice(GIMBAL_LAWS))
    gimbal: dict[str, object] = {
        "axis": [float(x) for x in g / np.linalg.norm(g)],
        "inertia": [float(x) for x in rng.permutation([a, b, c])],
        "m": float(10.0 ** rng.uniform(-1, 1)),
        "torque": law,
    }
    values: dict[str, float] = {}
    if rng.random() < 0.25:  # the frame's mass and some of its inertias at run time
        values[f"mG_{k}"] = float(gimbal["m"])  # type: ignore[arg-type]
        gimbal["m"] = "runtime"
        inertia = list(gimbal["inertia"])  # type: ignore[call-overload]
        for i, name in enumerate(("IGs", "IGt", "IGg")):
            if rng.random() < 0.5:
                values[f"{name}_{k}"], inertia[i] = float(inertia[i]), "runtime"
        gimbal["inertia"] = inertia
    drawn = {"T": float(rng.uniform(-1, 1) * size), "k": float(size * 10.0 ** rng.uniform(0, 2)),
             "rate_ref": float(rng.uniform(-0.5, 0.5))}  # fmt: skip
    if law == "table":
        times = np.sort(rng.uniform(-0.2, 1.2, rng.integers(2, 7)))
        torques = rng.uniform(-1, 1, times.size) * size
        gimbal["torque_table"] = [[float(t), float(x)] for t, x in zip(times, torques, strict=True)]
    for key in {"constant": ("T",), "rate_servo": ("k", "rate_ref")}.get(law, ()):
        name = {"T": "Tg", "k": "kg"}.get(key, key)
        if rng.random() < 0.5:
            gimbal[key] = "runtime"
            runtime.add(f"{name}_{k}")
            values[f"{name}_{k}"] = drawn[key]
        else:
            gimbal[key] = drawn[key]
    if law != "none" and rng.random() < 0.5:
        gimbal["tau_max"] = float(abs(drawn["T"]) + size * 10.0 ** rng.uniform(-2, 0))
    return gimbal, values


def _break_gimbal(gimbal: dict[str, object], spin: object, how: str) -> None:
    if how == "gimbal axis along the spin axis":
        gimbal["axis"] = spin
    else:
        gimbal["inertia"] = [0.1, 0.1, 0.3]


def _break(rotor: dict[str, object], how: str) -> None:
    if how == "axis of length 0":
        rotor["axis"] = [0.0, 0.0, 0.0]
    elif how == "axis of length 1.01":
        rotor["axis"] = [1.01 * float(x) for x in rotor["axis"]]  # type: ignore[attr-defined]
    elif how == "J > 2 I":
        rotor["J"] = 2.5 * float(rotor["I"])  # type: ignore[arg-type]
    elif how == "negative tau_max":
        rotor["tau_max"] = -0.1
    else:
        rotor["b"] = -1e-3


@st.composite
def clusters(draw: st.DrawFn, gimbals: bool = False) -> Draw:
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n = draw(st.integers(1, 3 if gimbals else MAX_ROTORS))
    carrier = _carrier(rng)
    runtime: set[str] = set()
    rotors = [_rotor(rng, carrier["I11"], runtime, k) for k in range(1, n + 1)]
    _lay_axes(rotors, draw(st.sampled_from(LAYOUTS)), rng)
    on = [k == 0 or rng.random() < 0.5 for k in range(n)] if gimbals else [False] * n
    breaks = list(BREAKS) + (list(GIMBAL_BREAKS) if gimbals else [])
    broken = draw(st.sampled_from([None] * (3 * len(breaks)) + breaks))
    at = 0 if broken in GIMBAL_BREAKS else draw(st.integers(0, n - 1))
    if broken is not None and broken not in GIMBAL_BREAKS:
        _break(rotors[at], broken)
    inertial = _runtime_inertia(carrier, rotors, at if broken else None, rng, on)
    runtime |= set(inertial)
    frames: dict[int, dict[str, object]] = {}
    for k in (k for k in range(1, n + 1) if on[k - 1]):
        wheel = rotors[k - 1]["I"]
        inertia = inertial[f"I_{k}"] if wheel == "runtime" else float(wheel)  # type: ignore[arg-type]
        frames[k], values = _gimbal(rng, rotors[k - 1], inertia, runtime, k)
        if broken in GIMBAL_BREAKS and k == 1:
            _break_gimbal(frames[k], rotors[0]["axis"], broken)
        else:  # a broken gimbal's runtime values would be refused anyway
            inertial.update(values)
            runtime |= set(values)
    attitude = draw(st.sampled_from(["euler312", "quaternion"]))
    initial = {f"u{i}": draw(st.floats(-1, 1)) for i in (1, 2, 3)}
    initial.update({f"w{k}": draw(st.floats(-100, 100)) for k in range(1, n + 1)})
    initial.update({f"gam{k}": draw(st.floats(-4, 4)) for k in frames})
    initial.update({f"gd{k}": draw(st.floats(-1, 1)) for k in frames})
    params = {name: inertial.get(name, _runtime_value(name, rng)) for name in sorted(runtime)}
    smooth = all(
        t.get("tau_max") is None and t.get("torque") != "table" for t in [*rotors, *frames.values()]
    )
    top = {
        "name": f"cmg{n}" if gimbals else f"cluster{n}",
        "description": f"a drawn cluster of {n} rotors" + (", on gimbals" if gimbals else ""),
        "attitude": attitude,
        "targets": draw(TARGET_LISTS),
        "integrators": offered(draw(INTEGRATOR_LISTS), smooth),
    }
    tables = {
        "parameters": carrier,
        "effects": {"rotor_angle": draw(st.booleans())},
        "outputs": {
            k: draw(st.booleans()) for k in ("kinetic_energy", "angular_momentum", "power")
        },
        "simulate": {"t_end": 1.0, "initial": initial, "parameters": params},
    }
    text = to_toml(top, tables)
    for k, rotor in enumerate(rotors, 1):
        text += "\n[[rotors]]\n" + "".join(f"{k} = {toml_value(v)}\n" for k, v in rotor.items())
        if k in frames:
            text += "[rotors.gimbal]\n" + "".join(
                f"{key} = {toml_value(v)}\n" for key, v in frames[k].items()
            )
    return Draw(text, broken is None, broken or "")


def _runtime_inertia(
    carrier: dict[str, object],
    rotors: list[dict[str, object]],
    broken: int | None,
    rng: np.random.Generator,
    on: list[bool],
) -> dict[str, float]:
    """Make some inertial values "runtime" (setup checks them; the drawn
    values go to simulate.parameters): the carrier's tensor and mass in one
    draw in four, in another one in four some of its diagonal moments alone
    (its products of inertia folded, of either sign), each rotor's m, I, J in
    one in four (not the broken one's), its position in one in four, its axis
    in one in four (not the broken one's, nor one on a gimbal: on)."""
    out: dict[str, float] = {}
    carrier_draw = rng.random()
    if carrier_draw < 0.25:
        names: tuple[str, ...] = ("m_a", "I11", "I22", "I33", "I12", "I13", "I23")
    elif carrier_draw < 0.5:  # diagonals beside folded products, each negative one time in two
        names = tuple(n for n in ("I11", "I22", "I33") if rng.random() < 0.5) or ("I11",)
    else:
        names = ()
    for name in names:
        out[name] = float(carrier[name])  # type: ignore[arg-type]
        carrier[name] = "runtime"
    for k, rotor in enumerate(rotors, 1):
        for key in ("m", "I", "J"):
            if k - 1 != broken and rng.random() < 0.25:
                out[f"{key}_{k}"] = float(rotor[key])  # type: ignore[arg-type]
                rotor[key] = "runtime"
        if rng.random() < 0.25:
            at = rotor["position"]
            out.update({f"r{i}_{k}": float(x) for i, x in enumerate(at, 1)})  # type: ignore[arg-type]
            rotor["position"] = "runtime"
        if k - 1 != broken and not on[k - 1] and rng.random() < 0.25:
            g = rotor["axis"]
            out.update({f"g{i}_{k}": float(x) for i, x in enumerate(g, 1)})  # type: ignore[arg-type]
            rotor["axis"] = "runtime"
    return out


def _runtime_value(name: str, rng: np.random.Generator) -> float:
    key = name.rsplit("_", 1)[0]
    if key in ("k", "kg"):
        return float(10.0 ** rng.uniform(-3, 0))
    if key == "rate_ref":
        return float(rng.uniform(-0.5, 0.5))
    return float(rng.uniform(-1, 1) * (200.0 if key == "w_ref" else 1e-2))
