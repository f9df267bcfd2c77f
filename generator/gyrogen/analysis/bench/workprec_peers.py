"""The compiled peers of the work-precision report (the `bench` extra):
numbalsoda's DOP853 and LSODA, and CasADi's cvodes (Adams for a
non-stiff scene, BDF with Newton for a stiff one).

Each peer integrates the scene's own equations, with no Python in its
loop:
- numbalsoda (DOP853 and LSODA; LSODA alone on a stiff scene) calls a
  numba ``@cfunc`` RHS. For every scene that cfunc calls
  gyrogen's compiled ``<prefix>_rhs`` (the same code gyrogen's integrators
  call, so the integrators are compared and not the RHS); for the default
  scene, also the hand-written numba RHS of peers.py, as a numba user would
  write it. Timed inside one ``@njit`` loop of many integrations.
- CasADi builds its SX graph from gyrogen's optimized rhs block (the same
  arithmetic), JIT-compiled with gcc when that works, else its virtual
  machine; one call of the integrator Function per integration.

A missing package skips its peer with a line saying how to install it.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from gyrogen.analysis.bench import peers, workprec
from gyrogen.analysis.bench.peer_rhs import rhs_values
from gyrogen.analysis.bench.timing import best_of, best_time
from gyrogen.analysis.bench.workprec import Config, Problem, Run
from gyrogen.oracle.compare import scaled_error

Echo = Callable[[str], None]
MIN_TIMED = 0.02
"""Seconds each timed repeat lasts at least (loops of fast integrations)."""


def runs(prob: Problem, cfg: Config, stiff: bool, echo: Echo, progress: Echo) -> list[Run]:
    """Every installed peer at the ladder of tolerances."""
    return (
        _numbalsoda_runs(prob, cfg, stiff, echo, progress)
        + _casadi_runs(prob, cfg, stiff, echo, progress)
        + _heyoka_runs(prob, cfg, stiff, echo, progress)
    )


HEYOKA = "heyoka taylor_adaptive"
HEYOKA_TAIL = (10.0**-14.5, 1e-15)
"""heyoka's tolerances past the ladder's tightest (its error lags its tol)."""


def _heyoka_runs(prob: Problem, cfg: Config, stiff: bool, echo: Echo, progress: Echo) -> list[Run]:
    """heyoka's scalar Taylor integrator (heyoka_peer), one per tolerance,
    timed as propagate_until from Python; its JIT times and its call floor
    (a propagation over no time) go into the report's notes."""
    from gyrogen.analysis.bench import heyoka_peer
    from gyrogen.codegen.generate import unit_of

    hy = heyoka_peer.module()
    if hy is None:
        echo("heyoka skipped (No module named 'heyoka'): pip install -e '.[bench]'")
        return []
    if stiff:
        echo("heyoka skipped: a stiff scene (its Taylor method is explicit)")
        return []
    try:
        sys = heyoka_peer.system(hy, unit_of(prob.scene))
    except ValueError as exc:
        echo(f"heyoka skipped: {exc}")
        return []
    heyoka_peer.check(sys, prob.compiled["C"].rhs, prob.c, prob.x0, echo)
    heyoka_peer.one_thread()
    progress(f"{HEYOKA} (LLVM JIT, from Python)")
    out, jits = [], []
    for tol in (*cfg.tolerances, *HEYOKA_TAIL):
        one = heyoka_peer.Scalar(sys, prob.x0, prob.c, prob.t1, tol)
        jits.append((tol, one.jit, int(one.ta.order)))
        x = one.final()
        secs = best_time(one.run, cfg.repeats, min_total=MIN_TIMED)
        out.append(Run(HEYOKA, "JIT, from Python", tol, scaled_error(x, prob.ref), secs, 0))
    floor = heyoka_peer.Scalar(sys, prob.x0, prob.c, 0.0, cfg.tolerances[0])
    first = {o: (t, j) for t, j, o in reversed(jits)}  # each order once
    prob.notes["heyoka JIT (taylor_adaptive construction, no cached code)"] = ", ".join(
        f"order {o} {j:.2f} s (tol {t:.0e})" for o, (t, j) in sorted(first.items())
    )
    us = best_time(floor.run, cfg.repeats, min_total=MIN_TIMED) * 1e6
    prob.notes["heyoka's Python call floor"] = (
        f"{us:.2f} us per propagate_until over no time (in every heyoka time)"
    )
    return out


