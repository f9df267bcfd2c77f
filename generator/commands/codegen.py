"""generate, scenes, new: from scene files to sources."""

from __future__ import annotations

import keyword
from pathlib import Path
from typing import TYPE_CHECKING

import click

from gyrogen.commands.options import SCENE, default_out, out_dir, progress
from gyrogen.errors import GyrogenError, SceneError
from gyrogen.scene import Scene, builtin_names, default, load

if TYPE_CHECKING:
    from gyrogen.unit import Unit


def _row(unit: Unit, full: Unit) -> str:
    outs = ", ".join(o.name for o in unit.outputs) or "-"
    return (
        f"{unit.prefix:<18} {unit.nx:>2}/{full.nx:<3} {unit.np:>3} {unit.nc:>3} "
        f"{unit.ops['setup']:>6} {unit.ops['rhs']:>5}  {outs}"
    )


def print_table(units: list[Unit]) -> None:
    from gyrogen.generate import full_model_unit

    full = full_model_unit()
    click.echo(f"{'scene':<18} {'states':<6} {'np':>3} {'nc':>3} {'setup':>6} {'rhs':>5}  outputs")
    for unit in units:
        click.echo(_row(unit, full))
    click.echo(
        f"{'(full model)':<18} {full.nx:>2}/{full.nx:<3} {full.np:>3} {full.nc:>3} "
        f"{full.ops['setup']:>6} {full.ops['rhs']:>5}"
    )
    click.echo("ops: sympy.count_ops summed over each function, temporaries and trig included")


@click.command()
@click.argument("scenes", type=SCENE, nargs=-1)
@click.option("--all", "every", is_flag=True, help="Every built-in scene.")
@click.option(
    "--lib", is_flag=True, help="Also write CMakeLists.txt and <prefix>.mk to build a library."
)
@out_dir
def generate(scenes: tuple[Scene, ...], every: bool, lib: bool, out: Path | None) -> None:
    """Write C, Fortran and manifest.json for each SCENE (a built-in name or a
    .toml file; default gyrostat). With one scene, --out is its directory;
    with several, --out is the parent of one directory per scene."""
    from gyrogen.generate import generate as run_generate

    chosen = [load(n) for n in builtin_names()] if every else list(scenes) or [default()]
    units = []
    for scene in progress("generating", chosen) if len(chosen) > 1 else chosen:
        if len(chosen) == 1:
            target = out or default_out(scene)
        else:
            target = (out or Path("generated")) / scene.name
        units.append(run_generate(scene, target, lib))
        click.echo(f"wrote {target}/")
    print_table(units)


@click.command()
def scenes() -> None:
    """List the built-in scenes: name, description, states and ops."""
    from gyrogen.unit import make_unit

    for name in builtin_names():
        s = load(name)
        unit = make_unit(s)
        click.echo(f"{name:<18} {s.description}")
        click.echo(
            f"{'':<18} states {', '.join(s.states)}; runtime {', '.join(s.runtime) or '-'}; "
            f"ops setup {unit.ops['setup']}, rhs {unit.ops['rhs']}"
        )


@click.command()
@click.argument("name")
@click.option(
    "--out", type=click.Path(dir_okay=False, path_type=Path), help="File [default: NAME.toml]."
)
@click.option("--force", is_flag=True, help="Overwrite an existing file.")
def new(name: str, out: Path | None, force: bool) -> None:
    """Write a commented starter scene NAME.toml to edit."""
    from gyrogen.generate import write_atomic
    from gyrogen.render import render
    from gyrogen.scene import parse

    if not name.isidentifier() or keyword.iskeyword(name) or not name.isascii():
        raise SceneError(f"{name!r} is not a valid scene name (a C identifier)")
    out = out or Path(f"{name}.toml")
    if out.exists() and not force:
        raise GyrogenError(f"{out} exists: choose another name or pass --force")
    text = render("scene/new.toml.jinja", name=name)
    parse(text, str(out))  # the starter must itself be a valid scene
    write_atomic(out.parent if str(out.parent) else Path("."), {out.name: text})
    click.echo(f"wrote {out}: edit it, then `gyrogen generate {out}`")


COMMANDS = [generate, scenes, new]
