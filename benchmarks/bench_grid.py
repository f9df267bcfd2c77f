"""`make bench-grid`: what an output grid costs against the end point alone,
and against restarting the integrator at every grid time, in C.

    python benchmarks/bench_grid.py [--t1 T] [--points N] [--tol TOL] [--repeats R] [--rounds K]
                                    [--states S]

The default scene, every adaptive method, rtol = atol = TOL, from 0 to T.
Three raw cffi calls on buffers made once, the state reset from the
scene's start before each: `_integrate` from 0 to T (the end point),
`_grid` over N + 1 equally spaced times (one integration, the states read
from the method's dense output), and N `_integrate` calls, one per interval,
each starting where the last ended (a grid without `_grid`). Each
figure is the best of R repeats of a loop of ~20 ms, in K rounds run side by
side, timed by the thread's CPU time (a loaded machine still times the calls
themselves; the load average is printed before and after). The errors, each
the largest over the states against dop853 at 1e-14 restarted per interval:
the grid's, runs from 0 stopped at each grid time ("stop err"), and the end
point's. Then a batch of S start states (the scene's, each rate scaled by a
draw from [0.5, 1.5]) on one thread: `_batch` to T against `_grid_batch`
over 21 and over N + 1 times (in SIMD lanes for the methods whose `_batch`
is).

Then (`--heyoka`, with heyoka installed: the `bench` extra) the grid
against heyoka's `propagate_grid` over the same N + 1 times, read at equal
error: taylor and dop853's `_grid` (raw cffi calls) and heyoka's
`taylor_adaptive.propagate_grid` (one Python call) at each tolerance of a
ladder, the error the largest over every grid time and state of
|x - ref| / (1 + |ref|) against heyoka's real128 integrator at 1e-32 (checked
against a second run at 1e-28), each contender's time read along its
work-precision front by log-log interpolation at equal error (no
extrapolation), and heyoka's own propagate_grid / propagate_until at each
tolerance beside it (the issue's anchor: 12.6 at 1e-10). The same in
batch (`--heyoka-states` S, default 16): `_grid_batch` over S start states
against heyoka's `taylor_adaptive_batch.propagate_grid` at its recommended
SIMD width, a Python loop over its batches, one thread each, the error the
largest over every state, grid time and start against real128 grids.
"""

from __future__ import annotations

import argparse
import itertools
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
from gyrogen.runtime.compiled import Compiled
from gyrogen.runtime.scene_build import build_scene
from gyrogen.scene import default


def load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min), {os.cpu_count()} cpus"


def contenders(
    comp: Compiled, method: str, x0: np.ndarray, c: np.ndarray, times: np.ndarray, tol: float
) -> dict[str, Callable[[], Any]]:
    """The end point, the grid and the restarted calls of method."""
    ffi = comp.ffi
    x = x0.copy()
    out = np.zeros((times.size, comp.nx))
    xb, cb, ob = ffi.from_buffer("double[]", x), comp.doubles(c), ffi.from_buffer("double[]", out)
    tb = ffi.from_buffer("double[]", times)
    stats = ffi.new("gyrogen_stats *")
    fn, grid = comp.function(method), comp.function(f"{method}_grid")
    t1, ends = float(times[-1]), [float(t) for t in times]

    def end() -> Any:
        x[:] = x0
        return fn(0.0, t1, xb, cb, tol, tol, 0.0, MAX_STEPS, stats)

    def on_grid() -> Any:
        x[:] = x0
        return grid(times.size, tb, xb, cb, tol, tol, 0.0, MAX_STEPS, ob, stats)

    def restarted() -> Any:
        x[:] = x0
        for a, b in itertools.pairwise(ends):
            fn(a, b, xb, cb, tol, tol, 0.0, MAX_STEPS, stats)

    return {"end point": end, "grid": on_grid, "restarted": restarted}


def batches(
    comp: Compiled, method: str, x0s: np.ndarray, c: np.ndarray, times: np.ndarray, tol: float
) -> dict[str, Callable[[], Any]]:
    """method's _batch to the end, and its _grid_batch over 21 times and
    over times, on buffers made once (x reset before each call)."""
    ffi, n = comp.ffi, len(x0s)
    x = x0s.copy()
    xb, cb = ffi.from_buffer("double[]", x), comp.doubles(c)
    batch, grid = comp.function(f"{method}_batch"), comp.function(f"{method}_grid_batch")
    t1 = float(times[-1])

    def plain() -> Any:
        x[:] = x0s
        return batch(n, 0.0, t1, xb, cb, tol, tol, 0.0, MAX_STEPS, ffi.NULL, ffi.NULL)

    def on_grid(ts: np.ndarray) -> Callable[[], Any]:
        out = np.zeros((n, ts.size, comp.nx))
        tb, ob = ffi.from_buffer("double[]", ts), ffi.from_buffer("double[]", out)

        def run() -> Any:
            x[:] = x0s
            return grid(n, ts.size, tb, xb, cb, tol, tol, 0.0, MAX_STEPS, ob, ffi.NULL, ffi.NULL)

        return run

    few = np.linspace(0.0, t1, 21)
    return {"batch": plain, "grid 21": on_grid(few), f"grid {times.size}": on_grid(times)}


