"""The numpy witness for reaction-wheel clusters, by hand from Newton-Euler.

Independent of the sympy model and of gyrogen.physics: the system's inertia
about its mass center C is summed body by body here (each rotor with its full
inertia I (1 - g g^T) + J g g^T), the angular momentum is

    H = I_C w + sum_k J_k (w_k - g_k . w) g_k      (A-components),

the whole system is torque-free about C (every motor and bearing torque is
internal), so dH/dt in N is 0: in A, H' + w x H = 0; and each wheel obeys
J_k w_k' = net_k (its axial Euler equation: an axisymmetric rotor has no
gyroscopic term about its axis). Then

    (I_C - sum_k J_k g_k g_k^T) w' = -w x H - sum_k net_k g_k,

solved per state with numpy. For one rotor on a2 this is the paper's
gyrostat without translation (tests/test_cluster.py holds it to
reference.rhs). Vectorized over states; the scene gives the values.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gyrogen.abi_rotors import rotor_name
from gyrogen.scene import Scene


@dataclass(frozen=True)
class Values:
    """A cluster's numbers: carrier, then one row per rotor."""

    m_a: float
    carrier: np.ndarray
    m: np.ndarray
    I: np.ndarray
    J: np.ndarray
    g: np.ndarray
    """(N, 3) unit axes in A."""
    r: np.ndarray
    """(N, 3) B_k* from A*."""
    b: np.ndarray


def values(scene: Scene, runtime: dict[str, float] | None = None) -> Values:
    """The numbers: folded, or runtime ones from runtime by their p[] names
    (an axial inertia missing there is 0: only the condition number, which
    J does not change, is computed without it)."""
    given = runtime or {}
    p = {n: float(given[n] if v == "runtime" else v) for n, v in scene.parameters.items()}
    i12, i13, i23 = p.get("I12", 0.0), p.get("I13", 0.0), p.get("I23", 0.0)
    carrier = np.array([[p["I11"], i12, i13], [i12, p["I22"], i23], [i13, i23, p["I33"]]])
    rotors = scene.rotors

    def each(key: str, missing: float | None = None) -> np.ndarray:
        out = []
        for k, r in enumerate(rotors, 1):
            v = getattr(r, key)
            name = rotor_name(key, k)
            out.append(float(v) if v != "runtime" else given.get(name, missing) if
                       missing is not None else given[name])  # fmt: skip
        return np.array(out)

    axes = np.array(
        [
            [given[rotor_name(f"g{i}", k)] for i in (1, 2, 3)] if r.axis == "runtime" else r.axis
            for k, r in enumerate(rotors, 1)
        ],
        dtype=float,
    )
    return Values(
        m_a=p["m_a"],
        carrier=carrier,
        m=each("m"),
        I=each("I"),
        J=each("J", 0.0),
        g=axes / np.linalg.norm(axes, axis=1, keepdims=True),
        r=np.array(
            [
                [given[rotor_name(f"r{i}", k)] for i in (1, 2, 3)]
                if r.position == "runtime"
                else r.position
                for k, r in enumerate(rotors, 1)
            ],
            dtype=float,
        ),
        b=np.array([r.b for r in rotors]),
    )


def system_inertia(v: Values) -> np.ndarray:
    """Every body's inertia about the system's mass center C, summed (rotors
    with their axial inertia J too)."""
    total = v.m_a + v.m.sum()
    center = (v.m[:, None] * v.r).sum(axis=0) / total
    out = v.carrier + _point(v.m_a, -center)
    for k in range(len(v.m)):
        g = v.g[k]
        body = v.I[k] * (np.eye(3) - np.outer(g, g)) + v.J[k] * np.outer(g, g)
        out = out + body + _point(v.m[k], v.r[k] - center)
    return out


def _point(mass: float, rho: np.ndarray) -> np.ndarray:
    """A point mass's inertia about a point rho away (parallel axes)."""
    return mass * (rho @ rho * np.eye(3) - np.outer(rho, rho))


def condition(scene: Scene, runtime: dict[str, float] | None = None) -> float:
    """||A||_F ||A^-1||_F of the inertia the speeds' equations solve with."""
    v = values(scene, runtime)  # the J_k cancel in it
    a = system_inertia(v) - (v.J[:, None, None] * np.einsum("ki,kj->kij", v.g, v.g)).sum(0)
    return float(np.linalg.norm(a) * np.linalg.norm(np.linalg.inv(a)))


Time = float | np.ndarray
"""One time for every state, or one per state (n,): a torque table reads it."""


def motor_torques(
    scene: Scene, runtime: dict[str, float], rel: np.ndarray, t: Time = 0.0
) -> np.ndarray:
    """(n, N) motor torques from each rotor's law at time t, clamped to its
    limit; rel (n, N) are the wheels' rates relative to A."""
    out = demanded_torques(scene, runtime, rel, t)
    for k, rotor in enumerate(scene.rotors):
        if rotor.tau_max is not None:
            out[:, k] = np.clip(out[:, k], -rotor.tau_max, rotor.tau_max)
    return out


