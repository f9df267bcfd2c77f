"""Benchmark of the generated right-hand sides against the numpy reference and PyDy.

Rows: one call from Python through cffi (C, Fortran), the same through the numpy
convenience path ``Compiled.rhs``, the batched C loop (``gyrogen_rhs_batch``), the
vectorized numpy reference, and PyDy's cython ODE function built from the *same*
symbolic model. Every time is the best of ``repeats``: the minimum is the least
disturbed by other load on the machine. Outputs are checked against the reference
once, so a fast but wrong row cannot pass unnoticed.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import tempfile
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from gyrogen.analysis.bench import RHS_JSON
from gyrogen.analysis.bench.timing import best_of, per_call_ns
from gyrogen.files import write_atomic
from gyrogen.oracle import reference, sampling
from gyrogen.runtime import flags
from gyrogen.runtime.compiled import Compiled
from gyrogen.runtime.rhs import RawRhs
from gyrogen.runtime.scene_build import build_scene
from gyrogen.scene import default
from gyrogen.symbolic import model

Array = np.ndarray
Echo = Callable[[str], None]

CALLS = 200_000
"""One-call loops through cffi; the slower paths use a fraction (see run)."""
BATCH = 100_000
"""States per batched call."""
MATCH_RTOL = 1e-9
"""Agreement with reference.rhs required of every backend (relative to each state's largest
component: the reference has exact zeros where a linear solve leaves ~1e-16)."""
GOAL_RATIO = 20.0
GOAL_BATCH_NS = 50.0


@dataclass(frozen=True)
class Measurement:
    name: str
    ns: float
    """Nanoseconds per ``unit``."""
    unit: Literal["call", "state"]
    detail: str


@dataclass(frozen=True)
class _Inputs:
    p: Array
    x: Array
    """One state, shape (14,)."""
    xs: Array
    """The batch, shape (batch, 14)."""


def _mismatch(got: Array, want: Array) -> float:
    """Largest error relative to the largest component of the same state."""
    got, want = np.atleast_2d(got), np.atleast_2d(want)
    scale = np.maximum(np.max(np.abs(want), axis=1, keepdims=True), np.finfo(float).tiny)
    return float(np.max(np.abs(got - want) / scale))


def _check(label: str, got: Array, want: Array, echo: Echo) -> str:
    err = _mismatch(got, want)
    ok = err <= MATCH_RTOL
    echo(
        f"check {label}: max relative difference to reference.rhs {err:.1e}"
        + ("" if ok else " MISMATCH")
    )
    return "" if ok else f"; OUTPUT MISMATCH {err:.1e}"


def _bench_backend(
    comp: Compiled, inp: _Inputs, calls: int, repeats: int, echo: Echo
) -> list[Measurement]:
    """The raw cffi call, Compiled.rhs and the batched loop of one backend."""
    lang = comp.language
    c = comp.setup(inp.p)
    raw = RawRhs(comp, c)  # pointers made once: from_buffer per call would be timed too
    raw.x[:] = inp.x
    xs, outs = np.ascontiguousarray(inp.xs), np.empty_like(inp.xs)
    xsp, outsp = comp.doubles(xs), comp.doubles(outs)
    batch_fn, cp = comp.lib.gyrogen_rhs_batch, raw.pointers[1]
    n, rhs_name = len(xs), comp.symbol("rhs")

    one = per_call_ns(raw.function, (0.0, *raw.pointers), calls, repeats)
    note = _check(f"{lang} one call", raw.out, reference.rhs(raw.x, inp.p), echo)  # the loop's
    conv = per_call_ns(comp.rhs, (raw.x, c), calls // 10, repeats)
    batch = best_of(lambda: batch_fn(n, 0.0, xsp, cp, outsp), repeats) / n * 1e9
    bnote = _check(f"{lang} batch", outs, reference.rhs(xs, inp.p), echo)
    return [
        Measurement(
            f"cffi_{lang}_call", one, "call", f"lib.{rhs_name}, preallocated pointers{note}"
        ),
        Measurement(f"compiled_{lang}_rhs", conv, "call", "Compiled.rhs(x, c), numpy in/out"),
        Measurement(f"batch_{lang}", batch, "state", f"gyrogen_rhs_batch, {n} states{bnote}"),
    ]


def _bench_numpy(inp: _Inputs, calls: int, repeats: int) -> list[Measurement]:
    n = len(inp.xs)
    batch = best_of(lambda: reference.rhs(inp.xs, inp.p), repeats) / n * 1e9
    one = per_call_ns(reference.rhs, (inp.x, inp.p), calls, repeats)
    return [
        Measurement("numpy_batch", batch, "state", f"reference.rhs vectorized, {n} states"),
        Measurement("numpy_call", one, "call", "reference.rhs on one state"),
    ]


def pydy_rhs(echo: Echo) -> Callable[..., Array] | None:
    """PyDy's cython ODE function of model.separate(), or None if PyDy is missing."""
    try:
        import Cython  # noqa: F401  (pydy's cython generator fails late without it)
        from pydy.codegen.ode_function_generators import generate_ode_function
    except ImportError as exc:
        echo(f"PyDy row skipped ({exc}): install with pip install -e '.[bench]'")
        return None
    eqs, s = model.separate(), model.symbols()
    t0 = time.perf_counter()
    # tmp_dir keeps the generated sources and build files out of the CWD.
    with tempfile.TemporaryDirectory(prefix="gyrogen-pydy-") as tmp:
        rhs = generate_ode_function(
            eqs.forcing,
            list(s.q),
            list(s.u),
            list(s.params),  # layout.PARAMETERS order, as p is drawn
            mass_matrix=eqs.mass_matrix,  # the 7x7 dynamic mass matrix: form M u' = F
            coordinate_derivatives=eqs.kinematics,  # explicit q'
            generator="cython",
            constants_arg_type="array",  # PyDy's fastest argument path
            tmp_dir=tmp,
        )
    echo(f"PyDy cython compile: {time.perf_counter() - t0:.1f} s (not in the timings)")
    return rhs


