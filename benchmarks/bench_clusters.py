"""`make bench-clusters`: the reaction-wheel clusters' rhs, hoisted (what
gyrogen generates: I~^-1 as numbers, no solve per call) against a plain
generated M-solve per call (the same named values, then the LU solve of the
constant (3+N)-square mass matrix, its nonzero entries as literals), and
the rhs op count against N; then each scene with every cluster property
runtime against its folded twin (RUNTIME_PAIRS: rw4_hardware against
rw4_pyramid), the generated rhs in one C loop each, timed interleaved.

    python benchmarks/bench_clusters.py [--states N] [--repeats R]

Both variants are compiled into one library with the project's C flags and
called by the same C loop over N states (default 10^5); the figure is the
best of R runs (default 5) in ns per state. The batched rhs through the
scene's own library (gyrogen_rhs_batch, Compiled) is printed beside them.
Every variant is checked against the numpy reference first. The M-solve
variant and the measurement are tests/cluster_msolve.py's, which
tests/test_cluster.py runs on a slice.
"""

from __future__ import annotations

import argparse
import ctypes
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the M-solve variant

from cluster_msolve import check, measure, msolve_ops, random_cluster, states_of

from gyrogen.analysis.bench.timing import best_of
from gyrogen.codegen.generate import generate, unit_of
from gyrogen.oracle import scene_view
from gyrogen.runtime import build, flags
from gyrogen.scene import load

SCENES = ("rw3_orthogonal", "rw4_pyramid", "rw4_pyramid_failed")
RUNTIME_PAIRS = (("rw4_hardware", "rw4_pyramid"),)
"""(everything runtime, folded): the issue's bar is 1.3x the folded ns per state."""
HOISTED = """
void bench_{prefix}(long n, const double *x, const double *c, double *out)
{{
    for (long i = 0; i < n; ++i) {prefix}_rhs(0.0, x + i * {nx}, c, out + i * {nx});
}}
"""


def runtime_against_folded(pair: tuple[str, str], states: int, repeats: int) -> list[float]:
    """ns per state of the runtime scene's rhs and the folded one's (the
    same states; each checked against the reference first), best of
    repeats rounds, the two timed alternately in each round."""
    scenes = [load(name) for name in pair]
    xs = states_of(scenes[0], states, np.random.default_rng(2))
    with tempfile.TemporaryDirectory(prefix="gyrogen-bench-runtime-") as tmp:
        src = Path(tmp)
        text = "#include <math.h>\n"
        calls = []
        for scene in scenes:
            unit = unit_of(scene)
            generate(scene, src / scene.name)
            text += f'#include "{scene.name}/{unit.prefix}.c"\n'
            text += HOISTED.format(prefix=unit.prefix, nx=unit.nx)
        (src / "bench.c").write_text(text)
        chosen = [f for f in flags.c_flags("gcc") if f not in ("-Wpedantic", "-Werror")]
        for scene in scenes:
            chosen += ["-I", str(src / scene.name)]
        lib = src / "libbench.so"
        subprocess.run(["gcc", *chosen, "-shared", "-o", str(lib), str(src / "bench.c"), "-lm"],
                       check=True)  # fmt: skip
        dll = ctypes.CDLL(str(lib))
        for scene in scenes:
            p = np.array([scene.simulate.parameters[n] for n in scene.runtime], dtype=float)
            comp = build.build(src / scene.name, "c")
            c = comp.setup(p)
            got = np.empty_like(xs)
            args = [
                ctypes.c_long(states),
                *(a.ctypes.data_as(ctypes.c_void_p) for a in (xs, c, got)),
            ]
            fn = getattr(dll, f"bench_{unit_of(scene).prefix}")
            fn(*args)
            check(f"{scene.name} hoisted", got, scene_view.rhs(scene, xs, p))
            calls.append((fn, args, c, got))
        best = [float("inf")] * len(scenes)
        for _ in range(repeats):
            for i, (fn, args, _, _) in enumerate(calls):
                best[i] = min(best[i], best_of(lambda fn=fn, args=args: fn(*args), 1))
    return [b / states * 1e9 for b in best]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--states", type=int, default=100_000)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    head = f"{'rhs ops':>8} {'M-solve ops':>12} {'hoisted ns':>11} {'M-solve ns':>11}"
    print(f"{'scene':<20} {head} {'rhs_batch ns':>13}")
    for name in SCENES:
        scene = load(name)
        t = measure(scene, args.states, args.repeats)
        print(
            f"{name:<20} {unit_of(scene).ops['rhs']:>8} {msolve_ops(scene):>12} "
            f"{t['hoisted_ns']:>11.1f} {t['msolve_ns']:>11.1f} {t['batch_ns']:>13.1f}"
        )
    print("\nops vs N (random axes and positions, friction only, 3-1-2 angles, seed 7):")
    print(f"{'N':>3} {'rhs ops':>8} {'M-solve ops':>12}")
    for n in range(1, 7):
        scene = random_cluster(n, 7)
        print(f"{n:>3} {unit_of(scene).ops['rhs']:>8} {msolve_ops(scene):>12}")
    print("\nevery cluster property runtime against folded (interleaved, ns per state):")
    columns = f"{'rhs ops':>8} {'ns':>7}"
    print(f"{'scene':<14} {columns}   {'folded':<12} {columns} {'ratio':>6}")
    for pair in RUNTIME_PAIRS:
        ns = runtime_against_folded(pair, args.states, 4 * args.repeats)
        ops = [unit_of(load(name)).ops["rhs"] for name in pair]
        print(
            f"{pair[0]:<14} {ops[0]:>8} {ns[0]:>7.1f}   {pair[1]:<12} {ops[1]:>8} {ns[1]:>7.1f} "
            f"{ns[0] / ns[1]:>6.2f}"
        )
    sys.stdout.flush()


if __name__ == "__main__":
    main()
