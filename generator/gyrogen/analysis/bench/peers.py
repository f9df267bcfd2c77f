"""The default scene for other ODE libraries (gyrogen bench-ensemble's
peers): a numba @cfunc RHS for numbalsoda's DOP853 and a jax RHS for
diffrax, both written from the numpy reference's formulas
(oracle/reference.py) with the parameter-only algebra done once, as a user
of those libraries would. Each is checked against reference.rhs before it
is timed. Missing packages: the peer is skipped with a note (the `bench`
extra installs them)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from gyrogen.abi import MAX_STEPS
from gyrogen.oracle import reference

Array = np.ndarray


def constants(p: Array) -> Array:
    """The reference's parameter-only coefficients: k11, k22, k33, k13, det,
    A1..A3 (the printed equations' u2 u3, u1 u3 and u1 u2 coefficients), J,
    T, g."""
    m_a, m_b, I11, I22, I33, I13, I, J, l1, l3, g, T = p
    M = m_a + m_b
    l1a, l3a, l1b, l3b = -l1 * m_b / M, -l3 * m_b / M, l1 * m_a / M, l3 * m_a / M
    k11 = I11 + m_a * l3a**2 + I + m_b * l3b**2
    k22 = I22 + m_a * (l1a**2 + l3a**2) + m_b * (l1b**2 + l3b**2)
    k33 = I33 + m_a * l1a**2 + I + m_b * l1b**2
    k13 = I13 - m_a * l1a * l3a - m_b * l1b * l3b
    a1 = I33 + I - I22 - m_a * l3a**2 - m_b * l3b**2
    a2 = I11 - I33 + m_a * (l3a**2 - l1a**2) + m_b * (l3b**2 - l1b**2)
    a3 = I22 - I11 + m_a * l1a**2 - I + m_b * l1b**2
    det = k11 * k33 - k13**2
    return np.array([k11, k22, k33, k13, det, a1, a2, a3, J, T, g])


def rates(x: Any, k: Any, s2: Any, c2: Any, s3: Any, c3: Any) -> tuple[Any, ...]:
    """dx/dt by the reference's formulas on the constants k: the 14 rates
    (x indexable by state; s2, c2, s3, c3 the sines and cosines of q2, q3)."""
    u1, u2, u3, u4, u5, u6, u7 = x[7], x[8], x[9], x[10], x[11], x[12], x[13]
    k11, k22, k33, k13, det, a1, a2, a3 = k[0], k[1], k[2], k[3], k[4], k[5], k[6], k[7]
    J, T, g = k[8], k[9], k[10]
    f1 = -(k13 * u1 * u2 + a1 * u2 * u3 - J * u3 * u4)
    f2 = -(T - k13 * u1 * u1 + k13 * u3 * u3 + a2 * u1 * u3)
    f3 = -(J * u1 * u4 + a3 * u1 * u2 - k13 * u2 * u3)
    t2 = s2 / c2
    return (
        -s3 * u1 / c2 + c3 * u3 / c2,
        c3 * u1 + s3 * u3,
        t2 * s3 * u1 + u2 - t2 * c3 * u3,
        -u2 + u4,
        u5,
        u6,
        u7,
        (f1 * k33 - k13 * f3) / det,
        f2 / k22,
        (k11 * f3 - k13 * f1) / det,
        T / J,
        0.0 * u1,
        0.0 * u1,
        g + 0.0 * u1,
    )


def check(name: str, rhs: Callable[[Array], Array], p: Array, echo: Callable[[str], None]) -> None:
    """rhs against reference.rhs at 100 random states; ValueError past 1e-12."""
    from gyrogen.oracle import sampling

    xs = sampling.random_states(np.random.default_rng(5), 100)
    got = np.array([rhs(x) for x in xs])
    want = reference.rhs(xs, p)
    err = float(np.max(np.abs(got - want) / (1.0 + np.abs(want))))
    echo(f"check {name} RHS against reference.rhs: max difference {err:.1e}")
    if not err <= 1e-12:
        raise ValueError(f"{name} RHS differs from reference.rhs by {err:.1e}")


def numba_rhs(p: Array) -> tuple[Any, Array]:
    """(cfunc, data): the default scene's rates as a numba @cfunc of
    numbalsoda's signature f(t, u, du, data), data the constants k of p.
    numba must be installed."""
    import math

    import numba as nb
    from numbalsoda import lsoda_sig

    rates_njit = nb.njit(rates)

    @nb.cfunc(lsoda_sig)
    def rhs(t: float, u: Any, du: Any, data: Any) -> None:
        q2, q3 = u[1], u[2]
        out = rates_njit(u, data, math.sin(q2), math.cos(q2), math.sin(q3), math.cos(q3))
        for i in range(14):
            du[i] = out[i]

    return rhs, constants(p)


def numbalsoda_peer(p: Array, echo: Callable[[str], None]) -> Any | None:
    """(single, ensemble) callables around numbalsoda.dop853 with a numba
    @cfunc RHS, or None when numbalsoda or numba is missing. single(x0, t1,
    tol, loops) runs loops integrations inside one @njit call and returns
    the final state; ensemble(x0s, t1, tol, threads) integrates every row
    under numba's prange and returns the final states."""
    try:
        import ctypes

        import numba as nb
        from numbalsoda import dop853
    except ImportError as exc:
        echo(f"numbalsoda skipped ({exc}): pip install -e '.[bench]'")
        return None
    t0 = time.perf_counter()
    rhs, k = numba_rhs(p)

    def call(x: Array) -> Array:
        du = np.empty(14)
        x = np.ascontiguousarray(x)
        ptr = ctypes.POINTER(ctypes.c_double)
        rhs.ctypes(0.0, x.ctypes.data_as(ptr), du.ctypes.data_as(ptr), k.ctypes.data_as(ptr))
        return du

    check("numba", call, p, echo)
    ptr = rhs.address

    @nb.njit
    def single(x0: Array, t1: float, tol: float, loops: int) -> Array:
        t_eval = np.array([0.0, t1])
        out = x0.copy()
        for _ in range(loops):
            usol, _ok = dop853(ptr, x0, t_eval, k, tol, tol, MAX_STEPS)
            out = usol[-1]
        return out

    @nb.njit(parallel=True)
    def many(x0s: Array, t1: float, tol: float) -> Array:
        t_eval = np.array([0.0, t1])
        out = np.empty_like(x0s)
        for i in nb.prange(x0s.shape[0]):
            usol, _ok = dop853(ptr, x0s[i], t_eval, k, tol, tol, MAX_STEPS)
            out[i] = usol[-1]
        return out

    def ensemble(x0s: Array, t1: float, tol: float, threads: int) -> Array:
        nb.set_num_threads(threads)
        return np.asarray(many(x0s, t1, tol))

    single(np.zeros(14) + 0.1, 0.1, 1e-6, 1)
    ensemble(np.zeros((2, 14)) + 0.1, 0.1, 1e-6, 1)
    echo(f"numba compile: {time.perf_counter() - t0:.1f} s (not in the timings)")
    return single, ensemble


def diffrax_peer(p: Array, echo: Callable[[str], None]) -> Any | None:
    """ensemble(x0s, t1, tol, solver_name) -> final states, by diffrax under
    jax.jit(jax.vmap(...)) in double precision, or None without diffrax."""
    try:
        import diffrax
        import jax
        import jax.numpy as jnp
    except ImportError as exc:
        echo(f"diffrax skipped ({exc}): pip install -e '.[bench]'")
        return None
    jax.config.update("jax_enable_x64", True)
    k = jnp.asarray(constants(p))

    def field(t: Any, y: Any, args: Any) -> Any:
        s2, c2, s3, c3 = jnp.sin(y[1]), jnp.cos(y[1]), jnp.sin(y[2]), jnp.cos(y[2])
        return jnp.stack(rates(y, k, s2, c2, s3, c3))

    check("jax", lambda x: np.asarray(field(0.0, jnp.asarray(x), None)), p, echo)
    compiled: dict[tuple[str, float, float], Any] = {}

    def ensemble(x0s: Array, t1: float, tol: float, solver: str) -> Array:
        key = (solver, t1, tol)
        if key not in compiled:

            def one(y0: Any) -> Any:
                sol = diffrax.diffeqsolve(
                    diffrax.ODETerm(field), getattr(diffrax, solver)(), 0.0, t1, None, y0,
                    stepsize_controller=diffrax.PIDController(rtol=tol, atol=tol),
                    max_steps=100_000,
                )  # fmt: skip
                return sol.ys[-1]

            compiled[key] = jax.jit(jax.vmap(one))
            compiled[key](jnp.asarray(x0s[:2])).block_until_ready()  # compile, not timed
        return np.asarray(compiled[key](jnp.asarray(x0s)).block_until_ready())

    return ensemble
