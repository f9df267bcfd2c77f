"""Physics checks of the numpy reference (gyrogen.oracle.reference) and of gyrogen.oracle.sampling.

The reference is checked against conservation laws, closed forms and the lumped
formulation of NOTES.md, computed independently here, never against itself.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from gyrogen import abi
from gyrogen.oracle import reference, sampling

P = {name: k for k, name in enumerate(abi.PARAMETERS)}
S = {name: k for k, name in enumerate(abi.STATES)}
U = slice(S["u1"], S["u7"] + 1)


def rk4(f: Callable[[np.ndarray], np.ndarray], x0: np.ndarray, dt: float, steps: int) -> np.ndarray:
    """Classical fixed-step RK4; returns the trajectory, shape (steps + 1, *x0.shape)."""
    out = np.empty((steps + 1, *x0.shape))
    out[0] = x = x0
    for k in range(steps):
        k1 = f(x)
        k2 = f(x + 0.5 * dt * k1)
        k3 = f(x + 0.5 * dt * k2)
        k4 = f(x + dt * k3)
        x = x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        out[k + 1] = x
    return out


def lumped(p: np.ndarray) -> dict[str, np.ndarray]:
    """NOTES.md's lumped inertia scalars, recomputed here by hand."""
    m_a, m_b = p[..., P["m_a"]], p[..., P["m_b"]]
    l1, l3 = p[..., P["l1"]], p[..., P["l3"]]
    M = m_a + m_b
    mu = m_a * m_b / M
    return {
        "M": M,
        "t11": p[..., P["I11"]] + p[..., P["I"]] + mu * l3**2,
        "t22": p[..., P["I22"]] + mu * (l1**2 + l3**2),
        "t33": p[..., P["I33"]] + p[..., P["I"]] + mu * l1**2,
        "t13": p[..., P["I13"]] - mu * l1 * l3,
        "J": p[..., P["J"]],
    }


@pytest.fixture(scope="module")
def batch() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(20240611)
    return sampling.random_states(rng, 200), sampling.random_parameters(rng, 200)


# (a) ---------------------------------------------------------------------------------------
def test_rotor_rate_constant_without_torque(batch: tuple[np.ndarray, np.ndarray]) -> None:
    x, p = batch
    p = p.copy()
    p[:, P["T"]] = 0.0
    assert np.all(reference.rhs(x, p)[:, S["u4"]] == 0.0)


def test_rotor_rate_with_torque(batch: tuple[np.ndarray, np.ndarray]) -> None:
    """J u4' = T: a positive T spins B up about +a2."""
    x, p = batch
    np.testing.assert_allclose(
        reference.rhs(x, p)[:, S["u4"]], p[:, P["T"]] / p[:, P["J"]], rtol=1e-15
    )


# (b) ---------------------------------------------------------------------------------------
def test_translation(batch: tuple[np.ndarray, np.ndarray]) -> None:
    x, p = batch
    xd = reference.rhs(x, p)
    assert np.all(xd[:, S["u5"]] == 0.0)
    assert np.all(xd[:, S["u6"]] == 0.0)
    assert np.array_equal(xd[:, S["u7"]], p[:, P["g"]])
    assert np.array_equal(xd[:, S["q5"] : S["q7"] + 1], x[:, S["u5"] : S["u7"] + 1])


def test_kinematics_match_table_1(batch: tuple[np.ndarray, np.ndarray]) -> None:
    """The q' of rhs move Table 1's a_i as d a_i/dt = omega^A x a_i (central differences)."""
    x, p = batch
    x = x[:50]
    xd = reference.rhs(x, p[:50])
    h = 1e-6
    dC = (reference.direction_cosines(x + h * xd) - reference.direction_cosines(x - h * xd)) / (
        2 * h
    )
    C = reference.direction_cosines(x)
    w_n = np.einsum("...i,...ij->...j", x[:, S["u1"] : S["u3"] + 1], C)
    expected = np.cross(w_n[:, None, :], C)
    scale = np.linalg.norm(w_n, axis=-1)[:, None, None] + 1.0
    np.testing.assert_allclose(dC / scale, expected / scale, rtol=0, atol=1e-7)
    # Rotor angle: relative rate of B about a2.
    assert np.array_equal(xd[:, S["q4"]], x[:, S["u4"]] - x[:, S["u2"]])


