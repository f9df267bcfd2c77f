"""The Taylor method on one trajectory against heyoka's scalar integrator
(`make bench-taylor`, scenes gyrostat and dual_spin). Both run a ladder of
tolerances, interleaved: steps, each one's error against heyoka's real128
reference, gyrogen's raw cffi call and heyoka's propagate_until each less
its own call floor (a call over no time), and both as a Python user calls
them (Compiled.integrate against propagate_until). Then each is read along
its work-precision front at the errors 1e-6 .. 1e-14 (workprec.seconds_at:
the two differ in their steps where gyrogen's step scale leaves out
translation and caps angles, so equal tolerances are not equal errors).
Best of the repeats; the load average is printed before and after.

With --base DIR (a checkout of another commit, e.g. a `git worktree add`),
that checkout's generated/SCENE is built too and timed in the same ladder,
interleaved with this one's, and read along its own front beside it.

usage: python benchmarks/bench_taylor.py SCENE [REPEATS] [--base DIR]
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from gyrogen.abi import MAX_STEPS
from gyrogen.analysis.bench import heyoka_peer as hp
from gyrogen.analysis.bench.timing import best_time
from gyrogen.analysis.bench.workprec import Run, seconds_at
from gyrogen.analysis.simulate.engine import runtime_values
from gyrogen.codegen.generate import unit_of
from gyrogen.oracle.compare import scaled_error
from gyrogen.runtime import build
from gyrogen.runtime.compiled import Compiled
from gyrogen.runtime.scene_build import build_scene
from gyrogen.scene import load

LEVELS = (1e-6, 1e-8, 1e-10, 1e-12, 1e-14)
LADDER = tuple(10.0 ** (-k / 2) for k in range(8, 31))
"""rtol = atol from 1e-4 to 1e-15, half a decade apart."""


class Raw:
    """One build's taylor_integrate through its raw cffi function."""

    def __init__(self, comp: Compiled, x0: np.ndarray, c: np.ndarray) -> None:
        self.fn, self.x0, self.x = comp.function("taylor"), x0, x0.copy()
        self.xb, self.cb = comp.doubles(self.x), comp.doubles(np.ascontiguousarray(c))
        self.stats = comp.ffi.new("gyrogen_stats *")

    def __call__(self, tol: float, end: float) -> None:
        self.x[:] = self.x0
        self.fn(0.0, end, self.xb, self.cb, tol, tol, 0.0, MAX_STEPS, self.stats)


