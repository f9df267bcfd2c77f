"""The numpy reference seen through a scene: the full model with the scene's
folded values, its torque law, and only the states it keeps.

Like reference.py, this never touches the sympy model: it reads the scene
(names and numbers) and fills in the full state and parameter vectors.
"""

from __future__ import annotations

import numpy as np

from gyrogen.abi import CONTROLLER_PARAMETERS, PARAMETERS, STATES
from gyrogen.abi_rotors import (
    AXIS_NORM_SLACK,
    GIMBAL_INERTIA,
    GIMBAL_KEYS,
    GIMBAL_PERP_SLACK,
    rotor_name,
)
from gyrogen.oracle import cluster_reference, gimbal_view, reference, sampling
from gyrogen.scene import Scene
from gyrogen.scene import events as scene_events

_P = {n: i for i, n in enumerate(PARAMETERS)}


def state_index(scene: Scene) -> np.ndarray:
    """Where each kept state sits in the full model's 14 (-1 for e0..e3)."""
    return np.array([STATES.index(s) if s in STATES else -1 for s in scene.states])


def full_states(scene: Scene, xs: np.ndarray) -> np.ndarray:
    """(n, nx) kept states -> (n, 14), the dropped ones at 0 (they couple to
    nothing the scene keeps; nor do the angles, which stand at 0 for e)."""
    xs = np.atleast_2d(xs)
    full = np.zeros((xs.shape[0], len(STATES)))
    idx = state_index(scene)
    full[:, idx[idx >= 0]] = xs[:, idx >= 0]
    return full


def quaternion_rates(e: np.ndarray, w: np.ndarray) -> np.ndarray:
    """e' = 1/2 e (x) (0, w) for Euler parameters of A in N (scalar first) and
    w the angular velocity of A in A-components (Kane, Likins and Levinson,
    Spacecraft Dynamics, 1983, eq. 1.13.6)."""
    e0, e1, e2, e3 = e.T
    w1, w2, w3 = w.T
    return 0.5 * np.stack(
        [
            -e1 * w1 - e2 * w2 - e3 * w3,
            e0 * w1 - e3 * w2 + e2 * w3,
            e3 * w1 + e0 * w2 - e1 * w3,
            -e2 * w1 + e1 * w2 + e0 * w3,
        ],
        axis=-1,
    )


def quaternion_dcm(e: np.ndarray) -> np.ndarray:
    """C with a_i = sum_j C[i, j] n_j, from Euler parameters (same source)."""
    e0, e1, e2, e3 = np.moveaxis(e, -1, 0)
    return np.stack(
        [
            np.stack(
                [e0**2 + e1**2 - e2**2 - e3**2, 2 * (e1 * e2 + e0 * e3), 2 * (e1 * e3 - e0 * e2)],
                -1,
            ),
            np.stack(
                [2 * (e1 * e2 - e0 * e3), e0**2 - e1**2 + e2**2 - e3**2, 2 * (e2 * e3 + e0 * e1)],
                -1,
            ),
            np.stack(
                [2 * (e1 * e3 + e0 * e2), 2 * (e2 * e3 - e0 * e1), e0**2 - e1**2 - e2**2 + e3**2],
                -1,
            ),
        ],
        axis=-2,
    )


def torque(scene: Scene, values: dict[str, float], x_full: np.ndarray, t: float) -> np.ndarray:
    law = scene.effects.torque
    n = x_full.shape[0]
    if law == "none":
        return np.zeros(n)
    if law == "constant":
        return np.full(n, values["T"])
    if law == "speed_controller":
        u2, u4 = x_full[:, STATES.index("u2")], x_full[:, STATES.index("u4")]
        return -values["k"] * (u4 - u2 - values["w_ref"])
    table = np.array(scene.effects.torque_table)
    return np.full(n, np.interp(t, table[:, 0], table[:, 1]))


def values(scene: Scene, p_runtime: np.ndarray) -> dict[str, float]:
    """Every parameter by name: the folded ones and p[] in manifest order."""
    out = {k: float(v) for k, v in scene.folded().items()}
    out.update(zip(scene.runtime, map(float, p_runtime), strict=True))
    return out


