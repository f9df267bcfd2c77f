"""`gyrogen verify`: generated code against the numpy reference."""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import click

from gyrogen.commands.options import SCENE, directory, progress, verify_options
from gyrogen.errors import GyrogenError
from gyrogen.scene import Scene, default

if TYPE_CHECKING:
    from gyrogen.runtime.compiled import Compiled


def verify_scene(
    scene: Scene,
    directory: Path,
    counts: tuple[int, int, int],
    written: Callable[[list[str]], None] = lambda names: None,
) -> tuple[str, bool]:
    """Write the scene's sources into directory (written is told their
    names), build
    every target, compare with the reference at counts (states, parameter
    sets, seed) and print the table: the build id, and whether everything
    passed. The sources are the ones scene_sources renders, or keeps from
    the last render of this scene by this gyrogen and sympy (`gyrogen
    generate`'s, a sweep's): the same bytes, without deriving again."""
    from gyrogen.files import claim, write_atomic
    from gyrogen.runtime.scene_build import build_dir, scene_sources

    claim(directory, scene.name)
    sources = scene_sources(scene)
    write_atomic(directory, sources.files)
    written(sorted(sources.files))
    click.echo(f"building {', '.join(scene.targets)} through cffi ...")
    backends = build_dir(directory, scene.targets)
    return sources.build_id, _compare(scene, list(backends.values()), *counts)


def _compare(scene: Scene, backends: list[Compiled], states: int, params: int, seed: int) -> bool:
    from gyrogen.oracle.compare import compare, given_parameters

    report = compare(
        backends,
        scene,
        states,
        params,
        seed=seed,
        progress=lambda label, items: progress(f"comparing, {label}", items),
        given=given_parameters(scene),
    )
    mine = report.n_params.get("own", 0)
    own = f" ({report.n_params['well'] - mine} random, {mine} the scene's own)" if mine else ""
    click.echo(
        f"{scene.name}: {states} random states x {report.n_params['well']} well-conditioned"
        f"{own} and {report.n_params['ill']} ill-conditioned parameter sets; error "
        "|a-b|/(1+|b|+S), S the sizes of the terms (see gyrogen.oracle.compare):"
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
@directory("--out", "Keep the sources here.")
@verify_options
def verify(scene: Scene | None, out: Path | None, states: int, params: int, seed: int) -> None:
    """Generate SCENE (default gyrostat), build it, compare with the reference."""
    scene = scene or default()
    with tempfile.TemporaryDirectory(prefix="gyrogen-") as tmp:
        _, ok = verify_scene(scene, out or Path(tmp), (states, params, seed))
        if not ok:
            raise GyrogenError("verification failed: see the table above")


command = verify
