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

The accelerations (w_A', gd') solve a (3 + N) system per state, symmetric
positive definite: the gimbal rows first (each couples its own gd' to w_A'
alone; a fixed wheel's row is gd' = 0), then what is left for w_A', a 3x3
system, by Gaussian elimination. Vectorized over M states: every array holds
components first and states last (a vector of each rotor (3, N, M), a
matrix (3, 3, N, M)), each operation a numpy one on whole arrays of states;
the functions take and return states first, (M, 3) and (M, N).
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
    """Per rotor and state (3, N, M), components first: the spin axis,
    g_g x g_s, the gimbal axis; and K (3, 3, N, M), the rotor's inertia
    fixed in its gimbal."""

    g_s: np.ndarray
    g_t: np.ndarray
    g_g: np.ndarray
    K: np.ndarray


_UPPER = ([0, 0, 0, 1, 1, 2], [0, 1, 2, 1, 2, 2])
"""A symmetric 3x3 matrix's six entries (rows, columns)."""
_FULL = [[0, 1, 2], [1, 3, 4], [2, 4, 5]]
"""Where each of the nine entries sits among the six."""


def frames(v: Values, gam: np.ndarray) -> Frames:
    """The gimbal frames at angles gam (M, N); a fixed wheel's angle is ignored.
    K as a sum of constant tensors times cos^2, sin^2, cos sin, cos, sin
    (_inertia_terms): no 3x3 matrix product per state and rotor; its six
    entries (K is symmetric)."""
    c, s, a, b = _turn(v, gam)
    g_s = c * a + s * b
    g_t = c * b - s * a  # g_g x g_s: g_g is a unit vector perpendicular to g_s0
    g_g = np.broadcast_to(_each(v.g_g), g_s.shape)
    t = _inertia_terms(v)[:, :, _UPPER[0], _UPPER[1], None]  # (6, N, 6, 1)
    t = t.transpose(0, 2, 1, 3)  # (6 terms, 6 entries, N, 1)
    k = t[0] + c * (c * t[1] + s * t[3] + t[4]) + s * (s * t[2] + t[5])
    return Frames(g_s, g_t, g_g, k[_FULL])


def _turn(v: Values, gam: np.ndarray) -> tuple[np.ndarray, ...]:
    """cos and sin of the gimbal angles (N, M) (a fixed wheel's: 0), g_s0 and
    g_g x g_s0 (3, N, 1): g_s = c g_s0 + s g_g x g_s0."""
    angle = _rotor(np.where(v.has_gimbal, gam, 0.0))
    return np.cos(angle), np.sin(angle), _each(v.g_s0), _each(np.cross(v.g_g, v.g_s0))


def _rotor(x: np.ndarray) -> np.ndarray:
    """(M, N) per state and rotor -> (N, M), contiguous."""
    return np.ascontiguousarray(np.asarray(x).T)


def _each(x: np.ndarray) -> np.ndarray:
    """A vector per rotor (N, 3) -> (3, N, 1), to broadcast over states."""
    return np.ascontiguousarray(x.T)[..., None]


def _state(x: np.ndarray) -> np.ndarray:
    """A vector per state (M, 3) -> (3, 1, M), to broadcast over rotors."""
    return np.ascontiguousarray(np.asarray(x).T)[:, None, :]


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
    """a x, a (3, 3, ...) and x (3, ...): components first."""
    return a[:, 0] * x[0] + a[:, 1] * x[1] + a[:, 2] * x[2]


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a . b, components first."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b, components first."""
    return np.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])  # fmt: skip


def _rates(v: Values, f: Frames, w_A: np.ndarray, gd: np.ndarray) -> np.ndarray:
    """w_G (3, N, M) from w_A (3, 1, M) and gd (N, M); a fixed wheel's gd is
    ignored."""
    return w_A + np.where(v.has_gimbal[:, None], gd, 0.0) * f.g_g


def _momenta(v: Values, f: Frames, w_G: np.ndarray, w: np.ndarray) -> np.ndarray:
    """h_k about each rotor's mass center (3, N, M), w (N, M)."""
    return _apply(f.K, w_G) + (v.J[:, None] * w) * f.g_s


def relative_spin(
    v: Values, gam: np.ndarray, w_A: np.ndarray, w: np.ndarray, f: Frames | None = None
) -> np.ndarray:
    """Omega = w - g_s . w_A (M, N): each wheel's rate relative to its gimbal
    (f: the frames at gam, if the caller has them)."""
    if f is None:  # the spin axes alone
        c, s, a, b = _turn(v, gam)
        g_s = c * a + s * b
    else:
        g_s = f.g_s
    return np.asarray(w) - _dot(g_s, _state(w_A)).T