def _bench_pydy(
    rhs: Callable[..., Array], inp: _Inputs, calls: int, repeats: int, echo: Echo
) -> Measurement:
    x, p = inp.x.copy(), inp.p.copy()
    ns = per_call_ns(rhs, (x, 0.0, p), calls, repeats)
    # PyDy returns the same buffer on every call: copy each result before the next.
    xs = inp.xs[:1000]
    got = np.array([rhs(row, 0.0, p).copy() for row in xs])
    note = _check("PyDy cython", got, reference.rhs(xs, p), echo)
    return Measurement(
        "pydy_cython_call", ns, "call", f"generate_ode_function(generator='cython')(x, t, p){note}"
    )


def _cmd_first_line(cmd: list[str]) -> str:
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return proc.stdout.splitlines()[0] if proc.stdout else "unknown"


def machine() -> dict[str, str]:
    """CPU model, usable cores and compilers, to read the numbers against."""
    cpu = platform.processor() or platform.machine()
    try:
        lscpu = subprocess.run(["lscpu"], capture_output=True, text=True, check=False, timeout=10)
        for line in lscpu.stdout.splitlines():
            if line.startswith("Model name:"):
                cpu = line.split(":", 1)[1].strip()
                break
    except (OSError, subprocess.SubprocessError):
        pass  # keep platform's answer
    nproc = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {
        "cpu": cpu,
        "nproc": str(nproc),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "gcc": _cmd_first_line(["gcc", "--version"]),
        "gfortran": _cmd_first_line(["gfortran", "--version"]),
        "c_flags": " ".join(flags.c_flags()),
        "fortran_flags": " ".join(flags.fortran_flags()),
    }


def _ns(ms: list[Measurement], name: str) -> float | None:
    return next((m.ns for m in ms if m.name == name), None)


def report(ms: list[Measurement], info: dict[str, str], echo: Echo) -> None:
    """The table, then the two goal lines."""
    echo(f"machine: {info['cpu']}, nproc {info['nproc']}")
    echo(f"compilers: {info['gcc']}; {info['gfortran']}")
    echo(f"C flags: {info['c_flags']}")
    echo(f"Fortran flags: {info['fortran_flags']}")
    echo("")
    echo(f"{'what':<20} {'time':>10}  {'unit':<9} note")
    for m in ms:
        echo(f"{m.name:<20} {m.ns:>10.1f}  {'ns/' + m.unit:<9} {m.detail}")
    echo("")
    c_call, pydy = _ns(ms, "cffi_c_call"), _ns(ms, "pydy_cython_call")
    if c_call is not None and pydy is not None:
        ratio = f"{pydy / c_call:.1f} x faster"
    else:
        ratio = "not measured (PyDy row skipped)"
    echo(f"one call through cffi (C) vs PyDy cython: {ratio} (goal >= {GOAL_RATIO:g}x)")
    batch = _ns(ms, "batch_c")
    shown = f"{batch:.1f}" if batch is not None else "not measured"
    echo(f"batched C: {shown} ns/state (goal < {GOAL_BATCH_NS:g} ns)")


def _write_json(out: Path, ms: list[Measurement], info: dict[str, str], repeats: int) -> Path:
    doc = {"machine": info, "repeats": repeats, "measurements": [asdict(m) for m in ms]}
    write_atomic(out, {RHS_JSON: json.dumps(doc, indent=2) + "\n"})
    return out / RHS_JSON


def run(
    out: Path | None = None,
    repeats: int = 5,
    echo: Echo = print,
    *,
    calls: int = CALLS,
    batch: int = BATCH,
    pydy: bool = True,
) -> list[Measurement]:
    """Run every row, print the table and goals; write out/RHS_JSON if out is given.

    ``calls`` sets the cffi one-call loops; Compiled.rhs and PyDy run calls // 10, the
    numpy one-state row calls // 100. ``pydy=False`` skips PyDy (and its cython compile).
    """
    p = sampling.random_parameters(np.random.default_rng(0), 1)[0]
    xs = sampling.random_states(np.random.default_rng(1), max(batch, 1))
    inp = _Inputs(p=p, x=xs[0].copy(), xs=xs)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="gyrogen-bench-") as tmp:
        backends = build_scene(default(), Path(tmp), ("c", "fortran"))
    echo(f"generated and built the default scene in {time.perf_counter() - t0:.1f} s")
    ms: list[Measurement] = []
    for comp in backends.values():
        ms += _bench_backend(comp, inp, calls, repeats, echo)
    ms += _bench_numpy(inp, calls // 100, repeats)
    rhs = pydy_rhs(echo) if pydy else None
    if rhs is not None:
        ms.append(_bench_pydy(rhs, inp, calls // 10, repeats, echo))
    info = machine()
    echo("")
    report(ms, info, echo)
    if out is not None:
        echo(f"wrote {_write_json(Path(out), ms, info, repeats)}")
    return ms
