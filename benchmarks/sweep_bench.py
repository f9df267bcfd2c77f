"""`make sweep-bench`: the sweep's figures on this machine, printed.

- the error of the chosen tolerance: the worst scaled error (workprec's)
  of 300 trajectories' final states against DOP853 at 1e-13;
- the bare batch compute: Compiled.integrate_batch on the same start states
  in chunks, on 1 and on 2 threads (the peer: no Dask, no metrics, no files),
  built as a sweep builds it (-march=native), and portable (`--portable`)
  on 1 thread: what portable code costs;
- end to end: `gyrogen sweep` as a user runs it (a new process, Parquet,
  summary and figures) with --workers 1 and 2, interleaved, best of
  --repeats; the overhead beyond the bare compute on as many threads;
- the scheduler's rate for empty tasks (the cluster estimate's input);
- with --memory N: the peak RSS of a sweep of N trajectories (its max RSS,
  getrusage's, as /usr/bin/time -v gives it);
- the fixed costs: the same sweep of 2 trajectories end to end (process,
  imports, build-cache look-up, engine, summary, figures);
- the per-chunk costs, phase by phase (benchmarks/sweep_bench_chunk.py);
- with --baseline REV: gyrogen as of that git revision (its generator/ and
  templates/ by git archive, first on PYTHONPATH), end to end beside this
  tree's in the same repeats: before and after, side by side;
- with --large N: end to end against the bare loop at N trajectories on 2
  threads (the bare loop then draws each chunk's start states in its loop:
  1.6% of the call), where the fixed costs weigh less.

    python benchmarks/sweep_bench.py --trajectories 1000000 --memory 10000000
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import NamedTuple

from sweep_bench_chunk import per_chunk

from gyrogen import api
from gyrogen.analysis.sweep.draws import inputs
from gyrogen.oracle.compare import scaled_error
from gyrogen.runtime.scene_build import compiled, scene_sources

GYROGEN = str(Path(sys.executable).with_name("gyrogen"))
SWEEP = """# make sweep-bench: Monte Carlo over the default scene's initial rates
scene = "gyrostat"
method = "dop853"
t_end = 10.0
rtol = {tol}
atol = {tol}
chunk = {chunk}
[draws]
seed = 1
count = {count}
u1 = {{ uniform = [-0.3, 0.3] }}
u3 = {{ uniform = [-0.3, 0.3] }}
u4 = {{ normal = [50.0, 5.0] }}
[metrics]
keep = ["final_state", "stats"]
"""


def error_of(spec: api.Spec, tol: float) -> float:
    model = api.compile(spec.scene)
    inp = inputs(spec, 0, 300)
    c = model.setup(inp.p[0])
    ref, _, _ = model.integrate_batch("dop853", inp.x0, c, 0.0, 10.0, rtol=1e-13, atol=1e-13)
    x, _, codes = model.integrate_batch("dop853", inp.x0, c, 0.0, 10.0, rtol=tol, atol=tol)
    assert not codes.any()
    return max(scaled_error(a, b) for a, b in zip(x, ref, strict=True))


class Timed(NamedTuple):
    wall: float
    cpu: float
    """CPU seconds (user + system) of every thread: what the load of the
    machine's other users changes least."""
    summary: dict


def wall_of(timed: Timed) -> float:
    return timed.wall


LAZY = 2 * 10**6
"""Above this many trajectories the bare loop draws each chunk's start states
in its loop (all of them beforehand would be 26 doubles a trajectory)."""


def bare(spec: api.Spec, tol: float, threads: int, chunk: int, portable: bool = False) -> Timed:
    """integrate_batch over every start state, chunk by chunk, on `threads`
    threads: each call on one core (threads=1: without it, OpenMP would put
    every call on every core and the 1-thread peer would run on two); the
    code built as a sweep builds it (-march=native), or portable."""
    model = compiled(scene_sources(spec.scene, portable))
    cuts = [(a, min(spec.size, a + chunk)) for a in range(0, spec.size, chunk)]
    starts = [inputs(spec, a, b) for a, b in cuts] if spec.size <= LAZY else []
    c = model.setup(inputs(spec, 0, 1).p[0])

    def one(k: int) -> None:
        x0 = starts[k].x0 if starts else inputs(spec, *cuts[k]).x0
        model.integrate_batch("dop853", x0, c, 0.0, 10.0, threads=1, rtol=tol, atol=tol)

    t0, cpu0 = time.perf_counter(), time.process_time()
    with ThreadPoolExecutor(threads) as pool:
        list(pool.map(one, range(len(cuts))))
    return Timed(time.perf_counter() - t0, time.process_time() - cpu0, {})


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def end_to_end(
    sweep_file: Path, out: Path, workers: int, env: dict[str, str] | None = None
) -> Timed:
    """`gyrogen sweep` in a new process (env: the baseline's PYTHONPATH)."""
    shutil.rmtree(out, ignore_errors=True)
    cmd = [GYROGEN, "sweep", str(sweep_file), "--out", str(out), "--quiet"]
    t0, cpu0 = time.perf_counter(), _children_cpu()
    subprocess.run([*cmd, "--workers", str(workers)], check=True, stdout=subprocess.DEVNULL,
                   env=env)  # fmt: skip
    wall, cpu = time.perf_counter() - t0, _children_cpu() - cpu0
    return Timed(wall, cpu, json.loads((out / "summary.json").read_text()))