def main(name: str, repeats: int, base: Path | None = None) -> None:
    scene = load(name)
    with tempfile.TemporaryDirectory() as tmp:
        built = build_scene(scene, Path(tmp), ("c",))
    comp = built["c"]
    c = comp.setup(runtime_values(scene))
    x0, t1 = np.array(scene.initial_state()), scene.simulate.t_end
    hy = hp.module()
    if hy is None:
        sys.exit("heyoka is not installed: pip install -e '.[bench]'")
    hp.one_thread()
    hsys = hp.system(hy, unit_of(scene))
    ref, _ = hp.reference(hsys, x0, c, t1)
    raw = Raw(comp, x0, c)
    old = None if base is None else Raw(build.build(base / "generated" / name, "c"), x0, c)
    g_floor = best_time(lambda: raw(1e-8, 0.0), repeats, min_total=0.02)
    b_floor = 0.0 if old is None else best_time(lambda: old(1e-8, 0.0), repeats, min_total=0.02)
    h_floor = best_time(hp.Scalar(hsys, x0, c, 0.0, 1e-8).run, repeats, min_total=0.02)
    print(f"{scene.name}, 0..{t1:g} s; call floors: gyrogen raw cffi {g_floor * 1e6:.2f} us, "
          f"heyoka {h_floor * 1e6:.2f} us; load {os.getloadavg()[0]:.2f}")  # fmt: skip
    print("| rtol = atol | steps gyrogen | steps heyoka | error gyrogen | error heyoka "
          "| gyrogen us | heyoka us | from Python: gyrogen us | heyoka us |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|")
    runs: dict[str, list[Run]] = {k: [] for k in ("g", "h", "pg", "ph", "b")}
    based: list[str] = []
    for tol in LADDER:
        theirs = hp.Scalar(hsys, x0, c, t1, tol)
        hx = theirs.final()
        hsteps = int(theirs.run()[3])  # propagate_until: (outcome, min h, max h, steps, ...)
        raw(tol, t1)
        gx, steps = raw.x.copy(), raw.stats.accepted
        tg = best_time(lambda tol=tol: raw(tol, t1), repeats, min_total=0.05) - g_floor
        if old is not None:
            old(tol, t1)
            eb = scaled_error(old.x, ref)
            tb = best_time(lambda tol=tol: old(tol, t1), repeats, min_total=0.05) - b_floor
            runs["b"].append(Run("b", "", tol, eb, tb, 0))
            based.append(f"| {tol:.1e} | {old.stats.accepted} | {eb:.1e} | {tb * 1e6:.2f} |")
        th = best_time(theirs.run, repeats, min_total=0.05) - h_floor

        def python(tol: float = tol) -> None:
            comp.integrate("taylor", x0, c, 0.0, t1, rtol=tol, atol=tol)

        pg = best_time(python, repeats, min_total=0.05)
        ph = best_time(theirs.run, repeats, min_total=0.05)
        eg, eh = scaled_error(gx, ref), scaled_error(hx, ref)
        for key, err, sec in (("g", eg, tg), ("h", eh, th), ("pg", eg, pg), ("ph", eh, ph)):
            runs[key].append(Run(key, "", tol, err, sec, 0))
        print(f"| {tol:.1e} | {steps} | {hsteps} | {eg:.1e} | {eh:.1e} | {tg * 1e6:.2f} "
              f"| {th * 1e6:.2f} | {pg * 1e6:.2f} | {ph * 1e6:.2f} |")  # fmt: skip
    print(f"\nread along each front ({scene.name}): us at an error <= level")
    print("| error | gyrogen us | heyoka us | heyoka / gyrogen | from Python: gyrogen us "
          "| heyoka us | ratio |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for level in LEVELS:
        g, h, pg, ph = (seconds_at(runs[k], level) for k in ("g", "h", "pg", "ph"))
        cells = [f"{v * 1e6:.2f}" if v is not None else "-" for v in (g, h, pg, ph)]
        ratio = f"{h / g:.2f}" if g and h else "-"
        pratio = f"{ph / pg:.2f}" if pg and ph else "-"
        print(f"| {level:.0e} | {cells[0]} | {cells[1]} | {ratio} | {cells[2]} | {cells[3]} "
              f"| {pratio} |")  # fmt: skip
    if old is not None:
        compare(scene.name, base, b_floor, based, runs)
    print(f"after: load {os.getloadavg()[0]:.2f}")


def compare(name: str, base: Path | None, floor: float, rows: list[str], runs: dict) -> None:
    """The base checkout's ladder, then both builds and heyoka read along
    their fronts at equal error."""
    print(f"\nbase {base}: call floor {floor * 1e6:.2f} us")
    print("| rtol = atol | steps base | error base | base us |\n|---|---|---|---|")
    print("\n".join(rows))
    print(f"\nread along each front ({name}): us at an error <= level, less the call floors")
    print("| error | this us | base us | heyoka us | this / base | heyoka / this "
          "| heyoka / base |\n|---|---|---|---|---|---|---|")  # fmt: skip
    for level in LEVELS:
        g, b, h = (seconds_at(runs[k], level) for k in ("g", "b", "h"))
        cells = [f"{v * 1e6:.2f}" if v is not None else "-" for v in (g, b, h)]
        ratios = [f"{p / q:.2f}" if p and q else "-" for p, q in ((g, b), (h, g), (h, b))]
        print(f"| {level:.0e} | {' | '.join(cells)} | {' | '.join(ratios)} |")


if __name__ == "__main__":
    args = sys.argv[1:]
    at = args.index("--base") if "--base" in args else None
    base_dir = None if at is None else Path(args[at + 1])
    rest = args if at is None else args[:at] + args[at + 2 :]
    main(
        rest[0] if rest else "gyrostat",
        int(rest[1]) if len(rest) > 1 else 7,
        base_dir,
    )
