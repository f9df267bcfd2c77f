"""linearize: the linear model A, B, C, D of a scene about an equilibrium."""

from __future__ import annotations

from pathlib import Path

import click

from gyrogen import methods
from gyrogen.commands.options import POSITIVE, SCENE, FiniteFloat, directory
from gyrogen.scene import Scene


def _pairs(value: str | None, flag: str) -> dict[str, float]:
    """'a=1,b=2' -> {a: 1.0, b: 2.0} (nan passes: the engine names it)."""
    if not value:
        return {}
    out: dict[str, float] = {}
    for item in value.split(","):
        name, eq, number = item.partition("=")
        try:
            if not eq or not name.strip():
                raise ValueError
            value_ = float(number)
        except ValueError:
            raise click.BadParameter(f"{item!r} is not NAME=NUMBER", param_hint=flag) from None
        if name.strip() in out:
            raise click.BadParameter(f"{name.strip()} is given twice", param_hint=flag)
        out[name.strip()] = value_
    return out


def _vector(value: str | None) -> list[float] | None:
    if value is None:
        return None
    try:
        return [float(v) for v in value.split(",")]
    except ValueError:
        raise click.BadParameter(
            f"{value!r} is not a comma-separated list of numbers", param_hint="--state"
        ) from None


@click.command()
@click.argument("scene", type=SCENE)
@click.option("--at", "at", default=None, metavar="NAME=V,...",
              help="The equilibrium by state name (others 0, e0 1).")  # fmt: skip
@click.option("--state", default=None, metavar="V1,V2,...",
              help="The equilibrium as the whole state vector, in the scene's order.")  # fmt: skip
@click.option("--param", "params", default=None, metavar="NAME=V,...",
              help="Runtime parameters [default: the scene's simulate.parameters].")  # fmt: skip
@click.option("--spin", type=FiniteFloat(), default=None,
              help="Find a steady spin at this rate, rad/s [default: the start's].")  # fmt: skip
@click.option("--axis", type=click.IntRange(1, 3), default=None,
              help="Find the spin about the principal axis nearest a1, a2 or a3 "
              "[default: nearest the start's w_A].")  # fmt: skip
@click.option("--along", is_flag=True,
              help="Linearize along the trajectory from the start (--at, --state, or the scene's "
              "simulate.initial) instead: the state transition matrix dx(t)/dx0 (and dx/dp "
              "for its [sensitivities]) every --dt to --t-end, into along.npz.")  # fmt: skip
@click.option("--t-end", type=POSITIVE, default=None,
              help="With --along: the end time, s [default: the scene's].")  # fmt: skip
@click.option("--dt", type=POSITIVE, default=None,
              help="With --along: the output step, s [default: the scene's].")  # fmt: skip
@click.option("--method", type=click.Choice(methods.NAMES), default="dop853", show_default=True,
              help="With --along: the compiled integrator of the variational system.")  # fmt: skip
@directory("--out", "Directory for linear.npz and poles.png, or along.npz and along.png "
           "[default: linear/<scene>].")  # fmt: skip
@click.option("--plot", is_flag=True, help="Also write poles.png (the pole map) or along.png.")
def linearize(
    scene: Scene,
    at: str | None,
    state: str | None,
    params: str | None,
    spin: float | None,
    axis: int | None,
    along: bool,
    t_end: float | None,
    dt: float | None,
    method: str,
    out: Path | None,
    plot: bool,
) -> None:
    """Linearize SCENE about an equilibrium: x' = A x + B u, y = C x + D u.

    The equilibrium is --at or --state if given, else the scene's
    `equilibrium`, else found: a steady spin about a principal axis (--spin,
    --axis) with each wheel at the rate its torque law holds. The inputs u
    are each rotor's motor torque, or its speed controller's w_ref; the
    outputs y the scene's outputs. About a spin the attitude and rotor
    angles turn and are left out. Writes linear.npz (A, B, C, D, their
    names, the point, the eigenvalues) and prints the modes in words:
    stable, unstable or marginal."""
    from gyrogen.analysis.linearize import engine, files

    if at is not None and state is not None:
        raise click.UsageError("--at and --state are exclusive: give the point one way")
    if along:
        _along(scene, at, state, params, spin, axis, t_end, dt, method, out, plot)
        return
    given = [flag for flag, v in (("--t-end", t_end), ("--dt", dt)) if v is not None]
    if given:
        raise click.UsageError(f"{given[0]} is for --along (the trajectory's times)")
    lin = engine.model(
        scene,
        state=_vector(state),
        at=_pairs(at, "--at") if at is not None else None,
        parameters=_pairs(params, "--param"),
        spin=spin,
        axis=axis,
    )
    if (line := files.warning(lin)) is not None:
        click.echo(f"gyrogen: {line}", err=True)
    written = files.write(lin, out or Path("linear") / scene.name, plot)
    for line in files.report(lin):
        click.echo(line)
    click.echo(f"wrote {', '.join(str(p) for p in written)}")


def _along(
    scene: Scene,
    at: str | None,
    state: str | None,
    params: str | None,
    spin: float | None,
    axis: int | None,
    t_end: float | None,
    dt: float | None,
    method: str,
    out: Path | None,
    plot: bool,
) -> None:
    """linearize --along: Phi on the output grid from the start."""
    import numpy as np

    from gyrogen.analysis.linearize import along, engine
    from gyrogen.scene.rules import check_output_grid

    if spin is not None or axis is not None:
        raise click.UsageError("--spin and --axis find an equilibrium: not with --along")
    if methods.get(method).fixed_step:
        raise click.BadParameter(f"{method} has no output grid: it is a fixed-step method",
                                 param_hint="--method")  # fmt: skip
    t_end, dt = t_end or scene.simulate.t_end, dt or scene.simulate.dt
    try:
        check_output_grid(t_end, dt)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--t-end / --dt") from exc
    if at is None and state is None:
        x0 = np.array(scene.initial_state())
    else:
        x0 = engine.state_of(scene, _vector(state), _pairs(at, "--at") if at is not None else None)
    p = engine.parameters_of(scene, _pairs(params, "--param"))
    run = along.along(scene, x0, p, method, t_end, dt)
    written = along.write(run, out or Path("linear") / scene.name, plot)
    for line in along.report(run):
        click.echo(line)
    click.echo(f"wrote {', '.join(str(p) for p in written)}")


command = linearize
