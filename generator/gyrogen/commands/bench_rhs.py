"""`gyrogen bench-rhs`: how fast the generated right-hand side is."""

from __future__ import annotations

from pathlib import Path

import click

from gyrogen.analysis.bench import RHS_JSON
from gyrogen.commands.options import directory
from gyrogen.limits import MAX_REPEATS


@click.command("bench-rhs")
@directory("--out", f"Write {RHS_JSON} here.")
@click.option(
    "--repeats",
    type=click.IntRange(1, MAX_REPEATS),
    default=5,
    show_default=True,
    help="Repeats per timing (best is kept).",
)
def bench_rhs(out: Path | None, repeats: int) -> None:
    """Time the RHS: cffi calls, batched C, numpy, and PyDy's cython."""
    from gyrogen.analysis.bench import rhs

    rhs.run(out=out, repeats=repeats, echo=click.echo)


command = bench_rhs
