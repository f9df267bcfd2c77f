"""simulate: integrate a scene with its compiled RHS and write the trajectory."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import click

from gyrogen import methods
from gyrogen.abi import MAX_STEPS
from gyrogen.commands.options import POSITIVE, SCENE, directory
from gyrogen.limits import MAX_OUTPUT_POINTS, MAX_RHS_CALLS
from gyrogen.scene import Scene, check_output_grid


@contextmanager
def time_bar(label: str) -> Iterator[Callable[[int], None]]:
    """A progress bar on stderr in percent of the simulated time."""
    with click.progressbar(length=100, label=label, file=sys.stderr) as bar:
        yield bar.update


@click.command()
@click.argument("scene", type=SCENE)
@directory(
    "--out", "Directory for the trajectory, summary, figure and sources [default: sim/<scene>]."
)
@click.option("--t-end", type=POSITIVE, default=None, help="End time, s [default: the scene's].")
@click.option(
    "--dt",
    type=POSITIVE,
    default=None,
    help=f"Output step, s, at most {MAX_OUTPUT_POINTS:,} in --t-end [default: the scene's].",
)
@click.option(
    "--method",
    type=click.Choice([methods.AUTO, *methods.SCIPY, *methods.NAMES]),
    default=methods.AUTO,
    show_default=True,
    help="Upper case: scipy solve_ivp; lower case: the scene's compiled integrators; "
    "auto: the scene's best compiled integrator of the kind its stiffness calls for "
    f"(radau5 or rodas4 if stiff, else {', '.join(methods.EXPLICIT_CHOICE)}: taylor where the "
    "rhs is smooth), scipy's Radau or DOP853 only "
    "when the scene compiled none of that kind.",
)
@click.option(
    "--max-nfev",
    type=click.IntRange(1, MAX_RHS_CALLS),
    default=MAX_STEPS,
    show_default=True,
    help="Give up after this many RHS calls.",
)
@click.option("--no-plot", is_flag=True, help="Skip trajectory.png.")
def simulate(
    scene: Scene,
    out: Path | None,
    t_end: float | None,
    dt: float | None,
    method: str,
    max_nfev: int,
    no_plot: bool,
) -> None:
    """Generate SCENE, build it, integrate it from simulate.initial with one
    of its compiled integrators or scipy's solve_ivp (--method), and write
    trajectory.csv, trajectory.npz, summary.json and trajectory.png with the
    invariants |H| in N and the energy balance. A scene with [[events]]
    also gets events.csv, the events located along the run (a compiled
    adaptive method's _events call); a terminal one ends the run there."""
    from gyrogen.analysis.simulate import engine as sim
    from gyrogen.analysis.simulate.result import Settings

    settings = Settings(
        t_end=t_end or scene.simulate.t_end,
        dt=dt or scene.simulate.dt,
        method=method,
        plot=not no_plot,
        max_nfev=max_nfev,
    )
    try:
        check_output_grid(settings.t_end, settings.dt)
    except ValueError as exc:  # an option, or the scene's t_end beside the default dt
        given = [f"'{n}'" for n, v in (("--t-end", t_end), ("--dt", dt)) if v is not None]
        hint = " / ".join(given) or "the scene's [simulate] t_end with dt's default (give --dt)"
        raise click.BadParameter(str(exc), param_hint=hint) from exc
    out = out or Path("sim") / scene.name
    echo = lambda s: click.echo(s, err=True)  # noqa: E731
    result = sim.run(scene, out, settings, progress=time_bar, echo=echo)
    for line in sim.summary_lines(result):
        click.echo(line)


command = simulate
