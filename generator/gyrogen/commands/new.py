"""`gyrogen new`: a commented starter scene to edit."""

from __future__ import annotations

import keyword
from pathlib import Path
from typing import TYPE_CHECKING

import click

from gyrogen.errors import GyrogenError, SceneError

if TYPE_CHECKING:
    pass


@click.command()
@click.argument("name")
@click.option(
    "--out", type=click.Path(dir_okay=False, path_type=Path), help="File [default: NAME.toml]."
)
@click.option("--force", is_flag=True, help="Overwrite an existing file.")
def new(name: str, out: Path | None, force: bool) -> None:
    """Write a commented starter scene NAME.toml to edit."""
    from gyrogen.codegen.render import render
    from gyrogen.files import write_atomic
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


command = new
