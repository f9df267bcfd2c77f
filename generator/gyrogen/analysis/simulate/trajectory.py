"""A simulated trajectory: the output grid's states, the run's states at
any other time (its dense output), and integrals over time by adaptive
quadrature on that dense output.

The run is one function of time: a compiled adaptive method's segment, run
again from its start as a `_grid` call, takes the same steps whatever
times it is asked for between its ends (rk4: every time a step end), and
solve_ivp's dense output is kept (runtime/segment.resampled, engine.py). An
integral is taken piece by piece, each output interval cut first at the
integrand's known kinks (a torque table's points): on a piece, Gauss-Legendre
with QUAD_NODES nodes, checked against Gauss-Lobatto with QUAD_NODES + 1
(the piece's ends and QUAD_NODES - 1 nodes between, the same degree
2 QUAD_NODES - 1). Where they disagree by more than the error allowed (QUAD_TOL
of the integral's scale over the run, spread by length; rounding; on a piece
no longer than a step, how far the rates are known: NOISE), the piece is cut
into SPLIT and sampled again, in passes (each segment holding pieces run once
a pass), at most MAX_PASSES. The Lobatto rule's ends see a transient
shorter than the Gauss nodes' spacing at a piece's edge (stiff_wheel's 1e-5 s
spin-up at the start); a kink (a clamped motor) makes the rules differ until
the piece holding it is short; an oscillation of many periods to an
interval (stiff_wheel's nutation at dt = 1000 s) aliases the two rules
differently.

QUAD_NODES = 8 for every method: inside one step an interpolant is a
polynomial of degree d (dopri5 4, rodas4 and radau5's collocation 3, dop853
7; the Taylor method's series of the order it takes, whose terms fall as the
solution's own) and a power or torque a polynomial of degree 2 at most in the
states for the smooth laws (a controller's torque times a rate), so of degree
2 d <= 14 in time: both rules (degree 15) integrate a piece within one step
exactly, and a piece across a step's end to the interpolant's own error.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

QUAD_NODES = 8
"""Gauss-Legendre nodes a piece (Gauss-Lobatto: one more, with the ends)."""
QUAD_TOL = 1e-12
"""The quadrature error allowed in an integral over the whole run, relative
to its scale (the balance's normalizer), spread over the run by length;
and at least ROUNDING of each piece's |integrand| times its length."""
ROUNDING = 1e3 * np.finfo(float).eps
NOISE = 1.0
"""On a piece no longer than the integrator's mean step across it, the
rules agree when they differ by at most this times how far the rates are
known (_known) times the width: the interpolant's slope jumps at each
step's end, which a piece across it sees, are of that size over a step.
Without it stiff_wheel's pieces went on being cut past 16 passes; allowed
on longer pieces too, its nutation at dt = 1000 s was taken 5e-5 of max K
off (aliased), and with 10 its 1e-5 s transient 1e-8."""
SPLIT = 8
"""Pieces a piece whose rules disagree is cut into, for the next pass."""
MAX_PASSES = 16
"""Passes at most: SPLIT^16 ~ 3e14, a piece down to the rounding of its
interval."""
MAX_PIECES = 10**5
"""Pieces cut in one pass at most (those whose rules disagree most); the
others keep their Gauss sums, and the integrals say so."""
CHUNK = 20_000
"""Pieces sampled at a time (their states in memory)."""
QUADRATURE = (
    f"Gauss-Legendre, {QUAD_NODES} nodes a piece, on the run's dense output (the compiled "
    "integrator's interpolant, each segment run again as a _grid call, or solve_ivp's); each "
    f"output interval cut at the torque tables' points; a piece cut into {SPLIT} and sampled "
    "again where "
    f"Gauss-Lobatto with {QUAD_NODES + 1} nodes (its ends among them) disagrees by more than "
    f"{QUAD_TOL:g} of the scale (a transient, a kink, an oscillation)"
)
_G, _GW = np.polynomial.legendre.leggauss(QUAD_NODES)
_LOBATTO = QUAD_NODES + 1
_L = np.sort(np.polynomial.legendre.Legendre.basis(QUAD_NODES).deriv().roots())
_LW = 2.0 / (_LOBATTO * QUAD_NODES * np.polynomial.legendre.Legendre.basis(QUAD_NODES)(_L) ** 2)
_LW_END = 2.0 / (_LOBATTO * QUAD_NODES)
_NODES = np.concatenate([[-1.0], _G, _L, [1.0]])
"""A piece's sample points on [-1, 1]: its start, the Gauss nodes, Lobatto's inner ones, its end."""
_GS, _LS = slice(1, 1 + QUAD_NODES), slice(1 + QUAD_NODES, _NODES.size - 1)

Sample = Callable[[np.ndarray], np.ndarray]
"""times (m,) within the run, in any order -> the run's states there (m, nx);
a failure raises."""


@dataclass(frozen=True)
class Trajectory:
    t: np.ndarray
    """(n,) the output grid."""
    x: np.ndarray
    """(n, nx) states in the scene's order."""
    nfev: int
    wall: float
    """Seconds spent integrating."""
    sample: Sample
    """The same run's states at any times between the grid's ends."""
    tol: tuple[float, float]
    """(rtol, atol) the run's states are known to."""
    spans: tuple[np.ndarray, np.ndarray]
    """(ends (s + 1,), steps (s,)): stretches of the run and the mean length
    of the integrator's steps across each (a segment's, or each step)."""


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


Rates = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""(times (m,), states (m, nx)) -> rates (m, k)."""


def running_integrals(
    traj: Trajectory, rates: Rates, scales: np.ndarray, knots: np.ndarray | None = None
) -> Integrals:
    """int_0^t of each rate at each grid time: each output interval cut at
    the knots (times where a rate may kink), each piece by Gauss-Legendre on
    the dense output, cut into SPLIT and sampled again where Gauss-Lobatto
    disagrees by more than QUAD_TOL of scales (k,)."""
    grid = traj.t
    inner = np.empty(0) if knots is None else np.asarray(knots, dtype=float)
    edges = np.union1d(grid, inner[(inner > grid[0]) & (inner < grid[-1])])
    a, b = edges[:-1], edges[1:]
    owner = np.searchsorted(grid, a, "right") - 1
    scales = np.asarray(scales, dtype=float)
    sums = np.zeros((len(grid) - 1, scales.size))
    cap = _Budget(QUAD_TOL * scales / max(grid[-1] - grid[0], np.finfo(float).tiny))
    for passes in range(MAX_PASSES + 1):
        if not a.size:
            break
        gauss, excess = _pieces(traj, rates, cap.per_second, a, b)
        done = excess <= 1.0
        if passes == MAX_PASSES:
            cap.unresolved += int(np.sum(~done))
            done[:] = True
        a, b, owner = _cut(a, b, owner, excess, done, gauss, sums, cap)
    _say(cap)
    return Integrals(
        np.vstack([np.zeros((1, scales.size)), np.cumsum(sums, axis=0)]), tuple(cap.said)
    )


@dataclass
class _Budget:
    """What one run's quadrature allows and what it could not resolve."""

    per_second: np.ndarray
    """(k,) the error allowed per second of each integral."""
    unresolved: int = 0
    """Pieces whose rules still disagreed after MAX_PASSES."""
    capped: int = 0
    """Pieces left uncut past MAX_PIECES."""
    said: list[str] = field(default_factory=list)


def _cut(
    a: np.ndarray, b: np.ndarray, owner: np.ndarray, excess: np.ndarray, done: np.ndarray,
    gauss: np.ndarray, sums: np.ndarray, cap: _Budget,
) -> tuple[np.ndarray, ...]:  # fmt: skip
    """Add the done pieces' (and the too short ones') Gauss sums to their
    intervals' sums; the others cut into SPLIT each, the MAX_PIECES worst."""
    worst = np.nonzero(~done)[0]
    if worst.size * SPLIT > MAX_PIECES:
        keep = worst[np.argsort(-excess[worst], kind="stable")[: MAX_PIECES // SPLIT]]
        cap.capped += worst.size - keep.size
        worst = np.sort(keep)
    frac = np.arange(SPLIT + 1) / SPLIT
    ends = a[worst, None] + (b - a)[worst, None] * frac  # (p, SPLIT + 1)
    ends[:, -1] = b[worst]
    nodes = np.sort(_times(ends[:, :-1].ravel(), ends[:, 1:].ravel()), axis=1)
    distinct = np.all(np.diff(nodes, axis=1) > 0, axis=1).reshape(worst.size, SPLIT).all(axis=1)
    worst = worst[distinct]  # too short to cut: the Gauss sum, to rounding
    ends = ends[distinct]
    keep = np.ones(a.size, dtype=bool)
    keep[worst] = False
    np.add.at(sums, owner[keep], gauss[keep])
    starts, stops = ends[:, :-1].ravel(), ends[:, 1:].ravel()
    return starts, stops, np.repeat(owner[worst], SPLIT)


def _say(cap: _Budget) -> None:
    if cap.unresolved:
        cap.said.append(
            f"{cap.unresolved} pieces still disagreed after {MAX_PASSES} passes (a piece cut "
            f"into {SPLIT} each): their Gauss sums are kept, and may be off"
        )
    if cap.capped:
        cap.said.append(
            f"{cap.capped} pieces were left uncut past the {MAX_PIECES} a pass may cut: their "
            "Gauss sums are kept, and may be off"
        )


def _pieces(
    traj: Trajectory, rates: Rates, per_second: np.ndarray, a: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each piece's Gauss sum (p, k), and its rules' difference over the
    error it is allowed (p,: the worst integral's)."""
    gauss, excess = np.empty((a.size, per_second.size)), np.empty(a.size)
    for lo in range(0, a.size, CHUNK):
        at = slice(lo, lo + CHUNK)
        gauss[at], excess[at] = _rules(traj, rates, per_second, a[at], b[at])
    return gauss, excess


def _rules(
    traj: Trajectory, rates: Rates, per_second: np.ndarray, a: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """_pieces on one chunk: its pieces sampled in one run."""
    p, q = a.size, _NODES.size
    times = _times(a, b)
    xs = traj.sample(times.ravel())
    fs = rates(times.ravel(), xs).reshape(p, q, -1)
    half = (0.5 * (b - a))[:, None]
    gauss = half * np.einsum("pqk,q->pk", fs[:, _GS], _GW)
    lobatto = half * (_LW_END * (fs[:, 0] + fs[:, -1]) + np.einsum("pqk,q->pk", fs[:, _LS], _LW))
    mid = 1 + QUAD_NODES // 2
    noise = _known(rates, times[:, mid], xs.reshape(p, q, -1)[:, mid], traj.tol)
    near = np.max(np.abs(fs), axis=1)
    ends, steps = traj.spans
    step = steps[np.clip(np.searchsorted(ends, a, "right") - 1, 0, steps.size - 1)]
    floor = np.where(2 * half <= step[:, None], 2 * half * noise, 0.0)  # a step long at most
    allowed = 2 * half * np.maximum(per_second, ROUNDING * near) + floor
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.abs(gauss - lobatto) / allowed
    ratio = np.where(np.abs(gauss - lobatto) == 0, 0.0, ratio)
    return gauss, np.max(np.where(np.isnan(ratio), np.inf, ratio), axis=1)


def _known(rates: Rates, t: np.ndarray, x: np.ndarray, tol: tuple[float, float]) -> np.ndarray:
    """(m, k): NOISE times how far the rates at (t, x) are known when x is
    known to rtol |x| + atol: their change along two such errors (of one
    sign, and alternating). The rules cannot agree closer than that, and
    need not (k = 3000 N m s makes stiff_wheel's wheel, known to 1e-8
    rad/s, a torque known to 3e-5 N m)."""
    dx = tol[0] * np.abs(x) + tol[1]
    sign = np.where(np.arange(x.shape[1]) % 2, -1.0, 1.0)
    f = rates(t, x)
    moved = np.maximum(np.abs(rates(t, x + dx) - f), np.abs(rates(t, x + sign * dx) - f))
    return NOISE * moved


def _times(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(p, 2 QUAD_NODES + 1): the sample times of pieces [a, b] (_NODES),
    its ends exact, no overflow near DBL_MAX."""
    times = (0.5 * a + 0.5 * b)[:, None] + (0.5 * (b - a))[:, None] * _NODES
    times[:, 0], times[:, -1] = a, b
    return np.clip(times, a[:, None], b[:, None])
