"""`gyrogen prove`: the lumped formulation equals the separate-body one."""

from __future__ import annotations

import click

from gyrogen.errors import GyrogenError


@click.command()
def prove() -> None:
    """Show that the lumped formulation equals the separate-body one."""
    from gyrogen.symbolic.proof import prove as run_prove

    click.echo("Substituting the lumped inertia scalars into formulation (b), lumped carrier")
    click.echo("+ massless rotor, and subtracting formulation (a), two separate bodies:")
    results = run_prove()
    for c in results:
        verdict = "equal" if c.equal else f"DIFFERENT at {', '.join(c.nonzero)}"
        click.echo(f"  {c.what:<26} {c.entries:3d} entries: difference simplifies to 0: {verdict}")
    if not all(c.equal for c in results):
        raise GyrogenError("the two formulations differ")
    click.echo("The two formulations are identical.")


command = prove
