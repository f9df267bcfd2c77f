"""bench-ensemble's table at errors 1e-6 to 1e-14: gyrogen's lanes
(dop853_batch and taylor_batch, the faster at each error) against heyoka's
taylor_adaptive_batch at its recommended
SIMD width, on one core and on two, each read along its work-precision
front (workprec.seconds_at: log-log between the tolerances around a level).

The error of a tolerance is the worst of the first CHECKED members against
heyoka's real128 reference of each (quadruple precision); the time is for
all N members. gyrogen runs integrate_batch with threads = 1 or 2 (OpenMP);
heyoka's propagate holds the GIL and its ensemble mode copies the
integrator per iteration, so its 2 cores are 2 worker processes (spawned,
each with the integrator, unpickled, and its half of the members sent once),
timed from the parent's request to the last final state back. Wall time is
what is compared; CPU time (this process and the workers, every thread) is
printed beside it, so that "2 cores" is seen to be two.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import pickle
import time
from collections.abc import Callable
from functools import partial
from multiprocessing.connection import Connection
from typing import Any

import numpy as np

from gyrogen import methods
from gyrogen.analysis.bench import ensemble as ens
from gyrogen.analysis.bench import heyoka_peer, workprec
from gyrogen.analysis.bench.workprec import Run
from gyrogen.analysis.bench.workprec_peers import HEYOKA_TAIL

LEVELS = (1e-6, 1e-8, 1e-10, 1e-12, 1e-14)
GYROGEN = {"dop853": ("g1", "g2"), "taylor": ("t1", "t2")}
"""gyrogen's batch methods in the table: each one's keys (1 core, 2 cores)."""
CHECKED = 200
"""Members whose worst error against the real128 reference rates a tolerance."""
Echo = Callable[[str], None]


def timed(fn: Callable[[], Any], repeats: int) -> tuple[float, float]:
    """(wall, CPU) seconds of fn's fastest of repeats runs (CPU: this
    process's, every thread)."""
    best = (np.inf, np.inf)
    for _ in range(max(1, repeats)):
        w0, c0 = time.perf_counter(), time.process_time()
        extra = fn()
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        if wall < best[0]:
            best = (wall, cpu + (extra if isinstance(extra, float) else 0.0))
    return best


def _worker(conn: Connection, x0s: np.ndarray) -> None:
    """A heyoka worker process: ("load", pickled Batch) -> True;
    ("run", None) -> (final states, CPU seconds); None ends it."""
    batch: Any = None
    while (msg := conn.recv()) is not None:
        kind, payload = msg
        if kind == "load":
            batch = pickle.loads(payload)
            heyoka_peer.one_thread()
            conn.send(heyoka_peer.module().get_nthreads())
        else:
            c0 = time.process_time()
            out = batch.run(x0s)
            conn.send((out, time.process_time() - c0))


class Workers:
    """count heyoka worker processes, each holding one slice of x0s."""

    def __init__(self, x0s: np.ndarray, count: int):
        ctx = mp.get_context("spawn")
        self.conns, self.procs = [], []
        for part in np.array_split(x0s, count):
            mine, theirs = ctx.Pipe()
            proc = ctx.Process(target=_worker, args=(theirs, part), daemon=True)
            proc.start()
            self.conns.append(mine)
            self.procs.append(proc)

    def load(self, batch: heyoka_peer.Batch) -> None:
        blob = pickle.dumps(batch)
        for conn in self.conns:
            conn.send(("load", blob))
        threads = [conn.recv() for conn in self.conns]
        if threads != [1] * len(self.conns):
            raise RuntimeError(f"heyoka's workers run {threads} threads, not 1 each")

    def run(self) -> tuple[np.ndarray, float]:
        """Every worker's final states, stacked, and their CPU seconds."""
        for conn in self.conns:
            conn.send(("run", None))
        parts = [conn.recv() for conn in self.conns]
        return np.concatenate([p[0] for p in parts]), sum(p[1] for p in parts)

    def close(self) -> None:
        for conn, proc in zip(self.conns, self.procs, strict=True):
            with contextlib.suppress(OSError):  # a worker that died has said why on stderr
                conn.send(None)
            proc.join(timeout=10)
            if proc.is_alive():
                proc.terminate()


LABELS = {
    "g1": "gyrogen dop853_batch (lanes), 1 core",
    "g2": "gyrogen dop853_batch (lanes), 2 cores (OpenMP)",
    "t1": "gyrogen taylor_batch (lanes), 1 core",
    "t2": "gyrogen taylor_batch (lanes), 2 cores (OpenMP)",
    "h1": "heyoka taylor_adaptive_batch, 1 core",
    "h2": "heyoka taylor_adaptive_batch, 2 processes",
}