def full_parameters(
    scene: Scene, p_runtime: np.ndarray, x_full: np.ndarray, t: float
) -> np.ndarray:
    """(n, 12) parameters of the full model: T follows the scene's law, g is
    0 when the scene has no translation."""
    v = values(scene, p_runtime)
    p = np.zeros((x_full.shape[0], len(PARAMETERS)))
    for name, i in _P.items():
        if name not in ("T", "g"):
            p[:, i] = v[name]
    p[:, _P["g"]] = v.get("g", 0.0)
    p[:, _P["T"]] = torque(scene, v, x_full, t)
    return p


def rhs(scene: Scene, xs: np.ndarray, p_runtime: np.ndarray, t: float = 0.0) -> np.ndarray:
    xs = np.atleast_2d(xs)
    if scene.rotors:
        cluster = gimbal_view if gimbal_view.has_gimbals(scene) else cluster_reference
        out = cluster.rhs(scene, xs, values(scene, p_runtime), t)
        if scene.attitude == "quaternion":
            out[:, :4] = quaternion_rates(xs[:, :4], xs[:, _body_rates(scene)])
        return out
    x_full = full_states(scene, xs)
    full = reference.rhs(x_full, full_parameters(scene, p_runtime, x_full, t))
    idx = state_index(scene)
    out = np.empty_like(xs, dtype=float)
    out[:, idx >= 0] = full[:, idx[idx >= 0]]
    if scene.attitude == "quaternion":
        w = x_full[:, [STATES.index(f"u{i}") for i in (1, 2, 3)]]
        out[:, :4] = quaternion_rates(xs[:, :4], w)
    return out


def table_times(scene: Scene) -> np.ndarray:
    """Scene.table_times as an array."""
    return np.array(scene.table_times, dtype=float)


def _body_rates(scene: Scene) -> list[int]:
    """Where u1..u3 sit in a cluster's x[]."""
    return [scene.states.index(f"u{i}") for i in (1, 2, 3)]


def kinks(scene: Scene, xs: np.ndarray, p_runtime: np.ndarray, t: float = 0.0) -> np.ndarray:
    """(n, K) values whose signs change exactly where the rhs is not smooth
    in the state: a cluster's torque clamps (cluster_reference.clamp_margins);
    none (K = 0) for the paper's scenes, smooth in the state."""
    xs = np.atleast_2d(xs)
    if not scene.rotors:
        return np.zeros((len(xs), 0))
    cluster = gimbal_view if gimbal_view.has_gimbals(scene) else cluster_reference
    return cluster.clamp_margins(scene, xs, values(scene, p_runtime), t)


def output(
    scene: Scene, name: str, xs: np.ndarray, p_runtime: np.ndarray, t: float = 0.0
) -> np.ndarray:
    """An output function of the scene, from the reference: shape (n, size)."""
    if scene.rotors:
        xs = np.atleast_2d(xs)
        if scene.attitude == "quaternion":
            dcm = quaternion_dcm(xs[:, :4])
        else:
            angles = np.zeros((len(xs), len(STATES)))
            angles[:, :3] = xs[:, :3]
            dcm = reference.direction_cosines(angles)
        cluster = gimbal_view if gimbal_view.has_gimbals(scene) else cluster_reference
        return cluster.outputs(scene, name, xs, values(scene, p_runtime), dcm, t)
    x_full = full_states(scene, xs)
    p = full_parameters(scene, p_runtime, x_full, t)
    if name == "kinetic_energy":
        return reference.kinetic_energy(x_full, p)[:, None]
    if name == "angular_momentum":
        if scene.attitude == "quaternion":  # H in A from the reference, turned into N here
            h_a = np.einsum(
                "nij,nj->ni",
                reference.direction_cosines(x_full),
                reference.angular_momentum_n(x_full, p),
            )
            return np.einsum("nij,ni->nj", quaternion_dcm(np.atleast_2d(xs)[:, :4]), h_a)
        return reference.angular_momentum_n(x_full, p)
    if name == "power":
        u2, u4 = x_full[:, STATES.index("u2")], x_full[:, STATES.index("u4")]
        return (p[:, _P["T"]] * (u4 - u2))[:, None]
    raise KeyError(name)


EVENT_FUNCTIONS = {
    "sin": np.sin,
    "cos": np.cos,
    "sqrt": np.sqrt,
    "abs": np.abs,
    "min": np.fmin,  # a NaN argument is ignored, as C's fmin and the generated min
    "max": np.fmax,
}


