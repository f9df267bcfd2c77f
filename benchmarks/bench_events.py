"""`make bench-events`: what locating events costs over the plain run, in C.

    python benchmarks/bench_events.py [--t1 T] [--tol TOL] [--repeats R] [--rounds K]
        [--write DIR | --against DIR]

The default scene with three non-terminal events, as a GNC engineer would
watch it: the nutation angle, the wheel rate u4 and the angle q2 each
crossing a threshold (set at the middle of the range each sweeps over the
run, so that all of them fire). Per adaptive method, rtol = atol = TOL,
from 0 to T: the raw cffi `_integrate` call (the end point) against the
`_events` call over the same interval (the events located on the dense
output, logged), the state reset before each. Each figure is the best of R
repeats of a loop of ~20 ms, in K rounds run side by side, timed by the
thread's CPU time; the load average is printed before and after. Also: how
many crossings each method logged, and the steps of each call.

--write DIR renders the scene's sources into DIR and stops (with the gyrogen
on PYTHONPATH: another tree's generator renders its own); --against DIR
builds DIR's sources by this tree's build path and times them as "old",
in the same rounds, each method's old row under its new one, and says
whether both logged the same times.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from gyrogen import methods
from gyrogen.abi import MAX_STEPS
from gyrogen.analysis.bench.timing import best_time
from gyrogen.analysis.simulate.engine import runtime_values
from gyrogen.analysis.sweep.spec import threshold_events
from gyrogen.runtime import build
from gyrogen.runtime.compiled import Compiled
from gyrogen.runtime.scene_build import build_scene, write_scene
from gyrogen.scene import Scene, default
from gyrogen.scene.events import Event

CAPACITY = 10_000


def load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min), {os.cpu_count()} cpus"


def watched(scene: Scene, t1: float, tol: float) -> Scene:
    """The scene with its three events, each threshold at the middle of
    what its quantity sweeps over 0..t1 (read from a grid of the plain
    scene's run)."""
    with tempfile.TemporaryDirectory(prefix="gyrogen-events-") as tmp:
        built = build_scene(scene, Path(tmp), ("c",))
    comp = built["c"]
    c = comp.setup(runtime_values(scene))
    times = np.linspace(0.0, t1, 2001)
    xs, _, code = comp.integrate_grid("dop853", np.array(scene.initial_state()), c, times,
                                      rtol=tol, atol=tol)  # fmt: skip
    assert code == 0, code
    values = {**scene.folded(), **dict(zip(scene.runtime, runtime_values(scene), strict=True))}
    lumped = {n: values[n] for n in ("m_a", "m_b", "I11", "I22", "I33", "I13", "I", "l1", "l3")}
    from gyrogen.physics import body_momentum, lumped_inertias

    u = [xs[:, scene.states.index(f"u{i}")] for i in range(1, 5)]
    h = body_momentum(lumped_inertias(*lumped.values()), values["J"], *u)
    nutation = np.arctan2(np.hypot(h[0], h[2]), h[1])
    q2 = xs[:, scene.states.index("q2")]
    mid = {q: float((v.min() + v.max()) / 2) for q, v in
           (("nutation", nutation), ("u4", u[3]), ("q2", q2))}  # fmt: skip
    names = {"nutation": "nutation", "u4": "wheel_rate", "q2": "q2_crossing"}
    events = [Event(name=names[q], expr=e.expr) for q, e in
              zip(mid, threshold_events(mid), strict=True)]  # fmt: skip
    return Scene.model_validate({**scene.model_dump(), "events": events})


def contenders(
    comp: Compiled, method: str, x0: np.ndarray, c: np.ndarray, t1: float, tol: float
) -> dict[str, Callable[[], Any]]:
    ffi = comp.ffi
    x = x0.copy()
    times = np.array([0.0, t1])
    out = np.zeros((2, comp.nx))
    log_t, log_k = np.zeros(CAPACITY), np.zeros(CAPACITY, dtype=np.intc)
    log_x = np.zeros((CAPACITY, comp.nx))
    b = ffi.from_buffer
    xb, cb, ob, tb = b("double[]", x), comp.doubles(c), b("double[]", out), b("double[]", times)
    lt, lk, lx = b("double[]", log_t), b("int[]", log_k), b("double[]", log_x)
    nlog, stats = ffi.new("long *"), ffi.new("gyrogen_stats *")
    fn, events = comp.function(method), comp.function(f"{method}_events")

    def plain() -> Any:
        x[:] = x0
        return fn(0.0, t1, xb, cb, tol, tol, 0.0, MAX_STEPS, stats)

    def located() -> Any:
        x[:] = x0
        return events(2, tb, xb, cb, tol, tol, 0.0, MAX_STEPS, ob, CAPACITY, lt, lk, lx, nlog,
                      stats)  # fmt: skip

    return {"plain": plain, "events": located}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--t1", type=float, default=10.0)
    ap.add_argument("--tol", type=float, default=1e-10)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=3)
    which = ap.add_mutually_exclusive_group()
    which.add_argument("--write", metavar="DIR", type=Path)
    which.add_argument("--against", metavar="DIR", type=Path)
    args = ap.parse_args()
    scene = watched(default(), args.t1, args.tol)
    if args.write:
        write_scene(scene, args.write)
        print(f"{scene.name} with its three events: sources in {args.write}")
        return
    with tempfile.TemporaryDirectory(prefix="gyrogen-events-") as tmp:
        built = {"new": build_scene(scene, Path(tmp), ("c",))["c"]}
    if args.against:
        built["old"] = build.build(args.against, "c")
    c = built["new"].setup(runtime_values(scene))
    x0 = np.array(scene.initial_state())
    print(f"{scene.name}, 0 to {args.t1:g} s, tol {args.tol:g}, three non-terminal events:")
    for e in scene.events:
        print(f"  {e.name}: {e.expr[:90]}{'...' if len(e.expr) > 90 else ''}")
    if args.against:
        print(f"old: the sources in {args.against}, built by this tree's build path")
    print(f"before: {load()}")
    print(f"\n{'method':<8} {'plain us':>10} {'events us':>10} {'events/plain':>13} "
          f"{'crossings':>10} {'steps':>6} {'rhs_calls':>10}")  # fmt: skip
    for method in methods.ADAPTIVE:
        runs = {
            (k, name): f
            for k, comp in built.items()
            for name, f in contenders(comp, method, x0, c, args.t1, args.tol).items()
        }
        best = dict.fromkeys(runs, np.inf)
        for _ in range(args.rounds):
            for key, fn in runs.items():
                best[key] = min(
                    best[key], best_time(fn, args.repeats, clock=time.thread_time) * 1e6
                )
        times = []
        for k, comp in built.items():
            _, log, stats, code = comp.integrate_events(
                method, x0, c, np.array([0.0, args.t1]), rtol=args.tol, atol=args.tol
            )
            assert code == 0, code
            times.append(log.times)
            p, e = best[(k, "plain")], best[(k, "events")]
            label = method if k == "new" else f"  {k}"
            print(f"{label:<8} {p:10.1f} {e:10.1f} {e / p:13.2f} {len(log):10d} "
                  f"{stats['accepted']:6d} {stats['rhs_calls']:10d}")  # fmt: skip
        if args.against:
            same = np.array_equal(times[0], times[1])
            print(f"  {'the same event times' if same else 'event times differ'}")
    print(f"\nafter: {load()}")


if __name__ == "__main__":
    main()