# (c) ---------------------------------------------------------------------------------------
def test_angular_momentum_conserved() -> None:
    """H about AB*, in N, is constant under RK4 (gravity through AB*, T internal)."""
    rng = np.random.default_rng(7)
    n = 4
    p = sampling.random_parameters(rng, n)
    x = sampling.random_states(rng, n, max_q2=0.3)
    # Moderate rates, so that dt = 1e-3 resolves the motion and q2 stays off gimbal lock.
    x[:, S["u1"]] = rng.uniform(-0.5, 0.5, n)
    x[:, S["u3"]] = rng.uniform(-0.5, 0.5, n)
    x[:, S["u2"]] = rng.uniform(-2.0, 2.0, n)
    x[:, S["u4"]] = rng.uniform(-5.0, 5.0, n)
    # A nonzero motor torque that changes u2 and u4 by at most ~2 rad/s over 2 s.
    lp = lumped(p)
    p[:, P["T"]] = rng.uniform(-1.0, 1.0, n) * np.minimum(lp["J"], lp["t22"])

    traj = rk4(lambda s: reference.rhs(s, p), x, 1e-3, 2000)
    assert np.max(np.abs(traj[:, :, S["q2"]])) < 1.4, "trajectory approached gimbal lock"
    H = reference.angular_momentum_n(traj, p)
    H0 = H[0]
    drift = np.max(np.abs(H - H0), axis=0) / np.linalg.norm(H0, axis=-1)[:, None]
    assert np.all(drift < 1e-9), drift
    # The motion is not trivial: the torque did change the spins.
    assert np.all(np.abs(traj[-1, :, S["u4"]] - x[:, S["u4"]]) > 1e-3)


def test_angular_momentum_formula() -> None:
    """H_N of a pure spin about a2 with A aligned to N is (0, I~22 u2 + J u4, 0)."""
    p = sampling.random_parameters(np.random.default_rng(3), 1)[0]
    x = np.zeros(14)
    x[S["u2"]], x[S["u4"]] = 1.5, -4.0
    lp = lumped(p)
    np.testing.assert_allclose(
        reference.angular_momentum_n(x, p),
        np.array([0.0, lp["t22"] * 1.5 - lp["J"] * 4.0, 0.0]),
        rtol=1e-15,
        atol=1e-15,
    )


# (d) ---------------------------------------------------------------------------------------
def test_energy_balance(batch: tuple[np.ndarray, np.ndarray]) -> None:
    """dK/dt = w.I~.w' + J u4 u4' + M v.v' equals the power T (u4 - u2) + M g u7."""
    x, p = batch
    xd = reference.rhs(x, p)
    lp = lumped(p)
    u1, u2, u3, u4 = (x[:, S[f"u{i}"]] for i in (1, 2, 3, 4))
    d1, d2, d3, d4 = (xd[:, S[f"u{i}"]] for i in (1, 2, 3, 4))
    v, vd = x[:, S["u5"] : S["u7"] + 1], xd[:, S["u5"] : S["u7"] + 1]
    T, g, M, J = p[:, P["T"]], p[:, P["g"]], lp["M"], lp["J"]
    terms_k = [
        lp["t11"] * u1 * d1,
        lp["t13"] * u1 * d3,
        lp["t13"] * u3 * d1,
        lp["t33"] * u3 * d3,
        lp["t22"] * u2 * d2,
        J * u4 * d4,
        M * np.sum(v * vd, axis=-1),
    ]
    terms_power = [T * u4, -T * u2, M * g * x[:, S["u7"]]]
    dK = np.sum(terms_k, axis=0)
    power = np.sum(terms_power, axis=0)
    scale = np.sum(np.abs(terms_k), axis=0) + np.sum(np.abs(terms_power), axis=0)
    assert np.all(np.abs(dK - power) <= 1e-10 * scale)


def test_kinetic_energy_formula(batch: tuple[np.ndarray, np.ndarray]) -> None:
    x, p = batch
    lp = lumped(p)
    u = x[:, U]
    expected = 0.5 * (
        lp["t11"] * u[:, 0] ** 2
        + lp["t22"] * u[:, 1] ** 2
        + lp["t33"] * u[:, 2] ** 2
        + 2 * lp["t13"] * u[:, 0] * u[:, 2]
        + lp["J"] * u[:, 3] ** 2
        + lp["M"] * np.sum(u[:, 4:7] ** 2, axis=-1)
    )
    np.testing.assert_allclose(reference.kinetic_energy(x, p), expected, rtol=1e-13)