def batch_table(
    comp: Compiled, x0: np.ndarray, c: np.ndarray, times: np.ndarray, args: Any
) -> None:
    """_batch against _grid_batch for every adaptive method, one thread."""
    x0s = starts(comp, x0, args.states)
    comp.lib.gyrogen_threads(1)
    many = f"grid {times.size}"
    print(f"\n{args.states} states, one thread: _batch against _grid_batch")
    print(f"{'method':<8} {'batch us':>10} {'grid 21 us':>11} {many + ' us':>13} "
          f"{'21/batch':>9} {str(times.size) + '/batch':>11}")  # fmt: skip
    for method in methods.ADAPTIVE:
        runs = batches(comp, method, x0s, c, times, args.tol)
        best = dict.fromkeys(runs, np.inf)
        for _ in range(args.rounds):
            for name, fn in runs.items():
                best[name] = min(
                    best[name], best_time(fn, args.repeats, clock=time.thread_time) * 1e6
                )
        b, f, m = best["batch"], best["grid 21"], best[many]
        print(f"{method:<8} {b:10.1f} {f:11.1f} {m:13.1f} {f / b:9.2f} {m / b:11.2f}")


def errors(
    comp: Compiled, method: str, x0: np.ndarray, c: np.ndarray, times: np.ndarray, tol: float
) -> tuple[float, float, float]:
    """The grid's largest error, the largest of runs from 0 stopped at each
    grid time, and the end point's, against dop853 at 1e-14."""
    ref, x = [x0.copy()], x0.copy()
    for a, b in itertools.pairwise(times):
        x, _, code = comp.integrate("dop853", x, c, float(a), float(b), rtol=1e-14, atol=1e-14)
        assert code == 0
        ref.append(x)
    states, _, code = comp.integrate_grid(method, x0, c, times, rtol=tol, atol=tol)
    single = [comp.integrate(method, x0, c, 0.0, float(t), rtol=tol, atol=tol) for t in times[1:]]
    assert code == 0 and all(k == 0 for _, _, k in single), code
    stopped = np.array([x0, *(x for x, _, _ in single)])
    grid_err = float(np.max(np.abs(states - np.array(ref))))
    return (
        grid_err,
        float(np.max(np.abs(stopped - np.array(ref)))),
        float(np.max(np.abs(stopped[-1] - ref[-1]))),
    )


LADDER = (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12, 1e-13, 1e-14)
"""The tolerances of the heyoka comparison (rtol = atol; heyoka's one tol)."""
LEVELS = (1e-6, 1e-8, 1e-10, 1e-12)
"""The error levels the fronts are read at."""


def grid_reference(hy: Any, peer: Any, x0: np.ndarray, c: np.ndarray, times: np.ndarray,
                   tol: float) -> np.ndarray:  # fmt: skip
    """The states at times by heyoka's real128 integrator at tol (compact
    mode), from the double x0, rounded to double."""
    q = hy.real128
    ta = hy.taylor_adaptive(
        peer.pairs, np.array([q(float(v)) for v in x0]), tol=q(tol), fp_type=q,
        compact_mode=True, pars=np.array([q(float(v)) for v in c[: peer.npars]]),
    )  # fmt: skip
    out = ta.propagate_grid(np.array([q(float(t)) for t in times]))
    if out[0] != hy.taylor_outcome.time_limit:
        raise RuntimeError(f"heyoka's real128 grid stopped: {out[0]}")
    return np.array([[float(v) for v in row] for row in out[-1]])


def starts(comp: Compiled, x0: np.ndarray, n: int) -> np.ndarray:
    """n start states: x0 with each body and wheel rate scaled by a draw from [0.5, 1.5]."""
    rates = [i for i, name in enumerate(comp.manifest["states"]) if name.startswith("u")]
    x0s = np.tile(x0, (n, 1))
    x0s[:, rates] *= np.random.default_rng(1).uniform(0.5, 1.5, (n, 1))
    return x0s


