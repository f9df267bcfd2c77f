"""prove, equations, ops: the symbolic side, for students of Kane's method."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import click

from gyrogen.errors import GyrogenError


@click.command()
def prove() -> None:
    """Show that the lumped formulation equals the separate-body one."""
    from gyrogen.proof import prove as run_prove

    click.echo("Substituting the lumped inertia scalars into formulation (b), lumped carrier")
    click.echo("+ massless rotor, and subtracting formulation (a), two separate bodies:")
    results = run_prove()
    for c in results:
        verdict = "equal" if c.equal else f"DIFFERENT at {', '.join(c.nonzero)}"
        click.echo(f"  {c.what:<26} {c.entries:3d} entries: difference simplifies to 0: {verdict}")
    if not all(c.equal for c in results):
        raise GyrogenError("the two formulations differ")
    click.echo("The two formulations are identical.")


@click.command()
@click.option("--latex", is_flag=True, help="Print LaTeX (align environments) instead of text.")
def equations(latex: bool) -> None:
    """Print both sets of equations of motion and the lumped scalars."""
    from gyrogen import show

    click.echo(show.latex() if latex else show.text())


@click.command()
def ops() -> None:
    """Op counts of the raw, CSE-only and lumped + hoisted + CSE variants."""
    from gyrogen.opcounts import variants

    print_ops(variants())


def print_ops(rows: Iterable[Any]) -> None:
    click.echo(f"{'variant':<8} {'ops':>6}  what")
    for v in rows:
        click.echo(f"({v.key}){'':<{6 - len(v.key)}} {v.ops:6d}  {v.what}")


COMMANDS = [prove, equations, ops]
