"""`make bench-lanes`: each laned method's _batch (trajectories in SIMD
lanes) against a C loop of its single-trajectory calls over the same
states, on one core, on the default scene and on stiff_wheel.

    python benchmarks/bench_lanes.py [--scenes A,B] [--methods M,N]
        [--tolerances 1e-6,1e-9] [--n N] [--t1-fraction F] [--repeats R] [--rounds K]
        [--grid] [--events]

Each scene is built with every method it offers (its `integrators` key left
out), the lanes of those whose lanes are generated only when asked for
(radau5: scene key `lanes`), and this machine's flags. N start states: the
scene's start with its carrier rates (u1..u3, or the scene's first three
rates) scaled by uniform factors in [0.9, 1.1]. Each method integrates them from 0 to F t_end at
each tolerance (rtol = atol): `<method>_batch` with one thread
(Compiled.integrate_batch, threads=1) and `gyrogen_each` (the cffi glue's
loop of `<method>` calls, one state after another); with --grid also
`<method>_grid_batch` over 101 times against a loop of `<method>_grid`
calls; with --events `<method>_events_batch` from 0 to F t_end (the
scene's [[events]], or for a scene without any, threshold events on its
first three rates at their start values, which the motion crosses back and
forth) against a loop of `<method>_events` calls, the Taylor method's too.
Each loop is Python's over raw cffi calls, buffers made once (its own cost
a call is well under a microsecond, against tens a trajectory); with
--events the batch is its raw call too, on one OpenMP thread. Printed: us per
trajectory of each, the best of R repeats in K rounds, side by side (the
order swapped every other round), and loop / lanes (above 1: the lanes
win); the steps per trajectory (mean); the load average before and after.
Figures only: nothing here fails on time.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from gyrogen import methods
from gyrogen.analysis.bench.ensemble import each_call
from gyrogen.analysis.bench.timing import best_time
from gyrogen.analysis.simulate.engine import runtime_values
from gyrogen.analysis.sweep.spec import threshold_events
from gyrogen.runtime.compiled import Compiled
from gyrogen.runtime.scene_build import compiled, scene_sources
from gyrogen.scene import builtin_text, default, load_toml, validate

MAX_STEPS = 1_000_000
GRID = 101
"""The output grid's times (`--grid`): t1 / 100 apart."""
STEPPED = [m.name for m in methods.METHODS.values() if m.lanes and (m.pair or m.implicit)]
"""The laned methods with the adaptive signature (the Taylor method's takes its order too)."""
CAPACITY = 1000
"""A trajectory's event log (`--events`): room for every crossing of the run."""


def load_average() -> str:
    one, five, fifteen = os.getloadavg()
    return (
        f"load average {one:.2f}, {five:.2f}, {fifteen:.2f} (1, 5, 15 min), {os.cpu_count()} cpus"
    )


def starts(comp: Compiled, x0: np.ndarray, n: int) -> np.ndarray:
    """n states: x0 with its first three rates scaled in [0.9, 1.1]."""
    names = comp.manifest["states"]
    rates = [names.index(s) for s in names if s.startswith("u")][:3]
    x0s = np.tile(x0, (n, 1))
    x0s[:, rates] *= np.random.default_rng(0).uniform(0.9, 1.1, (n, len(rates)))
    return x0s


def contenders(
    comp: Compiled, method: str, x0s: np.ndarray, c: np.ndarray, t1: float, tol: float
) -> dict[str, Callable[[], Any]]:
    """The batch on one thread and the loop of single calls (each on a fresh copy)."""

    def lanes() -> None:
        comp.integrate_batch(method, x0s, c, 0.0, t1, 1, rtol=tol, atol=tol, max_steps=MAX_STEPS)

    return {"lanes": lanes, "loop": each_call(comp, method, x0s, c, t1, tol, MAX_STEPS)}


