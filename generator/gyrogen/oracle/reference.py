"""Independent numpy witness of the gyrostat's equations of motion.

Written by hand from the paper's *first* formulation (``docs/gyrostat-eom.md``,
"Equations of motion": the carrier A and the rotor B treated as two separate
bodies, with the offsets l1a, l3a, l1b, l3b of their mass centers from AB*), with
misprint 1 of ``docs/NOTES.md`` fixed. It deliberately uses neither sympy nor any other
gyrogen module except :mod:`gyrogen.abi`, so that it can check the generated code.

Every function is vectorized: states have shape ``(..., 14)`` in ``abi.STATES``
order, parameters shape ``(12,)`` or ``(..., 12)`` in ``abi.PARAMETERS`` order,
and leading dimensions broadcast against each other.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gyrogen import abi

__all__ = ["angular_momentum_n", "direction_cosines", "kinetic_energy", "rhs"]

Array = NDArray[np.float64]

N_STATES = len(abi.STATES)
N_PARAMETERS = len(abi.PARAMETERS)


def _split(x: ArrayLike, p: ArrayLike) -> tuple[Array, Array, tuple[int, ...]]:
    """Check the trailing sizes; return x, p as float arrays and the broadcast batch shape."""
    xa = np.asarray(x, dtype=np.float64)
    pa = np.asarray(p, dtype=np.float64)
    if xa.ndim == 0 or xa.shape[-1] != N_STATES:
        raise ValueError(f"x must have shape (..., {N_STATES}), got {xa.shape}")
    if pa.ndim == 0 or pa.shape[-1] != N_PARAMETERS:
        raise ValueError(f"p must have shape (..., {N_PARAMETERS}), got {pa.shape}")
    batch = np.broadcast_shapes(xa.shape[:-1], pa.shape[:-1])
    return xa, pa, batch


def direction_cosines(x: ArrayLike) -> Array:
    """Table 1 of NOTES.md (3-1-2 Euler angles q1, q2, q3): ``a_i = sum_j C[..., i, j] n_j``.

    ``x`` is a state array of shape ``(..., 14)``; returns shape ``(..., 3, 3)``.
    """
    xa = np.asarray(x, dtype=np.float64)
    if xa.ndim == 0 or xa.shape[-1] != N_STATES:
        raise ValueError(f"x must have shape (..., {N_STATES}), got {xa.shape}")
    s1, s2, s3 = np.sin(xa[..., 0]), np.sin(xa[..., 1]), np.sin(xa[..., 2])
    c1, c2, c3 = np.cos(xa[..., 0]), np.cos(xa[..., 1]), np.cos(xa[..., 2])
    C = np.empty((*xa.shape[:-1], 3, 3))
    C[..., 0, 0] = c1 * c3 - s1 * s2 * s3
    C[..., 0, 1] = s1 * c3 + c1 * s2 * s3
    C[..., 0, 2] = -c2 * s3
    C[..., 1, 0] = -s1 * c2
    C[..., 1, 1] = c1 * c2
    C[..., 1, 2] = s2
    C[..., 2, 0] = s1 * s2 * c3 + c1 * s3
    C[..., 2, 1] = s1 * s3 - c1 * s2 * c3
    C[..., 2, 2] = c2 * c3
    return C


def rhs(x: ArrayLike, p: ArrayLike) -> Array:
    """Time derivative of the state, ``dx/dt``, from the paper's first formulation.

    Kinematics: the paper's kinematic differential equations (3-1-2 Euler angles,
    ``q4' = u4 - u2``, ``q5..7' = u5..7``); singular at ``cos q2 = 0``.

    Dynamics: the paper prints the four rotational equations as
    ``-(row r of the mass matrix) . u' = rhs_r``, i.e. Kane's ``F_r + F_r* = 0`` with
    the inertia terms kept on the left. Here ``M u' = F`` with ``F = -rhs_r``; the
    coefficients are the paper's, written with m_a l1a^2 + m_b l1b^2 etc. (misprint 1
    fixed: the u2' equation has ``m_b (l3b^2 - l1b^2)``). The coupled (u1, u3) block
    is solved by Cramer's rule; u2' and u4' come from their own rows. Translation:
    ``u5' = u6' = 0``, ``u7' = g``.

    Returns an array of shape ``broadcast(x.shape[:-1], p.shape[:-1]) + (14,)``.
    """
    xa, pa, batch = _split(x, p)
    q2, q3 = xa[..., 1], xa[..., 2]
    u1, u2, u3, u4, u5, u6, u7 = (xa[..., 7 + k] for k in range(7))
    m_a, m_b, I11, I22, I33, I13, I, J, l1, l3, g, T = (pa[..., k] for k in range(N_PARAMETERS))

    # Offsets of A* and B* from AB* ("For sake of symbolic brevity ...").
    M = m_a + m_b
    l1a = -l1 * m_b / M
    l3a = -l3 * m_b / M
    l1b = l1 * m_a / M
    l3b = l3 * m_a / M

    # Coefficients of the u' terms in the four printed rotational equations.
    k11 = I11 + m_a * l3a**2 + I + m_b * l3b**2
    k22 = I22 + m_a * (l1a**2 + l3a**2) + m_b * (l1b**2 + l3b**2)
    k33 = I33 + m_a * l1a**2 + I + m_b * l1b**2
    k13 = I13 - m_a * l1a * l3a - m_b * l1b * l3b

    # Right-hand sides exactly as printed (the paper's "-(mass) u' = r").
    r1 = k13 * u1 * u2 + (I33 + I - I22 - m_a * l3a**2 - m_b * l3b**2) * u2 * u3 - J * u3 * u4
    r2 = (
        T
        - k13 * u1**2
        + k13 * u3**2
        + (I11 - I33 + m_a * (l3a**2 - l1a**2) + m_b * (l3b**2 - l1b**2)) * u1 * u3
    )
    r3 = J * u1 * u4 + (I22 - I11 + m_a * l1a**2 - I + m_b * l1b**2) * u1 * u2 - k13 * u2 * u3
    r4 = -T

    # M u' = F, F = -r; M = [[k11, 0, k13, 0], [0, k22, 0, 0], [k13, 0, k33, 0], [0, 0, 0, J]].
    f1, f2, f3, f4 = -r1, -r2, -r3, -r4
    det = k11 * k33 - k13**2
    u1d = (f1 * k33 - k13 * f3) / det
    u3d = (k11 * f3 - k13 * f1) / det
    u2d = f2 / k22
    u4d = f4 / J

    # Kinematic differential equations, as printed.
    s3, c3 = np.sin(q3), np.cos(q3)
    c2 = np.cos(q2)
    t2 = np.tan(q2)

    out = np.empty((*batch, N_STATES))
    out[..., 0] = -s3 * u1 / c2 + c3 * u3 / c2
    out[..., 1] = c3 * u1 + s3 * u3
    out[..., 2] = t2 * s3 * u1 + u2 - t2 * c3 * u3
    out[..., 3] = -u2 + u4
    out[..., 4] = u5
    out[..., 5] = u6
    out[..., 6] = u7
    out[..., 7] = u1d
    out[..., 8] = u2d
    out[..., 9] = u3d
    out[..., 10] = u4d
    out[..., 11] = 0.0
    out[..., 12] = 0.0
    out[..., 13] = g
    return out


def lumped(pa: Array) -> tuple[Array, Array, Array, Array, Array, Array]:
    """Lumped inertia scalars of NOTES.md: (I~11, I~22, I~33, I~13, J, M), via mu = m_a m_b / M."""
    m_a, m_b, I11, I22, I33, I13, I, J, l1, l3 = (pa[..., k] for k in range(10))
    M = m_a + m_b
    mu = m_a * m_b / M
    t11 = I11 + I + mu * l3**2
    t22 = I22 + mu * (l1**2 + l3**2)
    t33 = I33 + I + mu * l1**2
    t13 = I13 - mu * l1 * l3
    return t11, t22, t33, t13, J, M


def angular_momentum_n(x: ArrayLike, p: ArrayLike) -> Array:
    """Angular momentum of the system about AB*, in N components; shape ``batch + (3,)``.

    NOTES.md: ``H = (I~11 u1 + I~13 u3) a1 + (I~22 u2 + J u4) a2 + (I~13 u1 + I~33 u3) a3``,
    converted to N with Table 1 (``a_i = sum_j C[i][j] n_j``, so ``H_j = sum_i h_i C[i][j]``).
    Conserved: gravity acts through AB* and the motor torque T is internal.
    """
    xa, pa, batch = _split(x, p)
    u1, u2, u3, u4 = (xa[..., 7 + k] for k in range(4))
    t11, t22, t33, t13, J, _ = lumped(pa)
    h = np.empty((*batch, 3))
    h[..., 0] = t11 * u1 + t13 * u3
    h[..., 1] = t22 * u2 + J * u4
    h[..., 2] = t13 * u1 + t33 * u3
    C = direction_cosines(xa)
    return np.asarray(np.einsum("...i,...ij->...j", h, C), dtype=np.float64)


def kinetic_energy(x: ArrayLike, p: ArrayLike) -> Array:
    """Kinetic energy, NOTES.md: ``K = 1/2 w.I~.w + 1/2 J u4^2 + 1/2 M v^2`` (w = omega^A).

    Obeys ``dK/dt = T (u4 - u2) + M g u7``. Returns shape ``batch``.
    """
    xa, pa, batch = _split(x, p)
    u1, u2, u3, u4, u5, u6, u7 = (xa[..., 7 + k] for k in range(7))
    t11, t22, t33, t13, J, M = lumped(pa)
    rot = t11 * u1**2 + t22 * u2**2 + t33 * u3**2 + 2.0 * t13 * u1 * u3
    K = 0.5 * (rot + J * u4**2 + M * (u5**2 + u6**2 + u7**2))
    return np.asarray(np.broadcast_to(K, batch), dtype=np.float64)