# (e) ---------------------------------------------------------------------------------------
def _axisymmetric_cases() -> np.ndarray:
    base = sampling.random_parameters(np.random.default_rng(11), 1)[0]
    # No offset: l1 = l3 = 0, I13 = 0, I11 = I33.
    p1 = base.copy()
    p1[[P["l1"], P["l3"], P["I13"], P["T"]]] = 0.0
    p1[[P["I11"], P["I33"], P["I22"], P["I"], P["J"]]] = [3.0, 3.0, 5.0, 0.5, 0.8]
    # Offset rotor whose mass offsets make the *lumped* inertia axisymmetric:
    # l1 = l3 = 1 and I13 = mu l1 l3 give I~13 = 0; I11 = I33 gives I~11 = I~33.
    p2 = base.copy()
    p2[[P["m_a"], P["m_b"], P["l1"], P["l3"], P["T"]]] = [2.0, 3.0, 1.0, 1.0, 0.0]
    mu = 2.0 * 3.0 / 5.0
    p2[[P["I11"], P["I33"], P["I22"], P["I13"], P["I"], P["J"]]] = [3.0, 3.0, 1.5, mu, 0.4, 0.7]
    return np.stack([p1, p2])


def test_axisymmetric_closed_form() -> None:
    p = _axisymmetric_cases()
    lp = lumped(p)
    assert np.all(lp["t13"] == 0.0)
    np.testing.assert_allclose(lp["t11"], lp["t33"], rtol=1e-15)
    x = np.zeros((2, 14))
    x[:, S["q1"] : S["q4"] + 1] = [[0.3, 0.1, -0.7, 0.2], [-1.0, -0.2, 2.0, 0.0]]
    x[:, U] = [[0.3, 1.5, -0.2, 2.0, 1.0, -2.0, 0.5], [-0.25, -1.0, 0.35, 6.0, 0.0, 0.0, 0.0]]
    dt, steps = 1e-3, 2000
    traj = rk4(lambda s: reference.rhs(s, p), x, dt, steps)
    t = dt * np.arange(steps + 1)[:, None]
    lam = ((lp["t22"] - lp["t11"]) * x[:, S["u2"]] + lp["J"] * x[:, S["u4"]]) / lp["t11"]
    u10, u30 = x[:, S["u1"]], x[:, S["u3"]]
    u1 = u10 * np.cos(lam * t) + u30 * np.sin(lam * t)
    u3 = u30 * np.cos(lam * t) - u10 * np.sin(lam * t)
    np.testing.assert_allclose(traj[:, :, S["u1"]], u1, rtol=0, atol=1e-9)
    np.testing.assert_allclose(traj[:, :, S["u3"]], u3, rtol=0, atol=1e-9)
    for name in ("u2", "u4"):
        np.testing.assert_allclose(traj[:, :, S[name]] - x[:, S[name]], 0.0, rtol=0, atol=1e-14)
    assert np.all(np.abs(lam) * 2.0 > 1.0)  # at least a sizeable fraction of a turn


# (f) ---------------------------------------------------------------------------------------
def test_random_parameters_valid() -> None:
    rng = np.random.default_rng(5)
    p = sampling.random_parameters(rng, 500)
    assert p.shape == (500, 12)
    assert all(sampling.setup_code(row) == 0 for row in p)
    assert np.all(p[:, P["I13"]] != 0.0)
    assert np.all(p[:, P["J"]] <= 2.0 * p[:, P["I"]] * (1 + 1e-15))
    for name in ("m_a", "m_b"):
        assert p[:, P[name]].min() >= 0.1 and p[:, P[name]].max() <= 1000.0
    assert np.all(np.abs(p[:, [P["l1"], P["l3"]]]) <= 2.0)
    assert np.all(np.abs(p[:, P["g"]]) <= 20.0) and np.all(np.abs(p[:, P["T"]]) <= 10.0)


def test_random_states_ranges() -> None:
    x = sampling.random_states(np.random.default_rng(6), 500, max_q2=0.9)
    assert x.shape == (500, 14)
    assert np.all(np.abs(x[:, S["q2"]]) <= 0.9)
    assert np.all(np.abs(x[:, [S["q1"], S["q3"], S["q4"]]]) <= np.pi)
    assert np.all(np.abs(x[:, S["q5"] : S["q7"] + 1]) <= 100.0)
    assert np.all(np.abs(x[:, S["u1"] : S["u3"] + 1]) <= 5.0)
    assert np.all(np.abs(x[:, S["u4"]]) <= 200.0)
    assert np.all(np.abs(x[:, S["u5"] : S["u7"] + 1]) <= 50.0)


