"""`gyrogen bench SCENE`: run the work-precision measurements of workprec.py
and write them as a table (CSV, JSON), a markdown summary and a PNG figure."""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from gyrogen.analysis.bench import workprec, workprec_peers
from gyrogen.analysis.bench.rhs import machine, pydy_rhs
from gyrogen.analysis.bench.workprec import Config, Problem, Run
from gyrogen.analysis.check import stiffness
from gyrogen.analysis.simulate.engine import given_constants, runtime_values
from gyrogen.errors import SceneError
from gyrogen.files import write_atomic
from gyrogen.runtime.compiled import Language
from gyrogen.runtime.scene_build import build_scene
from gyrogen.scene import Scene

LEVELS = (1e-4, 1e-6, 1e-8, 1e-10)
QUAD_LEVELS = (*LEVELS, 1e-12, 1e-14)
"""The error levels read against the real128 reference (the DOP853 one is
itself ~1e-12 off)."""
PEERS = ("numbalsoda", "CasADi", "heyoka")
"""How the compiled peers' labels start."""
_LABELS = {"c": "C", "fortran": "Fortran"}
Echo = Callable[[str], None]


def check_scene(scene: Scene) -> np.ndarray:
    """SceneError unless the report can run on scene; its runtime values."""
    if "c" not in scene.targets or "dop853" not in scene.integrators:
        raise SceneError(
            f"{scene.name}: the work-precision report needs the c target and the dop853 "
            "integrator (its reference)"
        )
    return runtime_values(scene)


def problem(scene: Scene, src: Path, cfg: Config) -> Problem:
    p = check_scene(scene)
    wanted: tuple[Language, ...] = ("c", "fortran") if cfg.fortran else ("c",)
    built = build_scene(scene, src, [lang for lang in wanted if lang in scene.targets])
    compiled = {_LABELS[lang]: comp for lang, comp in built.items()}
    x0 = np.array(scene.initial_state())
    c = given_constants(scene, compiled["C"], p)
    return Problem(scene, compiled, p, c, x0, scene.simulate.t_end)


def measure(scene: Scene, cfg: Config, echo: Echo, progress: Echo) -> tuple[Problem, list[Run]]:
    with tempfile.TemporaryDirectory(prefix="gyrogen-wp-") as tmp, _empty_cache(Path(tmp)):
        t0 = time.perf_counter()
        prob = problem(scene, Path(tmp) / scene.name, cfg)
        languages = " and ".join(prob.compiled)
        prob.notes["gyrogen generate and build"] = (
            f"{time.perf_counter() - t0:.1f} s ({languages}, every integrator, an empty cache)"
        )
        comp = prob.compiled["C"]
        stiff = stiffness.index(comp, prob.c, prob.x0, prob.t1) > stiffness.STIFF
        workprec.reference(prob, quadruple=not stiff)
        runs = workprec.compiled_runs(prob, cfg, progress)
        runs += workprec.scipy_runs(prob, "numpy RHS", workprec.numpy_rhs(prob), cfg, progress)
        runs += workprec.scipy_runs(
            prob, "C RHS via cffi", workprec.compiled_rhs(prob), cfg, progress
        )
        runs += _pydy_runs(prob, cfg, echo, progress)
        runs += workprec_peers.runs(prob, cfg, stiff, echo, progress)
    return prob, runs


@contextlib.contextmanager
def _empty_cache(tmp: Path) -> Iterator[None]:
    """GYROGEN_CACHE in tmp for the block: the build is timed from nothing."""
    before = os.environ.get("GYROGEN_CACHE")
    os.environ["GYROGEN_CACHE"] = str(tmp / "cache")
    try:
        yield
    finally:
        if before is None:
            del os.environ["GYROGEN_CACHE"]
        else:
            os.environ["GYROGEN_CACHE"] = before


def _pydy_runs(prob: Problem, cfg: Config, echo: Echo, progress: Echo) -> list[Run]:
    """PyDy's RHS is built from the full model: only the default scene matches it."""
    if not workprec.full_model(prob.scene):
        return []
    rhs = pydy_rhs(echo)
    if rhs is None:
        return []
    p = prob.p.copy()

    def f(t: float, x: np.ndarray) -> np.ndarray:
        return np.array(rhs(x, t, p), copy=True)  # PyDy reuses its output buffer

    return workprec.scipy_runs(prob, "PyDy cython RHS", f, cfg, progress, which=("DOP853",))


def summary(prob: Problem, runs: list[Run]) -> list[str]:
    """Markdown: the fastest contender at each error, and gyrogen against
    each peer, both read along the contenders' work-precision curves."""
    info = machine()
    lines = [f"# Work-precision: {prob.scene.name}", "", prob.scene.description, ""]
    lines += [f"- t in [0, {prob.t1:g}] s; reference: {prob.reference_name}"]
    lines += [f"- reference check, {k}: {v:.2e}" for k, v in prob.checks.items()]
    lines += [f"- {k}: {v}" for k, v in prob.notes.items()]
    lines += [f"- machine: {info['cpu']}; C flags {info['c_flags']}; {load()}"]
    lines += [
        "- each contender's time at an error level is read along its curve (the runs no "
        "faster run beats in accuracy), interpolated in log-log between the runs around it",
        "",
        "| error at most | fastest | time |",
        "|---|---|---|",
    ]
    labels = sorted({r.label for r in runs})
    for level in levels(prob):
        times = {lb: workprec.seconds_at(_by(runs, lb), level) for lb in labels}
        known = {lb: t for lb, t in times.items() if t is not None}
        if known:
            best = min(known, key=lambda lb: known[lb])
            lines.append(f"| {level:.0e} | {best} | {_time(known[best])} |")
    return [*lines, "", *against_peers(runs, levels(prob))]


