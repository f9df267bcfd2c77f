"""`gyrogen run`: the main job on the default scene."""

from __future__ import annotations

from pathlib import Path

import click

from gyrogen.commands.ops import print_ops
from gyrogen.commands.options import default_out, out_dir, verify_options
from gyrogen.commands.verify import verify_scene
from gyrogen.errors import GyrogenError
from gyrogen.scene import default


@click.command()
@out_dir
@verify_options
def run(out: Path | None, states: int, params: int, seed: int) -> None:
    """The main job: generate, build, verify, and summarize the default scene."""
    from gyrogen.codegen.generate import unit_of
    from gyrogen.symbolic.opcounts import variants

    scene = default()
    where = out or default_out(scene)

    def listing(names: list[str]) -> None:
        # the names written: the directory also holds, until the command ends,
        # the old versions its transaction keeps aside (gyrogen.files)
        click.echo(f"generated {where}/ ({', '.join(names)})")

    built, ok = verify_scene(scene, where, (states, params, seed), listing)
    click.echo("op counts of the full model (sympy.count_ops, temporaries included):")
    print_ops(variants(unit_of(scene).ops))
    if not ok:
        raise GyrogenError("verification failed: see the table above")
    click.echo(f"all checks passed; sources in {where}/ (build id {built})")


command = run
