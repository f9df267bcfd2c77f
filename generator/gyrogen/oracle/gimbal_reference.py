"""The numpy witness for variable-speed control-moment gyros, by hand from Newton-Euler.

Independent of the sympy model and of gyrogen.physics. A carrier A holds N
rotors; each is a fixed-axis wheel (as in cluster_reference) or a CMG: a
gimbal frame G_k turning about g_g (fixed in A) by the angle gam, carrying a
wheel W_k that spins about

    g_s = cos(gam) g_s0 + sin(gam) g_g x g_s0,    g_t = g_g x g_s.

Every mass center is fixed in A, so the system's mass center C is too, and
the whole is free and torque-free about C. With w_G = w_A + gd g_g and the
wheel's absolute spin rate w = g_s . w_W (Omega = w - g_s . w_A relative to
the gimbal), each rotor's angular momentum about its mass center is

    h_k = K_k w_G + J_k w g_s,    K_k = IG_k (in A) + I_k (1 - g_s g_s^T),

K_k fixed in G_k (its rate of change in A is gd (S K - K S), S = [g_g x]);
a fixed wheel is the same with g_g = 0, gd = 0 and no frame. Three laws:

- the system:  H = I_P w_A + sum_k h_k about C, dH/dt in N = 0, in A:
  H' + w_A x H = 0 (I_P: the carrier and every mass as a point at its place);
- each gimbal with its wheel about g_g:  g_g . (h_k' + w_A x h_k) = u_g
  (the bearings' other torques are perpendicular to g_g);
- each wheel about its axis:  J_k w' = u_s - b Omega (axisymmetric: no
  gyroscopic term about g_s).

The accelerations (w_A', gd') solve a (3 + N) system per state, with numpy;
a fixed wheel's row is gd' = 0. Vectorized over M states.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Values:
    """A carrier with N rotors, in A-components, SI units.

    m_a, carrier: the carrier's mass and its inertia tensor about its own
    mass center A* (3, 3). Per rotor k (arrays of N rows):
    has_gimbal: True for a CMG, False for a fixed-axis wheel.
    m, I, J: the wheel's mass, transverse and axial inertia about its center.
    g_s0: the wheel's unit spin axis at gimbal angle 0 (a fixed wheel's axis).
    g_g: the unit gimbal axis, perpendicular to g_s0 (zeros for a fixed wheel).
    r: the wheel's and the gimbal frame's common mass center from A* (the
    gimbal axis passes through it).
    b: the wheel's bearing friction coefficient (torque -b Omega on it).
    mg, IG: the gimbal frame's mass and inertia tensor about its mass center
    in its own axes (g_s, g_t, g_g), (N, 3, 3) symmetric; zeros for a fixed
    wheel.
    """

    m_a: float
    carrier: np.ndarray
    has_gimbal: np.ndarray
    m: np.ndarray
    I: np.ndarray
    J: np.ndarray
    g_s0: np.ndarray
    g_g: np.ndarray
    r: np.ndarray
    b: np.ndarray
    mg: np.ndarray
    IG: np.ndarray


def values_from_arrays(
    m_a: float,
    carrier: np.ndarray,
    m: np.ndarray,
    I: np.ndarray,
    J: np.ndarray,
    g_s0: np.ndarray,
    r: np.ndarray,
    g_g: np.ndarray | None = None,
    b: np.ndarray | None = None,
    mg: np.ndarray | None = None,
    IG: np.ndarray | None = None,
) -> Values:
    """Values from arrays; a rotor whose g_g row is zero (or all of them,
    g_g None) is a fixed wheel. Axes are normalized; a gimbal axis not
    perpendicular to its spin axis, a frame's tensor not symmetric, a fixed
    wheel with a frame or an axial inertia not positive is a ValueError."""
    g_s0 = np.atleast_2d(np.asarray(g_s0, dtype=float))
    n = len(g_s0)
    gg = np.zeros((n, 3)) if g_g is None else np.atleast_2d(np.asarray(g_g, dtype=float))
    has = np.linalg.norm(gg, axis=1) > 0
    gg = np.where(has[:, None], gg / np.where(has, np.linalg.norm(gg, axis=1), 1.0)[:, None], 0.0)
    spin = g_s0 / np.linalg.norm(g_s0, axis=1, keepdims=True)
    if np.any(np.abs((gg * spin).sum(1)) > 1e-12):
        raise ValueError("g_g: a gimbal axis is not perpendicular to its spin axis g_s0")
    frame_m = np.zeros(n) if mg is None else np.asarray(mg, dtype=float).reshape(n)
    frame_i = np.zeros((n, 3, 3)) if IG is None else np.asarray(IG, dtype=float).reshape(n, 3, 3)
    if np.any(frame_m[~has] != 0) or np.any(frame_i[~has] != 0):
        raise ValueError("mg, IG: a fixed wheel (g_g = 0) has no gimbal frame")
    if np.any(
        np.abs(frame_i - frame_i.transpose(0, 2, 1)) > 1e-12 * np.abs(frame_i).max(initial=0)
    ):
        raise ValueError("IG: a gimbal frame's inertia tensor is not symmetric")
    axial = np.asarray(J, dtype=float).reshape(n)
    if np.any(~(axial > 0)):
        raise ValueError("J: a wheel's axial inertia is not positive")
    return Values(
        m_a=float(m_a),
        carrier=np.asarray(carrier, dtype=float).reshape(3, 3),
        has_gimbal=has,
        m=np.asarray(m, dtype=float).reshape(n),
        I=np.asarray(I, dtype=float).reshape(n),
        J=axial,
        g_s0=spin,
        g_g=gg,
        r=np.asarray(r, dtype=float).reshape(n, 3),
        b=np.zeros(n) if b is None else np.asarray(b, dtype=float).reshape(n),
        mg=frame_m,
        IG=frame_i,
    )


def _point(mass: np.ndarray | float, rho: np.ndarray) -> np.ndarray:
    """Point masses' inertias about a point rho away (parallel axes), (..., 3, 3)."""
    rho = np.asarray(rho)
    rr = np.einsum("...i,...i->...", rho, rho)[..., None, None]
    return np.asarray(mass)[..., None, None] * (
        rr * np.eye(3) - np.einsum("...i,...j->...ij", rho, rho)
    )


