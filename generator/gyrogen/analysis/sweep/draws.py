"""The inputs of a sweep's trajectories start..stop-1: grid values, draws,
start states and runtime parameters, computed from the sweep alone.

Trajectory i is grid point i // count (the axes in the order written, the
last varying fastest, or zipped) with draw i % count. Its draws are a
function of (seed, i) alone: Philox, a counter-based generator, keyed by the
seed, gives trajectory i the 64-bit words of its counter blocks i * B to
(i + 1) * B - 1 (B blocks of 4 words hold one word per drawn variable), and
each word becomes a value through the inverse of its distribution's CDF
(truncated: restricted to [F(lo), F(hi)]). One word per value, never a
rejection loop, so no value depends on another trajectory, on the chunking,
the worker count or the engine. A misalignment takes two words after the
drawn variables': its tilt (the size of a draw from its cone's angle, in
degrees) and the tilt's direction about the nominal axis (uniform), so the
axis stays a unit vector; a gimbal's spin axis is turned by the same
rotation as its gimbal axis, so the pair stays orthonormal.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtri

from gyrogen.analysis.sweep.spec import Spec, rotor_of, tilted_names
from gyrogen.scene.rotors import gimbal_axes
from gyrogen.sweep_values import Axis, Distribution, Misalignment

WORDS_PER_BLOCK = 4
"""A Philox counter block gives four 64-bit words."""


@dataclass(frozen=True)
class Inputs:
    sample: np.ndarray
    """(n,) int64: the trajectories' indices in the sweep."""
    values: dict[str, np.ndarray]
    """Each swept name's (n,) values: the grid's, then the drawn ones."""
    x0: np.ndarray
    """(n, nx) start states."""
    p: np.ndarray
    """(n, np) runtime parameters, in the scene's p[] order."""


def axis_values(axis: Axis) -> np.ndarray:
    if axis.values is not None:
        return np.array(axis.values, dtype=np.float64)
    a, b, n = axis.spaced
    return np.linspace(a, b, n) if axis.linspace is not None else np.logspace(a, b, n)


def grid_values(spec: Spec, points: np.ndarray) -> dict[str, np.ndarray]:
    """Each grid axis's value at the grid points (indices into the grid)."""
    axes = {name: axis_values(axis) for name, axis in spec.sweep.grid.items()}
    if spec.sweep.combine == "zip":
        return {name: values[points] for name, values in axes.items()}
    shape = tuple(len(v) for v in axes.values())
    index = np.unravel_index(points, shape) if shape else ()
    return {name: values[i] for (name, values), i in zip(axes.items(), index, strict=True)}


