"""`make bench-methods`: the cost of one step of every compiled integrator
(methods.METHODS), on the default scene and on stiff_wheel, in C.

    python benchmarks/methods.py [--baseline REV [--same-flags]] [--scenes A,B]
        [--tolerances 1e-4,1e-6] [--repeats R] [--rounds K] [--max-steps N] [--clock cpu|wall]

Each scene is built with every method it offers (its `integrators` key left
out). Each method runs the raw single-trajectory call (workprec.raw_call:
cffi on buffers made once, the state reset from the scene's start) from 0 to
the scene's t_end at each tolerance (rtol = atol), at most N steps (a stiff
scene's explicit methods stop there: "to t" is the time a run reached). A
fixed-step method takes the steps of the first explicit pair at that
tolerance over half the time it covered (half its step: on a stiff scene
the pair's step sits at its stability bound, beyond rk4's). Printed: us per
call, steps (accepted and rejected), rhs calls and ns per step, the best of
R repeats of a loop of ~20 ms, in K rounds; the load average before and
after.

With --baseline REV, gyrogen as of REV (a git worktree of it in a temp dir,
its generator/ first on PYTHONPATH) renders the same scenes and builds them
with its own build path and flags; each call of this tree and of REV runs
side by side, interleaved, in the same rounds, and the table adds REV's
figures and the ratio new/old of ns per step. A method slower per step by
more than FLAG (3 %) is flagged, row by row and over its rows (geometric
mean). --same-flags builds REV's sources with this tree's build path and
flags instead: the generated code's share alone. Figures only: nothing
here fails on time.

--clock cpu (the default) times with the thread's CPU time (timing.py): a
machine with more runnable processes than cores then still times the calls
themselves; --clock wall with the wall clock.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gyrogen import methods
from gyrogen.analysis.bench.timing import Clock, best_time
from gyrogen.analysis.bench.workprec import raw_call
from gyrogen.analysis.simulate.engine import runtime_values
from gyrogen.runtime import cache
from gyrogen.runtime.compiled import Compiled, controls
from gyrogen.runtime.scene_build import build_dir, compiled, scene_sources
from gyrogen.scene import Scene, builtin_text, default, parse

FLAG = 1.03
"""new/old ns per step above this: flagged."""
CLOCKS: dict[str, Clock] = {"cpu": time.thread_time, "wall": time.perf_counter}
GYROGEN = str(Path(sys.executable).with_name("gyrogen"))
REV_BUILD = (
    "import json, sys; from pathlib import Path; from gyrogen.runtime import build, cache; "
    "d = Path(sys.argv[1]); build.build(d, 'c'); plan = build._plan(d, 'c'); "
    "print(json.dumps([plan.module_name, str(cache.cache_dir() / plan.key)]))"
)
"""Run with REV's gyrogen: its build of a generated directory, and where its
cache keeps the module (the entry this tree's cache.load then loads)."""


def load_average() -> str:
    one, five, fifteen = os.getloadavg()
    cpus = os.cpu_count()
    return f"load average {one:.2f}, {five:.2f}, {fifteen:.2f} (1, 5, 15 min), {cpus} cpus"


def every_method(text: str) -> str:
    """A built-in scene's text without its `integrators` key (one line in
    each of them): the scene then renders every method it offers."""
    return re.sub(r"(?m)^integrators\s*=.*\n", "", text)


@dataclass(frozen=True)
class Start:
    """Where every method of a scene starts, and for how long."""

    x0: np.ndarray
    p: np.ndarray
    t1: float


@dataclass
class Row:
    """One method at one tolerance (a fixed-step one: at its steps) in each build."""

    method: str
    setting: str
    calls: dict[str, Callable[[], Any]]
    steps: dict[str, int]
    rhs: dict[str, int]
    reached: dict[str, float]
    best: dict[str, float]

    def ns_per_step(self, build: str) -> float:
        return self.best[build] * 1e9 / max(self.steps[build], 1)


def controls_of(method: str, tol: float, steps: int, max_steps: int) -> Any:
    return controls(method, steps=steps, rtol=tol, atol=tol, max_steps=max_steps)


def measure(
    builds: dict[str, Compiled], start: Start, method: str, tol: float, max_steps: int,
    fixed: dict[str, tuple[int, float]],
) -> Row:  # fmt: skip
    """The row's calls and statistics in each build (fixed: the steps and
    the time a fixed-step method takes there)."""
    pick = methods.get(method)
    row = Row(method, f"{tol:.0e}", {}, {}, {}, {}, {})
    for name, comp in builds.items():
        if method not in comp.manifest["integrators"]:
            continue
        steps, t1 = fixed.get(name, (1000, start.t1)) if pick.fixed_step else (1, start.t1)
        kw = controls_of(method, tol, steps, max_steps)
        c = comp.setup(start.p)
        _, stats, code = comp.integrate(method, start.x0, c, 0.0, t1, **kw)
        row.steps[name] = int(stats["accepted"] + stats["rejected"])
        row.rhs[name] = int(stats["rhs_calls"])
        row.reached[name] = float(stats["t"])
        row.calls[name] = raw_call(comp, method, start.x0, c, t1, kw)
        if pick.fixed_step:
            row.setting = f"{steps} steps"
        if pick.pair and name not in fixed:  # half its step: within rk4's stability interval
            fixed[name] = (row.steps[name], row.reached[name] / 2)
        if code not in (0, 2):  # 2: max_steps, a stiff scene's explicit method
            row.setting += f" (code {code})"
    return row


def time_rows(rows: list[Row], repeats: int, rounds: int, clock: Clock) -> None:
    """Each row's builds side by side: every round times each in turn, the
    order reversed every other round."""
    for row in rows:
        names = list(row.calls)
        row.best = dict.fromkeys(names, math.inf)
        for k in range(rounds):
            for name in names if k % 2 == 0 else names[::-1]:
                secs = best_time(row.calls[name], repeats, clock=clock)
                row.best[name] = min(row.best[name], secs)


def print_rows(scene: str, start: Start, rows: list[Row], baseline: str | None) -> None:
    head = "| method | rtol = atol | steps | rhs calls | to t | us per call | ns per step |"
    line = "|---|---|---|---|---|---|---|"
    if baseline:
        head += f" {baseline}: steps | us per call | ns per step | new/old per step |"
        line += "---|---|---|---|"
    print(f"\n{scene}, 0..{start.t1:g} s\n{head}\n{line}")
    for row in rows:
        if "new" not in row.best:
            continue
        text = (f"| {row.method} | {row.setting} | {row.steps['new']} | {row.rhs['new']} "
                f"| {row.reached['new']:.3g} | {row.best['new'] * 1e6:.2f} "
                f"| {row.ns_per_step('new'):.0f} |")  # fmt: skip
        if baseline and "old" in row.best:
            ratio = row.ns_per_step("new") / row.ns_per_step("old")
            mark = " SLOWER" if ratio > FLAG else ""
            text += (f" {row.steps['old']} | {row.best['old'] * 1e6:.2f} "
                     f"| {row.ns_per_step('old'):.0f} | {ratio:.3f}{mark} |")  # fmt: skip
        elif baseline:
            text += " - | - | - | - |"
        print(text)


def summary(rows: list[Row], baseline: str) -> None:
    """Each method's geometric mean of new/old ns per step over its rows."""
    print(f"\nper step, new/old against {baseline} (geometric mean over both scenes' rows):")
    for method in methods.NAMES:
        both = [r for r in rows if r.method == method and {"new", "old"} <= set(r.best)]
        ratios = [r.ns_per_step("new") / r.ns_per_step("old") for r in both]
        if not ratios:
            print(f"  {method:<8} not in {baseline}")
            continue
        mean = math.exp(sum(map(math.log, ratios)) / len(ratios))
        mark = f"  SLOWER by more than {100 * (FLAG - 1):.0f} %" if mean > FLAG else ""
        print(f"  {method:<8} {mean:.3f} (rows {min(ratios):.3f} .. {max(ratios):.3f}){mark}")


def run(cmd: list[str], what: str, env: dict[str, str] | None = None) -> str:
    """cmd's output; a failure ends the run with one line: what, and the
    last line cmd wrote to stderr."""
    done = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    if done.returncode != 0:
        said = (done.stderr.strip().splitlines() or ["no message"])[-1]
        sys.exit(f"bench-methods: {what}: {said}")
    return done.stdout


@contextmanager
def rev_tree(rev: str) -> Iterator[Path]:
    """A git worktree of rev in a temp dir, removed afterwards."""
    root = Path(__file__).resolve().parent.parent
    with tempfile.TemporaryDirectory(prefix="gyrogen-baseline-") as tmp:
        there = Path(tmp) / "src"
        run(
            ["git", "-C", str(root), "worktree", "add", "--detach", str(there), rev],
            f"cannot check out {rev}",
        )
        try:
            yield there
        finally:
            subprocess.run(["git", "-C", str(root), "worktree", "remove", "--force", str(there)],
                           check=False, capture_output=True)  # fmt: skip


def rev_build(there: Path, name: str, work: Path, same_flags: bool) -> Compiled:
    """Scene name rendered by gyrogen as of the worktree there (its own
    built-in scene, every method it offers), built by its own build path or,
    same_flags, by this tree's."""
    env = {**os.environ, "PYTHONPATH": str(there / "generator")}
    scene_file, out = work / f"{name}.toml", work / name
    text = (there / "generator" / "gyrogen" / "scenes" / f"{name}.toml").read_text()
    scene_file.write_text(every_method(text))
    run([GYROGEN, "generate", str(scene_file), "--out", str(out)], f"{name}: cannot render it", env)
    if same_flags:
        return build_dir(out, ["c"])["c"]
    done = run([sys.executable, "-c", REV_BUILD, str(out)], f"{name}: cannot build it", env)
    module_name, entry = json.loads(done.splitlines()[-1])
    module = cache.load(module_name, Path(entry))
    manifest = json.loads((out / "manifest.json").read_text())
    return Compiled("c", manifest, module.ffi, module.lib)


def scene_rows(
    scene: Scene, builds: dict[str, Compiled], tolerances: list[float], max_steps: int
) -> tuple[Start, list[Row]]:
    start = Start(np.array(scene.initial_state()), runtime_values(scene), scene.simulate.t_end)
    order = sorted(methods.NAMES, key=lambda m: methods.get(m).fixed_step)  # pairs first
    rows = []
    for tol in tolerances:
        fixed: dict[str, tuple[int, float]] = {}
        found = [measure(builds, start, m, tol, max_steps, fixed) for m in order]
        rows += [r for r in found if r.calls]
    rows.sort(key=lambda r: methods.NAMES.index(r.method))
    return start, rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", metavar="REV", default="")
    ap.add_argument("--same-flags", action="store_true")
    ap.add_argument("--scenes", default=f"{default().name},stiff_wheel")
    ap.add_argument("--tolerances", default="1e-4,1e-6,1e-8,1e-10")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--max-steps", type=int, default=10000)
    ap.add_argument("--clock", choices=tuple(CLOCKS), default="cpu")
    args = ap.parse_args()
    tolerances = [float(t) for t in args.tolerances.split(",")]
    names = args.scenes.split(",")
    print(f"before: {load_average()}")
    flags = "this tree's flags" if args.same_flags else "its own build and flags"
    print(f"clock: {args.clock}; best of {args.repeats} x {args.rounds} rounds; C; "
          + (f"old: gyrogen as of {args.baseline} ({flags})" if args.baseline else ""))  # fmt: skip
    every: list[Row] = []
    with (
        tempfile.TemporaryDirectory(prefix="gyrogen-bench-methods-") as tmp,
        rev_tree(args.baseline) if args.baseline else nullcontext() as there,
    ):
        for name in names:
            scene = parse(every_method(builtin_text(name)), f"{name} (built-in)")
            builds = {"new": compiled(scene_sources(scene))}
            if there is not None:
                builds["old"] = rev_build(there, name, Path(tmp), args.same_flags)
            start, rows = scene_rows(scene, builds, tolerances, args.max_steps)
            time_rows(rows, args.repeats, args.rounds, CLOCKS[args.clock])
            print_rows(name, start, rows, args.baseline or None)
            every += rows
    if args.baseline:
        summary(every, args.baseline)
    print(f"\nafter: {load_average()}")


if __name__ == "__main__":
    main()
