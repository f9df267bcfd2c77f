"""The benchmarks page of the documentation: measure, record, render.

    python tools/docs_bench.py run [--out docs/benchmarks] [--repeats R] [--full]
    python tools/docs_bench.py page [--dir docs/benchmarks]

``run`` times the generated right-hand sides as ``gyrogen bench-rhs`` does
(gyrogen.analysis.bench.rhs: one call through cffi in C and Fortran,
Compiled.rhs, the batched C loop, the numpy reference; PyDy's cython RHS
where PyDy is installed) and writes one JSON record into docs/benchmarks/
with the machine it ran on: CPU model, cores, load average before and
after, compiler, flags and library versions, the date and the command.
Without ``--full`` the loops are a tenth of bench-rhs's (a quick run).

``page`` renders every record as markdown; the documentation's hook
(docs/hooks/reference.py) calls it when the site is built, so the page
shows exactly what the records hold. ``make docs-bench`` runs ``run``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import sys
from datetime import UTC, datetime
from importlib.metadata import version
from pathlib import Path

HERE = Path(__file__).resolve().parents[1] / "docs" / "benchmarks"
LIBRARIES = ("gyrogen", "sympy", "numpy", "cffi", "scipy")


def _load() -> list[float]:
    return [round(v, 2) for v in os.getloadavg()]


def run(out: Path, repeats: int, full: bool, argv: list[str]) -> Path:
    from gyrogen.analysis.bench import rhs as bench_rhs
    from gyrogen.files import write_atomic

    before, started = _load(), datetime.now(UTC)
    scale = 1 if full else 10
    ms = bench_rhs.run(
        None,
        repeats,
        calls=bench_rhs.CALLS // scale,
        batch=bench_rhs.BATCH // scale,
    )
    machine = {
        **bench_rhs.machine(),
        "cores": str(os.cpu_count()),
        "load_before": before,
        "load_after": _load(),
        "platform": platform.platform(),
        "libraries": {name: version(name) for name in LIBRARIES},
    }
    record = {
        "bench": "rhs",
        "title": "Right-hand side of the default scene, per call and per state",
        "command": "python tools/docs_bench.py " + " ".join(argv),
        "date": started.isoformat(timespec="seconds"),
        "repeats": repeats,
        "quick": not full,
        "machine": machine,
        "measurements": [m.__dict__ for m in ms],
    }
    cpu = re.sub(r"[^a-z0-9]+", "-", machine["cpu"].lower()).strip("-")[:40]
    name = f"rhs-{started:%Y%m%d}-{cpu}.json"
    write_atomic(out, {name: json.dumps(record, indent=2) + "\n"})
    return out / name


def _record(path: Path) -> list[str]:
    r = json.loads(path.read_text(encoding="utf-8"))
    m = r["machine"]
    libs = ", ".join(f"{k} {v}" for k, v in m["libraries"].items())
    lines = [
        f"## {r['title']}",
        "",
        f"Recorded in `docs/benchmarks/{path.name}` by `{r['command']}`"
        f"{' (a quick run)' if r.get('quick') else ''}; best of {r['repeats']} repeats.",
        "",
        "| machine | |",
        "|---|---|",
        f"| date | {r['date'][:10]} |",
        f"| CPU | {m['cpu']} |",
        f"| cores | {m['cores']} ({m['nproc']} usable) |",
        f"| load average (1, 5, 15 min) | {_triple(m['load_before'])} before, "
        f"{_triple(m['load_after'])} after |",
        f"| C compiler | {m['gcc']} |",
        f"| Fortran compiler | {m['gfortran']} |",
        f"| C flags | `{m['c_flags']}` |",
        f"| Python | {m['python']} ({m['platform']}) |",
        f"| libraries | {libs} |",
        "",
        "| what | time | unit | how |",
        "|---|---|---|---|",
    ]
    lines += [
        f"| `{x['name']}` | {x['ns']:.1f} ns | per {x['unit']} | {x['detail']} |"
        for x in r["measurements"]
    ]
    return [*lines, ""]


def _triple(values: list[float]) -> str:
    return ", ".join(f"{v:.2f}" for v in values)


def page(directory: Path) -> str:
    """Every record in directory as markdown, newest first."""
    records = sorted(directory.glob("*.json"), reverse=True)
    if not records:
        return "No benchmark has been recorded yet: run `make docs-bench`.\n"
    return "\n".join(line for path in records for line in _record(path))


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="what", required=True)
    r = sub.add_parser("run", help="measure and write one JSON record")
    r.add_argument("--out", type=Path, default=HERE)
    r.add_argument("--repeats", type=int, default=5)
    r.add_argument("--full", action="store_true", help="bench-rhs's full loop lengths")
    p = sub.add_parser("page", help="print the page's markdown")
    p.add_argument("--dir", type=Path, default=HERE)
    args = parser.parse_args(argv)
    if args.what == "run":
        print(f"wrote {run(args.out, args.repeats, args.full, argv)}")
    else:
        print(page(args.dir))


if __name__ == "__main__":
    main(sys.argv[1:])
