"""`gyrogen bench`: the work-precision report of a scene."""

from __future__ import annotations

from pathlib import Path

import click

from gyrogen.commands.options import SCENE, directory
from gyrogen.scene import Scene, default


@click.command("bench")
@click.argument("scene", type=SCENE, required=False)
@click.option("--quick", is_flag=True, help="Fewer tolerances and repeats, C only (for CI).")
@directory("--out", "Where to write the figure and tables [default: report/<scene>].")
def bench(scene: Scene | None, quick: bool, out: Path | None) -> None:
    """Work-precision report: error against run time for every integrator of
    SCENE (default gyrostat) and for scipy and PyDy, in one run."""
    from gyrogen.analysis.bench import workprec, workprec_report
    from gyrogen.files import can_write

    scene = scene or default()
    workprec_report.check_scene(scene)  # before the first line of progress
    out = out or Path("report") / scene.name
    can_write(out, workprec_report.FILES)  # before the minutes of measuring
    cfg = workprec.QUICK if quick else workprec.FULL
    step = [0]

    def progress(label: str) -> None:
        step[0] += 1
        click.echo(f"  [{step[0]}] {label}", err=True)

    click.echo(
        f"measuring {scene.name} ({'quick' if quick else 'full'} configuration) ...", err=True
    )
    prob, runs = workprec_report.measure(scene, cfg, click.echo, progress)
    files = workprec_report.write(prob, runs, out)
    click.echo("\n".join(workprec_report.summary(prob, runs)))
    click.echo("wrote " + ", ".join(str(f) for f in files))


command = bench