def angular_momentum(
    v: Values, w_A: np.ndarray, gam: np.ndarray, gd: np.ndarray, w: np.ndarray,
    f: Frames | None = None,
) -> np.ndarray:  # fmt: skip
    """H about C (M, 3), A-components."""
    f = frames(v, gam) if f is None else f
    w_a = _state(w_A)
    h = _momenta(v, f, _rates(v, f, w_a, _rotor(gd)), _rotor(w)).sum(1)
    return (point_inertia(v) @ w_a[:, 0] + h).T


def kinetic_energy(
    v: Values, w_A: np.ndarray, gam: np.ndarray, gd: np.ndarray, w: np.ndarray,
    f: Frames | None = None,
) -> np.ndarray:  # fmt: skip
    """T (M,): the carrier and the points, each frame and each wheel."""
    f = frames(v, gam) if f is None else f
    w_a = _state(w_A)
    w_G = _rates(v, f, w_a, _rotor(gd))
    rotors = _dot(w_G, _apply(f.K, w_G)).sum(0) + (v.J[:, None] * _rotor(w) ** 2).sum(0)
    return 0.5 * (_dot(w_a[:, 0], point_inertia(v) @ w_a[:, 0]) + rotors)


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
    on = v.has_gimbal[:, None]
    w_a, spin_rate = _state(w_A), _rotor(w)
    rate = np.where(on, _rotor(gd), 0.0)
    w_G = _rates(v, f, w_a, rate)
    k_w = _apply(f.K, w_G)
    h = k_w + (v.J[:, None] * spin_rate) * f.g_s
    omega = spin_rate - _dot(f.g_s, w_a)
    J = v.J[:, None]
    w_dot = (_rotor(u_s) - v.b[:, None] * omega) / J
    # K' w_G, K' = gd (S K - K S) in A: gd (g_g x K w_G - K (g_g x w_G)),
    # products of a matrix and a vector (two 3x3 matrix products cost 5x more)
    k_dot_w = rate * (_cross(f.g_g, k_w) - _apply(f.K, _cross(f.g_g, w_G)))
    i_p = point_inertia(v)
    total = i_p @ w_a[:, 0] + h.sum(1)
    spin = J * (w_dot * f.g_s + (spin_rate * rate) * f.g_t)
    k_g = _apply(f.K, f.g_g)  # K g_g: how gd' turns the momentum
    # the system [[A, B^T], [B, D]] (w_A', gd') = (r, torque): A the carrier's
    # block, B's row k = g_g^T K (K symmetric), D diagonal
    a = i_p[..., None] + f.K.sum(2)
    d = np.where(on, _dot(f.g_g, k_g), 1.0)
    r = -_cross(w_a[:, 0], total) - (k_dot_w + spin).sum(1)
    torque = _rotor(u_g) - _dot(f.g_g, k_dot_w + _cross(w_a, h))
    torque = np.where(on, torque, 0.0)
    # each gimbal row gives gd' in terms of w_A'; what is left for w_A':
    # (A - B^T D^-1 B) w_A' = r - B^T D^-1 torque
    scaled = k_g / d
    w_a_dot = _solve_symmetric(
        a - (scaled[:, None] * k_g[None]).sum(2), r - (scaled * torque).sum(1)
    )
    gd_dot = (torque - _dot(k_g, w_a_dot[:, None])) / d
    return w_a_dot.T, rate.T, gd_dot.T, w_dot.T


def _solve_symmetric(a: np.ndarray, y: np.ndarray) -> np.ndarray:
    """x with a x = y per state, a (3, 3, M) symmetric positive definite (its
    upper triangle read), y (3, M): Gaussian elimination, no pivoting (none
    is needed for such a matrix)."""
    l1, l2 = a[0, 1] / a[0, 0], a[0, 2] / a[0, 0]
    a11, a12, a22 = a[1, 1] - l1 * a[0, 1], a[1, 2] - l1 * a[0, 2], a[2, 2] - l2 * a[0, 2]
    y1, y2 = y[1] - l1 * y[0], y[2] - l2 * y[0]
    l12 = a12 / a11
    x2 = (y2 - l12 * y1) / (a22 - l12 * a12)
    x1 = (y1 - a12 * x2) / a11
    x0 = (y[0] - a[0, 1] * x1 - a[0, 2] * x2) / a[0, 0]
    return np.stack([x0, x1, x2])