def uniforms(seed: int, start: int, stop: int, k: int) -> np.ndarray:
    """(stop - start, k) numbers in (0, 1): row i - start is trajectory i's,
    from its own counter blocks of Philox keyed by seed."""
    blocks = -(-k // WORDS_PER_BLOCK)
    words = blocks * WORDS_PER_BLOCK
    gen = np.random.Philox(key=seed, counter=start * blocks)
    raw = gen.random_raw((stop - start) * words).reshape(stop - start, words)[:, :k]
    return ((raw >> np.uint64(11)).astype(np.float64) + 0.5) * 2.0**-53


def inverse_cdf(dist: Distribution, u: np.ndarray) -> np.ndarray:
    """The values of quantiles u in (0, 1) of dist (truncated if it says so)."""
    if dist.truncate is not None:
        lo, hi = dist.truncate
        f_lo, f_hi = dist.cdf(lo), dist.cdf(hi)
        u = f_lo + u * (f_hi - f_lo)
    a, b = dist.args
    if dist.kind == "uniform":
        x = a + u * (b - a)
    elif dist.kind == "normal":
        x = a + b * ndtri(u)
    else:
        x = np.exp(a + b * ndtri(u))
    if dist.truncate is not None:
        x = np.clip(x, *dist.truncate)
    return np.asarray(x, dtype=np.float64)


def drawn_values(spec: Spec, start: int, stop: int) -> dict[str, np.ndarray]:
    draws = spec.sweep.draws
    if draws is None or not (draws.variables or draws.misalign):
        return {}
    n = len(draws.variables)
    u = uniforms(draws.seed, start, stop, n + 2 * len(draws.misalign))
    out = {name: inverse_cdf(d, u[:, j]) for j, (name, d) in enumerate(draws.variables.items())}
    for j, (key, tilt) in enumerate(draws.misalign.items()):
        turned = tilted(nominal(spec, key), tilt, u[:, n + 2 * j], u[:, n + 2 * j + 1])
        for names, g in zip(tilted_names(key), turned, strict=True):
            out.update({name: g[:, i] for i, name in enumerate(names)})
    return out


def nominal(spec: Spec, key: str) -> list[np.ndarray]:
    """The unit vectors a misalignment turns (tilted_names), from the base
    parameters as setup makes them: an axis normalized; a gimbal's pair
    orthonormal (gimbal_axes: g_g normalized, g_s0 made perpendicular to it)."""
    base = spec.base_parameters()
    kind, k = rotor_of(key)
    if kind == "gimbal":
        return list(gimbal_axes(spec.scene.rotors[k - 1], k, base))
    (names,) = tilted_names(key)
    g = np.array([base[name] for name in names], dtype=np.float64)
    return [g / np.sqrt(g @ g)]


def tilted(
    nominal: Sequence[np.ndarray], tilt: Misalignment, u: np.ndarray, v: np.ndarray
) -> list[np.ndarray]:
    """(n, 3) unit vectors for each of nominal (unit vectors, the first g0
    the cone's axis): g0 turned by the angle |draw| (quantile u of the
    cone's angle, degrees) toward the direction side at angle 2 pi v about
    it (from e1, perpendicular to it in the plane of g0 and the axis of A it
    is least along, and e2 = g0 x e1); each other vector w by the same
    rotation, about g0 x side: its parts a along g0 and b along side turn
    in their plane, the rest stays."""
    g0 = nominal[0]
    away = np.eye(3)[int(np.argmin(np.abs(g0)))]
    e1 = away - (away @ g0) * g0
    e1 /= np.sqrt(e1 @ e1)
    e2 = np.cross(g0, e1)
    theta = np.radians(np.abs(inverse_cdf(tilt.cone, u)))[:, None]
    phi = 2.0 * np.pi * v
    side = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
    c, s = np.cos(theta), np.sin(theta)
    out = [c * g0 + s * side]
    for w in nominal[1:]:
        a, b = (w @ g0), (side @ w)[:, None]
        out.append(w + (c - 1.0) * (a * g0 + b * side) + s * (a * side - b * g0))
    return out


def _rows(values: Sequence[float], n: int) -> np.ndarray:
    """(n, len(values)) doubles, each row values (np.tile's, without its repeat)."""
    out = np.empty((n, len(values)), dtype=np.float64)
    out[:] = np.array(values, dtype=np.float64)
    return out


def inputs(spec: Spec, start: int, stop: int) -> Inputs:
    """Everything trajectories start..stop-1 start from."""
    sample = np.arange(start, stop, dtype=np.int64)
    values = {**grid_values(spec, sample // spec.sweep.count), **drawn_values(spec, start, stop)}
    scene = spec.scene
    base = scene.model_copy(
        update={"simulate": scene.simulate.model_copy(update={"initial": spec.base_state()})}
    )
    params = spec.base_parameters()
    x0 = _rows(base.initial_state(), len(sample))
    p = _rows([params.get(n, np.nan) for n in scene.runtime], len(sample))
    for name, v in values.items():
        if name in scene.states:
            x0[:, scene.states.index(name)] = v
        else:
            p[:, scene.runtime.index(name)] = v
    return Inputs(sample, values, x0, p)
