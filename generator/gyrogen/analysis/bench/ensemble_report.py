"""gyrogen bench-ensemble's report: the single trajectory against
numbalsoda's DOP853 at three error levels, then an ensemble of N members at
error <= 1e-8 on one core and on every core against numbalsoda's prange and
diffrax, then how the lanes scale with N. Printed, with the machine's load."""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from typing import Any

import numpy as np

from gyrogen.analysis.bench import ensemble as ens
from gyrogen.analysis.bench import ensemble_levels, peers
from gyrogen.analysis.bench.rhs import machine
from gyrogen.analysis.bench.timing import best_time
from gyrogen.analysis.bench.workprec import REF_TOL
from gyrogen.runtime.compiled import cores

Echo = Callable[[str], None]
LEVELS = (1e-6, 1e-8, 1e-10)
ENSEMBLE_LEVEL = 1e-8
CHECKED = 200
"""Members on which a peer's tolerance is chosen (all N for gyrogen)."""


def _load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min) on {cores()} cores"


def single(prob: ens.Problem, nbs: Any, repeats: int, echo: Echo) -> None:
    runs = ens.single_runs(prob, nbs[0] if nbs else None, repeats)
    echo("single trajectory, default scene, 0..10 s: us per integration at an error <= level")
    echo(f"{'error':>8} {'gyrogen dop853':>15} {'numbalsoda DOP853':>18} {'ratio':>6}")
    for level in LEVELS:
        g, b = ens.time_at(runs, "gyrogen", level), ens.time_at(runs, "numbalsoda", level)
        ratio = f"{b / g:.2f}x" if math.isfinite(b) else "-"
        theirs = f"{b:.2f}" if math.isfinite(b) else "skipped" if not nbs else "not reached"
        echo(f"{level:>8.0e} {g:>15.2f} {theirs:>18} {ratio:>6}")
    if nbs:
        echo("(numbalsoda timed inside an @njit loop: no Python per call; gyrogen through cffi)")


def _peer_tol(run: Callable[[np.ndarray, float], np.ndarray], x0s: np.ndarray, ref: np.ndarray,
              start: float) -> float:  # fmt: skip
    """The loosest ladder tolerance from start whose error on x0s is <= level."""
    ladder = [t for t in ens.LADDER if t <= start]
    for tol in ladder:
        if ens.ensemble_error(ref, run(x0s, tol)) <= ENSEMBLE_LEVEL:
            return tol
    raise RuntimeError("no tolerance reaches the error level")


def _diffrax(
    dfx: Any, solver: str, t1: float, data: tuple[np.ndarray, ...], tol: float, repeats: int,
    every: int,
) -> tuple[str, float]:  # fmt: skip
    """A diffrax solver's row: its tolerance for the error level, its time."""
    x0s, few, few_ref = data

    def run(x: np.ndarray, tl: float) -> np.ndarray:
        return np.asarray(dfx(x, t1, tl, solver))

    t = _peer_tol(run, few, few_ref, tol * 10)
    secs = best_time(lambda: run(x0s, t), repeats, min_total=0.0)
    return f"diffrax {solver} jit(vmap), {every} cores (tol {t:g})", secs / len(x0s) * 1e6


def ensemble(prob: ens.Problem, n: int, nbs: Any, dfx: Any, repeats: int, echo: Echo) -> None:
    x0s = ens.members(prob, n)
    ref = ens.finals(prob, x0s, REF_TOL)
    tol = ens.loosest(lambda t: ens.ensemble_error(ref, ens.finals(prob, x0s, t)), ENSEMBLE_LEVEL)
    every = cores()
    echo(f"ensemble: {n} members, u1..u3 +-10 %, error <= {ENSEMBLE_LEVEL:g} "
         f"(gyrogen dop853 at rtol = atol = {tol:g}); us per trajectory")  # fmt: skip
    rows = [
        ("gyrogen dop853, single-trajectory loop, 1 core", ens.loop_us(prob, x0s, tol, repeats)),
        ("gyrogen dop853_batch (lanes), 1 core", ens.batch_us(prob, x0s, tol, 1, repeats)),
        (f"gyrogen dop853_batch (lanes), {every} cores",
         ens.batch_us(prob, x0s, tol, every, repeats)),
    ]  # fmt: skip
    few, few_ref = x0s[:CHECKED], ref[:CHECKED]
    if nbs:
        many = nbs[1]
        t = _peer_tol(lambda x, tl: many(x, prob.t1, tl, every), few, few_ref, tol * 10)
        secs = best_time(lambda: many(x0s, prob.t1, t, every), repeats, min_total=0.0)
        rows.append((f"numbalsoda DOP853 prange, {every} threads (tol {t:g})", secs / n * 1e6))
    if dfx:
        for solver in ("Tsit5", "Dopri8"):
            rows.append(_diffrax(dfx, solver, prob.t1, (x0s, few, few_ref), tol, repeats, every))
    for label, us in rows:
        echo(f"  {label:<58} {us:>8.2f}")
    loop, one, all_ = rows[0][1], rows[1][1], rows[2][1]
    echo(f"lanes on 1 core vs the single-trajectory loop: {loop / one:.2f}x")
    echo(f"lanes on {every} cores: {all_:.2f} us per trajectory")
    for label, us in rows[3:]:
        echo(f"  vs {label}: {us / all_:.1f}x")


def run(
    n: int, repeats: int, peers_on: bool = True, echo: Echo = print, **kw: Any
) -> dict[str, bytes]:
    """Measure and print; the figures by file name (the fronts against heyoka)."""
    info = machine()
    echo(f"machine: {info['cpu']}; {_load()}")
    echo(f"C flags: {info['c_flags']}")
    prob = ens.problem()
    nbs = peers.numbalsoda_peer(prob.p, echo) if peers_on else None
    dfx = peers.diffrax_peer(prob.p, echo) if peers_on else None
    echo("")
    single(prob, nbs, repeats, echo)
    echo("")
    ensemble(prob, n, nbs, dfx, repeats, echo)
    figures = {}
    if peers_on:
        echo("")
        fronts = ensemble_levels.table(prob, n, repeats, echo)
        if fronts:
            figures["ensemble_fronts.png"] = ensemble_levels.figure(fronts, n)
    echo("")
    echo("lanes, us per trajectory against N and threads:")
    sizes = tuple(sorted({16, 100, 1000, n}))  # --n 16 once, not twice
    for size, threads, us in ens.scaling(prob, sizes, ens.default_threads(), 1e-9, repeats):
        echo(f"  N = {size:>6}, {threads} thread(s): {us:.2f}")
    echo(f"after: {_load()}")
    return figures