def table(prob: ens.Problem, n: int, repeats: int, echo: Echo) -> dict[str, list[Run]]:
    """Measure and print the table (echo each line): each contender's runs
    by its LABELS key (none without heyoka)."""
    from gyrogen.codegen.generate import unit_of
    from gyrogen.scene import default

    hy = heyoka_peer.module()
    if hy is None:
        echo("heyoka skipped (No module named 'heyoka'): pip install -e '.[bench]'")
        return {}
    sys = heyoka_peer.system(hy, unit_of(default()))
    heyoka_peer.check(sys, prob.comp.rhs, prob.c, prob.x0, echo)
    heyoka_peer.one_thread()
    echo(f"heyoka's threads (set_nthreads): {hy.get_nthreads()} here and in each worker")
    x0s = ens.members(prob, n)
    few = x0s[:CHECKED]
    quad = heyoka_peer.Quad(sys, prob.c, prob.t1)
    ref = np.array([quad.final(x) for x in few])
    two = 2
    runs: dict[str, list[Run]] = {k: [] for k in LABELS}
    cpu: dict[str, list[Run]] = {k: [] for k in LABELS}

    def add(key: str, tol: float, err: float, wall: float, c: float) -> None:
        runs[key].append(Run(LABELS[key], "wall", tol, err, wall / n, 0))
        cpu[key].append(Run(LABELS[key], "CPU", tol, err, c / n, 0))

    workers = Workers(x0s, two)
    widths = set()
    try:  # each tolerance: gyrogen's then heyoka's, side by side under one load
        for tol in (*ens.LADDER, *HEYOKA_TAIL):
            for method, keys in GYROGEN.items():
                if tol not in ens.LADDER and not tol > methods.get(method).rtol_floor:
                    continue  # past the ladder: Taylor, whose error lags its tol as heyoka's
                err = ens.ensemble_error(ref, ens.finals(prob, few, tol, method=method))
                for key, threads in zip(keys, (1, two), strict=True):
                    run = partial(ens.finals, prob, x0s, tol, threads, method)
                    add(key, tol, err, *timed(run, repeats))
            batch = heyoka_peer.Batch(sys, prob.x0, prob.c, prob.t1, tol)
            widths.add(batch.width)
            err = ens.ensemble_error(ref, batch.run(few, checked=True))
            add("h1", tol, err, *timed(partial(batch.run, x0s), repeats))
            workers.load(batch)
            add("h2", tol, err, *timed(lambda: workers.run()[1], repeats))
    finally:
        workers.close()
    w = "/".join(str(x) for x in sorted(widths))
    echo(f"ensembles against heyoka (batch width {w}): {n} members, us per trajectory at the "
         f"worst error of the first {CHECKED} members against heyoka's real128 reference, "
         "read along each front; wall time:")  # fmt: skip
    _table(runs, echo)
    echo("CPU time (user + system of every thread and worker process):")
    _table(cpu, echo)
    echo("ratio: heyoka / gyrogen (above 1: gyrogen faster). CPU / wall at the runs: "
         + ", ".join(f"{k} {_spread(cpu[k], runs[k])}" for k in LABELS)
         + " (g: gyrogen, h: heyoka; 1 or 2 cores)")  # fmt: skip
    return runs


def _spread(cpu: list[Run], wall: list[Run]) -> str:
    ratios = [c.seconds / w.seconds for c, w in zip(cpu, wall, strict=True)]
    return f"{min(ratios):.2f}-{max(ratios):.2f}"


def _table(runs: dict[str, list[Run]], echo: Echo) -> None:
    head = ("error", "gyrogen lanes 1 core", "heyoka batch 1 core", "ratio",
            "gyrogen lanes 2 cores", "heyoka batch 2 processes", "ratio")  # fmt: skip
    echo("| " + " | ".join(head) + " |")
    echo("|" + "---|" * len(head))
    for level in LEVELS:
        t = {k: workprec.seconds_at(v, level) for k, v in runs.items()}
        cells = [f"{level:.0e}"]
        for cores, h in ((0, "h1"), (1, "h2")):
            times = {m: s for m, keys in GYROGEN.items() if (s := t[keys[cores]]) is not None}
            best = min(times, key=times.__getitem__) if times else None
            tg, th = (times[best] if best else None), t[h]
            ratio = "-" if tg is None or th is None else f"{th / tg:.2f}"
            cells += [_cell(tg) + (f" ({best})" if best else ""), _cell(th), ratio]
        echo("| " + " | ".join(cells) + " |")


def _cell(seconds: float | None) -> str:
    return "-" if seconds is None else f"{seconds * 1e6:.2f}"


def figure(runs: dict[str, list[Run]], n: int) -> bytes:
    """The four fronts: us per trajectory against the worst member's error."""
    from matplotlib.figure import Figure  # matplotlib: loaded only for the figure

    from gyrogen.analysis.simulate.plots import png_bytes

    fig = Figure(figsize=(10, 6), dpi=100)
    ax = fig.subplots()
    styles = {"g1": "-o", "g2": "-s", "t1": "-v", "t2": "-P", "h1": ":D", "h2": ":^"}
    for key, key_runs in runs.items():
        pts = [(r.seconds * 1e6, r.error) for r in workprec.front(key_runs)]
        if pts:
            ax.loglog(*zip(*pts, strict=True), styles[key], label=LABELS[key], ms=4)
    for level in LEVELS:
        ax.axhline(level, color="0.85", lw=0.8, zorder=0)
    ax.set_xlabel("us per trajectory (wall)")
    ax.set_ylabel(f"worst scaled error of {CHECKED} members vs real128")
    ax.set_title(f"Ensembles of {n}, default scene, 10 s: fronts (gyrogen solid, heyoka dotted)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return png_bytes(fig)
