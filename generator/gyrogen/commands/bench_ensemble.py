"""`gyrogen bench-ensemble`: the lane-batched ensembles and the single
trajectory against numbalsoda and diffrax."""

from __future__ import annotations

from pathlib import Path

import click

from gyrogen.commands.options import directory
from gyrogen.limits import MAX_REPEATS


@click.command("bench-ensemble")
@click.option("--n", "n", type=click.IntRange(16, 10**6), default=10_000, show_default=True,
              help="Ensemble members.")  # fmt: skip
@click.option("--repeats", type=click.IntRange(1, MAX_REPEATS), default=5, show_default=True,
              help="Repeats per timing (best is kept).")  # fmt: skip
@click.option("--no-peers", is_flag=True, help="Skip numbalsoda, diffrax and heyoka.")
@directory(
    "--out",
    "Also write the report into this directory: ensemble.md, and ensemble_fronts.png with heyoka.",
)
def bench_ensemble(n: int, repeats: int, no_peers: bool, out: Path | None) -> None:
    """Ensembles (error <= 1e-8) and the single trajectory, side by side."""
    from gyrogen.analysis.bench import ensemble_report
    from gyrogen.files import write_atomic

    lines: list[str] = []

    def echo(line: str) -> None:
        lines.append(line)
        click.echo(line)

    figures = ensemble_report.run(n, repeats, peers_on=not no_peers, echo=echo)
    if out is not None:
        text = "# Ensembles: gyrogen's lanes against numbalsoda, diffrax and heyoka\n\n```\n"
        write_atomic(out, {"ensemble.md": text + "\n".join(lines) + "\n```\n", **figures})
        click.echo("wrote " + ", ".join(str(out / name) for name in ["ensemble.md", *figures]))


command = bench_ensemble
