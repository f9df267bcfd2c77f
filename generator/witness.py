"""The numpy reference seen through a scene: the full model with the scene's
folded values, its torque law, and only the states it keeps.

Like reference.py, this never touches the sympy model: it reads the scene
(names and numbers) and fills in the full state and parameter vectors.
"""

from __future__ import annotations

import numpy as np

from gyrogen import reference, sampling
from gyrogen.layout import PARAMETERS, STATES
from gyrogen.scene import CONTROLLER_PARAMETERS, Scene

_P = {n: i for i, n in enumerate(PARAMETERS)}


def state_index(scene: Scene) -> np.ndarray:
    return np.array([STATES.index(s) for s in scene.states])


def full_states(scene: Scene, xs: np.ndarray) -> np.ndarray:
    """(n, nx) kept states -> (n, 14), the dropped ones at 0 (they couple to
    nothing the scene keeps)."""
    xs = np.atleast_2d(xs)
    full = np.zeros((xs.shape[0], len(STATES)))
    full[:, state_index(scene)] = xs
    return full


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
    x_full = full_states(scene, xs)
    out = reference.rhs(x_full, full_parameters(scene, p_runtime, x_full, t))
    return out[:, state_index(scene)]


def output(
    scene: Scene, name: str, xs: np.ndarray, p_runtime: np.ndarray, t: float = 0.0
) -> np.ndarray:
    """An output function of the scene, from the reference: shape (n, size)."""
    x_full = full_states(scene, xs)
    p = full_parameters(scene, p_runtime, x_full, t)
    if name == "kinetic_energy":
        return reference.kinetic_energy(x_full, p)[:, None]
    if name == "angular_momentum":
        return reference.angular_momentum_n(x_full, p)
    if name == "power":
        u2, u4 = x_full[:, STATES.index("u2")], x_full[:, STATES.index("u4")]
        return (p[:, _P["T"]] * (u4 - u2))[:, None]
    raise KeyError(name)


def random_runtime(
    scene: Scene, rng: np.random.Generator, n: int, max_condition: float | None = None
) -> np.ndarray:
    """n runtime parameter vectors that, with the scene's folded values, make a
    physically valid system (and a well-conditioned one with max_condition)."""
    if not scene.runtime:
        return np.zeros((1, 0))
    rows: list[np.ndarray] = []
    folded = scene.folded()
    for _ in range(1000):
        draw = sampling.random_parameters(rng, max(4 * n, 16))
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
            return np.array(rows[:n])
    raise RuntimeError(f"could not draw valid runtime parameters for scene {scene.name}")
