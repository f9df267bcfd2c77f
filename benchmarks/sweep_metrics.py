"""`make bench-sweep-metrics`: what a sweep's sampled metrics and located
events cost over a final-state sweep, per chunk.

    python benchmarks/sweep_metrics.py [--baseline REV] [--rounds K] [--repeats R]
                                       [--methods dop853,taylor]

run_chunk over one chunk of 500 trajectories of the default scene (10 s,
rtol = atol = 1e-9, u1, u3 and u4 drawn), three sweeps: end (the final
state and statistics), sampled (and max_nutation, max_rate and
invariant_drift over 20 samples: the output grid) and time_to (and the
first time the nutation reaches 0.3 rad: an event located); with one
parameter set, and with a set per trajectory (I11 and J drawn too). Each
figure is the best of R repeats in each of K rounds, run in a process of
its own, timed by the thread's CPU time (run_chunk runs on one thread);
with --baseline, gyrogen as of REV (a git archive of its generator/ and
templates/) runs in the rounds between, so that the two are
measured side by side. The ratios are of one tree's figures. The load
average is printed before and after.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BASE = """
scene = "gyrostat"
method = "{method}"
t_end = 10.0
rtol = 1e-9
atol = 1e-9
chunk = 500
[draws]
seed = 2026
count = 500
{params}
u1  = {{ uniform = [-0.3, 0.3] }}
u3  = {{ uniform = [-0.3, 0.3] }}
u4  = {{ normal = [50.0, 2.0] }}
[metrics]
keep = {keep}
{extra}
"""
PER_TRAJECTORY = "I11 = { normal = [12.0, 0.3] }\nJ = { lognormal = [-3.5066, 0.05] }"
SAMPLED = '"max_nutation", "max_rate", "invariant_drift"'
SWEEPS = {
    "end": ('["final_state", "stats"]', ""),
    "sampled": (f'["final_state", "stats", {SAMPLED}]', "samples = 20"),
    "time_to": (
        f'["final_state", "stats", {SAMPLED}, "time_to"]',
        "samples = 20\ntime_to = { nutation = 0.3 }",
    ),
}
CASES = {"one set": "", "per trajectory": PER_TRAJECTORY}


def load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min), {os.cpu_count()} cpus"


def worker(methods: list[str], repeats: int) -> None:
    """One round in this process: each sweep's best run_chunk, as JSON."""
    from gyrogen import api
    from gyrogen.analysis.sweep.metrics import run_chunk
    from gyrogen.runtime.scene_build import compiled, scene_sources

    best: dict[str, float] = {}
    for method in methods:
        for case, params in CASES.items():
            texts = {
                name: BASE.format(method=method, keep=keep, extra=extra, params=params)
                for name, (keep, extra) in SWEEPS.items()
            }
            specs = {name: api.load_sweep(text) for name, text in texts.items()}
            comps = {name: compiled(scene_sources(s.scene)) for name, s in specs.items()}
            for _ in range(repeats):  # the sweeps interleaved
                for name, spec in specs.items():
                    t = time.thread_time()
                    run_chunk(comps[name], spec, 0, 500)
                    key = f"{method}|{case}|{name}"
                    best[key] = min(best.get(key, float("inf")), time.thread_time() - t)
    print(json.dumps(best))


def rounds(env: dict[str, str], args: argparse.Namespace) -> dict[str, float]:
    """One round of the worker in a process run with env."""
    cmd = [sys.executable, __file__, "--worker", "--repeats", str(args.repeats),
           "--methods", args.methods]  # fmt: skip
    out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
    return dict(json.loads(out.splitlines()[-1]))


def table(label: str, best: dict[str, float], methods: list[str]) -> None:
    print(f"\n{label}: run_chunk of 500 trajectories, CPU ms, and the ratio to end")
    print(f"  {'method':8} {'parameters':15} {'end ms':>8} {'sampled':>8} {'time_to':>8}")
    for method in methods:
        for case in CASES:
            end, sampled, time_to = (best[f"{method}|{case}|{s}"] for s in SWEEPS)
            print(f"  {method:8} {case:15} {end * 1e3:8.1f} {sampled / end:7.2f}x "
                  f"{time_to / end:7.2f}x")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", metavar="REV", default="")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--methods", default="dop853,taylor")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    methods = args.methods.split(",")
    if args.worker:
        worker(methods, args.repeats)
        return
    from sweep_bench import baseline

    print(load())
    here = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parent.parent / "generator")}
    with tempfile.TemporaryDirectory(prefix="gyrogen-sweep-metrics-") as tmp:
        trees = {"this tree": here}
        if args.baseline:
            trees[f"gyrogen as of {args.baseline}"] = baseline(args.baseline, Path(tmp))
        best: dict[str, dict[str, float]] = {label: {} for label in trees}
        for _ in range(args.rounds):  # the trees alternate
            for label, env in trees.items():
                for key, t in rounds(env, args).items():
                    best[label][key] = min(best[label].get(key, float("inf")), t)
    for label in trees:
        table(label, best[label], methods)
    print(f"\n{load()}")


if __name__ == "__main__":
    main()
