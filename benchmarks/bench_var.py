"""`make bench-var`: what the state transition matrix costs over the plain
trajectory, per compiled method, and what measuring Phi's error does.

    python benchmarks/bench_var.py [--t1 T] [--tol TOL] [--repeats R] [--rounds K]
        [--baseline REV] [--clock cpu|wall]

The default scene with [sensitivities] wrt = ["state"] (Phi 14 x 14), built
in C twice: error = "all" (the step control measures x and Phi) and error =
"state" (x alone). For each method: the plain `integrate` from the scene's
start over [0, T] at rtol = atol = TOL, then `integrate_var` in both modes;
each figure the best of R repeats of a loop lasting ~20 ms, the K rounds
side by side, one after another, so that each saw the same load (printed
before and after). Phi's error: the largest entry of |Phi - Phi_ref|
relative to its column's largest entry, Phi_ref from taylor at 1e-15.
Then the Taylor jets' sizes (nodes, full convolutions), plain and with Phi,
64 trajectories in SIMD lanes against a loop, and (when installed)
heyoka's var_ode_sys against gyrogen's taylor.

With --baseline REV, gyrogen as of REV (methods.rev_tree: a git worktree in a
temp dir) renders the same two scenes, built by this tree's build path and
flags (the generated code's share alone); its calls run interleaved with this
tree's in the same rounds, each method's rows new and old one under the other.
--clock cpu (the default) times with the thread's CPU time, as
`make bench-methods` does (a loaded machine still times the calls
themselves); --clock wall with the wall clock.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from contextlib import nullcontext
from pathlib import Path

import numpy as np
from methods import CLOCKS, GYROGEN, rev_tree, run

from gyrogen.analysis.bench import heyoka_peer
from gyrogen.analysis.bench.timing import best_time
from gyrogen.analysis.simulate.engine import runtime_values
from gyrogen.codegen.context import make_context
from gyrogen.codegen.generate import unit_of
from gyrogen.runtime.compiled import Compiled
from gyrogen.runtime.scene_build import build_dir, build_scene
from gyrogen.scene import builtin_text, parse

Builds = dict[str, Compiled]
"""One gyrogen's two builds of the scene: by sensitivities.error."""

REFERENCE_TOL = 1e-15


def load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min), {os.cpu_count()} cpus"


def scene_text(error: str) -> str:
    return builtin_text("gyrostat") + f'\n[sensitivities]\nwrt = ["state"]\nerror = "{error}"\n'


def builds(where: Path) -> Builds:
    """The default scene with Phi, its error measured with x or not."""
    out = {}
    for error in ("all", "state"):
        built = build_scene(parse(scene_text(error), "gyrostat.toml"), where / error, ["c"])
        out[error] = built["c"]
    return out


def rev_builds(there: Path, where: Path) -> Builds:
    """builds as gyrogen in the worktree there renders them, built here."""
    env = {**os.environ, "PYTHONPATH": str(there / "generator")}
    out = {}
    for error in ("all", "state"):
        scene_file, sources = where / f"old_{error}.toml", where / f"old_{error}"
        scene_file.write_text(scene_text(error))
        cmd = [GYROGEN, "generate", str(scene_file), "--no-check", "--out", str(sources)]
        run(cmd, f"error = {error}: cannot render it", env)
        out[error] = build_dir(sources, ["c"])["c"]
    return out


