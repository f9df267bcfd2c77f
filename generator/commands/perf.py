"""bench-rhs: how fast the generated right-hand side is."""

from __future__ import annotations

from pathlib import Path

import click


@click.command("bench-rhs")
@click.option(
    "--out", type=click.Path(file_okay=False, path_type=Path), help="Write bench.json here."
)
@click.option("--repeats", default=5, show_default=True, help="Repeats per timing (best is kept).")
def bench_rhs(out: Path | None, repeats: int) -> None:
    """Time the RHS: cffi calls, batched C, numpy, and PyDy's cython."""
    from gyrogen import bench

    bench.run(out=out, repeats=repeats, echo=click.echo)


COMMANDS = [bench_rhs]
