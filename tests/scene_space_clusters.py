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
"""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st
from scene_space import INTEGRATOR_LISTS, TARGET_LISTS, Draw, offered, to_toml, toml_value

from gyrogen.abi_rotors import MAX_ROTORS

LAWS = ("none", "constant", "speed_controller", "table")
BREAKS = ("axis of length 0", "axis of length 1.01", "J > 2 I", "negative tau_max", "negative b")


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
sign), or all in one plane (issue 21: such clusters failed `verify`)."""


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
def clusters(draw: st.DrawFn) -> Draw:
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n = draw(st.integers(1, MAX_ROTORS))
    carrier = _carrier(rng)
    runtime: set[str] = set()
    rotors = [_rotor(rng, carrier["I11"], runtime, k) for k in range(1, n + 1)]
    _lay_axes(rotors, draw(st.sampled_from(LAYOUTS)), rng)
    broken = draw(st.sampled_from([None] * 15 + list(BREAKS)))
    at = draw(st.integers(0, n - 1))
    if broken is not None:
        _break(rotors[at], broken)
    inertial = _runtime_inertia(carrier, rotors, at if broken else None, rng)
    runtime |= set(inertial)
    attitude = draw(st.sampled_from(["euler312", "quaternion"]))
    initial = {f"u{i}": draw(st.floats(-1, 1)) for i in (1, 2, 3)}
    initial.update({f"w{k}": draw(st.floats(-100, 100)) for k in range(1, n + 1)})
    params = {name: inertial.get(name, _runtime_value(name, rng)) for name in sorted(runtime)}
    top = {
        "name": f"cluster{n}",
        "description": f"a drawn cluster of {n} rotors",
        "attitude": attitude,
        "targets": draw(TARGET_LISTS),
        "integrators": offered(
            draw(INTEGRATOR_LISTS),
            all(r.get("tau_max") is None and r.get("torque") != "table" for r in rotors),
        ),
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
    for rotor in rotors:
        text += "\n[[rotors]]\n" + "".join(f"{k} = {toml_value(v)}\n" for k, v in rotor.items())
    return Draw(text, broken is None, broken or "")


def _runtime_inertia(
    carrier: dict[str, object],
    rotors: list[dict[str, object]],
    broken: int | None,
    rng: np.random.Generator,
) -> dict[str, float]:
    """Make some inertial values "runtime" (setup checks them; the drawn
    values go to simulate.parameters): the carrier's tensor and mass in one
    draw in four, in another one in four some of its diagonal moments alone
    (its products of inertia folded, of either sign), each rotor's m, I, J in
    one in four (not the broken one's), its position in one in four, its axis
    in one in four (not the broken one's)."""
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
        if k - 1 != broken and rng.random() < 0.25:
            g = rotor["axis"]
            out.update({f"g{i}_{k}": float(x) for i, x in enumerate(g, 1)})  # type: ignore[arg-type]
            rotor["axis"] = "runtime"
    return out


def _runtime_value(name: str, rng: np.random.Generator) -> float:
    key = name.rsplit("_", 1)[0]
    if key == "k":
        return float(10.0 ** rng.uniform(-3, 0))
    return float(rng.uniform(-1, 1) * (200.0 if key == "w_ref" else 1e-2))
