"""The control-moment-gyro witness (oracle/gimbal_reference.py): without
gimbals it is cluster_reference; a held gimbal is a fixed wheel; torque-free
it holds T and H in N; its energy rate is the motors' power less friction;
and Kane's equations, assembled numerically body by body, agree with it."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from wide import WIDE

from gyrogen.oracle import cluster_reference
from gyrogen.oracle import gimbal_reference as gr
from gyrogen.scene import parse

RPM = 2 * np.pi / 60


def unit(a: np.ndarray) -> np.ndarray:
    return a / np.linalg.norm(a, axis=-1, keepdims=True)


def spd(rng: np.random.Generator, low: float, high: float) -> np.ndarray:
    """A random full symmetric positive-definite tensor, principal moments in
    [low, high], satisfying the triangle inequality."""
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q @ np.diag(rng.uniform(low, high, 3)) @ q.T


def cluster_scene(carrier: np.ndarray, m_a: float, wheels: list[dict]) -> str:
    """A cluster scene: constant torques given at run time (T_k)."""

    def num(x: float) -> str:
        return repr(float(x))

    def vec(a: np.ndarray) -> str:
        return f"[{', '.join(num(x) for x in a)}]"

    c = carrier
    rows = [
        f'name = "ref"\ndescription = "reference cluster"\nattitude = "quaternion"\n'
        f"[parameters]\nm_a = {num(m_a)}\nI11 = {num(c[0, 0])}\nI22 = {num(c[1, 1])}\n"
        f"I33 = {num(c[2, 2])}\nI12 = {num(c[0, 1])}\nI13 = {num(c[0, 2])}\n"
        f"I23 = {num(c[1, 2])}\n[effects]\nrotor_angle = false\n"
    ]
    for w in wheels:
        rows.append(
            f"[[rotors]]\nm = {num(w['m'])}\nI = {num(w['I'])}\nJ = {num(w['J'])}\n"
            f"axis = {vec(w['g'])}\nposition = {vec(w['r'])}\nb = {num(w['b'])}\n"
            'torque = "constant"\nT = "runtime"\n'
        )
    return "".join(rows)


def random_wheels(rng: np.random.Generator, n: int) -> list[dict]:
    out = []
    for _ in range(n):
        i = float(rng.uniform(0.01, 0.05))
        out.append(
            {
                "m": float(rng.uniform(1, 10)), "I": i, "J": float(rng.uniform(0.5, 2)) * i,
                "g": unit(rng.normal(size=3)), "r": rng.uniform(-0.5, 0.5, 3),
                "b": float(rng.choice([0.0, 1e-3])),
            }
        )  # fmt: skip
    return out


def from_cluster(cv: cluster_reference.Values) -> gr.Values:
    """The same numbers (the scene's exactly normalized axes), no gimbals."""
    return gr.values_from_arrays(cv.m_a, cv.carrier, cv.m, cv.I, cv.J, cv.g, cv.r, b=cv.b)


@pytest.mark.parametrize("n", [1, 3, 5])
def test_without_gimbals_it_is_the_cluster_reference(n: int) -> None:
    rng = np.random.default_rng(n)
    carrier = spd(rng, 60, 120)
    scene = parse(cluster_scene(carrier, 250.0, random_wheels(rng, n)), "ref")
    m = 300
    for _ in range(3):
        runtime = {f"T_{k + 1}": float(rng.uniform(-0.5, 0.5)) for k in range(n)}
        v = from_cluster(cluster_reference.values(scene, runtime))
        xs = np.zeros((m, len(scene.states)))
        xs[:, 0] = 1.0
        xs[:, -3 - n : -n] = rng.uniform(-1, 1, (m, 3))
        xs[:, -n:] = rng.uniform(-500, 500, (m, n))
        theirs = cluster_reference.rhs(scene, xs, runtime)
        w_A, w = xs[:, -3 - n : -n], xs[:, -n:]
        zero = np.zeros((m, n))
        u_s = np.broadcast_to([runtime[f"T_{k + 1}"] for k in range(n)], (m, n))
        wd, gam_d, gd_d, w_d = gr.derivatives(v, w_A, zero, zero, w, u_s, rng.normal(size=(m, n)))
        assert not gam_d.any() and not gd_d.any()
        state = (v, w_A, zero, zero, w)
        eye = np.broadcast_to(np.eye(3), (m, 3, 3))
        pairs = [
            (wd, theirs[:, -3 - n : -n]),
            (w_d, theirs[:, -n:]),
            (gr.kinetic_energy(*state)[:, None],
             cluster_reference.outputs(scene, "kinetic_energy", xs, runtime, eye)),
            (gr.angular_momentum(*state),
             cluster_reference.outputs(scene, "angular_momentum", xs, runtime, eye)),
            (gr.power(*state, u_s, zero),
             cluster_reference.outputs(scene, "power", xs, runtime, eye)),
        ]  # fmt: skip
        for ours, ref in pairs:
            assert np.max(np.abs(ours - ref) / np.abs(ref).max()) < 1e-14


def random_cmgs(rng: np.random.Generator, n_cmg: int, n_fixed: int) -> gr.Values:
    """Random CMGs (full frame tensors) and fixed wheels on a full carrier."""
    n = n_cmg + n_fixed
    g_g = unit(rng.normal(size=(n, 3)))
    g_s0 = unit(np.cross(g_g, rng.normal(size=(n, 3))))
    g_g[n_cmg:] = 0.0
    IG = np.array([spd(rng, 0.05, 0.3) for _ in range(n)])
    IG[n_cmg:] = 0.0
    i = rng.uniform(0.02, 0.08, n)
    return gr.values_from_arrays(
        m_a=float(rng.uniform(100, 800)), carrier=spd(rng, 100, 900),
        m=rng.uniform(2, 8, n), I=i, J=i * rng.uniform(0.5, 2, n), g_s0=g_s0,
        r=rng.uniform(-0.8, 0.8, (n, 3)), g_g=g_g, b=rng.uniform(0, 1e-3, n),
        mg=np.where(np.arange(n) < n_cmg, rng.uniform(1, 6, n), 0.0), IG=IG,
    )  # fmt: skip


def random_states(rng: np.random.Generator, m: int, n: int) -> tuple[np.ndarray, ...]:
    """w_A, gam, gd, w, u_s, u_g."""
    return (
        rng.uniform(-0.5, 0.5, (m, 3)), rng.uniform(-np.pi, np.pi, (m, n)),
        rng.uniform(-0.5, 0.5, (m, n)), rng.uniform(-400, 400, (m, n)),
        rng.uniform(-0.2, 0.2, (m, n)), rng.uniform(-2, 2, (m, n)),
    )  # fmt: skip


def test_a_held_gimbal_is_a_fixed_wheel() -> None:
    """gd = 0 and u_g the torque that keeps gd' = 0: the frames join the
    carrier and each wheel spins on g_s(gam), as cluster_reference has it."""
    rng = np.random.default_rng(7)
    n, m = 3, 40
    v = random_cmgs(rng, n, 0)
    w_A, gam, _, w, u_s, _ = random_states(rng, m, n)
    gd = np.zeros((m, n))
    base = gr.derivatives(v, w_A, gam, gd, w, u_s, np.zeros((m, n)))[2]
    per_unit = np.stack(
        [gr.derivatives(v, w_A, gam, gd, w, u_s, np.tile(np.eye(n)[j], (m, 1)))[2] - base
         for j in range(n)], axis=-1,
    )  # fmt: skip
    hold = np.linalg.solve(per_unit, -base[..., None])[..., 0]
    wd, _, gd_d, w_d = gr.derivatives(v, w_A, gam, gd, w, u_s, hold)
    assert np.max(np.abs(gd_d)) < 1e-12 * np.max(np.abs(base))
    f = gr.frames(v, gam)
    mass = v.m_a + v.mg.sum()
    for s in range(m):
        center = (v.mg[:, None] * v.r).sum(0) / mass  # the carrier with its frames
        carrier = v.carrier + gr._point(v.m_a, -center)
        for k in range(n):
            rot = np.column_stack([f.g_s[:, k, s], f.g_t[:, k, s], f.g_g[:, k, s]])
            carrier += rot @ v.IG[k] @ rot.T + gr._point(v.mg[k], v.r[k] - center)
        wheels = [
            {"m": v.m[k], "I": v.I[k], "J": v.J[k], "g": f.g_s[:, k, s], "r": v.r[k] - center,
             "b": v.b[k]} for k in range(n)
        ]  # fmt: skip
        scene = parse(cluster_scene(carrier, mass, wheels), "ref")
        runtime = {f"T_{k + 1}": float(u_s[s, k]) for k in range(n)}
        x = np.concatenate([[1.0, 0, 0, 0], w_A[s], w[s]])[None]
        ref = cluster_reference.rhs(scene, x, runtime)[0]
        assert np.allclose(wd[s], ref[4:7], rtol=0, atol=1e-13 * np.abs(ref[4:7]).max())
        assert np.allclose(w_d[s], ref[7:], rtol=0, atol=1e-13 * np.abs(ref[7:]).max())


def vscmg3() -> gr.Values:
    """Three VSCMGs, gimbals on a1, a2, a3, off the mass center."""
    a = np.eye(3)
    return gr.values_from_arrays(
        m_a=750.0, carrier=np.diag([900.0, 800.0, 600.0]), m=[6.0] * 3, I=[0.0795] * 3,
        J=[0.159] * 3, g_s0=a[[1, 2, 0]], g_g=a, r=[[0.5, 0.1, -0.2], [-0.3, 0.6, 0.1],
        [0.2, -0.4, 0.7]], mg=[6.0] * 3, IG=[np.diag([0.1, 0.2, 0.3])] * 3,
    )  # fmt: skip


def dcm(q: np.ndarray) -> np.ndarray:
    """A-components to N-components, from the Euler parameters (e0 scalar)."""
    e0, e1, e2, e3 = q / np.linalg.norm(q)
    return np.array(
        [[1 - 2 * (e2**2 + e3**2), 2 * (e1 * e2 - e0 * e3), 2 * (e1 * e3 + e0 * e2)],
         [2 * (e1 * e2 + e0 * e3), 1 - 2 * (e1**2 + e3**2), 2 * (e2 * e3 - e0 * e1)],
         [2 * (e1 * e3 - e0 * e2), 2 * (e2 * e3 + e0 * e1), 1 - 2 * (e1**2 + e2**2)]]
    )  # fmt: skip


def run(
    v: gr.Values, u_s: np.ndarray, u_g: np.ndarray, t_end: float
) -> tuple[np.ndarray, np.ndarray]:
    """The 3-VSCMG run from its initial state, DOP853 at 1e-13, under constant
    motor torques: 601 times, and rows (e0..e3, w_A, gam, gd, w, W), W the
    work of the motors less friction, integrated beside the motion."""

    def f(_t: float, x: np.ndarray) -> np.ndarray:
        q, w_A, gam, gd, w = x[:4], x[None, 4:7], x[None, 7:10], x[None, 10:13], x[None, 13:16]
        e0, e1, e2, e3 = q
        w1, w2, w3 = w_A[0]
        qd = 0.5 * np.array(
            [-e1 * w1 - e2 * w2 - e3 * w3, e0 * w1 + e2 * w3 - e3 * w2,
             e0 * w2 + e3 * w1 - e1 * w3, e0 * w3 + e1 * w2 - e2 * w1]
        )  # fmt: skip
        d = gr.derivatives(v, w_A, gam, gd, w, u_s, u_g)
        friction = v.b * gr.relative_spin(v, gam, w_A, w) ** 2
        work = gr.power(v, w_A, gam, gd, w, u_s, u_g).sum() - friction.sum()
        return np.concatenate([qd, *(a[0] for a in d), [work]])

    x0 = np.concatenate(
        [[1.0, 0, 0, 0], [0.08, 0.01, 0.0], np.zeros(3), [0.06, 0.011, -0.003],
         np.array([2000.0, 350.0, -900.0]) * RPM, [0.0]]
    )  # fmt: skip
    sol = solve_ivp(f, (0, t_end), x0, method="DOP853", rtol=1e-13, atol=1e-13, dense_output=True)
    assert sol.success
    ts = np.linspace(0, t_end, 601)
    return ts, sol.sol(ts).T


def torque_free_drift(t_end: float = 60.0) -> dict[str, float]:
    """The 3-VSCMG run torque-free: relative drifts of T, |H|, H in N."""
    v = vscmg3()
    zero = np.zeros((1, 3))
    _, xs = run(v, zero, zero, t_end)
    args = (v, xs[:, 4:7], xs[:, 7:10], xs[:, 10:13], xs[:, 13:16])
    energy = gr.kinetic_energy(*args)
    h_a = gr.angular_momentum(*args)
    h_n = np.einsum("mij,mj->mi", np.array([dcm(q) for q in xs[:, :4]]), h_a)
    h0 = np.linalg.norm(h_n[0])
    return {
        "T": float(np.max(np.abs(energy / energy[0] - 1))),
        "|H|": float(np.max(np.abs(np.linalg.norm(h_a, axis=1) / h0 - 1))),
        "H_N": float(np.max(np.linalg.norm(h_n - h_n[0], axis=1)) / h0),
        "max_gam": float(np.max(np.abs(xs[:, 7:10]))),
    }


@pytest.mark.slow
@WIDE
def test_torque_free_vscmgs_hold_energy_and_momentum_in_n() -> None:
    drift = torque_free_drift()
    print(" ".join(f"{k}={val:.3g}" for k, val in drift.items()))
    assert drift["T"] < 1e-11 and drift["|H|"] < 1e-11 and drift["H_N"] < 1e-11


@pytest.mark.slow
@WIDE
def test_driven_vscmgs_gain_the_motors_work_less_friction() -> None:
    """T(t) - T(0) = the integral of sum(u_s Omega + u_g gd) - b Omega^2."""
    v = dataclasses.replace(vscmg3(), b=np.array([2e-3, 1e-3, 5e-4]))
    u_s, u_g = np.array([[0.05, -0.02, 0.01]]), np.array([[0.3, -0.1, 0.2]])
    _, xs = run(v, u_s, u_g, 20.0)
    energy = gr.kinetic_energy(v, xs[:, 4:7], xs[:, 7:10], xs[:, 10:13], xs[:, 13:16])
    gained = energy - energy[0]
    assert np.max(np.abs(gained)) > 1e-2 * energy[0]  # the motors do change it
    miss = np.max(np.abs(gained - xs[:, 16])) / energy[0]
    print(f"energy balance: max |T - T0 - W| / T0 = {miss:.3g}")
    assert miss < 1e-11


def along(
    fn: Callable[..., np.ndarray], args: tuple[np.ndarray, ...], rates: tuple[np.ndarray, ...]
) -> np.ndarray:
    """d fn / dt along the motion, by the complex step (exact to rounding)."""
    h = 1e-30
    return np.imag(fn(*(a + 1j * h * r for a, r in zip(args, rates, strict=True)))) / h


def test_energy_rate_is_motor_power_less_friction_and_h_is_held_in_n() -> None:
    """Exactly, at random states, mixed CMGs and fixed wheels, motors on."""
    rng = np.random.default_rng(3)
    v = random_cmgs(rng, 3, 2)
    m, n = 200, 5
    w_A, gam, gd, w, u_s, u_g = random_states(rng, m, n)
    d = gr.derivatives(v, w_A, gam, gd, w, u_s, u_g)
    state = (w_A, gam, gd, w)
    t_dot = along(lambda *x: gr.kinetic_energy(v, *x), state, d)
    omega = gr.relative_spin(v, gam, w_A, w)
    balance = gr.power(v, *state, u_s, u_g).sum(1) - (v.b * omega**2).sum(1)
    scale = np.abs(gr.power(v, *state, u_s, u_g)).sum(1) + (v.b * omega**2).sum(1)
    assert np.max(np.abs(t_dot - balance) / scale) < 1e-12
    # every torque is internal (motors, friction): dH/dt in N = H' + w_A x H = 0
    h = gr.angular_momentum(v, *state)
    h_dot = along(lambda *x: gr.angular_momentum(v, *x), state, d) + np.cross(w_A, h)
    assert np.max(np.linalg.norm(h_dot, axis=1) / np.linalg.norm(h, axis=1)) < 1e-13


def kane(
    v: gr.Values,
    w_A: np.ndarray,
    gam: np.ndarray,
    gd: np.ndarray,
    w: np.ndarray,
    u_s: np.ndarray,
    u_g: np.ndarray,
) -> np.ndarray:
    """(w_A', gd', w') of one state by Kane's equations: every body's
    angular velocity written from the kinematics alone, partial angular
    velocities read off as the columns of that linear map, its gimbal-angle
    derivative by the complex step, Euler's I alpha + w x I w per body."""
    n = len(v.m)
    gimbal = v.has_gimbal
    rotor_mass = v.m + v.mg
    center = (rotor_mass[:, None] * v.r).sum(0) / (v.m_a + rotor_mass.sum())

    def axes(angles: np.ndarray) -> tuple[np.ndarray, ...]:
        g_s = np.array([
            np.cos(a) * s + np.sin(a) * np.cross(g, s) if c else s
            for a, s, g, c in zip(angles, v.g_s0, v.g_g, gimbal, strict=True)
        ])  # fmt: skip
        return g_s, np.cross(v.g_g, g_s)

    def bodies(angles: np.ndarray, speeds: np.ndarray) -> list[tuple]:
        """(omega, inertia in A, mass, rho) per body."""
        wa, rates, spins = speeds[:3], speeds[3 : 3 + n], speeds[3 + n :]
        g_s, g_t = axes(angles)
        out = [(wa, v.carrier, v.m_a, -center)]
        for k in range(n):
            w_g = wa + rates[k] * v.g_g[k] if gimbal[k] else wa
            omega = w_g + (spins[k] - g_s[k] @ wa) * g_s[k]
            ss = np.outer(g_s[k], g_s[k])
            out.append((omega, v.I[k] * (np.eye(3) - ss) + v.J[k] * ss, v.m[k], v.r[k] - center))
            if gimbal[k]:
                rot = np.column_stack([g_s[k], g_t[k], v.g_g[k]])
                out.append((w_g, rot @ v.IG[k] @ rot.T, v.mg[k], v.r[k] - center))
        return out

    speeds = np.concatenate([w_A, np.where(gimbal, gd, 0.0), w])
    size = speeds.size
    now = bodies(gam, speeds)
    partial = [bodies(gam, np.eye(size)[r]) for r in range(size)]
    h = 1e-30
    turned = [bodies(gam + 1j * h * np.eye(n)[k], speeds) for k in range(n)]
    g_s, _ = axes(gam)
    net = u_s - v.b * (w - np.einsum("ki,i->k", g_s, w_A))
    torques = [-(np.where(gimbal, u_g, 0.0)[:, None] * v.g_g).sum(0) - (
        (~gimbal * net)[:, None] * g_s).sum(0)]  # fmt: skip
    for k in range(n):
        torques.append(net[k] * g_s[k])
        if gimbal[k]:
            torques.append(-net[k] * g_s[k] + u_g[k] * v.g_g[k])
    mat, rhs = np.zeros((size, size)), np.zeros(size)
    for b, (omega, inertia, mass, rho) in enumerate(now):
        tilt = sum(np.imag(t[b][0]) / h * gd[k] for k, t in enumerate(turned) if gimbal[k])
        alpha = tilt + np.cross(w_A, omega)  # with the speeds' rates held at 0
        accel = np.cross(w_A, np.cross(w_A, rho))
        for r in range(size):
            p_w = partial[r][b][0]
            p_v = np.cross(partial[r][0][0], rho)
            for s in range(size):
                mat[r, s] += p_w @ inertia @ partial[s][b][0] + mass * p_v @ np.cross(
                    partial[s][0][0], rho)  # fmt: skip
            rhs[r] += p_w @ torques[b] - p_w @ (inertia @ alpha + np.cross(omega, inertia @ omega))
            rhs[r] -= mass * p_v @ accel
    keep = np.concatenate([[True] * 3, gimbal, [True] * n])
    out = np.zeros(size)
    out[keep] = np.linalg.solve(mat[np.ix_(keep, keep)], rhs[keep])
    return out


@pytest.mark.parametrize("config", [(3, 2), (4, 0), (1, 0), (2, 3), "vscmg3"])
def test_kanes_equations_agree(config: tuple[int, int] | str) -> None:
    """Random CMGs (full frame tensors) and fixed wheels, and the 3-VSCMG set."""
    rng = np.random.default_rng(11)
    v = vscmg3() if config == "vscmg3" else random_cmgs(rng, *config)
    m, n = 25, len(v.m)
    states = random_states(rng, m, n)
    w_A_d, _, gd_d, w_d = gr.derivatives(v, *states)
    ours = np.column_stack([w_A_d, gd_d, w_d])
    theirs = np.array([kane(v, *(a[s] for a in states)) for s in range(m)])
    assert np.max(np.abs(ours - theirs) / np.abs(theirs).max(1, keepdims=True)) < 1e-12


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (
            {"g_g": [[1.0, 0.1, 0.0]]},
            "g_g: a gimbal axis is not perpendicular to its spin axis g_s0",
        ),
        ({"mg": [1.0]}, "mg, IG: a fixed wheel (g_g = 0) has no gimbal frame"),
        ({"IG": [np.eye(3)]}, "mg, IG: a fixed wheel (g_g = 0) has no gimbal frame"),
        (
            {"g_g": [[1.0, 0.0, 0.0]], "IG": [[[1.0, 0.1, 0], [0, 1, 0], [0, 0, 1]]]},
            "IG: a gimbal frame's inertia tensor is not symmetric",
        ),
        ({"J": [0.0]}, "J: a wheel's axial inertia is not positive"),
        ({"J": [np.nan]}, "J: a wheel's axial inertia is not positive"),
    ],
)
def test_inconsistent_arrays_are_one_line_errors(change: dict, message: str) -> None:
    given = {"m_a": 10.0, "carrier": np.eye(3), "m": [1.0], "I": [0.1], "J": [0.1],
             "g_s0": [[0.0, 1.0, 0.0]], "r": [[0.0, 0.0, 0.0]], **change}  # fmt: skip
    with pytest.raises(ValueError) as err:
        gr.values_from_arrays(**given)
    assert str(err.value) == message