def scheduler_rate(tasks: int) -> float:
    """Empty tasks per second through a local dask.distributed scheduler."""
    from distributed import Client, LocalCluster

    with (
        LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                     dashboard_address=":0", silence_logs=logging.CRITICAL) as cluster,
        Client(cluster) as client,
    ):  # fmt: skip
        client.gather(client.map(abs, range(100)))
        t0 = time.perf_counter()
        client.gather(client.map(abs, range(1, tasks + 1)))
        return tasks / (time.perf_counter() - t0)


RSS_PROBE = (
    "import resource, subprocess, sys; subprocess.run(sys.argv[1:], check=True); "
    "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)"
)
"""A process whose one child is the sweep: its children's max RSS (KB on
Linux) is the sweep's (what /usr/bin/time -v reports, with no system package)."""


def peak_rss(sweep_file: Path, out: Path) -> tuple[float, float]:
    """(max RSS in MB, wall seconds) of a sweep in a process of its own."""
    shutil.rmtree(out, ignore_errors=True)
    cmd = [GYROGEN, "sweep", str(sweep_file), "--out", str(out), "--quiet"]
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", RSS_PROBE, *cmd], check=True,
                          capture_output=True, text=True)  # fmt: skip
    wall = time.perf_counter() - t0
    return int(proc.stdout.split()[-1]) / 1024, wall


def baseline(rev: str, work: Path) -> dict[str, str]:
    """The environment that runs gyrogen as of rev (git archive of its
    generator/ and templates/, first on PYTHONPATH)."""
    root = Path(__file__).resolve().parent.parent
    there = work / "baseline"
    there.mkdir()
    tar = subprocess.run(["git", "-C", str(root), "archive", rev, "generator", "templates"],
                         check=True, capture_output=True).stdout  # fmt: skip
    subprocess.run(["tar", "-x", "-C", str(there)], input=tar, check=True)
    return {**os.environ, "PYTHONPATH": str(there / "generator")}


def ratios(label: str, runs: list[Timed], peer: list[Timed]) -> str:
    wall, cpu = min(map(wall_of, runs)), min(t.cpu for t in runs)
    every = ", ".join(f"{t.wall:.2f}" for t in runs)
    return (f"{label}: {wall:.2f} s (all: {every}), {wall / min(map(wall_of, peer)):.2f}x the bare "
            f"wall; CPU {cpu:.2f} s, {cpu / min(t.cpu for t in peer):.2f}x")  # fmt: skip


