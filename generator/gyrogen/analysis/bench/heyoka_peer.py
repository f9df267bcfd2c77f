"""heyoka (the `bench` extra): Taylor-series integration compiled through
LLVM, the reports' peer and their quadruple-precision reference.

Its system is gyrogen's own optimized rhs block (peer_rhs.rhs_values:
the same arithmetic as the generated code, the hoisted constants c as
heyoka's runtime parameters par[i]), checked against the compiled rhs at
random states before anything is timed (`check`, a bar of 1e-14).

- `Scalar`: a `taylor_adaptive` per tolerance (rtol = atol = tol, heyoka's
  one tolerance), timed as `propagate_until` from Python; its construction
  (the JIT) timed apart, with no cached code (`cold`).
- `Batch`: `taylor_adaptive_batch` at heyoka's recommended SIMD width, an
  ensemble run as a Python loop over its batches. heyoka's propagate holds
  the GIL, and its ensemble mode copies the integrator per iteration
  (~100 us per trajectory measured here), so 2 cores are 2 worker
  processes, each with its own integrator, each running half the loop.
- `reference`: heyoka's real128 integrator (quadruple precision, tol
  1e-32, compact mode) from the same double x0 and c, checked against a
  second run at 1e-28.

There is no compiled-loop measurement of heyoka here: its Python package
exposes the integrator only through Python calls (a cfunc compiles
expressions, not the integrator), so every heyoka figure includes one
Python call per propagation (or per batch of width trajectories).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyrogen.analysis.bench.peer_rhs import rhs_values
from gyrogen.oracle.compare import scaled_error

MATCH = 1e-14
"""Largest scaled difference of heyoka's rhs from the compiled one."""
QUAD_TOL = 1e-32
QUAD_CHECK_TOL = 1e-28


def module() -> Any:
    """heyoka, or None when it is not installed."""
    try:
        import heyoka
    except ImportError:
        return None
    return heyoka


def one_thread() -> None:
    """heyoka's own parallelism (its TBB thread pool: ensembles, parallel
    mode) held to one thread in this process, so that a row's cores are
    the ones it says."""
    module().set_nthreads(1)


def cold(hy: Any) -> None:
    """No compiled code at hand: heyoka's disk cache (~/.cache/heyoka,
    across processes) off in this process and its memory cache emptied, so
    that a construction's time is its JIT's, as gyrogen's build is timed
    from an empty cache."""
    hy.llvm_state.set_diskcache_enabled(False)
    hy.llvm_state.clear_memcache()


@dataclass(frozen=True)
class System:
    hy: Any
    pairs: list[tuple[Any, Any]]
    """(state variable, its rate) for heyoka's integrators."""
    nx: int
    npars: int
    """Parameters the rhs reads: c[:npars] (heyoka counts up to the last used)."""


def system(hy: Any, unit: Any) -> System:
    """The scene's rhs as heyoka expressions; ValueError when it reads t
    or a function heyoka has no counterpart for here."""
    if unit.uses_time:
        raise ValueError("its torque table depends on t")
    xs = hy.make_vars(*(str(s) for s in unit.states))
    xs = list(xs) if isinstance(xs, list | tuple) else [xs]
    pars = [hy.par[i] for i in range(unit.nc)]
    funcs = {"sin": hy.sin, "cos": hy.cos, "sqrt": hy.sqrt}
    try:
        rates = rhs_values(unit, xs, pars, funcs)
    except (NameError, TypeError) as exc:
        raise ValueError(f"its rhs is not expressible in heyoka here ({exc})") from exc
    rates = [r if isinstance(r, hy.expression) else hy.expression(float(r)) for r in rates]
    npars = int(hy.cfunc(rates, xs).nparams)
    return System(hy, list(zip(xs, rates, strict=True)), len(xs), npars)


def rhs_difference(sys: System, rhs: Any, c: np.ndarray, x0: np.ndarray, count: int = 100
                   ) -> float:  # fmt: skip
    """Largest scaled difference between heyoka's rhs (a cfunc) and rhs(xs,
    c) over x0 and count states drawn around it."""
    hy = sys.hy
    f = hy.cfunc([r for _, r in sys.pairs], [v for v, _ in sys.pairs])
    rng = np.random.default_rng(11)
    xs = x0 + (0.3 + 0.3 * np.abs(x0)) * rng.standard_normal((count, sys.nx))
    xs[0] = x0
    pars = np.ascontiguousarray(c[: sys.npars])
    got = np.array([f(x, pars=pars) for x in xs])
    return scaled_error(got, rhs(xs, c))


