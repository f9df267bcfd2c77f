"""A simulated trajectory: the output grid, the quadrature nodes sampled
inside each of its intervals, and integrals over time by those nodes.

The integrals are Gauss-Legendre sums, QUAD_NODES nodes inside each output
interval, sampled along with the grid (from solve_ivp's dense output, or as
step ends of a compiled integrator): a trapezoid on the grid alone is off by
~(dt/tau)^2 wherever the integrand changes on a time scale tau near dt (the
speed controller's torque: 1e-2). A transient much shorter than dt
(stiff_wheel's 1e-5 s) is not resolved either way.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

QUAD_NODES = 3
QUADRATURE = f"Gauss-Legendre, {QUAD_NODES} nodes per output interval, on solve_ivp's dense output"
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(QUAD_NODES)


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
    grid: np.ndarray, samples: np.ndarray, y: np.ndarray, nfev: int, wall: float
) -> Trajectory:
    """Split the states y at the sample times into the output grid and the
    quadrature nodes inside each interval."""
    step, n = QUAD_NODES + 1, len(grid)
    inner = y[:-1].reshape(n - 1, step, -1)[:, 1:]  # drop the grid point opening each interval
    t_nodes = samples[:-1].reshape(n - 1, step)[:, 1:]
    return Trajectory(grid, y[::step], t_nodes, inner, nfev, wall)


Rates = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""(times (m,), states (m, nx)) -> rates (m, k)."""


def running_integrals(traj: Trajectory, rates: Rates) -> np.ndarray:
    """(n, k): int_0^t of each rate at each grid time, Gauss-Legendre per interval."""
    n1, q = traj.t_nodes.shape
    values = rates(traj.t_nodes.ravel(), traj.x_nodes.reshape(n1 * q, -1))
    k = values.shape[1]
    half = 0.5 * np.diff(traj.t)
    pieces = half[:, None] * np.einsum("iqk,q->ik", values.reshape(n1, q, k), _WEIGHTS)
    return np.vstack([np.zeros((1, k)), np.cumsum(pieces, axis=0)])