def demanded_torques(
    scene: Scene, runtime: dict[str, float], rel: np.ndarray, t: Time = 0.0
) -> np.ndarray:
    """(n, N) what each rotor's law asks of its motor, before the clamp; a
    table: T(t) by linear interpolation, its end values outside it."""
    out = np.zeros_like(rel)
    for k, rotor in enumerate(scene.rotors):
        law = {key: runtime.get(f"{key}_{k + 1}", val) for key, val in rotor.law().items()}
        if rotor.torque == "constant":
            out[:, k] = float(law["T"])
        elif rotor.torque == "speed_controller":
            out[:, k] = -float(law["k"]) * (rel[:, k] - float(law["w_ref"]))
        elif rotor.torque == "table":
            table = np.array(rotor.torque_table, dtype=float)
            out[:, k] = np.interp(t, table[:, 0], table[:, 1])
    return out


def clamp_margins(
    scene: Scene, xs: np.ndarray, runtime: dict[str, float], t: Time = 0.0
) -> np.ndarray:
    """(n, N) |demanded torque| - tau_max per wheel (-inf without a limit):
    positive where the clamp holds the motor; its sign changes where the
    power's slope jumps."""
    mo = motion(scene, np.atleast_2d(xs), runtime, t)
    limit = np.array([np.inf if r.tau_max is None else r.tau_max for r in scene.rotors])
    return np.abs(demanded_torques(scene, runtime, mo.rel, t)) - limit


@dataclass(frozen=True)
class Motion:
    """What the rhs and the outputs read, per state."""

    w: np.ndarray
    """(n, 3) rates of A."""
    wheels: np.ndarray
    """(n, N) absolute wheel rates."""
    rel: np.ndarray
    motor: np.ndarray
    h: np.ndarray
    """(n, 3) angular momentum about C, A-components."""


def motion(scene: Scene, xs: np.ndarray, runtime: dict[str, float], t: Time = 0.0) -> Motion:
    v = values(scene, runtime)
    n = len(v.m)
    w, wheels = xs[:, -3 - n : -n], xs[:, -n:]
    rel = wheels - w @ v.g.T
    h = w @ system_inertia(v).T + (v.J * rel) @ v.g
    return Motion(w, wheels, rel, motor_torques(scene, runtime, rel, t), h)


def rhs(scene: Scene, xs: np.ndarray, runtime: dict[str, float], t: Time = 0.0) -> np.ndarray:
    """dx/dt of a cluster's states (scene.states order); 3-1-2 angles or the
    quaternion rates are filled in by the caller when the attitude is e."""
    v = values(scene, runtime)
    n = len(v.m)
    mo = motion(scene, xs, runtime, t)
    net = mo.motor - v.b * mo.rel
    a = system_inertia(v) - (v.J[:, None, None] * np.einsum("ki,kj->kij", v.g, v.g)).sum(0)
    f = -np.cross(mo.w, mo.h) - net @ v.g
    out = np.zeros_like(xs)
    out[:, -3 - n : -n] = np.linalg.solve(a, f.T).T
    out[:, -n:] = net / v.J
    if scene.effects.rotor_angle:
        out[:, -3 - 2 * n : -3 - n] = mo.rel
    if scene.attitude == "euler312":
        q2, q3 = xs[:, 1], xs[:, 2]
        w1, w2, w3 = mo.w.T
        q1d = (np.cos(q3) * w3 - np.sin(q3) * w1) / np.cos(q2)
        out[:, 0] = q1d
        out[:, 1] = np.cos(q3) * w1 + np.sin(q3) * w3
        out[:, 2] = w2 - np.sin(q2) * q1d
    return out


def outputs(scene: Scene, name: str, xs: np.ndarray, runtime: dict[str, float],
            dcm: np.ndarray, t: Time = 0.0) -> np.ndarray:  # fmt: skip
    """Energy, H in N (dcm: a_i = sum_j C[i, j] n_j per state), motor power."""
    v = values(scene, runtime)
    mo = motion(scene, xs, runtime, t)
    if name == "kinetic_energy":
        i_c = system_inertia(v)
        spin = (v.J * (mo.rel**2 + 2 * mo.rel * (mo.w @ v.g.T))).sum(1)
        return (0.5 * (np.einsum("ni,ij,nj->n", mo.w, i_c, mo.w) + spin))[:, None]
    if name == "angular_momentum":
        return np.einsum("nij,ni->nj", dcm, mo.h)
    if name == "power":
        return mo.motor * mo.rel
    raise KeyError(name)


def power_and_torque(
    scene: Scene, xs: np.ndarray, runtime: dict[str, float], t: Time = 0.0
) -> np.ndarray:
    """(n, 2): dK/dt (sum of net torque times relative rate: motors and
    friction) and wheel 1's net torque (its J w1' = net_1)."""
    v = values(scene, runtime)
    mo = motion(scene, np.atleast_2d(xs), runtime, t)
    net = mo.motor - v.b * mo.rel
    return np.column_stack([(net * mo.rel).sum(1), net[:, 0]])
