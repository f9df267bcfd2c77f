"""A simulated trajectory: the output grid, the quadrature nodes sampled
inside each of its intervals, and integrals over time by those nodes.

The integrals are Gauss-Legendre sums, QUAD_NODES nodes inside each output
interval, sampled along with the grid (from solve_ivp's dense output, or as
step ends of a compiled integrator): a trapezoid on the grid alone is off by
~(dt/tau)^2 wherever the integrand changes on a time scale tau near dt (the
speed controller's torque: 1e-2). A transient much shorter than dt
(stiff_wheel's 1e-5 s at the start: the wheel's whole spin-up) or a kink (a
clamped motor) falls between the nodes; there Simpson's rule on the
interval's ends and midpoint disagrees with the nodes' sum, and the interval
is bisected, its states integrated again from its start (Trajectory.again,
at a tighter tolerance), until they agree to QUAD_TOL of the integral's
scale, or to how far the rates are known (the states' tolerance times the
rates' gain), or to rounding.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

QUAD_NODES = 3
"""Odd: the middle node is the interval's midpoint, which Simpson's rule shares."""
QUAD_TOL = 1e-12
"""The quadrature error allowed in an integral over the whole run, relative
to its scale (the balance's normalizer), spread over the run by length;
and at least ROUNDING of each piece's |integrand| times its length."""
ROUNDING = 1e3 * np.finfo(float).eps
NOISE = 10.0
"""Simpson's rule and the nodes agree when they differ by at most this times
the width times how far the rates are known (_known)."""
PROGRESS = 1.5
"""A bisection goes on while it shrinks the rules' difference at least this
much (a transient's halves: 2; a kink's: 4; a smooth rate's: 32); where it
does not STALLS times in a row, the rates' noise is what they see (a kink
near a node may stall once)."""
STALLS = 3
MAX_BISECTIONS = 10**5
"""Intervals bisected in one run at most (a layer takes ~50)."""
QUADRATURE = (
    f"Gauss-Legendre, {QUAD_NODES} nodes per output interval (the states from solve_ivp's dense "
    "output or the compiled integrator's step ends), bisected and integrated again from its "
    f"start where Simpson's rule disagrees by more than {QUAD_TOL:g} of the scale (a transient, "
    "a kink)"
)
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(QUAD_NODES)
_MID = QUAD_NODES // 2


@dataclass(frozen=True)
class Again:
    """The run's method once more from a state, for the quadrature's bisection."""

    states: Callable[[float, np.ndarray, np.ndarray], np.ndarray | None]
    """(a, x(a), times after a) -> the states at those times (None: it failed)."""
    tol: tuple[float, float]
    """(rtol, atol) of the trajectory's states."""
    tighter: tuple[float, float]
    """(rtol, atol) of states: tighter, so that the bisection measures the
    trajectory rather than its own integration's error."""


@dataclass(frozen=True)
class Trajectory:
    t: np.ndarray
    """(n,) the output grid."""
    x: np.ndarray
    """(n, nx) states in the scene's order."""
    t_nodes: np.ndarray
    """(n - 1, QUAD_NODES) Gauss-Legendre nodes inside each output interval."""
    x_nodes: np.ndarray
    """(n - 1, QUAD_NODES, nx) the states there."""
    nfev: int
    wall: float
    """Seconds spent integrating."""
    again: Again | None = None
    """States anywhere inside an interval, for running_integrals' bisection
    (None: the nodes' sums as they are)."""


def output_grid(t_end: float, dt: float) -> np.ndarray:
    """k dt for every k >= 0 with k dt < t_end + dt/2, clipped at t_end
    (rounding must not put the last point past it, which solve_ivp refuses):
    arange(0, t_end + dt/2, dt)'s points, counted in halves, exactly as
    arange counts them (halving is exact above MIN_OUTPUT_STEP), since
    t_end + dt/2 itself overflowed near DBL_MAX."""
    n = math.ceil((t_end / 2 + dt / 4) / (dt / 2))
    with np.errstate(over="ignore"):  # a last k dt past DBL_MAX is inf, clipped to t_end
        return np.minimum(np.arange(n) * dt, t_end)


def sample_times(grid: np.ndarray) -> np.ndarray:
    """The grid with the quadrature nodes of each interval between its
    points, in order: every (QUAD_NODES + 1)-th time is a grid point."""
    a, b = grid[:-1, None], grid[1:, None]
    nodes = (0.5 * a + 0.5 * b) + 0.5 * (
        b - a
    ) * _NODES  # the same bits as 0.5 (a + b), no overflow
    return np.concatenate([np.column_stack([grid[:-1], nodes]).ravel(), grid[-1:]])


def from_samples(
    grid: np.ndarray,
    samples: np.ndarray,
    y: np.ndarray,
    nfev: int,
    wall: float,
    again: Again | None = None,
) -> Trajectory:
    """Split the states y at the sample times into the output grid and the
    quadrature nodes inside each interval."""
    step, n = QUAD_NODES + 1, len(grid)
    inner = y[:-1].reshape(n - 1, step, -1)[:, 1:]  # drop the grid point opening each interval
    t_nodes = samples[:-1].reshape(n - 1, step)[:, 1:]
    return Trajectory(grid, y[::step], t_nodes, inner, nfev, wall, again)


Rates = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""(times (m,), states (m, nx)) -> rates (m, k)."""


def running_integrals(
    traj: Trajectory, rates: Rates, scales: np.ndarray | None = None
) -> np.ndarray:
    """(n, k): int_0^t of each rate at each grid time, Gauss-Legendre per
    interval; with scales (k,) and traj.again, an interval whose nodes miss
    what Simpson's rule sees is bisected (to QUAD_TOL of scales)."""
    n1, q = traj.t_nodes.shape
    values = rates(traj.t_nodes.ravel(), traj.x_nodes.reshape(n1 * q, -1))
    k = values.shape[1]
    values = values.reshape(n1, q, k)
    half = 0.5 * np.diff(traj.t)
    pieces = half[:, None] * np.einsum("iqk,q->ik", values, _WEIGHTS)
    again = traj.again
    if again is None or scales is None or not n1:
        return np.vstack([np.zeros((1, k)), np.cumsum(pieces, axis=0)])
    ends = rates(traj.t, traj.x)
    budget = QUAD_TOL * np.asarray(scales) / (traj.t[-1] - traj.t[0])  # per second
    noise = _known(rates, traj.t_nodes[:, _MID], traj.x_nodes[:, _MID], again.tol)
    simpson = (half / 3.0)[:, None] * (ends[:-1] + 4.0 * values[:, _MID] + ends[1:])
    near = np.max(np.abs(np.concatenate([ends[:-1, None], values, ends[1:, None]], 1)), 1)
    agree = _agree(np.abs(simpson - pieces), near, 2 * half[:, None], np.maximum(budget, noise))
    left = [MAX_BISECTIONS]
    for i in np.nonzero(~agree)[0]:
        edge = _Edge(float(traj.t[i]), traj.x[i], ends[i])
        pieces[i] = _bisected(again, rates, budget, noise[i], left, edge,
                              float(traj.t[i + 1]), ends[i + 1], values[i])  # fmt: skip
    return np.vstack([np.zeros((1, k)), np.cumsum(pieces, axis=0)])


def _known(rates: Rates, t: np.ndarray, x: np.ndarray, tol: tuple[float, float]) -> np.ndarray:
    """(m, k): NOISE times how far the rates at (t, x) are known when x is
    known to rtol |x| + atol: their change along two such errors (of one
    sign, and alternating). Simpson's rule and the nodes cannot agree
    closer than that, and need not (k = 3000 N m s makes stiff_wheel's
    wheel, known to 1e-8 rad/s, a torque known to 3e-5 N m)."""
    dx = tol[0] * np.abs(x) + tol[1]
    sign = np.where(np.arange(x.shape[1]) % 2, -1.0, 1.0)
    f = rates(t, x)
    moved = np.maximum(np.abs(rates(t, x + dx) - f), np.abs(rates(t, x + sign * dx) - f))
    return NOISE * moved


def _agree(off: np.ndarray, near: np.ndarray, width: Any, per_second: np.ndarray) -> Any:
    """Whether Simpson's rule and the nodes agree (off: their difference)
    in every column (the last axis), to per_second times the width, or
    ROUNDING of the width times the largest |rate| seen (near)."""
    return np.all(off <= width * np.maximum(per_second, ROUNDING * near), axis=-1)


@dataclass(frozen=True)
class _Edge:
    """An interval's start: its time, state and rates."""

    t: float
    x: np.ndarray
    f: np.ndarray


def _bisected(
    again: Again, rates: Rates, budget: np.ndarray, noise: np.ndarray, left: list[int],
    a: _Edge, b: float, fb: np.ndarray, nodes: np.ndarray, stalled: int = 0,
) -> np.ndarray:  # fmt: skip
    """int_a^b of the rates (k,), Gauss-Legendre on [a, b] (its nodes'
    rates given, known to noise) where Simpson's rule agrees, else the sum
    over its halves, their states integrated again from a."""
    gauss, off, near = _rules(a.t, b, a.f, nodes, fb)
    mid = 0.5 * a.t + 0.5 * b
    times = np.concatenate([_inside(a.t, mid), [mid], _inside(mid, b)])
    if _agree(off, near, b - a.t, np.maximum(budget, noise)) or not left[0]:
        return gauss
    if not np.all(np.diff(np.concatenate([[a.t], times, [b]])) > 0):
        return gauss  # too short for distinct nodes
    left[0] -= 1
    xs = again.states(a.t, a.x, times)
    if xs is None:
        return gauss
    fs = rates(times, xs)
    m = _Edge(float(mid), xs[QUAD_NODES], fs[QUAD_NODES])
    halves = [(a, mid, m.f, fs[:QUAD_NODES]), (m, b, fb, fs[QUAD_NODES + 1 :])]
    parts = [_rules(e.t, end, e.f, inner, f_end) for e, end, f_end, inner in halves]
    stalled = stalled + 1 if np.all(parts[0][1] + parts[1][1] > off / PROGRESS) else 0
    if stalled >= STALLS:
        return parts[0][0] + parts[1][0]  # noise: halving the width no longer helps
    at = slice(QUAD_NODES, QUAD_NODES + 1)
    finer = _known(rates, times[at], xs[at], again.tighter)[0]
    first, second = (_bisected(again, rates, budget, finer, left, *h, stalled) for h in halves)
    return first + second


def _rules(
    a: float, b: float, fa: np.ndarray, nodes: np.ndarray, fb: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """On [a, b]: the nodes' Gauss-Legendre sum, its difference from
    Simpson's rule, and the largest |rate| seen (each (k,))."""
    half = 0.5 * (b - a)
    gauss = half * (_WEIGHTS @ nodes)
    simpson = (half / 3.0) * (fa + 4.0 * nodes[_MID] + fb)
    return gauss, np.abs(simpson - gauss), np.max(np.abs(np.vstack([fa, nodes, fb])), axis=0)


def _inside(a: float, b: float) -> np.ndarray:
    """The Gauss-Legendre nodes of [a, b]."""
    return (0.5 * a + 0.5 * b) + 0.5 * (b - a) * _NODES
