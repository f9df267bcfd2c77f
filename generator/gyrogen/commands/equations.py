"""`gyrogen equations`: both sets of equations of motion, as text or LaTeX."""

from __future__ import annotations

import click


@click.command()
@click.option("--latex", is_flag=True, help="Print LaTeX (align environments) instead of text.")
def equations(latex: bool) -> None:
    """Print both sets of equations of motion and the lumped scalars."""
    from gyrogen.symbolic import pretty

    click.echo(pretty.latex() if latex else pretty.text())


command = equations