def point_inertia(v: Values) -> np.ndarray:
    """I_P: the carrier's inertia plus every mass as a point, about C (3, 3)."""
    masses = v.m + v.mg
    center = (masses[:, None] * v.r).sum(0) / (v.m_a + masses.sum())
    return v.carrier + _point(v.m_a, -center) + _point(masses, v.r - center).sum(0)


@dataclass(frozen=True)
class Frames:
    """Per state and rotor (M, N, 3): the spin axis, g_g x g_s, the gimbal
    axis; and K (M, N, 3, 3), the rotor's inertia fixed in its gimbal."""

    g_s: np.ndarray
    g_t: np.ndarray
    g_g: np.ndarray
    K: np.ndarray


def frames(v: Values, gam: np.ndarray) -> Frames:
    """The gimbal frames at angles gam (M, N); a fixed wheel's angle is ignored.
    K as a sum of constant tensors times cos^2, sin^2, cos sin, cos, sin
    (_inertia_terms): no 3x3 matrix product per state and rotor."""
    angle = np.where(v.has_gimbal, gam, 0.0)
    c, s = np.cos(angle)[..., None], np.sin(angle)[..., None]
    g_s = c * v.g_s0 + s * np.cross(v.g_g, v.g_s0)
    g_g = np.broadcast_to(v.g_g, g_s.shape)
    g_t = np.cross(g_g, g_s)
    t = _inertia_terms(v)
    c, s = c[..., None], s[..., None]
    k = t[0] + c * (c * t[1] + s * t[3] + t[4]) + s * (s * t[2] + t[5])
    return Frames(g_s, g_t, g_g, k)


