"""A reaction-wheel cluster's rhs as a plain generated M-solve per call
(the same named values, then the LU solve of the constant (3+N)-square
mass matrix, its nonzero entries as literals), compiled into one library
with gyrogen's hoisted rhs and checked against the numpy reference: what
`make bench-clusters` (benchmarks/bench_clusters.py) times, and
tests/test_cluster.py checks on a slice.
"""

from __future__ import annotations

import ctypes
import random
import subprocess
import tempfile
import tomllib
from pathlib import Path

import numpy as np
import sympy as sm
from sympy.printing.c import C99CodePrinter

from gyrogen.analysis.bench.timing import best_of
from gyrogen.codegen.generate import generate, unit_of
from gyrogen.oracle import scene_view
from gyrogen.runtime import build, flags
from gyrogen.scene import Scene, builtin_text, validate
from gyrogen.symbolic import cluster
from gyrogen.symbolic.optimize import count_ops, cse_only

MATCH = 1e-12
"""Largest difference to the reference, relative to each state's largest rate."""


def msolve_block(scene: Scene) -> tuple[list[tuple[sm.Symbol, sm.Expr]], list[sm.Expr]]:
    """The M-solve per call variant: the named values (h, rel, net, f
    inlined), the kinematics, then M x = F solved by a symbolic LU of the
    mass matrix whose nonzero entries are literals; CSE over all of it."""
    eqs = cluster.derive(scene)
    named = dict(eqs.shared)
    f = [s for s in named if s.name.startswith(cluster.FORCING)]
    forcing = eqs.forcing.xreplace({s: named.pop(s) for s in f})  # f1..f3 back into F
    entries = {
        (i, j): sm.Symbol(f"m{i}_{j}", real=True)
        for i in range(eqs.mass_matrix.rows)
        for j in range(eqs.mass_matrix.cols)
        if eqs.mass_matrix[i, j] != 0
    }
    m_sym = sm.Matrix(*eqs.mass_matrix.shape, lambda i, j: entries.get((i, j), 0))
    solved = m_sym.LUsolve(forcing)
    block = cse_only([*named.values(), *eqs.kinematics, *solved])
    n = len(named)
    assigns = [(a.lhs, a.rhs) for a in block.temporaries]
    assigns += list(zip(named, block.outputs[:n], strict=True))
    return _ordered(assigns), list(block.outputs[n:])


def mass_entries(scene: Scene) -> np.ndarray:
    """The mass matrix's nonzero entries, row by row: read from memory per
    call (as a generated solve would read them), not folded by the compiler."""
    mm = cluster.derive(scene).mass_matrix
    return np.array([float(v) for v in mm if v != 0])


def _ordered(assigns: list[tuple[sm.Symbol, sm.Expr]]) -> list[tuple[sm.Symbol, sm.Expr]]:
    defined = {s for s, _ in assigns}
    done: set[sm.Symbol] = set()
    out, waiting = [], list(assigns)
    while waiting:
        ready = next(a for a in waiting if not (a[1].free_symbols & defined) - done)
        waiting.remove(ready)
        out.append(ready)
        done.add(ready[0])
    return out


def msolve_ops(scene: Scene) -> int:
    assigns, outs = msolve_block(scene)
    return count_ops([e for _, e in assigns], outs)


def msolve_c(scene: Scene, name: str) -> str:
    """void name(const double *x, const double *p, double *dxdt)."""
    printer = C99CodePrinter()
    assigns, outs = msolve_block(scene)
    lines = [f"void {name}(const double *x, const double *p, double *dxdt)", "{"]
    lines += [f"    const double {s} = x[{i}];" for i, s in enumerate(scene.states) if s != "q1"]
    lines += [f"    const double {s} = p[{i}];" for i, s in enumerate(scene.runtime)]
    mm = cluster.derive(scene).mass_matrix
    at = len(scene.runtime)
    for i in range(mm.rows):
        for j in range(mm.cols):
            if mm[i, j] != 0:
                lines.append(f"    const double m{i}_{j} = p[{at}];")
                at += 1
    lines += [f"    const double {s} = {printer.doprint(e)};" for s, e in assigns]
    lines += [f"    dxdt[{i}] = {printer.doprint(e)};" for i, e in enumerate(outs)]
    return "\n".join([*lines, "}"]) + "\n"