def events(scene: Scene, xs: np.ndarray, p_runtime: np.ndarray, t: float = 0.0) -> np.ndarray:
    """The scene's event functions g(t, x), from the reference: shape (n, events)."""
    xs = np.atleast_2d(xs)
    v = values(scene, p_runtime)
    column = {s: xs[:, i] for i, s in enumerate(scene.states)}
    outputs: dict[str, np.ndarray] = {}

    def value(leaf: scene_events.Node) -> object:
        if leaf[0] == "output" or leaf[1] in scene_events.OUTPUTS:
            name = str(leaf[1])
            if name not in outputs:
                outputs[name] = output(scene, name, xs, p_runtime, t)
            return outputs[name][:, leaf[2] if leaf[0] == "output" else 0]
        name = str(leaf[1])
        if name in column:
            return column[name]
        return t if name == scene_events.TIME else v[name]

    cols = []
    for e in scene.events:
        with np.errstate(all="ignore"):  # a NaN or Inf g is the event's own (as in C)
            g = scene_events.evaluate(scene_events.parse(e.expr), value, EVENT_FUNCTIONS)
        cols.append(np.broadcast_to(np.asarray(g, dtype=float), (len(xs),)))
    return np.stack(cols, axis=1) if cols else np.zeros((len(xs), 0))


def random_runtime(
    scene: Scene, rng: np.random.Generator, n: int, max_condition: float | None = None
) -> np.ndarray:
    """Up to n runtime parameter vectors that, with the scene's folded values,
    make a physically valid system (and a well-conditioned one with
    max_condition). Fewer (maybe none) when the folded values leave the
    valid runtime values a sliver the draws rarely hit."""
    if not scene.runtime:
        return np.zeros((1, 0))
    if scene.rotors:
        return _cluster_runtime(scene, rng, n)
    rows: list[np.ndarray] = []
    folded = scene.folded()
    for _ in range(200):
        draw = sampling.random_parameters(rng, max(4 * n, 16))
        _near_folded(draw, folded, rng)
        for name, value in folded.items():
            if name in _P:
                draw[:, _P[name]] = value
        ok = np.array([sampling.setup_code(row) == 0 for row in draw])
        if max_condition is not None:
            ok &= sampling.lumped_condition(draw) <= max_condition
        extra = {
            "k": np.exp(rng.uniform(np.log(1e-2), np.log(10.0), len(draw))),
            "w_ref": rng.uniform(-300.0, 300.0, len(draw)),
        }
        for i in np.flatnonzero(ok):
            rows.append(
                np.array(
                    [
                        extra[r][i] if r in CONTROLLER_PARAMETERS else draw[i, _P[r]]
                        for r in scene.runtime
                    ]
                )
            )
        if len(rows) >= n:
            break
    return np.array(rows[:n]).reshape(-1, len(scene.runtime))


_CARRIER = ("I11", "I22", "I33", "I13")


def _near_folded(draw: np.ndarray, folded: dict[str, float], rng: np.random.Generator) -> None:
    """In half of the rows, draw the runtime carrier and rotor inertias on the
    scale of the folded ones (a carrier's triangle inequality, the rotor's
    J <= 2 I), so that a split of those groups still finds valid values."""
    half = rng.random(len(draw)) < 0.5
    m = int(half.sum())
    scale = [abs(folded[k]) for k in _CARRIER if folded.get(k)]
    if scale and m:
        s = float(np.mean(scale))
        for k in _CARRIER:
            if k not in folded:
                if k == "I13":
                    draw[half, _P[k]] = rng.uniform(-s, s, m)
                else:
                    draw[half, _P[k]] = s * np.exp(rng.uniform(-np.log(20), np.log(20), m))
    if m and "I" in folded and "J" not in folded:
        draw[half, _P["J"]] = 2.0 * folded["I"] * rng.uniform(0.05, 1.0, m)
    if m and "J" in folded and "I" not in folded:
        draw[half, _P["I"]] = folded["J"] / 2.0 * np.exp(rng.uniform(0.0, np.log(20), m))