def read(runs: dict[str, list[Any]], title: str) -> None:
    """Each contender's time at LEVELS along its front, and heyoka's over ours."""
    from gyrogen.analysis.bench.workprec import seconds_at

    print(f"\n{title}, us:")
    print(f"{'error':>8} {'taylor':>10} {'dop853':>10} {'heyoka':>10} "
          f"{'heyoka/taylor':>14} {'heyoka/dop853':>14}")  # fmt: skip
    for level in LEVELS:
        at = {name: seconds_at(rs, level) for name, rs in runs.items()}
        cells = [f"{v * 1e6:10.1f}" if v else f"{'-':>10}" for v in at.values()]
        ratio = [f"{at['heyoka'] / at[m]:14.2f}" if at["heyoka"] and at[m] else f"{'-':>14}"
                 for m in ("taylor", "dop853")]  # fmt: skip
        print(f"{level:8.0e} {' '.join(cells)} {' '.join(ratio)}")


def heyoka_batch(comp: Compiled, peer: Any, x0: np.ndarray, c: np.ndarray, times: np.ndarray,
                 args: Any) -> None:  # fmt: skip
    """_grid_batch against heyoka's taylor_adaptive_batch.propagate_grid."""
    from gyrogen.analysis.bench import heyoka_peer
    from gyrogen.analysis.bench.workprec import Run

    hy, n = peer.hy, args.heyoka_states
    x0s = starts(comp, x0, n)
    refs = np.array([grid_reference(hy, peer, x, c, times, heyoka_peer.QUAD_TOL) for x in x0s])
    comp.lib.gyrogen_threads(1)
    runs: dict[str, list[Run]] = {"taylor": [], "dop853": [], "heyoka": []}
    for tol in LADDER:
        for method in ("taylor", "dop853"):
            if tol < methods.get(method).rtol_floor:
                continue
            run = batches(comp, method, x0s, c, times, tol)[f"grid {times.size}"]
            seconds = min(best_time(run, args.repeats, clock=time.thread_time)
                          for _ in range(args.rounds))  # fmt: skip
            states, _, codes = comp.integrate_grid_batch(method, x0s, c, times, rtol=tol,
                                                         atol=tol)  # fmt: skip
            err = float(np.max(np.abs(states - refs) / (1 + np.abs(refs))))
            ok = "ok" if not np.any(codes) else "failed"
            runs[method].append(Run(method, "c", tol, err, seconds, 0, ok))
        batch = heyoka_peer.Batch(peer, x0, c, float(times[-1]), tol)
        w, ta = batch.width, batch.ta
        pad = -n % w
        xs = np.concatenate([x0s, np.repeat(x0s[-1:], pad, axis=0)]) if pad else x0s
        grid = np.ascontiguousarray(np.repeat(times[:, None], w, axis=1))
        out = np.empty((len(xs), times.size, comp.nx))

        def on_grid(ta: Any = ta, w: int = w, xs: np.ndarray = xs, grid: np.ndarray = grid,
                    out: np.ndarray | None = None) -> None:  # fmt: skip
            """Every batch over the grid (out: the states kept, outside the timing)."""
            for i in range(0, len(xs), w):
                ta.set_time(0.0)
                ta.state[:] = xs[i : i + w].T
                states = ta.propagate_grid(grid)[1]
                if out is not None:
                    out[i : i + w] = np.moveaxis(states, 2, 0)

        seconds = min(best_time(on_grid, args.repeats, clock=time.thread_time)
                      for _ in range(args.rounds))  # fmt: skip
        on_grid(out=out)
        err = float(np.max(np.abs(out[:n] - refs) / (1 + np.abs(refs))))
        runs["heyoka"].append(Run("heyoka", "llvm", tol, err, seconds, 0))
    read(runs, f"batch of {n} starts on one thread, read at equal error (heyoka's SIMD width "
               f"{hy.recommended_simd_size()})")  # fmt: skip