def test_invalid_parameters_codes() -> None:
    bases = sampling.random_parameters(np.random.default_rng(8), 5)
    for base in bases:
        cases = sampling.invalid_parameters(base)
        assert len(cases) >= 12
        assert {code for _, _, code in cases} == {1, 2, 3, 4, 5, 6, 7, 9}
        for description, vector, code in cases:
            assert sampling.setup_code(vector) == code, description
            assert code in {c.value for c in abi.SETUP_CODES}


def test_setup_code_boundaries() -> None:
    """Equality in either triangle inequality is allowed (a lamina, a thin disc)."""
    base = sampling.random_parameters(np.random.default_rng(9), 1)[0]
    lamina = base.copy()
    lamina[[P["I11"], P["I22"], P["I33"], P["I13"]]] = [0.3, 0.7, 1.0, 0.0]
    assert sampling.setup_code(lamina) == 0
    disc = base.copy()
    disc[P["J"]] = 2.0 * disc[P["I"]]
    assert sampling.setup_code(disc) == 0
    with pytest.raises(ValueError):
        sampling.setup_code(base[:11])


# (g) ---------------------------------------------------------------------------------------
def test_vectorized_equals_rowwise(batch: tuple[np.ndarray, np.ndarray]) -> None:
    x, p = batch
    xd = reference.rhs(x, p)
    assert xd.shape == x.shape
    rows = np.array([reference.rhs(xi, pi) for xi, pi in zip(x, p, strict=True)])
    np.testing.assert_allclose(xd, rows, rtol=1e-13, atol=0)
    H = reference.angular_momentum_n(x, p)
    H_rows = np.array([reference.angular_momentum_n(xi, pi) for xi, pi in zip(x, p, strict=True)])
    np.testing.assert_allclose(H, H_rows, rtol=1e-13, atol=1e-300)
    K_rows = np.array([reference.kinetic_energy(xi, pi) for xi, pi in zip(x, p, strict=True)])
    np.testing.assert_allclose(reference.kinetic_energy(x, p), K_rows, rtol=1e-13)


def test_parameter_broadcasting(batch: tuple[np.ndarray, np.ndarray]) -> None:
    x, p = batch
    grid = x[:12].reshape(3, 4, 14)
    out = reference.rhs(grid, p[0])
    assert out.shape == (3, 4, 14)
    np.testing.assert_allclose(out.reshape(12, 14), reference.rhs(x[:12], p[0]), rtol=1e-13)
    fan = reference.rhs(x[0], p[:5])
    assert fan.shape == (5, 14)
    np.testing.assert_allclose(fan[2], reference.rhs(x[0], p[2]), rtol=1e-13)
    with pytest.raises(ValueError):
        reference.rhs(x[:, :13], p)


# (h) ---------------------------------------------------------------------------------------
def test_misprint_1_u2_equation() -> None:
    """u2' uses m_b (l3b^2 - l1b^2): compare with the lumped equation of NOTES.md,
    I~22 u2' = -T + I~13 (u1^2 - u3^2) + (I~33 - I~11) u1 u3."""
    p = sampling.random_parameters(np.random.default_rng(12), 1)[0]
    p[[P["m_a"], P["m_b"], P["l1"], P["l3"], P["T"]]] = [4.0, 1.5, 0.7, -1.3, 0.8]
    x = np.zeros(14)
    x[U] = [1.1, 0.4, -0.6, 3.0, 0.0, 0.0, 0.0]
    lp = lumped(p)
    u1, u3, T = 1.1, -0.6, 0.8
    expected = (-T + lp["t13"] * (u1**2 - u3**2) + (lp["t33"] - lp["t11"]) * u1 * u3) / lp["t22"]
    got = reference.rhs(x, p)[S["u2"]]
    np.testing.assert_allclose(got, expected, rtol=1e-13)

    # The misprinted coefficient m_b (l3b - l1b^2) would give a clearly different u2'.
    m_a, m_b, l1, l3 = 4.0, 1.5, 0.7, -1.3
    l3b = l3 * m_a / (m_a + m_b)
    l1b = l1 * m_a / (m_a + m_b)
    wrong_shift = m_b * ((l3b - l1b**2) - (l3b**2 - l1b**2)) * u1 * u3
    assert abs(wrong_shift / lp["t22"]) > 1e-3 * abs(expected)
