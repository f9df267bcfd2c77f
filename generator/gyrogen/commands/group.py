"""The click group of every command, in NAMES' order, and one run of it:
errors as one line on stderr and their exit codes. Imported by cli.main
behind its Ctrl-C handling (it imports every command, and they numpy,
scipy and the rest)."""

from __future__ import annotations

import importlib
import sys

import click

from gyrogen import __version__
from gyrogen.commands import NAMES
from gyrogen.errors import GyrogenError


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="gyrogen")
def cli() -> None:
    """Equations of motion of a gyrostat (carrier + axisymmetric rotor) from
    Kane's method, as fast, verified C and Fortran right-hand sides."""


for _name in NAMES:
    cli.add_command(importlib.import_module(f"gyrogen.commands.{_name}").command)


def run(argv: list[str] | None) -> None:
    """The command line argv (None: the process's): one line per error, exit
    1 for failures, 2 for usage; click's Abort (a prompt's end of input) is
    a KeyboardInterrupt, which cli.main reports."""
    try:
        cli.main(args=argv, prog_name="gyrogen", standalone_mode=False)
    except click.UsageError as exc:
        where = exc.ctx.command_path if exc.ctx else "gyrogen"
        click.echo(f"{where}: error: {exc.format_message()} (see --help)", err=True)
        sys.exit(2)
    except click.Abort:
        raise KeyboardInterrupt from None
    except GyrogenError as exc:
        click.echo(f"gyrogen: error: {exc}", err=True)
        sys.exit(exc.exit_code)