def grid_contenders(
    comp: Compiled, method: str, x0s: np.ndarray, c: np.ndarray, t1: float, tol: float
) -> dict[str, Callable[[], Any]]:
    """The same over an output grid of GRID times: _grid_batch on one thread,
    and a Python loop of raw _grid calls (cffi, buffers made once: its own
    cost a call is well under a microsecond, against tens a trajectory)."""
    times = np.linspace(0.0, t1, GRID)
    grid = comp.function(f"{method}_grid")
    ts, cb = comp.doubles(times), comp.doubles(np.ascontiguousarray(c))
    out = np.empty((len(x0s), GRID, comp.nx))
    rows = [comp.doubles(out[k]) for k in range(len(x0s))]
    x = np.array(x0s, order="C")
    xs = [comp.doubles(x[k]) for k in range(len(x0s))]
    null = comp.ffi.NULL

    def lanes() -> None:
        comp.integrate_grid_batch(method, x0s, c, times, 1, rtol=tol, atol=tol, max_steps=MAX_STEPS)

    def loop() -> None:
        x[:] = x0s
        for k in range(len(x0s)):
            grid(GRID, ts, xs[k], cb, tol, tol, 0.0, MAX_STEPS, rows[k], null)

    return {"lanes": lanes, "loop": loop}


def events_contenders(
    comp: Compiled, method: str, x0s: np.ndarray, c: np.ndarray, t1: float, tol: float
) -> dict[str, Callable[[], Any]]:
    """_events_batch from 0 to t1 (its raw call, one OpenMP thread), and a
    Python loop of raw _events calls over the same states and buffers."""
    n, nx, ffi = len(x0s), comp.nx, comp.ffi
    times = np.array([0.0, t1])
    x = np.array(x0s, order="C")
    out = np.empty((n, len(times), nx))
    log_t, log_k = np.empty((n, CAPACITY)), np.empty((n, CAPACITY), dtype=np.intc)
    log_x, nlog = np.empty((n, CAPACITY, nx)), np.empty(n, dtype=np.int_)
    b = ffi.from_buffer
    ts, cb, xb, ob = b("double[]", times), comp.doubles(np.ascontiguousarray(c)), \
        b("double[]", x), b("double[]", out)  # fmt: skip
    lt, lk, lx, nl = (b("double[]", log_t), b("int[]", log_k), b("double[]", log_x),
                      b("long[]", nlog))  # fmt: skip
    batch, one, null = (
        comp.function(f"{method}_events_batch"),
        comp.function(f"{method}_events"),
        ffi.NULL,
    )
    rows = [(b("double[]", x[k]), b("double[]", out[k]), b("double[]", log_t[k]),
             b("int[]", log_k[k]), b("double[]", log_x[k]), ffi.cast("long *", nl) + k)
            for k in range(n)]  # fmt: skip

    def lanes() -> None:
        x[:] = x0s
        comp.lib.gyrogen_threads(1)
        batch(n, 2, ts, xb, cb, tol, tol, 0.0, MAX_STEPS, ob, CAPACITY, lt, lk, lx, nl, null, null)

    def loop() -> None:
        x[:] = x0s
        for xk, ok, tk, kk, lxk, nk in rows:
            one(2, ts, xk, cb, tol, tol, 0.0, MAX_STEPS, ok, CAPACITY, tk, kk, lxk, nk, null)

    return {"lanes": lanes, "loop": loop}


def located(
    comp: Compiled, method: str, x0s: np.ndarray, c: np.ndarray, t1: float, tol: float
) -> str:
    """What a trajectory's _events call did (mean over x0s): its steps and
    the crossings it logged."""
    _, logs, stats, _ = comp.integrate_events_batch(
        method, x0s, c, np.array([0.0, t1]), 1, rtol=tol, atol=tol, max_steps=MAX_STEPS,
        capacity=CAPACITY,
    )  # fmt: skip
    steps = np.mean(stats["accepted"] + stats["rejected"])
    return f"  (events: {steps:.0f} steps, {np.mean(logs.counts):.1f} crossings)"