def report(
    size: int, bares: dict[int, list[Timed]], runs: dict[int, list[Timed]], portable: list[Timed]
) -> None:
    """Each figure best of the repeats, with every repeat shown."""
    best = {n: min(got, key=wall_of) for n, got in bares.items()}
    for what, of in (("wall", wall_of), ("CPU", lambda t: t.cpu)):
        if not portable:
            break
        slow, fast = min(map(of, portable)), min(map(of, bares[1]))
        print(
            f"portable code, bare, 1 thread: {what} {slow:.2f} s against {fast:.2f} s native "
            f"(all: {', '.join(f'{of(t):.2f}' for t in portable)}): "
            f"{(slow - fast) / size * 1e9:+.0f} ns/traj ({100 * (slow / fast - 1):+.1f}%)"
        )
    for n, got in bares.items():
        wall, cpu = best[n].wall, min(t.cpu for t in got)
        every = ", ".join(f"{t.wall:.2f}" for t in got)
        print(f"bare integrate_batch, {n} thread(s): {wall:.2f} s ({wall / size * 1e6:.2f} us/traj)"
              f" (all: {every}); CPU {cpu:.2f} s")  # fmt: skip
    for n, got in runs.items():
        wall, cpu, summary = min(got, key=wall_of)
        run, cpu = summary["run"], min(t.cpu for t in got)
        every = ", ".join(f"{t.wall:.2f}" for t in got)
        print(
            f"end to end, --workers {n}: {wall:.2f} s (all: {every})"
            f"; start-up {run['startup_s']:.2f} s, compute {run['wall_s']:.2f} s, tasks "
            f"{run['chunks_computed']} x {run['task_s_mean']:.3f} s, busy {run['busy_share']:.3f}"
            f"; overhead beyond bare ({n} thread(s)): wall {100 * (wall / best[n].wall - 1):.1f}%"
            f", CPU {cpu:.2f} s: {100 * (cpu / min(t.cpu for t in bares[n]) - 1):.1f}%"
        )
    e2e = {n: min(got, key=wall_of).wall for n, got in runs.items()}
    print(f"scaling 1 -> 2 workers (end to end): {e2e[1] / e2e[2]:.2f}x"
          f"; bare: {best[1].wall / best[2].wall:.2f}x")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--trajectories", type=int, default=10**6)
    ap.add_argument("--tol", type=float, default=1e-9)
    ap.add_argument("--chunk", type=int, default=20_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--portable", type=int, default=1, help="1: measure portable code, 0: not")
    ap.add_argument("--memory", type=int, default=0, help="trajectories of the memory run")
    ap.add_argument("--baseline", help="a git revision to run end to end beside this tree")
    ap.add_argument("--large", type=int, default=0, help="trajectories of the large run")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="sweep-bench-"))
    text = SWEEP.format(tol=args.tol, chunk=args.chunk, count=args.trajectories)
    sweep_file, tiny = work / "bench.toml", work / "tiny.toml"
    sweep_file.write_text(text)
    tiny.write_text(SWEEP.format(tol=args.tol, chunk=args.chunk, count=2))
    spec = api.load_sweep(text, "bench")
    print(f"load: {os.getloadavg()}  cores: {os.cpu_count()}")
    print(f"error at rtol = atol = {args.tol:g}: {error_of(spec, args.tol):.3g} (300 trajectories)")
    envs: dict[str, dict[str, str] | None] = {"this tree": None}
    if args.baseline:
        envs[f"baseline {args.baseline}"] = baseline(args.baseline, work)
    for env in envs.values():  # each code's sources rendered and built before any timing
        end_to_end(tiny, work / "warm", 2, env)
    bares: dict[int, list[Timed]] = {1: [], 2: []}
    runs: dict[int, list[Timed]] = {1: [], 2: []}
    others: dict[tuple[str, int], list[Timed]] = {(v, n): [] for v in envs for n in (2, 1)}
    fixed: dict[str, list[Timed]] = {v: [] for v in envs}
    portable: list[Timed] = []
    for _ in range(args.repeats):  # interleaved: each repeat sees the same load
        for n in (2, 1):
            bares[n].append(bare(spec, args.tol, n, args.chunk))
            for v, env in envs.items():
                others[v, n].append(end_to_end(sweep_file, work / f"e2e-{n}", n, env))
        runs = {n: others["this tree", n] for n in (2, 1)}
        for v, env in envs.items():
            fixed[v].append(end_to_end(tiny, work / "tiny", 2, env))
        if args.portable:
            portable.append(bare(spec, args.tol, 1, args.chunk, portable=True))
    report(spec.size, bares, runs, portable)
    print(f"side by side, {spec.size:,} trajectories, against the bare loop on as many threads:")
    for (v, n), got in others.items():
        print("  " + ratios(f"{v}, --workers {n}", got, bares[n]))
    for v, got in fixed.items():
        wall, cpu = min(map(wall_of, got)), min(t.cpu for t in got)
        print(f"  fixed costs, {v} (2 trajectories end to end): {wall:.2f} s wall, {cpu:.2f} s CPU")
    parts = sum(p.stat().st_size for p in (work / "e2e-2" / "parts").iterdir())
    print(f"Parquet: {parts / spec.size:.1f} bytes per trajectory ({parts / 1e6:.1f} MB)")
    per_chunk(spec, args.tol, args.chunk, work)
    print(f"scheduler: {scheduler_rate(5000):,.0f} empty tasks per second (local, 2 processes)")
    if args.large:
        big_text = SWEEP.format(tol=args.tol, chunk=args.chunk, count=args.large)
        big, big_spec = work / "large.toml", api.load_sweep(big_text, "large")
        big.write_text(big_text)
        peer: list[Timed] = []
        large: dict[str, list[Timed]] = {v: [] for v in envs}
        for _ in range(args.repeats):
            peer.append(bare(big_spec, args.tol, 2, args.chunk))
            for v, env in envs.items():
                large[v].append(end_to_end(big, work / "large", 2, env))
        print(f"{args.large:,} trajectories on 2 threads (load {os.getloadavg()[0]:.2f}):")
        print(f"  bare integrate_batch: {min(map(wall_of, peer)):.2f} s wall, "
              f"{min(t.cpu for t in peer):.2f} s CPU")  # fmt: skip
        for v, got in large.items():
            print("  " + ratios(f"{v}, --workers 2", got, peer))
    if args.memory:
        big = work / "memory.toml"
        big.write_text(SWEEP.format(tol=args.tol, chunk=args.chunk, count=args.memory))
        mb, wall = peak_rss(big, work / "memory")
        print(f"peak RSS, {args.memory:,} trajectories: {mb:.0f} MB ({wall:.1f} s)")
    print(f"load: {os.getloadavg()}")
    shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
