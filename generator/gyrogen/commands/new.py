"""`gyrogen new`: a commented starter scene to edit."""

from __future__ import annotations

import os
from pathlib import Path

import click

from gyrogen.commands.options import STDOUT
from gyrogen.errors import GyrogenError, SceneError


def _file(ctx: click.Context, param: click.Parameter, value: str | None) -> Path | None:
    """--out names the file to write: not empty, and not a directory's
    spelling (DIR/, DIR/., DIR/..), which pathlib would read as DIR."""
    if value is None:
        return None
    if os.path.basename(value) in ("", ".", ".."):
        shown = f"{value!r} is empty" if not value else f"{value!r} names a directory"
        raise click.BadParameter(f"{shown}: give the file to write, as DIR/NAME.toml")
    return Path(value)


@click.command()
@click.argument("name")
@click.option(
    "--out",
    type=click.Path(dir_okay=False),
    callback=_file,
    help="File, created with any missing directories above it; - for standard output "
    "[default: NAME.toml].",
)
@click.option("--force", is_flag=True, help="Overwrite an existing file.")
def new(name: str, out: Path | None, force: bool) -> None:
    """Write a commented starter scene NAME.toml to edit."""
    from gyrogen.codegen.render import render
    from gyrogen.files import write_atomic
    from gyrogen.scene import parse
    from gyrogen.scene.rules import check_name

    try:
        check_name(name)  # before any path is made of it: a 300-character one was an OSError
    except ValueError as exc:
        raise SceneError(f"not a valid scene name: {exc}") from None
    text = render("scene/new.toml.jinja", name=name)
    if out is not None and str(out) == STDOUT:  # the scene alone, to pipe or redirect
        parse(text, name)
        click.echo(text, nl=False)
        return
    out = out or Path(f"{name}.toml")
    try:
        exists = out.exists()
    except OSError as exc:  # a name too long for the file system
        raise GyrogenError(f"cannot write {out}: {exc.strerror}") from None
    if exists and not force:
        raise GyrogenError(f"{out} exists: choose another name or pass --force")
    parse(text, str(out))  # the starter must itself be a valid scene
    write_atomic(out.parent if str(out.parent) else Path("."), {out.name: text})
    click.echo(f"wrote {out}: edit it, then `gyrogen generate {out}`")


command = new