def watched(data: dict[str, Any]) -> None:
    """A scene without [[events]] gets threshold events on its first three
    rates at their start values (`--events`)."""
    if data.get("events"):
        return
    scene = validate(dict(data), "bench")
    rates = [s for s in scene.states if s.startswith("u")][:3]
    start = dict(zip(scene.states, scene.initial_state(), strict=True))
    data["events"] = [{"name": e.name, "expr": e.expr}
                      for e in threshold_events({u: start[u] for u in rates})]  # fmt: skip


def timed(calls: dict[str, Callable[[], Any]], repeats: int, rounds: int) -> dict[str, float]:
    """Each call's best time, side by side: the order swapped every other round."""
    best = dict.fromkeys(calls, math.inf)
    for k in range(rounds):
        for who in calls if k % 2 == 0 else list(calls)[::-1]:
            best[who] = min(best[who], best_time(calls[who], repeats, clock=time.thread_time))
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=f"{default().name},stiff_wheel")
    ap.add_argument("--methods", help="default: the laned methods (--events: and taylor)")
    ap.add_argument("--tolerances", default="1e-6,1e-9")
    ap.add_argument("--n", type=int, default=64)
    ap.add_argument("--t1-fraction", type=float, default=0.1)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--grid", action="store_true", help=f"_grid_batch over {GRID} times too")
    ap.add_argument("--events", action="store_true", help="_events_batch too (the Taylor method's)")
    args = ap.parse_args()
    chosen = args.methods or ",".join(STEPPED + ["taylor"] * args.events)
    print(f"before: {load_average()}")
    print(f"{args.n} trajectories, one core, best of {args.repeats} x {args.rounds} rounds "
          "(thread CPU time); loop / lanes above 1: the lanes win")  # fmt: skip
    print(f"{'scene':<12} {'method':<14} {'tol':>6} {'steps':>8} {'lanes us':>10} "
          f"{'loop us':>10} {'loop/lanes':>10}")  # fmt: skip
    for name in args.scenes.split(","):
        data = load_toml(builtin_text(name), name)
        data.pop("integrators", None)
        data["lanes"] = [n for n, m in methods.METHODS.items() if m.lanes_asked]
        if args.events:
            watched(data)
        scene = validate(data, f"{name} (built-in)")
        comp = compiled(scene_sources(scene))
        c = comp.setup(runtime_values(scene))
        x0s = starts(comp, np.array(scene.initial_state()), args.n)
        t1 = scene.simulate.t_end * args.t1_fraction
        for method in chosen.split(","):
            if method not in comp.manifest["integrators"]:
                continue
            for tol in (float(t) for t in args.tolerances.split(",")):
                _, stats, codes = comp.integrate_batch(
                    method, x0s, c, 0.0, t1, 1, rtol=tol, atol=tol, max_steps=MAX_STEPS
                )
                steps = float(np.mean(stats["accepted"] + stats["rejected"]))
                bad = f"  ({np.count_nonzero(codes)} failed)" if np.any(codes) else ""
                kinds = [("", contenders)] * (method in STEPPED)
                kinds += [("_grid", grid_contenders)] * (args.grid and method in STEPPED)
                kinds += [("_events", events_contenders)] * args.events
                for suffix, make in kinds:
                    us = timed(make(comp, method, x0s, c, t1, tol), args.repeats, args.rounds)
                    us = {who: secs / args.n * 1e6 for who, secs in us.items()}
                    logged = located(comp, method, x0s, c, t1, tol) if suffix == "_events" else ""
                    print(f"{name:<12} {method + suffix:<14} {tol:>6.0e} {steps:>8.0f} "
                          f"{us['lanes']:>10.1f} {us['loop']:>10.1f} "
                          f"{us['loop'] / us['lanes']:>10.2f}{bad}{logged}")  # fmt: skip
    print(f"after: {load_average()}")


if __name__ == "__main__":
    main()