def random_states(scene: Scene, rng: np.random.Generator, n: int) -> np.ndarray:
    """n random states of the scene: sampling.random_states restricted to the
    kept ones, with random unit quaternions for e0..e3."""
    if scene.rotors:
        return _cluster_states(scene, rng, n)
    full = sampling.random_states(rng, n)
    idx = state_index(scene)
    out = np.zeros((n, len(scene.states)))
    out[:, idx >= 0] = full[:, idx[idx >= 0]]
    if scene.attitude == "quaternion":
        e = rng.normal(size=(n, 4))
        out[:, :4] = e / np.linalg.norm(e, axis=1, keepdims=True)
    return out


def condition(scene: Scene, p_runtime: np.ndarray) -> float:
    """The condition number compare groups parameter sets by: the coupled
    block's (a cluster's: its folded inertia's, ||A||_F ||A^-1||_F)."""
    if gimbal_view.has_gimbals(scene):
        return gimbal_view.condition(scene, values(scene, p_runtime))
    if scene.rotors:
        return cluster_reference.condition(scene, values(scene, p_runtime))
    full = full_parameters(scene, p_runtime, np.zeros((1, len(STATES))), 0.0)[0]
    return float(sampling.lumped_condition(full))


_CLUSTER_DRAWS = {
    "T": lambda rng, n: rng.uniform(-0.5, 0.5, n),
    "k": lambda rng, n: np.exp(rng.uniform(np.log(1e-2), np.log(10.0), n)),
    "w_ref": lambda rng, n: rng.uniform(-300.0, 300.0, n),
    "Tg": lambda rng, n: rng.uniform(-0.5, 0.5, n),
    "kg": lambda rng, n: np.exp(rng.uniform(np.log(1e-3), np.log(1.0), n)),
    "rate_ref": lambda rng, n: rng.uniform(-1.0, 1.0, n),
}
"""A runtime torque law's values, by key (a gimbal's Tg, kg and rate_ref too)."""


def _cluster_runtime(scene: Scene, rng: np.random.Generator, n: int) -> np.ndarray:
    """A cluster's runtime values: torque laws' (T, k, w_ref), any draw
    valid; an axial inertia J_k within (0.1, 2] of its rotor's I_k."""
    cols: dict[str, np.ndarray] = {}
    folded = scene.folded()
    diagonal = [float(folded[d]) for d in ("I11", "I22", "I33") if d in folded]
    scale = float(np.mean(diagonal)) if diagonal else 100.0
    for name in scene.runtime:  # in p[] order: a rotor's I before its J
        key, _, k = name.rpartition("_")  # I11: key ""
        if name == "m_a":
            cols[name] = rng.uniform(50.0, 500.0, n)
        elif name in ("I11", "I22", "I33"):  # within 0.8..1.2 of each other: triangle kept
            cols[name] = scale * rng.uniform(0.8, 1.2, n)
        elif name in ("I12", "I13", "I23"):
            cols[name] = scale * rng.uniform(-0.05, 0.05, n)
        elif key in ("m", GIMBAL_KEYS["m"]):
            cols[name] = rng.uniform(1.0, 10.0, n)
        elif key in GIMBAL_INERTIA:
            cols[name] = _frame_inertia(scene, int(k), key, cols, rng, n)
        elif key == "I":
            axial = scene.rotors[int(k) - 1].J
            if axial == "runtime":
                cols[name] = rng.uniform(0.01, 0.05, n)
            else:  # J <= 2 I: I at least half the folded J
                cols[name] = float(axial) * rng.uniform(0.5, 2.5, n)
        elif key in ("r1", "r2", "r3"):
            cols[name] = rng.uniform(-0.5, 0.5, n)
        elif key in ("g1", "gg1") and scene.rotors[int(k) - 1].gimbal is not None:
            cols.update(_gimbal_pair(scene, int(k), key, cols, rng, n))
        elif key == "g1":  # a direction anywhere, its length within the slack of 1
            g = rng.normal(size=(n, 3))
            g *= rng.uniform(1.0 - AXIS_NORM_SLACK, 1.0 + AXIS_NORM_SLACK, (n, 1)) / np.linalg.norm(
                g, axis=1, keepdims=True
            )
            for i in (1, 2, 3):
                cols[f"g{i}_{k}"] = g[:, i - 1]
        elif key in ("g2", "g3", "gg2", "gg3"):
            pass  # drawn with g1 or gg1
        elif key == "J":
            inertia = scene.rotors[int(k) - 1].I
            base = cols[f"I_{k}"] if inertia == "runtime" else float(inertia)
            cols[name] = base * rng.uniform(0.1, 2.0, n)
        else:
            cols[name] = _CLUSTER_DRAWS[key](rng, n)
    return np.stack([cols[name] for name in scene.runtime], axis=1)


