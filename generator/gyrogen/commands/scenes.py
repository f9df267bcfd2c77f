"""`gyrogen scenes`: the built-in scenes."""

from __future__ import annotations

from typing import TYPE_CHECKING

import click

from gyrogen.scene import builtin_names, load

if TYPE_CHECKING:
    pass


@click.command()
def scenes() -> None:
    """List the built-in scenes: name, description, states and ops."""
    from gyrogen.codegen.context import make_unit

    for name in builtin_names():
        s = load(name)
        unit = make_unit(s)
        click.echo(f"{name:<18} {s.description}")
        click.echo(
            f"{'':<18} states {', '.join(s.states)}; runtime {', '.join(s.runtime) or '-'}; "
            f"ops setup {unit.ops['setup']}, rhs {unit.ops['rhs']}"
        )


command = scenes