def column_error(phi: np.ndarray, ref: np.ndarray) -> float:
    scale = np.abs(ref).max(axis=0)
    return float((np.abs(phi - ref).max(axis=0) / np.where(scale > 0, scale, 1.0)).max())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--t1", type=float, default=10.0)
    ap.add_argument("--tol", type=float, default=1e-10)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--baseline", metavar="REV", default="")
    ap.add_argument("--clock", choices=sorted(CLOCKS), default="cpu")
    args = ap.parse_args()
    scene = parse(builtin_text("gyrostat"), "gyrostat.toml")
    x0, p = np.array(scene.initial_state()), runtime_values(scene)
    with (
        tempfile.TemporaryDirectory() as tmp,
        rev_tree(args.baseline) if args.baseline else nullcontext() as there,
    ):
        trees = {"new": builds(Path(tmp))}
        if there is not None:
            trees["old"] = rev_builds(there, Path(tmp))
    every = trees["new"]["all"]
    c = every.setup(p)
    methods = [m for m in every.manifest["variational"]["integrators"] if m != "rk4"]
    ref = every.integrate_var("taylor", x0, c, 0.0, args.t1, rtol=REFERENCE_TOL,
                              atol=REFERENCE_TOL)[1]  # fmt: skip
    print(f"Phi 14 x 14 on the default scene over {args.t1:g} s, rtol = atol = {args.tol:g}")
    if args.baseline:
        print(f"old: gyrogen as of {args.baseline}, built by this tree's build path and flags")
    print(f"before: {load()}")
    best = timed(trees, methods, x0, c, args)
    print(f"after:  {load()}")
    table(trees, methods, best, x0, c, ref, args)
    jets()
    lanes(every, x0, c, args)
    heyoka(every, x0, c, ref, args)


def timed(
    trees: dict[str, Builds], methods: list[str], x0: np.ndarray, c: np.ndarray,
    args: argparse.Namespace,
) -> dict[tuple[str, str, str], float]:  # fmt: skip
    """Best time per (tree, method, run): the plain integrate and
    integrate_var with error "all" and "state", every tree's side by side."""
    tol = {"rtol": args.tol, "atol": args.tol}
    best: dict[tuple[str, str, str], float] = {}
    for _ in range(args.rounds):
        for m in methods:
            for name, built in trees.items():
                calls = {
                    "plain": lambda m=m, b=built: b["all"].integrate(m, x0, c, 0.0, args.t1, **tol),
                    **{
                        key: lambda m=m, b=built[key]: b.integrate_var(
                            m, x0, c, 0.0, args.t1, **tol
                        )
                        for key in ("all", "state")
                    },
                }
                for key, call in calls.items():
                    t = best_time(call, args.repeats, clock=CLOCKS[args.clock])
                    best[(name, m, key)] = min(best.get((name, m, key), np.inf), t)
    return best


def table(
    trees: dict[str, Builds], methods: list[str], best: dict[tuple[str, str, str], float],
    x0: np.ndarray, c: np.ndarray, ref: np.ndarray, args: argparse.Namespace,
) -> None:  # fmt: skip
    tol = {"rtol": args.tol, "atol": args.tol}
    tag = len(trees) > 1
    head = f"{'method':8} {'tree ' if tag else ''}{'plain us':>10} {'Phi/all us':>11}"
    head += f" {'ratio':>6} {'steps':>11} {'err Phi':>8}"
    print(head + f" {'Phi/state us':>13} {'ratio':>6} {'steps':>6} {'err Phi':>8}")
    for m in methods:
        for name, built in trees.items():
            every = built["all"]
            plain = best[(name, m, "plain")]
            steps_plain = every.integrate(m, x0, c, 0.0, args.t1, **tol)[1]["accepted"]
            row = [f"{m:8} {name + ' ' if tag else ''}{plain * 1e6:10.0f}"]
            for key in ("all", "state"):
                _, phi, stats, code = built[key].integrate_var(m, x0, c, 0.0, args.t1, **tol)
                if code != 0:
                    sys.exit(f"bench-var: {m} ({name}, error = {key}) stopped with code {code}")
                t = best[(name, m, key)]
                steps = f"{stats['accepted']}" + (f"/{steps_plain}" if key == "all" else "")
                width, sw = (11, 11) if key == "all" else (13, 6)
                row.append(f"{t * 1e6:{width}.0f} {t / plain:6.2f} {steps:>{sw}}"
                           f" {column_error(phi, ref):8.1e}")  # fmt: skip
            print(" ".join(row))