def heyoka_table(comp: Compiled, x0: np.ndarray, c: np.ndarray, times: np.ndarray,
                 args: Any) -> None:  # fmt: skip
    """taylor and dop853's _grid against heyoka's propagate_grid, at equal error."""
    from gyrogen.analysis.bench import heyoka_peer
    from gyrogen.analysis.bench.workprec import Run
    from gyrogen.codegen.generate import unit_of

    hy = heyoka_peer.module()
    if hy is None:
        print("\nheyoka: not installed (the bench extra); no comparison")
        return
    heyoka_peer.one_thread()
    peer = heyoka_peer.system(hy, unit_of(default()))
    heyoka_peer.check(peer, comp.rhs, c, x0, print)
    ref = grid_reference(hy, peer, x0, c, times, heyoka_peer.QUAD_TOL)
    check = grid_reference(hy, peer, x0, c, times, heyoka_peer.QUAD_CHECK_TOL)
    print(f"reference: heyoka {hy.__version__} real128 at {heyoka_peer.QUAD_TOL:g}, "
          f"{np.max(np.abs(check - ref) / (1 + np.abs(ref))):.1e} from a run at "
          f"{heyoka_peer.QUAD_CHECK_TOL:g}")  # fmt: skip
    runs: dict[str, list[Run]] = {"taylor": [], "dop853": [], "heyoka": []}
    anchor: list[str] = []
    t1 = float(times[-1])
    for tol in LADDER:
        for method in ("taylor", "dop853"):
            if tol < methods.get(method).rtol_floor:
                continue
            grid = contenders(comp, method, x0, c, times, tol)["grid"]
            seconds = min(best_time(grid, args.repeats, clock=time.thread_time)
                          for _ in range(args.rounds))  # fmt: skip
            states, _, code = comp.integrate_grid(method, x0, c, times, rtol=tol, atol=tol)
            err = float(np.max(np.abs(states - ref) / (1 + np.abs(ref))))
            runs[method].append(Run(method, "c", tol, err, seconds, 0, "ok" if code == 0 else
                                    f"code {code}"))  # fmt: skip
        ta = heyoka_peer.Scalar(peer, x0, c, t1, tol).ta

        def on_grid(ta: Any = ta) -> Any:
            ta.time = 0.0
            ta.state[:] = x0
            return ta.propagate_grid(times)

        def until(ta: Any = ta) -> Any:
            ta.time = 0.0
            ta.state[:] = x0
            return ta.propagate_until(t1)

        grid_s = min(best_time(on_grid, args.repeats, clock=time.thread_time)
                     for _ in range(args.rounds))  # fmt: skip
        until_s = min(best_time(until, args.repeats, clock=time.thread_time)
                      for _ in range(args.rounds))  # fmt: skip
        err = float(np.max(np.abs(on_grid()[-1] - ref) / (1 + np.abs(ref))))
        runs["heyoka"].append(Run("heyoka", "llvm", tol, err, grid_s, 0))
        anchor.append(f"{tol:g}: {grid_s / until_s:.1f}")
    print(
        f"\nheyoka's propagate_grid / propagate_until over {times.size} times, by tol: "
        + ", ".join(anchor)
    )
    read(runs, "one trajectory on one thread, read at equal error (error over every grid time "
               "and state)")  # fmt: skip
    heyoka_batch(comp, peer, x0, c, times, args)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--t1", type=float, default=10.0)
    ap.add_argument("--points", type=int, default=1000)
    ap.add_argument("--tol", type=float, default=1e-10)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--states", type=int, default=500)
    ap.add_argument("--heyoka", action="store_true", help="and against heyoka's propagate_grid")
    ap.add_argument("--heyoka-states", type=int, default=16, help="the batch against heyoka's")
    args = ap.parse_args()
    scene = default()
    with tempfile.TemporaryDirectory(prefix="gyrogen-grid-") as tmp:
        built = build_scene(scene, Path(tmp), ("c",))
    comp = built["c"]
    c = comp.setup(runtime_values(scene))
    x0 = np.array(scene.initial_state())
    times = np.linspace(0.0, args.t1, args.points + 1)
    print(f"{scene.name}, 0 to {args.t1:g} s, {args.points + 1} grid times, tol {args.tol:g}")
    print(f"before: {load()}")
    print(f"\n{'method':<8} {'end us':>10} {'grid us':>10} {'restart us':>11} "
          f"{'grid/end':>9} {'restart/end':>12} {'grid err':>10} {'stop err':>10} "
          f"{'end err':>10}")  # fmt: skip
    for method in methods.ADAPTIVE:
        runs = contenders(comp, method, x0, c, times, args.tol)
        best = dict.fromkeys(runs, np.inf)
        for _ in range(args.rounds):
            for name, fn in runs.items():
                best[name] = min(
                    best[name], best_time(fn, args.repeats, clock=time.thread_time) * 1e6
                )
        grid_err, stop_err, end_err = errors(comp, method, x0, c, times, args.tol)
        e, g, r = best["end point"], best["grid"], best["restarted"]
        print(f"{method:<8} {e:10.1f} {g:10.1f} {r:11.1f} {g / e:9.2f} {r / e:12.1f} "
              f"{grid_err:10.2e} {stop_err:10.2e} {end_err:10.2e}")  # fmt: skip
    batch_table(comp, x0, c, times, args)
    if args.heyoka:
        heyoka_table(comp, x0, c, times, args)
    print(f"\nafter: {load()}")


if __name__ == "__main__":
    main()
