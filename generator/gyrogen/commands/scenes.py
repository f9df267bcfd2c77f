"""`gyrogen scenes`: the built-in scenes."""

from __future__ import annotations

import click

from gyrogen.commands.options import progress
from gyrogen.scene import builtin_names, load


@click.command()
@click.option(
    "--ops", is_flag=True, help="Also derive each scene for its op counts (a few seconds each)."
)
def scenes(ops: bool) -> None:
    """List the built-in scenes: name, description, attitude, states, runtime
    parameters, outputs and integrators (a file each under scenes/ in the
    package; copy one to start your own, or run `gyrogen new`)."""
    names = builtin_names()
    counts = _op_counts(names) if ops else {}
    for name in names:
        s = load(name)
        outs = [k for k, on in s.outputs.model_dump().items() if on]
        click.echo(f"{name:<18} {s.description}")
        click.echo(
            f"{'':<18} {s.attitude}; states {', '.join(s.states)}; "
            f"runtime {', '.join(s.runtime) or '-'}"
        )
        click.echo(
            f"{'':<18} outputs {', '.join(outs) or '-'}; integrators "
            f"{', '.join(s.integrators) or '-'}" + counts.get(name, "")
        )


def _op_counts(names: tuple[str, ...]) -> dict[str, str]:
    from gyrogen.codegen.generate import unit_of

    out = {}
    for name in progress("deriving", names):
        unit = unit_of(load(name))
        out[name] = f"; ops setup {unit.ops['setup']}, rhs {unit.ops['rhs']}"
    return out


command = scenes