def jets() -> None:
    """The Taylor jets' sizes, plain and with Phi: their nodes, and the
    convolutions whose sums run over every lower order (Jet.full), which set
    the cost of an order (k terms each at order k) and so of a step."""
    context = make_context(parse(scene_text("all"), "gyrostat.toml"))
    assert context.variational is not None, "the scene has [sensitivities]"
    print("taylor's jet: nodes, full convolutions (a sum over every lower order)")
    for name, jet in (("plain", context.jet), ("Phi", context.variational.jet)):
        assert jet is not None, "the default scene has a Taylor jet"
        print(f"{name:<8} nx {jet.nx:4d}  nodes {len(jet.nodes):4d}  full {jet.full():4d}")


def lanes(m: Compiled, x0: np.ndarray, c: np.ndarray, args: argparse.Namespace) -> None:
    """64 starts near x0: integrate_var_batch on one thread (SIMD lanes)
    against a loop of integrate_var."""
    starts = x0 + 0.01 * np.random.default_rng(1).standard_normal((64, len(x0)))
    tol = {"rtol": args.tol, "atol": args.tol}
    print("64 trajectories with Phi, one thread: a loop of integrate_var, integrate_var_batch")
    for method in ("dopri5", "dop853", "taylor"):

        def each(method: str = method) -> None:
            for x in starts:
                m.integrate_var(method, x, c, 0.0, args.t1, **tol)

        def batch(method: str = method) -> None:
            m.integrate_var_batch(method, starts, c, 0.0, args.t1, threads=1, **tol)

        clock = CLOCKS[args.clock]
        t_each, t_batch = (best_time(f, args.repeats, clock=clock) for f in (each, batch))
        print(f"{method:8} loop {t_each * 1e3:8.2f} ms  lanes {t_batch * 1e3:8.2f} ms  "
              f"{t_each / t_batch:5.2f}x")  # fmt: skip


def heyoka(
    m: Compiled, x0: np.ndarray, c: np.ndarray, ref: np.ndarray, args: argparse.Namespace
) -> None:
    """heyoka's var_ode_sys (its Taylor method, the same rhs block) against
    gyrogen's taylor with Phi, each at tolerances 1e-10 and 1e-13: time
    (state and Phi reset, propagate; the JIT apart) and Phi's error."""
    hy = heyoka_peer.module()
    if hy is None:
        print("heyoka is not installed: no comparison")
        return
    heyoka_peer.one_thread()
    scene = parse(builtin_text("gyrostat") + '\n[sensitivities]\nwrt = ["state"]\n', "g.toml")
    sys_ = heyoka_peer.system(hy, unit_of(scene))
    variational = hy.var_ode_sys(sys_.pairs, hy.var_args.vars, order=1)
    nx = len(x0)
    start = np.concatenate([x0, np.eye(nx).ravel()])
    print("Phi 14 x 14 over the same interval: heyoka var_ode_sys, gyrogen taylor")
    for tol in (1e-10, 1e-13):
        ta = hy.taylor_adaptive(variational, start, tol=tol, pars=c[: sys_.npars])

        def run(ta: object = ta) -> None:
            ta.time = 0.0  # type: ignore[attr-defined]
            ta.state[:] = start  # type: ignore[attr-defined]
            ta.propagate_until(args.t1)  # type: ignore[attr-defined]

        run()
        theirs = column_error(ta.state[nx:].reshape(nx, nx), ref)
        t_theirs = best_time(run, args.repeats, clock=CLOCKS[args.clock])
        ours = m.integrate_var("taylor", x0, c, 0.0, args.t1, rtol=tol, atol=tol)[1]
        t_ours = best_time(
            lambda tol=tol: m.integrate_var("taylor", x0, c, 0.0, args.t1, rtol=tol, atol=tol),
            args.repeats,
            clock=CLOCKS[args.clock],
        )
        print(f"tol {tol:g}: heyoka {t_theirs * 1e6:8.0f} us err {theirs:.1e}   "
              f"gyrogen {t_ours * 1e6:8.0f} us err {column_error(ours, ref):.1e}")  # fmt: skip


if __name__ == "__main__":
    main()
