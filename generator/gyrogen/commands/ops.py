"""`gyrogen ops`: op counts of the ways one could code the full model."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import click


@click.command()
def ops() -> None:
    """Op counts of the raw, CSE-only and lumped + hoisted + CSE variants."""
    from gyrogen.codegen.generate import full_model_unit
    from gyrogen.symbolic.opcounts import variants

    print_ops(variants(full_model_unit().ops))


def print_ops(rows: Iterable[Any]) -> None:
    click.echo(f"{'variant':<8} {'ops':>6}  what")
    for v in rows:
        click.echo(f"({v.key}){'':<{6 - len(v.key)}} {v.ops:6d}  {v.what}")


command = ops