def _c_rhs_address(prob: Problem) -> int:
    comp = prob.compiled["C"]
    fn = comp.ffi.addressof(comp.lib, comp.symbol("rhs"))
    return int(comp.ffi.cast("uintptr_t", fn))


def _numbalsoda_runs(
    prob: Problem, cfg: Config, stiff: bool, echo: Echo, progress: Echo
) -> list[Run]:
    """DOP853 and LSODA; LSODA alone on a stiff scene (where DOP853 crawls
    and prints a line per run that the problem seems stiff)."""
    try:
        import ctypes

        import numba as nb
        from numbalsoda import dop853, lsoda, lsoda_sig
    except ImportError as exc:
        echo(f"numbalsoda skipped ({exc}): pip install -e '.[bench]'")
        return []
    dp = ctypes.POINTER(ctypes.c_double)
    proto = ctypes.CFUNCTYPE(None, ctypes.c_double, dp, dp, dp)
    c_rhs = proto(_c_rhs_address(prob))

    @nb.cfunc(lsoda_sig)
    def gyrogen_rhs(t: float, u: Any, du: Any, data: Any) -> None:
        c_rhs(t, u, data, du)

    address: Any = gyrogen_rhs.address  # numba types it loosely
    rhs = {"gyrogen's C RHS": (int(address), np.ascontiguousarray(prob.c))}
    if workprec.full_model(prob.scene):
        hand, k = peers.numba_rhs(prob.p)
        rhs["numba RHS"] = (int(hand.address), k)
    solvers = {"LSODA": lsoda} if stiff else {"DOP853": dop853, "LSODA": lsoda}
    out = []
    for solver_name, solver in solvers.items():
        loop = _njit_loop(nb, solver)
        for rhs_name, (address, data) in rhs.items():
            progress(f"numbalsoda {solver_name} ({rhs_name})")
            for tol in cfg.tolerances:
                out.append(_loop_run(prob, loop, address, data, solver_name, rhs_name, tol, cfg))
    return out


def _njit_loop(nb: Any, solver: Any) -> Any:
    @nb.njit
    def loop(address: int, x0: Any, t1: float, data: Any, tol: float, n: int) -> Any:
        t_eval = np.array([0.0, t1])
        last = x0.copy()
        ok = True
        for _ in range(n):
            usol, ok = solver(address, x0, t_eval, data, tol, tol, 10**8)
            last = usol[-1]
        return last, ok

    return loop


def _loop_run(
    prob: Problem, loop: Any, address: int, data: Any, solver: str, rhs: str, tol: float,
    cfg: Config,
) -> Run:  # fmt: skip
    label = f"numbalsoda {solver}"
    t0 = time.perf_counter()
    x, ok = loop(address, prob.x0, prob.t1, data, tol, 1)
    once = time.perf_counter() - t0
    if not ok or not np.all(np.isfinite(x)):
        return Run(label, rhs, tol, math.inf, 0.0, 0, "failed")
    n = max(1, int(MIN_TIMED / max(once, 1e-7)))
    secs = best_of(lambda: loop(address, prob.x0, prob.t1, data, tol, n), cfg.repeats) / n
    return Run(label, rhs, tol, scaled_error(x, prob.ref), min(secs, once), 0)


