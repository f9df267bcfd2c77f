"""`gyrogen ops`: op counts of the ways one could code the full model."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import click

from gyrogen.commands.options import SCENE
from gyrogen.errors import GyrogenError
from gyrogen.scene import Scene


@click.command()
@click.argument("scene", type=SCENE, required=False)
def ops(scene: Scene | None) -> None:
    """Op counts of the raw, CSE-only and lumped + hoisted + CSE variants of
    the full model; with SCENE, a cluster with rotors on gimbals: its rhs
    split into the same cluster with fixed axes, the carrier's 3x3 solve
    and the gimbals' kinematics."""
    if scene is not None:
        if not any(r.gimbal is not None for r in scene.rotors):
            raise GyrogenError(f"{scene.name}: no rotor on a gimbal; `gyrogen ops` alone "
                               "counts the full model's variants")  # fmt: skip
        from gyrogen.symbolic.opcounts import gimbal_split

        print_ops(gimbal_split(scene))
        return
    from gyrogen.codegen.generate import full_model_unit
    from gyrogen.symbolic.opcounts import variants

    print_ops(variants(full_model_unit().ops))


def print_ops(rows: Iterable[Any]) -> None:
    click.echo(f"{'variant':<8} {'ops':>6}  what")
    for v in rows:
        click.echo(f"({v.key}){'':<{6 - len(v.key)}} {v.ops:6d}  {v.what}")


command = ops
