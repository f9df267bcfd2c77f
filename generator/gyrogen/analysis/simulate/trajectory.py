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
rates' gain), or to rounding. An oscillation many periods to an interval
(stiff_wheel's nutation at dt = 1000 s) fools both rules alike: an interval
the integrator took several steps across (Trajectory.steps) is first cut
into as many pieces, their states integrated again. What it could not
resolve (bisections or pieces spent) Integrals.unresolved says.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
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
"""Intervals bisected in one run at most (a layer takes ~50); a piece still
unresolved when they are spent keeps its nodes' sum, and the integrals say so."""
MAX_PIECES = 10**6
"""Pieces the integrator's steps may cut the intervals into, in one run at
most (a state each, integrated again); past it, pieces wider than a step,
and the integrals say so."""
CHUNK = 4096
"""Pieces of one interval integrated again at a time (their states in memory)."""
QUADRATURE = (
    f"Gauss-Legendre, {QUAD_NODES} nodes per output interval (the states from solve_ivp's dense "
    "output or the compiled integrator's step ends); an interval the integrator took several "
    "steps across is cut into as many pieces (a fast oscillation the nodes would alias), their "
    "states integrated again from its start; a piece is bisected and integrated again where "
    f"Simpson's rule disagrees by more than {QUAD_TOL:g} of the scale (a transient, a kink)"
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
    steps: np.ndarray | None = None
    """(n - 1,) the integrator's steps across each output interval (None:
    one each): running_integrals cuts an interval into as many pieces."""


@dataclass(frozen=True)
class Integrals:
    values: np.ndarray
    """(n, k): int_0^t of each rate at each grid time."""
    unresolved: tuple[str, ...] = ()
    """What the quadrature could not resolve, in words (empty: nothing)."""


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
    nodes = _inside(grid[:-1, None], grid[1:, None])
    return np.concatenate([np.column_stack([grid[:-1], nodes]).ravel(), grid[-1:]])


def from_samples(
    grid: np.ndarray,
    samples: np.ndarray,
    y: np.ndarray,
    nfev: int,
    wall: float,
    again: Again | None = None,
    steps: np.ndarray | None = None,
) -> Trajectory:
    """Split the states y at the sample times into the output grid and the
    quadrature nodes inside each interval (steps: Trajectory.steps)."""
    step, n = QUAD_NODES + 1, len(grid)
    inner = y[:-1].reshape(n - 1, step, -1)[:, 1:]  # drop the grid point opening each interval
    t_nodes = samples[:-1].reshape(n - 1, step)[:, 1:]
    return Trajectory(grid, y[::step], t_nodes, inner, nfev, wall, again, steps)


def steps_of_segments(accepted: np.ndarray) -> np.ndarray:
    """Trajectory.steps from a compiled run's accepted steps in each segment
    between sample times (QUAD_NODES + 1 to an interval): a segment's last
    step may be one cut short to end on its time, so 1 + the others."""
    per = np.asarray(accepted, dtype=np.int64).reshape(-1, QUAD_NODES + 1)
    return 1 + np.sum(np.maximum(per - 1, 0), axis=1)


def steps_between(grid: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Trajectory.steps from the times an integrator's steps ended (solve_ivp's):
    1 + the ends strictly inside each interval."""
    inside = np.searchsorted(ends, grid[1:], "left") - np.searchsorted(ends, grid[:-1], "right")
    return 1 + np.maximum(inside, 0)


Rates = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""(times (m,), states (m, nx)) -> rates (m, k)."""


def running_integrals(
    traj: Trajectory, rates: Rates, scales: np.ndarray | None = None
) -> Integrals:
    """int_0^t of each rate at each grid time, Gauss-Legendre per interval;
    with scales (k,) and traj.again, an interval the integrator took several
    steps across (traj.steps) is cut into as many pieces, and an interval or
    piece whose nodes miss what Simpson's rule sees is bisected (to QUAD_TOL
    of scales)."""
    n1, q = traj.t_nodes.shape
    values = rates(traj.t_nodes.ravel(), traj.x_nodes.reshape(n1 * q, -1))
    k = values.shape[1]
    values = values.reshape(n1, q, k)
    again = traj.again
    if again is None or scales is None or not n1:
        pieces = 0.5 * np.diff(traj.t)[:, None] * np.einsum("iqk,q->ik", values, _WEIGHTS)
        return Integrals(np.vstack([np.zeros((1, k)), np.cumsum(pieces, axis=0)]))
    ends = rates(traj.t, traj.x)
    cap = _Budget(QUAD_TOL * np.asarray(scales) / (traj.t[-1] - traj.t[0]), MAX_BISECTIONS)
    steps = np.ones(n1, np.int64) if traj.steps is None else np.maximum(traj.steps, 1)
    if steps.sum() > MAX_PIECES:
        cap.said.append(
            f"the integrator took {steps.sum()} steps, more than the {MAX_PIECES} pieces the "
            "quadrature cuts a run into: its pieces are wider than the steps, and may alias a "
            "fast oscillation"
        )
        steps = np.maximum(steps * MAX_PIECES // steps.sum(), 1)
    pieces = np.empty((n1, k))
    for j in np.nonzero(steps > 1)[0]:
        edge = _Edge(float(traj.t[j]), traj.x[j], ends[j])
        cut = _cut(again, rates, cap, edge, float(traj.t[j + 1]), int(steps[j]))
        cap.failed += cut is None
        steps[j] = 1 if cut is None else steps[j]  # None: its nodes as they are, below
        pieces[j] = 0.0 if cut is None else cut
    i = np.nonzero(steps == 1)[0]
    spans = _Spans(traj.t[i], traj.x[i], ends[i], traj.t[i + 1], ends[i + 1])
    pieces[i] = _sums(
        again, rates, cap, spans, traj.t_nodes[i], traj.x_nodes[i], values[i], again.tol
    )
    if cap.failed:
        cap.said.append(
            f"{cap.failed} intervals the integrator stepped across several times could not be "
            "integrated again in pieces: their nodes' sums are kept, and may alias"
        )
    if cap.short:
        cap.said.append(
            f"{cap.short} pieces still missed what Simpson's rule sees when the {MAX_BISECTIONS} "
            "bisections were spent: their nodes' sums are kept, and may be off"
        )
    return Integrals(np.vstack([np.zeros((1, k)), np.cumsum(pieces, axis=0)]), tuple(cap.said))


@dataclass
class _Budget:
    """What one run's quadrature may spend and what it could not resolve."""

    per_second: np.ndarray
    """(k,) the error allowed per second of each integral."""
    left: int
    short: int = 0
    """Pieces left unresolved when the bisections were spent."""
    failed: int = 0
    said: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class _Spans:
    """Intervals (p of them): their starts' times, states and rates, their ends'
    times and rates."""

    t: np.ndarray
    x: np.ndarray
    f: np.ndarray
    t_end: np.ndarray
    f_end: np.ndarray


def _sums(
    again: Again, rates: Rates, cap: _Budget, spans: _Spans,
    t_nodes: np.ndarray, x_nodes: np.ndarray, values: np.ndarray, tol: tuple[float, float],
) -> np.ndarray:  # fmt: skip
    """(p, k): each span's Gauss-Legendre sum on its nodes (times, states,
    rates; states known to tol), bisected where Simpson's rule disagrees."""
    half = 0.5 * (spans.t_end - spans.t)
    pieces = half[:, None] * np.einsum("iqk,q->ik", values, _WEIGHTS)
    noise = _known(rates, t_nodes[:, _MID], x_nodes[:, _MID], tol)
    simpson = (half / 3.0)[:, None] * (spans.f + 4.0 * values[:, _MID] + spans.f_end)
    near = np.max(np.abs(np.concatenate([spans.f[:, None], values, spans.f_end[:, None]], 1)), 1)
    per_second = np.maximum(cap.per_second, noise)
    agree = _agree(np.abs(simpson - pieces), near, 2 * half[:, None], per_second)
    for i in np.nonzero(~agree)[0]:
        edge = _Edge(float(spans.t[i]), spans.x[i], spans.f[i])
        end = float(spans.t_end[i])
        pieces[i] = _bisected(again, rates, cap, noise[i], edge, end, spans.f_end[i], values[i])
    return pieces


def _cut(again: Again, rates: Rates, cap: _Budget, a: _Edge, b: float, m: int) -> np.ndarray | None:
    """int_a^b of the rates (k,) over m equal pieces, their states integrated
    again from a, CHUNK pieces at a time, each bisected where Simpson's rule
    disagrees (None: the pieces are too short for distinct nodes, or the
    integration failed)."""
    edges = a.t + (b - a.t) * (np.arange(1, m + 1) / m)
    edges[-1] = b
    total = np.zeros_like(a.f)
    for lo in range(0, m, CHUNK):
        ends = edges[lo : lo + CHUNK]
        starts = np.concatenate([[a.t], ends[:-1]])
        nodes = _inside(starts[:, None], ends[:, None])
        times = np.column_stack([nodes, ends]).ravel()
        if not np.all(np.diff(np.concatenate([[a.t], times])) > 0):
            return None
        xs = again.states(a.t, a.x, times)
        if xs is None:
            return None
        fs = rates(times, xs)
        p, q = len(ends), QUAD_NODES
        xs, fs = xs.reshape(p, q + 1, -1), fs.reshape(p, q + 1, -1)
        spans = _Spans(
            starts,
            np.concatenate([a.x[None], xs[:-1, q]]),
            np.concatenate([a.f[None], fs[:-1, q]]),
            ends,
            fs[:, q],
        )
        total += _sums(again, rates, cap, spans, nodes, xs[:, :q], fs[:, :q], again.tighter).sum(0)
        a = _Edge(float(ends[-1]), xs[-1, q], fs[-1, q])
    return total


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
    again: Again, rates: Rates, cap: _Budget, noise: np.ndarray,
    a: _Edge, b: float, fb: np.ndarray, nodes: np.ndarray, stalled: int = 0,
) -> np.ndarray:  # fmt: skip
    """int_a^b of the rates (k,), Gauss-Legendre on [a, b] (its nodes'
    rates given, known to noise) where Simpson's rule agrees, else the sum
    over its halves, their states integrated again from a."""
    gauss, off, near = _rules(a.t, b, a.f, nodes, fb)
    mid = 0.5 * a.t + 0.5 * b
    times = np.concatenate([_inside(a.t, mid), [mid], _inside(mid, b)])
    if _agree(off, near, b - a.t, np.maximum(cap.per_second, noise)):
        return gauss
    if not cap.left:
        cap.short += 1
        return gauss
    if not np.all(np.diff(np.concatenate([[a.t], times, [b]])) > 0):
        return gauss  # too short for distinct nodes
    cap.left -= 1
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
    first, second = (_bisected(again, rates, cap, finer, *h, stalled) for h in halves)
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


def _inside(a: Any, b: Any) -> np.ndarray:
    """The Gauss-Legendre nodes of [a, b] (floats, or columns (p, 1): (p,
    QUAD_NODES)), with the same bits as 0.5 (a + b) at the middle, no overflow."""
    return (0.5 * a + 0.5 * b) + 0.5 * (b - a) * _NODES
