"""`gyrogen verify`: generated code against the numpy reference."""

from __future__ import annotations

import tempfile
from pathlib import Path

import click

from gyrogen.commands.options import SCENE, progress, verify_options
from gyrogen.errors import GyrogenError
from gyrogen.scene import Scene, default


def verify_sources(scene: Scene, source: Path, states: int, params: int, seed: int) -> bool:
    """Build every target of the scene in source and compare; print the table."""
    from gyrogen.oracle.compare import compare, given_parameters
    from gyrogen.runtime import build

    click.echo(f"building {', '.join(scene.targets)} through cffi ...")
    backends = [build.build(source, lang) for lang in scene.targets]
    report = compare(
        backends,
        scene,
        states,
        params,
        seed=seed,
        progress=lambda label, items: progress(f"comparing, {label}", items),
        given=given_parameters(scene),
    )
    click.echo(
        f"{scene.name}: {states} random states x {report.n_params['well']} well-conditioned and "
        f"{report.n_params['ill']} ill-conditioned parameter sets; error |a-b|/(1+|b|+S), S the "
        "sizes of the terms (see gyrogen.oracle.compare):"
    )
    for r in report.rows:
        mark = "ok" if r.passed else "FAIL"
        click.echo(
            f"  {r.group:<12} {r.pair:<38} {r.error:9.2e}  (bar {r.bar:8.2e}, "
            f"cond {r.worst_condition:8.3g})  {mark}"
        )
    click.echo(
        f"setup refusals: {report.refusals_checked - len(report.refusal_failures)}"
        f"/{report.refusals_checked} invalid parameter vectors refused with the documented code"
    )
    for f in report.refusal_failures:
        click.echo(f"  FAIL {f}")
    return report.passed


@click.command()
@click.argument("scene", type=SCENE, required=False)
@click.option(
    "--out", type=click.Path(file_okay=False, path_type=Path), help="Keep the sources here."
)
@verify_options
def verify(scene: Scene | None, out: Path | None, states: int, params: int, seed: int) -> None:
    """Generate SCENE (default gyrostat), build it, compare with the reference."""
    from gyrogen.codegen.generate import generate

    scene = scene or default()
    with tempfile.TemporaryDirectory(prefix="gyrogen-") as tmp:
        source = out or Path(tmp)
        generate(scene, source)
        if not verify_sources(scene, source, states, params, seed):
            raise GyrogenError("verification failed: see the table above")


command = verify
