"""`make bench-call`: what Compiled.integrate and integrate_batch cost on top
of the raw cffi call, in microseconds.

    python benchmarks/bench_call.py [--repeats R] [--rounds K]

The default scene built in C; dop853 and rk4 (one adaptive and one
fixed-step method). For each: t1 = t0 (the call and nothing else) and a
short integration (0.01 s). The raw call is the C function through cffi on
buffers made once: alone ("bare", at t1 = t0 only: integrating on from
where it ended, its angles would grow and their sin and cos cost more),
and with the state reset from x0 before it (what a loop of integrations
from one start pays).
integrate_batch is timed on one state against its raw _batch call, on one
thread. Every figure is the best of R repeats of a loop lasting ~20 ms; the
K rounds run the contenders side by side, one after another, so that each
saw the same load (printed before and after).
"""

from __future__ import annotations

import argparse
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from gyrogen.abi import MAX_STEPS
from gyrogen.analysis.bench.timing import best_time
from gyrogen.analysis.simulate.engine import runtime_values
from gyrogen.runtime.compiled import Compiled
from gyrogen.runtime.scene_build import build_scene
from gyrogen.scene import default


def load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min), {os.cpu_count()} cpus"


def contenders(comp: Compiled, x0: np.ndarray, c: np.ndarray, method: str, t1: float
               ) -> dict[str, Callable[[], Any]]:  # fmt: skip
    """method's raw calls and its Python calls from 0 to t1."""
    ffi = comp.ffi
    x, x1 = x0.copy(), x0[None, :].copy()
    xb, x1b, cb = ffi.from_buffer("double[]", x), ffi.from_buffer("double[]", x1), comp.doubles(c)
    stats, stats1 = ffi.new("gyrogen_stats *"), ffi.new("gyrogen_stats[1]")
    code1 = ffi.new("int[1]")
    fn, batch = comp.function(method), comp.function(f"{method}_batch")
    comp.lib.gyrogen_threads(1)
    if method == "rk4":
        kw: dict[str, Any] = {"steps": 10}
        ctl: tuple[Any, ...] = ()
        head: tuple[Any, ...] = (0.0, t1, 10)
    else:
        kw = {"rtol": 1e-8, "atol": 1e-8}
        ctl = (1e-8, 1e-8, 0.0, MAX_STEPS)
        head = (0.0, t1)

    if method == "rk4":

        def bare() -> Any:
            return fn(0.0, t1, 10, xb, cb, stats)

        def reset() -> Any:
            x[:] = x0
            return fn(0.0, t1, 10, xb, cb, stats)
    else:

        def bare() -> Any:
            return fn(0.0, t1, xb, cb, 1e-8, 1e-8, 0.0, MAX_STEPS, stats)

        def reset() -> Any:
            x[:] = x0
            return fn(0.0, t1, xb, cb, 1e-8, 1e-8, 0.0, MAX_STEPS, stats)

    def bare_batch() -> Any:
        x1[0] = x0
        return batch(1, *head, x1b, cb, *ctl, stats1, code1)

    x0s = x0[None, :]
    bare_row = {"raw call, bare": bare} if t1 == 0.0 else {}  # else its state runs away
    return {
        **bare_row,
        "raw call, state reset": reset,
        "Compiled.integrate": lambda: comp.integrate(method, x0, c, 0.0, t1, **kw),
        "raw _batch call, n = 1": bare_batch,
        "Compiled.integrate_batch, n = 1": lambda: comp.integrate_batch(
            method, x0s, c, 0.0, t1, threads=1, **kw
        ),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    scene = default()
    with tempfile.TemporaryDirectory(prefix="gyrogen-call-") as tmp:
        built = build_scene(scene, Path(tmp), ("c",))
    comp = built["c"]
    c = comp.setup(runtime_values(scene))
    x0 = np.array(scene.initial_state())
    print(f"before: {load()}")
    for method in ("dop853", "rk4"):
        for t1 in (0.0, 0.01):
            runs = contenders(comp, x0, c, method, t1)
            best = dict.fromkeys(runs, np.inf)
            for _ in range(args.rounds):
                for name, fn in runs.items():
                    best[name] = min(best[name], best_time(fn, args.repeats) * 1e6)
            print(f"\n{method}, t1 = {t1:g} s (us per call, best of {args.rounds} x "
                  f"{args.repeats}):")  # fmt: skip
            for name, us in best.items():
                print(f"  {name:<34} {us:8.3f}")
            single = best["Compiled.integrate"]
            batch = best["Compiled.integrate_batch, n = 1"] - best["raw _batch call, n = 1"]
            bare_gap = f"bare call {single - best['raw call, bare']:.3f}, " if t1 == 0.0 else ""
            print(f"  integrate - {bare_gap}"
                  f"state reset and call {single - best['raw call, state reset']:.3f}; "
                  f"integrate_batch - raw _batch call {batch:.3f}")  # fmt: skip
    print(f"\nafter: {load()}")


if __name__ == "__main__":
    main()