LOOPS = """
void bench_hoisted(long n, const double *x, const double *c, double *out)
{{
    for (long i = 0; i < n; ++i) {prefix}_rhs(0.0, x + i * {nx}, c, out + i * {nx});
}}

void bench_msolve(long n, const double *x, const double *p, double *out)
{{
    for (long i = 0; i < n; ++i) msolve(x + i * {nx}, p, out + i * {nx});
}}
"""


def compile_both(scene: Scene, src: Path) -> ctypes.CDLL:
    """The generated source and the M-solve variant, one library, the build's C flags."""
    unit = unit_of(scene)
    # one translation unit: the compiler may inline either variant into its loop
    text = f'#include <math.h>\n#include "{unit.prefix}.c"\n' + msolve_c(scene, "msolve")
    text += LOOPS.format(prefix=unit.prefix, nx=unit.nx)
    (src / "bench.c").write_text(text)
    lib = src / "libbench.so"
    chosen = [f for f in flags.c_flags("gcc") if f not in ("-Wpedantic", "-Werror")]
    cmd = ["gcc", *chosen, "-shared", "-I", str(src), "-o", str(lib)]
    subprocess.run([*cmd, str(src / "bench.c"), "-lm"], check=True)
    return ctypes.CDLL(str(lib))


def states_of(scene: Scene, n: int, rng: np.random.Generator) -> np.ndarray:
    x = rng.uniform(-1.0, 1.0, (n, len(scene.states)))
    wheels = len(scene.rotors)
    x[:, -wheels:] *= 100.0  # wheel rates
    x[:, -3 - wheels : -wheels] *= 0.5
    return x


def measure(scene: Scene, states: int, repeats: int) -> dict[str, float]:
    p = np.array([scene.simulate.parameters[n] for n in scene.runtime], dtype=float)
    xs = states_of(scene, states, np.random.default_rng(1))
    want = scene_view.rhs(scene, xs, p)
    with tempfile.TemporaryDirectory(prefix="gyrogen-bench-clusters-") as tmp:
        generate(scene, Path(tmp))
        comp = build.build(Path(tmp), "c")
        c = comp.setup(p)
        lib = compile_both(scene, Path(tmp))
        out = {}
        for name, consts in (("hoisted", c), ("msolve", np.concatenate([p, mass_entries(scene)]))):
            got = np.empty_like(xs)
            fn = getattr(lib, f"bench_{name}")
            args = [
                ctypes.c_long(states),
                *(a.ctypes.data_as(ctypes.c_void_p) for a in (xs, consts, got)),
            ]
            out[f"{name}_ns"] = best_of(lambda fn=fn, args=args: fn(*args), repeats) / states * 1e9
            check(f"{scene.name} {name}", got, want)
        got = comp.rhs(xs, c)
        check(f"{scene.name} gyrogen_rhs_batch", got, want)
        out["batch_ns"] = best_of(lambda: comp.rhs(xs, c), repeats) / states * 1e9
    return out


def check(label: str, got: np.ndarray, want: np.ndarray) -> None:
    scale = np.max(np.abs(want), axis=1, keepdims=True)
    err = float(np.max(np.abs(got - want) / scale))
    if not err <= MATCH:
        raise SystemExit(f"{label}: differs from the reference by {err:.2e}")


def random_cluster(n: int, seed: int) -> Scene:
    """N wheels on random axes at random positions, bearing friction only, 3-1-2 angles."""
    rng = random.Random(seed)
    data = tomllib.loads(builtin_text("rw3_orthogonal"))  # its carrier, N new rotors
    data["name"], data["rotors"] = f"random_{n}", []
    for _ in range(n):
        g = np.array([rng.gauss(0, 1) for _ in range(3)])
        axis = tuple(float(x) for x in g / np.linalg.norm(g))
        pos = tuple(rng.uniform(-0.5, 0.5) for _ in range(3))
        data["rotors"].append(
            {"m": 4.0, "I": 0.02, "J": 0.035, "axis": axis, "position": pos, "b": 1e-4}
        )
    data.pop("simulate", None)
    return validate(data, data["name"])