def check(sys: System, rhs: Any, c: np.ndarray, x0: np.ndarray, echo: Any) -> None:
    """ValueError unless heyoka's rhs equals the compiled one to MATCH."""
    err = rhs_difference(sys, rhs, c, x0)
    echo(f"check heyoka's rhs against the compiled rhs: max difference {err:.1e}")
    if not err <= MATCH:
        raise ValueError(f"heyoka's rhs differs from the compiled rhs by {err:.1e}")


class Scalar:
    """A taylor_adaptive at tol (rtol = atol = tol); jit: the seconds its
    construction took."""

    def __init__(self, sys: System, x0: np.ndarray, c: np.ndarray, t1: float, tol: float):
        cold(sys.hy)
        t0 = time.perf_counter()
        self.ta = sys.hy.taylor_adaptive(sys.pairs, x0, tol=tol, pars=c[: sys.npars])
        self.jit = time.perf_counter() - t0
        self.x0, self.t1 = x0, t1
        self.limit = sys.hy.taylor_outcome.time_limit

    def run(self) -> Any:
        """From x0 at t = 0 to t1 (what is timed)."""
        ta = self.ta
        ta.time = 0.0
        ta.state[:] = self.x0
        return ta.propagate_until(self.t1)

    def final(self) -> np.ndarray:
        """run(), then the state at t1 (RuntimeError unless it got there)."""
        outcome = self.run()[0]
        if outcome != self.limit:
            raise RuntimeError(f"heyoka stopped before t1: {outcome}")
        return np.array(self.ta.state)


class Quad:
    """heyoka's real128 integrator (quadruple precision, compact mode) at
    tol: final(x0) integrates from the double x0 at t = 0 to t1 and rounds
    the state to double."""

    def __init__(self, sys: System, c: np.ndarray, t1: float, tol: float = QUAD_TOL):
        hy = sys.hy
        self.q = q = hy.real128
        self.ta = hy.taylor_adaptive(
            sys.pairs, np.array([q(0.0)] * sys.nx), tol=q(tol), fp_type=q, compact_mode=True,
            pars=np.array([q(float(v)) for v in c[: sys.npars]]),
        )  # fmt: skip
        self.t1 = q(t1)
        self.limit = hy.taylor_outcome.time_limit

    def final(self, x0: np.ndarray) -> np.ndarray:
        ta, q = self.ta, self.q
        ta.time = q(0.0)
        ta.state[:] = np.array([q(float(v)) for v in x0])
        outcome = ta.propagate_until(self.t1)[0]
        if outcome != self.limit:
            raise RuntimeError(f"heyoka's real128 reference stopped before t1: {outcome}")
        return np.array([float(v) for v in ta.state])


def reference(sys: System, x0: np.ndarray, c: np.ndarray, t1: float) -> tuple[np.ndarray, float]:
    """The state at t1 in quadruple precision (QUAD_TOL), rounded to
    double, and its scaled difference from a run at QUAD_CHECK_TOL."""
    ref = Quad(sys, c, t1).final(x0)
    return ref, scaled_error(Quad(sys, c, t1, QUAD_CHECK_TOL).final(x0), ref)


class Batch:
    """An ensemble by taylor_adaptive_batch at width w (heyoka's recommended
    SIMD size): run(x0s) integrates every row from 0 to t1 on this thread."""

    def __init__(self, sys: System, x0: np.ndarray, c: np.ndarray, t1: float, tol: float):
        hy = sys.hy
        self.width = w = int(hy.recommended_simd_size())
        cold(hy)
        t0 = time.perf_counter()
        self.ta = hy.taylor_adaptive_batch(
            sys.pairs, np.ascontiguousarray(np.tile(x0[:, None], (1, w))), tol=tol,
            pars=np.ascontiguousarray(np.tile(c[: sys.npars, None], (1, w))),
        )  # fmt: skip
        self.jit = time.perf_counter() - t0
        self.t1 = t1
        self.limit = hy.taylor_outcome.time_limit

    def run(self, x0s: np.ndarray, checked: bool = False) -> np.ndarray:
        """Final states (n, nx); a last partial batch is padded with its last
        row; checked: RuntimeError unless every row got to t1 (not timed)."""
        ta, w, t1 = self.ta, self.width, self.t1
        n = len(x0s)
        pad = -n % w
        xs = np.concatenate([x0s, np.repeat(x0s[-1:], pad, axis=0)]) if pad else x0s
        out = np.empty_like(xs)
        for i in range(0, len(xs), w):
            ta.set_time(0.0)
            ta.state[:] = xs[i : i + w].T
            ta.propagate_until(t1)
            if checked and any(r[0] != self.limit for r in ta.propagate_res):
                raise RuntimeError(f"heyoka's batch stopped before t1 (rows {i}..{i + w - 1})")
            out[i : i + w] = ta.state.T
        return out[:n]
