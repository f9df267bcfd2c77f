"""`gyrogen generate`: from scene files to checked sources."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from gyrogen.commands.options import SCENE, default_out, out_dir, progress
from gyrogen.scene import Scene, builtin_names, default, load

if TYPE_CHECKING:
    from gyrogen.codegen.context import SceneContext


def _row(unit: SceneContext, full: Mapping[str, Any]) -> str:
    outs = ", ".join(o.name for o in unit.outputs) or "-"
    return (
        f"{unit.prefix:<18} {unit.nx:>2}/{full['nx']:<3} {unit.np:>3} {unit.nc:>3} "
        f"{unit.ops['setup']:>6} {unit.ops['rhs']:>5}  {outs}"
    )


def print_table(units: list[SceneContext], full: Mapping[str, Any]) -> None:
    """Each unit's sizes and op counts beside the full model's (full: its
    manifest, or manifest.sizes of its unit)."""
    nx, ops = full["nx"], full["ops"]
    click.echo(f"{'scene':<18} {'states':<6} {'np':>3} {'nc':>3} {'setup':>6} {'rhs':>5}  outputs")
    for unit in units:
        click.echo(_row(unit, full))
    click.echo(
        f"{'(full model)':<18} {nx:>2}/{nx:<3} {full['np']:>3} {full['nc']:>3} "
        f"{ops['setup']:>6} {ops['rhs']:>5}"
    )
    click.echo("ops: sympy.count_ops summed over each function, temporaries and trig included")


@click.command()
@click.argument("scenes", type=SCENE, nargs=-1)
@click.option("--all", "every", is_flag=True, help="Every built-in scene.")
@click.option(
    "--lib", is_flag=True, help="Also write CMakeLists.txt and <prefix>.mk to build a library."
)
@click.option(
    "--no-check",
    is_flag=True,
    help="Write without compiling and comparing first (see above): faster, unchecked.",
)
@out_dir
def generate(
    scenes: tuple[Scene, ...], every: bool, lib: bool, no_check: bool, out: Path | None
) -> None:
    """Write C, Fortran and manifest.json for each SCENE (a built-in name or a
    .toml file; default gyrostat). With one scene, --out is its directory;
    with several, --out is the parent of one directory per scene.

    Before writing, each scene's code is compiled (C with the strict flags,
    Fortran with -std=f2008 -Werror) and its rhs, outputs and Jacobian are
    compared with the numpy reference at a sample of states and parameter
    sets; on any failure nothing is written and the exit code is 1.
    --no-check skips this. With several scenes, every one is rendered and
    checked before any is written."""
    from gyrogen.codegen import buildfiles
    from gyrogen.codegen.generate import render_all, unit_of
    from gyrogen.codegen.manifest import sizes
    from gyrogen.errors import SceneError
    from gyrogen.files import can_write, claim, transaction, write_atomic
    from gyrogen.oracle.compare import check_rendered
    from gyrogen.runtime.scene_build import full_model_manifest, keep_sources

    chosen = [load(n) for n in builtin_names()] if every else list(scenes) or [default()]
    names = [scene.name for scene in chosen]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise SceneError(
            f"two scenes named {twice[0]!r}: each writes its own directory named after the "
            "scene, so the second would overwrite the first; give one another name"
        )
    if len(chosen) == 1:
        targets = [out or default_out(chosen[0])]
    else:
        targets = [(out or Path("generated")) / name for name in names]
    pairs = list(zip(chosen, targets, strict=True))
    for scene, target in pairs:  # every scene's, before any work
        claim(target, scene.name)
        can_write(target, [])
    # the full model every manifest compares with: the default scene's unit when it is
    # rendered here, else its manifest in the cache (which derives nothing when kept)
    full = sizes(unit_of(default())) if default() in chosen else full_model_manifest()
    rendered = []
    for scene, target in progress("generating", pairs) if len(pairs) > 1 else pairs:
        unit = unit_of(scene)
        files = render_all(unit, lib, full)
        can_write(target, files)  # before the check's seconds, not after
        rendered.append((scene, target, unit, files))
    if not no_check:
        for scene, _, unit, files in rendered:
            seconds = check_rendered(unit, files)
            click.echo(
                f"checked {scene.name}: {', '.join(scene.targets)} compiled and compared "
                f"with the reference in {seconds:.1f} s"
            )
    with transaction():  # every scene checked: now written, all or none
        for _, target, _, files in rendered:
            write_atomic(target, files)
    for scene, _, unit, files in rendered:  # verify and sweeps of them derive nothing again
        lib_files = buildfiles.names(unit.prefix)
        keep_sources(scene, unit.build_id, {n: t for n, t in files.items() if n not in lib_files})
    for _, target, _, _ in rendered:
        click.echo(f"wrote {target}/")
    print_table([unit for _, _, unit, _ in rendered], full)


command = generate