def _gimbal_pair(
    scene: Scene, k: int, key: str, cols: dict[str, np.ndarray], rng: np.random.Generator, n: int
) -> dict[str, np.ndarray]:
    """A gimbal's runtime spin axis (key g1) or gimbal axis (gg1): anywhere
    perpendicular to the other (folded, or drawn: the spin axis comes first
    in p[]), tilted from it by up to half GIMBAL_PERP_SLACK, its length
    within the slack of 1."""
    r = scene.rotors[k - 1]
    assert r.gimbal is not None
    other = r.gimbal.axis if key == "g1" else r.axis
    if other == "runtime":
        other_key = "gg" if key == "g1" else "g"
        if f"{other_key}1_{k}" not in cols:  # the first of the pair: anywhere
            return _unit_draws(key[:-1], k, rng.normal(size=(n, 3)), rng, n)
        base = np.column_stack([cols[f"{other_key}{i}_{k}"] for i in (1, 2, 3)])
    else:
        base = np.tile(np.array(other, dtype=float), (n, 1))
    base /= np.linalg.norm(base, axis=1, keepdims=True)
    g = rng.normal(size=(n, 3))
    g -= (g * base).sum(1, keepdims=True) * base
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    g += rng.uniform(-0.5, 0.5, (n, 1)) * GIMBAL_PERP_SLACK * base
    return _unit_draws(key[:-1], k, g, rng, n)


def _unit_draws(
    key: str, k: int, g: np.ndarray, rng: np.random.Generator, n: int
) -> dict[str, np.ndarray]:
    """Directions g (n, 3) scaled to a length within the slack of 1, as
    columns key1_k..key3_k."""
    g = (
        g
        * rng.uniform(1.0 - AXIS_NORM_SLACK, 1.0 + AXIS_NORM_SLACK, (n, 1))
        / np.linalg.norm(g, axis=1, keepdims=True)
    )
    return {f"{key}{i}_{k}": g[:, i - 1] for i in (1, 2, 3)}


def _frame_inertia(
    scene: Scene, k: int, key: str, cols: dict[str, np.ndarray], rng: np.random.Generator, n: int
) -> np.ndarray:
    """A gimbal frame's runtime principal inertia (key of GIMBAL_INERTIA),
    drawn in p[] order after the ones before it: with two others known
    (folded or drawn), strictly inside the triangle inequality's interval
    (|a - b|, a + b); else within 0.8..1.2 of the known ones' mean (0.2
    kg m^2 with none)."""
    gimbal = scene.rotors[k - 1].gimbal
    assert gimbal is not None
    known = [
        np.full(n, float(v)) if v != "runtime" else cols[rotor_name(other, k)]
        for other, v in zip(GIMBAL_INERTIA, gimbal.inertia, strict=True)
        if other != key and (v != "runtime" or rotor_name(other, k) in cols)
    ]
    if len(known) == 2:
        low, high = np.abs(known[0] - known[1]), known[0] + known[1]
        return low + (high - low) * rng.uniform(0.1, 0.9, n)
    scale = np.mean(known, axis=0) if known else np.full(n, 0.2)
    return scale * rng.uniform(0.8, 1.2, n)


def _cluster_states(scene: Scene, rng: np.random.Generator, n: int) -> np.ndarray:
    """Attitudes away from gimbal lock (or unit quaternions), rotor and
    gimbal angles, body and gimbal rates of order 1 rad/s and wheel rates up
    to 300 rad/s."""
    names = scene.states
    out = np.zeros((n, len(names)))
    if scene.attitude == "quaternion":
        e = rng.normal(size=(n, 4))
        out[:, :4] = e / np.linalg.norm(e, axis=1, keepdims=True)
    else:
        out[:, :3] = rng.uniform(-1.4, 1.4, (n, 3))
    for i, name in enumerate(names):
        if name.startswith(("th", "gam")):
            out[:, i] = rng.uniform(-np.pi, np.pi, n)
        elif name.startswith(("u", "gd")):
            out[:, i] = rng.normal(size=n)
        elif name.startswith("w"):
            out[:, i] = rng.uniform(-300.0, 300.0, n)
    return out
