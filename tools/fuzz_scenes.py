"""`make fuzz`: the scene-space property test at scale, with a fresh seed.

    python tools/fuzz_scenes.py [--examples N] [--jobs J] [--seed S] [--out DIR]
                                [--clusters | --gimbals]

Draws N scenes (default 2000) in J processes (default: every core), each a
shard of tests/scene_space.py's strategy with its own seed, checks each
(generate, compile with gcc, clang and gfortran -Werror, compare with the
reference, integrate), prints the counts, and writes a reproducing TOML for
every failure into DIR (default fuzz-failures/). Exit 1 if any failed.
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the strategies

from scene_space import run_shard
from scene_space_clusters import clusters

SHARD = 100
"""Examples per task: small enough that the progress line moves."""


def _task(seed: int, examples: int, out: str, kind: str) -> tuple[dict[str, int], list[str]]:
    """kind: "scenes", "clusters" or "gimbals" (clusters of control-moment gyros)."""
    drawn = {"scenes": None, "clusters": clusters(), "gimbals": clusters(gimbals=True)}[kind]
    with tempfile.TemporaryDirectory(prefix="gyrogen-fuzz-cache-") as cache:
        os.environ["GYROGEN_CACHE"] = cache  # builds die with the task: the disk stays clean
        return run_shard(seed, examples, Path(out), drawn)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--examples", type=int, default=2000)
    ap.add_argument("--jobs", type=int, default=len(os.sched_getaffinity(0)))
    ap.add_argument("--seed", type=int, default=None, help="default: a fresh one")
    ap.add_argument("--out", type=Path, default=Path("fuzz-failures"))
    kind = ap.add_mutually_exclusive_group()
    kind.add_argument("--clusters", action="store_true", help="draw [[rotors]] clusters instead")
    kind.add_argument(
        "--gimbals", action="store_true", help="draw clusters of control-moment gyros instead"
    )
    args = ap.parse_args()
    if args.examples < 1 or args.jobs < 1:
        ap.error("--examples and --jobs must be at least 1")
    base = args.seed if args.seed is not None else random.SystemRandom().randrange(2**31)
    sizes = [SHARD] * (args.examples // SHARD) + (
        [args.examples % SHARD] if args.examples % SHARD else []
    )
    drawn = "clusters" if args.clusters else "gimbals" if args.gimbals else "scenes"
    print(f"fuzz: {args.examples} scenes, seed {base}, {args.jobs} jobs, failures to {args.out}/")
    totals = {"examples": 0, "checked": 0, "refused": 0, "failed": 0}
    failures: list[str] = []
    t0 = time.monotonic()
    with ProcessPoolExecutor(args.jobs) as pool:
        futures = [
            pool.submit(_task, base + i, n, str(args.out), drawn) for i, n in enumerate(sizes)
        ]
        for fut in as_completed(futures):
            counts, found = fut.result()
            for k, v in counts.items():
                totals[k] += v
            failures += found
            rate = totals["examples"] / (time.monotonic() - t0)
            eta = (args.examples - totals["examples"]) / rate if rate else 0.0
            print(f"  {totals['examples']}/{args.examples} scenes, {totals['failed']} failed, "
                  f"{rate:.2f}/s, eta {eta / 60:.0f} min", flush=True)  # fmt: skip
    print(f"fuzz: {totals['examples']} scenes drawn (seed {base}): {totals['checked']} generated, "
          f"compiled and compared, {totals['refused']} refused as they should be, "
          f"{totals['failed']} failed, in {(time.monotonic() - t0) / 60:.1f} min")  # fmt: skip
    for f in failures:
        print("\n" + f.split("--- scene ---")[0].strip())
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