def _casadi_runs(prob: Problem, cfg: Config, stiff: bool, echo: Echo, progress: Echo) -> list[Run]:
    try:
        import casadi as ca
    except ImportError as exc:
        echo(f"CasADi skipped ({exc}): pip install -e '.[bench]'")
        return []
    from gyrogen.codegen.generate import unit_of

    unit = unit_of(prob.scene)
    if unit.uses_time:
        echo(f"CasADi skipped: {prob.scene.name}'s torque table depends on t")
        return []
    x = ca.SX.sym("x", unit.nx)
    c = ca.SX.sym("c", unit.nc)
    try:
        ode = _sx_rhs(ca, unit, x, c)
    except (RuntimeError, TypeError, NameError) as exc:  # an operation SX does not take
        echo(f"CasADi skipped: {prob.scene.name}'s rhs does not translate to SX ({exc})")
        return []
    _check_sx(ca.Function("rhs", [x, c], [ode]), prob, echo)
    variant = "BDF" if stiff else "Adams"
    label = f"CasADi cvodes {variant}"
    opts: dict[str, Any] = {
        "linear_multistep_method": variant.lower(),
        "max_num_steps": 10**8,
    }
    if not stiff:
        opts["nonlinear_solver_iteration"] = "functional"
    jit = _jit_options(ca, x, c, ode, echo)
    backend = "JIT" if jit else "VM"
    progress(f"{label} ({backend})")
    out = []
    for tol in cfg.tolerances:
        f = ca.integrator(
            "F", "cvodes", {"x": x, "p": c, "ode": ode}, 0.0, prob.t1,
            {**opts, **jit, "abstol": tol, "reltol": tol},
        )  # fmt: skip
        out.append(_casadi_run(prob, f, label, backend, tol, cfg))
        if out[-1].status != "ok":
            break
    return out


def _sx_rhs(ca: Any, unit: Any, x: Any, c: Any) -> Any:
    """gyrogen's optimized rhs block in SX: a clamp's Min and Max as CasADi's
    fmin and fmax (Python's min and max would ask an SX for its truth)."""
    funcs = {
        "sin": ca.sin,
        "cos": ca.cos,
        "sqrt": ca.sqrt,
        "Min": lambda *a: functools.reduce(ca.fmin, a),
        "Max": lambda *a: functools.reduce(ca.fmax, a),
    }
    return ca.vertcat(*rhs_values(unit, x, c, funcs))


def _check_sx(f: Any, prob: Problem, echo: Echo) -> None:
    """The SX rhs against the compiled one at x0 and 20 states near it;
    ValueError past 1e-12 (mixed)."""
    comp = prob.compiled["C"]
    rng = np.random.default_rng(3)
    xs = [prob.x0, *(prob.x0 + 0.1 * rng.standard_normal(prob.x0.shape) for _ in range(20))]
    err = max(scaled_error(np.asarray(f(x, prob.c)).ravel(), comp.rhs(x, prob.c)) for x in xs)
    echo(f"check CasADi's SX rhs against the compiled rhs: max difference {err:.1e}")
    if not err <= 1e-12:
        raise ValueError(f"CasADi's SX rhs differs from the compiled rhs by {err:.1e}")


def _jit_options(ca: Any, x: Any, c: Any, ode: Any, echo: Echo) -> dict[str, Any]:
    """CasADi's JIT through gcc ("shell" compiler) when it works here."""
    opts = {"jit": True, "compiler": "shell", "jit_options": {"flags": ["-O3"]}}
    try:
        f = ca.Function("probe", [x, c], [ode], opts)
        f(np.zeros(x.shape[0]), np.zeros(c.shape[0]))
    except RuntimeError as exc:
        echo(f"CasADi JIT unavailable ({str(exc).splitlines()[0]}): its virtual machine is timed")
        return {}
    return opts


def _casadi_run(prob: Problem, f: Any, label: str, backend: str, tol: float, cfg: Config) -> Run:
    x0, c = prob.x0, prob.c
    try:
        t0 = time.perf_counter()
        xf = np.asarray(f(x0=x0, p=c)["xf"]).ravel()
        once = time.perf_counter() - t0
    except RuntimeError as exc:
        return Run(label, backend, tol, math.inf, 0.0, 0, f"failed: {str(exc).splitlines()[0]}")
    secs = best_time(lambda: f(x0=x0, p=c), max(1, cfg.repeats // 2), min_total=MIN_TIMED)
    return Run(label, backend, tol, scaled_error(xf, prob.ref), min(secs, once), 0)