def _inertia_terms(v: Values) -> np.ndarray:
    """(6, N, 3, 3): K(gam) = T0 + c^2 T1 + s^2 T2 + c s T3 + c T4 + s T5,
    c = cos(gam), s = sin(gam). The frame's axes are R = c P + s Q + G, P =
    [g_s0, b, 0], Q = [b, -g_s0, 0], G = [0, 0, g_g], b = g_g x g_s0 (g_t =
    g_g x g_s = c b - s g_s0: g_g is a unit vector perpendicular to g_s0),
    and K = R IG R^T + I (1 - g_s g_s^T)."""
    a, g = v.g_s0, v.g_g
    b = np.cross(g, a)
    zero = np.zeros_like(a)
    p = np.stack([a, b, zero], axis=-1)
    q = np.stack([b, -a, zero], axis=-1)
    gg = np.stack([zero, zero, g], axis=-1)

    def sym(x: np.ndarray, y: np.ndarray) -> np.ndarray:  # x IG y^T + y IG x^T
        xy = x @ v.IG @ y.swapaxes(-1, -2)
        return xy + xy.swapaxes(-1, -2)

    def outer(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return v.I[:, None, None] * x[:, :, None] * y[:, None, :]

    eye = v.I[:, None, None] * np.eye(3)
    return np.stack([
        gg @ v.IG @ gg.swapaxes(-1, -2) + eye,
        p @ v.IG @ p.swapaxes(-1, -2) - outer(a, a),
        q @ v.IG @ q.swapaxes(-1, -2) - outer(b, b),
        sym(p, q) - outer(a, b) - outer(b, a),
        sym(p, gg),
        sym(q, gg),
    ])  # fmt: skip


def _apply(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """a x for stacks of 3x3 matrices a (..., 3, 3) and vectors x (..., 3)."""
    return (a @ x[..., None])[..., 0]


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a . b over the last axis."""
    return (a * b).sum(-1)


def _rates(v: Values, f: Frames, w_A: np.ndarray, gd: np.ndarray) -> np.ndarray:
    """w_G (M, N, 3); a fixed wheel's gd is ignored."""
    return w_A[:, None, :] + np.where(v.has_gimbal, gd, 0.0)[..., None] * f.g_g


def _momenta(v: Values, f: Frames, w_G: np.ndarray, w: np.ndarray) -> np.ndarray:
    """h_k about each rotor's mass center (M, N, 3)."""
    return _apply(f.K, w_G) + (v.J * w)[..., None] * f.g_s


def relative_spin(
    v: Values, gam: np.ndarray, w_A: np.ndarray, w: np.ndarray, f: Frames | None = None
) -> np.ndarray:
    """Omega = w - g_s . w_A (M, N): each wheel's rate relative to its gimbal
    (f: the frames at gam, if the caller has them)."""
    f = frames(v, gam) if f is None else f
    return w - _dot(f.g_s, w_A[:, None, :])


def angular_momentum(
    v: Values, w_A: np.ndarray, gam: np.ndarray, gd: np.ndarray, w: np.ndarray,
    f: Frames | None = None,
) -> np.ndarray:  # fmt: skip
    """H about C (M, 3), A-components."""
    f = frames(v, gam) if f is None else f
    return w_A @ point_inertia(v).T + _momenta(v, f, _rates(v, f, w_A, gd), w).sum(1)


def kinetic_energy(
    v: Values, w_A: np.ndarray, gam: np.ndarray, gd: np.ndarray, w: np.ndarray,
    f: Frames | None = None,
) -> np.ndarray:  # fmt: skip
    """T (M,): the carrier and the points, each frame and each wheel."""
    f = frames(v, gam) if f is None else f
    w_G = _rates(v, f, w_A, gd)
    rotors = _dot(w_G, _apply(f.K, w_G)).sum(1) + (v.J * w**2).sum(1)
    return 0.5 * (_dot(w_A, w_A @ point_inertia(v).T) + rotors)


def power(
    v: Values,
    w_A: np.ndarray,
    gam: np.ndarray,
    gd: np.ndarray,
    w: np.ndarray,
    u_s: np.ndarray,
    u_g: np.ndarray,
    f: Frames | None = None,
) -> np.ndarray:
    """(M, N) each rotor's motor power u_s Omega + u_g gd (a fixed wheel's
    u_g does no work); dT/dt = sum of it - sum b Omega^2."""
    omega = relative_spin(v, gam, w_A, w, f)
    return u_s * omega + np.where(v.has_gimbal, u_g * gd, 0.0)


def derivatives(
    v: Values,
    w_A: np.ndarray,
    gam: np.ndarray,
    gd: np.ndarray,
    w: np.ndarray,
    u_s: np.ndarray,
    u_g: np.ndarray,
    f: Frames | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(w_A', gam', gd', w') of M states: w_A (M, 3), the rest (M, N). A
    fixed wheel's gam' and gd' are 0 and its u_g is ignored. The rows solved
    per state: the system's momentum (3), then each gimbal about g_g (a fixed
    wheel's row: gd' = 0); w' comes first, from each wheel's own law
    (f: the frames at gam, if the caller has them)."""
    f = frames(v, gam) if f is None else f
    rate = np.where(v.has_gimbal, gd, 0.0)
    w_G = _rates(v, f, w_A, gd)
    h = _momenta(v, f, w_G, w)
    omega = relative_spin(v, gam, w_A, w, f)
    w_dot = (u_s - v.b * omega) / v.J
    # K' w_G, K' = gd (S K - K S) in A: gd (g_g x K w_G - K (g_g x w_G)),
    # products of a matrix and a vector (two 3x3 matrix products cost 5x more)
    turned = np.cross(f.g_g, _apply(f.K, w_G)) - _apply(f.K, np.cross(f.g_g, w_G))
    k_dot_w = rate[..., None] * turned
    total = w_A @ point_inertia(v).T + h.sum(1)
    spin = v.J[:, None] * (w_dot[..., None] * f.g_s + (w * rate)[..., None] * f.g_t)
    m, n = gam.shape
    mat = np.zeros((m, 3 + n, 3 + n))
    rhs = np.zeros((m, 3 + n))
    k_g = _apply(f.K, f.g_g)  # K g_g: how gd' turns the momentum
    mat[:, :3, :3] = point_inertia(v) + f.K.sum(1)
    mat[:, :3, 3:] = k_g.transpose(0, 2, 1)
    mat[:, 3:, :3] = k_g  # K symmetric: g_g^T K
    diag = np.where(v.has_gimbal, _dot(f.g_g, k_g), 1.0)
    mat[:, 3:, 3:] = diag[..., None] * np.eye(n)
    rhs[:, :3] = -np.cross(w_A, total) - (k_dot_w + spin).sum(1)
    torque = u_g - _dot(f.g_g, k_dot_w + np.cross(w_A[:, None, :], h))
    rhs[:, 3:] = np.where(v.has_gimbal, torque, 0.0)
    acc = np.linalg.solve(mat, rhs[..., None])[..., 0]
    return acc[:, :3], rate, acc[:, 3:], w_dot
