"""Ensembles and the single trajectory, measured (gyrogen bench-ensemble).

The problem: the default scene over 10 s from its
[simulate] state, errors against DOP853 in C at rtol = atol = 1e-13, with
the scaled error of workprec (max |x - ref| / (1 + |ref|)). An ensemble
perturbs u1..u3 by up to +-10 % (uniform, seeded). Every time is the best
of several repeats; the peers (analysis/bench/peers.py) are timed in the same run.
These functions return figures for a report to use; commands/ prints them.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gyrogen.abi import MAX_STEPS
from gyrogen.analysis.bench.timing import best_time
from gyrogen.analysis.bench.workprec import REF_TOL
from gyrogen.analysis.simulate.engine import runtime_values
from gyrogen.oracle.compare import scaled_error
from gyrogen.runtime.compiled import Compiled, cores
from gyrogen.runtime.scene_build import build_scene
from gyrogen.scene import default

LADDER = tuple(10.0 ** (-k / 2) for k in range(8, 29))
"""Tolerances tried (1e-4 .. 1e-14, half decades), loosest first."""
PEER_LOOPS = 200
"""numbalsoda integrations per timed @njit call."""


@dataclass(frozen=True)
class Problem:
    comp: Compiled
    c: np.ndarray
    p: np.ndarray
    x0: np.ndarray
    t1: float


def problem(directory: Path | None = None) -> Problem:
    """The default scene built in C (into directory, else a temporary one)."""
    scene = default()
    with tempfile.TemporaryDirectory(prefix="gyrogen-ens-") as tmp:
        backends = build_scene(scene, Path(directory or tmp), ("c",))
    comp = backends["c"]
    p = runtime_values(scene)
    x0 = np.array(scene.initial_state())
    return Problem(comp, comp.setup(p), p, x0, scene.simulate.t_end)


def members(prob: Problem, n: int, seed: int = 0) -> np.ndarray:
    """n initial states: x0 with u1..u3 scaled by uniform factors in [0.9, 1.1]."""
    x0s = np.tile(prob.x0, (n, 1))
    u = [prob.comp.manifest["states"].index(f"u{k}") for k in (1, 2, 3)]
    x0s[:, u] *= np.random.default_rng(seed).uniform(0.9, 1.1, (n, 3))
    return x0s


def finals(
    prob: Problem, x0s: np.ndarray, tol: float, threads: int | None = None, method: str = "dop853"
) -> np.ndarray:
    x, _, codes = prob.comp.integrate_batch(
        method, x0s, prob.c, 0.0, prob.t1, threads, rtol=tol, atol=tol, max_steps=MAX_STEPS
    )
    if np.any(codes != 0):
        raise RuntimeError(f"{method} failed on {np.count_nonzero(codes)} members at tol {tol:g}")
    return x


def ensemble_error(ref: np.ndarray, got: np.ndarray) -> float:
    """The worst member's scaled error."""
    return max(scaled_error(a, b) for a, b in zip(got, ref, strict=True))


def loosest(errors: Callable[[float], float], level: float) -> float:
    """The loosest tolerance of LADDER whose error is <= level."""
    for tol in LADDER:
        if errors(tol) <= level:
            return tol
    raise RuntimeError(f"no tolerance down to {LADDER[-1]:g} reaches an error of {level:g}")


def batch_us(prob: Problem, x0s: np.ndarray, tol: float, threads: int, repeats: int) -> float:
    """us per trajectory of one integrate_batch call on threads cores."""
    secs = best_time(lambda: finals(prob, x0s, tol, threads), repeats, min_total=0.05)
    return secs / len(x0s) * 1e6


def loop_us(prob: Problem, x0s: np.ndarray, tol: float, repeats: int) -> float:
    """us per trajectory of a C loop of single-trajectory calls on one core
    (what a batch replaces; gyrogen_each in the cffi glue)."""
    run = each_call(prob.comp, "dop853", x0s, prob.c, prob.t1, tol, MAX_STEPS)
    return best_time(run, repeats, min_total=0.05) / len(x0s) * 1e6


def each_call(
    comp: Compiled, method: str, x0s: np.ndarray, c: np.ndarray, t1: float, tol: float,
    max_steps: int,
) -> Callable[[], None]:  # fmt: skip
    """A C loop of method's single-trajectory calls over x0s, one after
    another on this thread (gyrogen_each in the cffi glue), each run on a
    fresh copy: what a caller without the lanes would write."""
    fn = comp.ffi.cast("gyrogen_adaptive", comp.ffi.addressof(comp.lib, comp.symbol(method)))
    cb = comp.doubles(np.ascontiguousarray(c))

    def run() -> None:
        x = np.array(x0s, order="C")  # a copy: integrated in place
        comp.lib.gyrogen_each(fn, len(x), 0.0, t1, comp.doubles(x), cb, tol, tol, max_steps)

    return run


def scaling(
    prob: Problem, sizes: Iterable[int], threads: Iterable[int], tol: float, repeats: int
) -> list[tuple[int, int, float]]:
    """(N, threads, us per trajectory) of the lane-batched dop853."""
    rows = []
    for n in sizes:
        x0s = members(prob, n)
        rows += [(n, t, batch_us(prob, x0s, tol, t, repeats)) for t in threads]
    return rows


def default_threads() -> tuple[int, ...]:
    return tuple(sorted({1, cores()}))


@dataclass(frozen=True)
class SingleRun:
    who: str
    tol: float
    error: float
    us: float


def single_runs(
    prob: Problem, numbalsoda: Callable[..., np.ndarray] | None, repeats: int
) -> list[SingleRun]:
    """The single trajectory over LADDER: gyrogen's dop853 (one cffi call,
    preallocated buffers) and numbalsoda's DOP853 with the numba RHS (timed
    inside an @njit loop, so that neither pays Python per call)."""
    comp = prob.comp
    ref = comp.integrate("dop853", prob.x0, prob.c, 0.0, prob.t1, rtol=REF_TOL, atol=REF_TOL)[0]
    fn, x = comp.function("dop853"), prob.x0.copy()
    xb, cb = comp.doubles(x), comp.doubles(np.ascontiguousarray(prob.c))
    stats = comp.ffi.new("gyrogen_stats *")
    runs = []
    for tol in LADDER:

        def gyro(tol: float = tol) -> None:
            x[:] = prob.x0
            fn(0.0, prob.t1, xb, cb, tol, tol, 0.0, MAX_STEPS, stats)

        gyro()
        runs.append(SingleRun("gyrogen", tol, scaled_error(x, ref), best_time(gyro, repeats) * 1e6))
        if numbalsoda is not None:
            got = numbalsoda(prob.x0, prob.t1, tol, 1)

            def peer(tol: float = tol) -> None:
                numbalsoda(prob.x0, prob.t1, tol, PEER_LOOPS)

            secs = best_time(peer, repeats) / PEER_LOOPS
            runs.append(SingleRun("numbalsoda", tol, scaled_error(got, ref), secs * 1e6))
    return runs


def time_at(runs: list[SingleRun], who: str, level: float) -> float:
    """The fastest of who's runs whose error is <= level (inf if none)."""
    ok = [r.us for r in runs if r.who == who and r.error <= level]
    return min(ok) if ok else math.inf