def levels(prob: Problem) -> tuple[float, ...]:
    return QUAD_LEVELS if prob.quadruple else LEVELS


def load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min)"


def _time(seconds: float) -> str:
    return f"{seconds * 1e6:.3g} us" if seconds < 1e-3 else f"{seconds * 1e3:.3g} ms"


def _ratio(r: float) -> str:
    return f"{r:.2f}x" if r < 10 else f"{r:.0f}x"


def _by(runs: list[Run], label: str) -> list[Run]:
    return [r for r in runs if r.label == label]


def _peers(runs: list[Run]) -> list[str]:
    """The peers' labels: the compiled ones, PyDy, then scipy's fastest."""
    labels = sorted({r.label for r in runs if r.method.startswith(PEERS)})
    return labels + sorted({r.label for r in runs if "PyDy" in r.backend})


def against_peers(runs: list[Run], levels: tuple[float, ...] = LEVELS) -> list[str]:
    """Markdown: per error level, gyrogen's fastest compiled C run and each
    peer's time with the ratio peer / gyrogen."""
    peers = _peers(runs)
    scipy = [r for r in runs if r.method.startswith("scipy") and "PyDy" not in r.backend]
    head = ["error", "gyrogen (fastest C integrator)", *peers, "fastest scipy solve_ivp"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for level in levels:
        mine = _fastest([r for r in runs if r.backend == "C"], level)
        if mine is None:
            continue
        cells = [f"{level:.0e}", f"{mine[0]} {_time(mine[1])}"]
        for peer in peers:
            t = workprec.seconds_at(_by(runs, peer), level)
            cells.append("-" if t is None else f"{_time(t)} ({_ratio(t / mine[1])})")
        fastest = _fastest(scipy, level)
        if fastest is None:
            cells.append("-")
        else:
            label, t = fastest
            cells.append(f"{label} {_time(t)} ({_ratio(t / mine[1])})")
        out.append("| " + " | ".join(cells) + " |")
    return [
        "## gyrogen against its peers (peer time, and in brackets peer / gyrogen)",
        "",
        *out,
        "",
        "numbalsoda runs inside one @njit loop (no Python per integration); gyrogen "
        "through cffi (its call and a state copy included); CasADi one Function call each; "
        "heyoka one propagate_until each (its Python call floor in the notes above: heyoka's "
        "integrator cannot be called from a compiled loop through its Python package).",
    ]


def _fastest(runs: list[Run], level: float) -> tuple[str, float] | None:
    """The contender of runs fastest at level: (label, seconds)."""
    times = {lb: workprec.seconds_at(_by(runs, lb), level) for lb in {r.label for r in runs}}
    known = {lb: t for lb, t in times.items() if t is not None}
    return min(known.items(), key=lambda kv: kv[1]) if known else None


def table_csv(runs: list[Run]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(
        ["method", "backend", "setting", "error", "digits", "seconds", "rhs_calls", "status"]
    )
    for r in runs:
        w.writerow(
            [r.method, r.backend, f"{r.setting:g}", f"{r.error:.3e}", f"{r.digits:.2f}",
             f"{r.seconds:.6e}", r.rhs_calls, r.status]
        )  # fmt: skip
    return buf.getvalue()


def table_json(prob: Problem, runs: list[Run]) -> str:
    data: dict[str, Any] = {
        "scene": prob.scene.name,
        "t1": prob.t1,
        "reference_checks": prob.checks,
        "machine": machine(),
        "runs": [
            {**r.__dict__, "error": r.error if math.isfinite(r.error) else None} for r in runs
        ],
    }
    return json.dumps(data, indent=2, sort_keys=True) + "\n"


def figure(prob: Problem, runs: list[Run]) -> bytes:
    from matplotlib import colormaps
    from matplotlib.figure import Figure  # matplotlib: loaded only for the figure

    from gyrogen.analysis.simulate.plots import png_bytes

    fig = Figure(figsize=(14, 7), dpi=100)
    ax = fig.subplots()
    palette = colormaps["tab20"]
    labels = sorted({r.label for r in runs})
    for i, label in enumerate(labels):
        pts = sorted((r.seconds, r.error) for r in _by(runs, label) if r.status.startswith("ok"))
        if not pts:
            continue
        peer = label.startswith(PEERS)
        style = "--s" if "scipy" in label else ":D" if peer else "-o"  # gyrogen: solid
        ax.loglog(*zip(*pts, strict=True), style, label=label, color=palette(i % 20), ms=4)
    ax.set_xlabel("wall time per integration (s)")
    ax.set_ylabel("mixed error at t1: max |x - ref| / (1 + |ref|)")
    ax.set_title(f"Work-precision, scene {prob.scene.name} (t1 = {prob.t1:g} s)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(
        fontsize=8,
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        title="method (backend): gyrogen solid, compiled peers dotted, scipy dashed",
    )
    fig.tight_layout()
    return png_bytes(fig)


FILES = ("workprecision.png", "workprecision.csv", "workprecision.json", "summary.md")
"""What the report writes (`gyrogen bench` checks the way is clear before measuring)."""


def write(prob: Problem, runs: list[Run], out: Path) -> list[Path]:
    md = "\n".join(summary(prob, runs)) + "\n"
    contents: dict[str, str | bytes] = {
        "workprecision.png": figure(prob, runs),
        "workprecision.csv": table_csv(runs),
        "workprecision.json": table_json(prob, runs),
        "summary.md": md,
    }
    write_atomic(out, contents)
    return [out / n for n in FILES]
