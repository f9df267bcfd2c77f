"""check: numerical stability on the built-in stiff and extreme cases."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

import click

from gyrogen.commands.options import directory, progress
from gyrogen.errors import GyrogenError, SceneError
from gyrogen.scene import load

if TYPE_CHECKING:
    from gyrogen.analysis.check.engine import Result


@click.command()
@click.argument("names", nargs=-1)
@click.option("--all", "every", is_flag=True, help="Every case (the default with no NAMES).")
@click.option("--quick", is_flag=True, help="Fewer and shorter cases (for CI, under a minute).")
@directory("--plots", "Write one PNG per case into this directory.")
@click.option("--list", "listing", is_flag=True, help="List the cases and exit.")
def check(
    names: tuple[str, ...], every: bool, quick: bool, plots: Path | None, listing: bool
) -> None:
    """Run stiff and extreme cases: pass or fail, invariant drift, stiffness,
    conditioning, step statistics, method, and a diagnosis. NAMES select
    the built-in cases whose name contains them, or name a scene (built-in or
    .toml) to check its own simulate settings."""
    from gyrogen.analysis.check import cases, engine
    from gyrogen.codegen.context import build_id
    from gyrogen.files import write_atomic
    from gyrogen.runtime.compiled import Compiled
    from gyrogen.runtime.scene_build import build_scene

    suite = cases.cases(quick)
    if names and not every:
        unknown = [
            n for n in names if not cases.is_scene(n) and not any(n in c.name for c in suite)
        ]
        for name in unknown:
            if name.endswith(".toml") or os.sep in name:
                load(name)  # a scene file that is not one: load's one line (exit 2)
        if unknown:
            raise SceneError(
                f"no case or scene matches {', '.join(unknown)} (see gyrogen check --list)"
            )
        scenes = [cases.scene_case(n) for n in names if cases.is_scene(n)]
        suite = scenes + [c for c in suite if any(n in c.name for n in names)]
    if listing:
        for case in suite:
            click.echo(f"{case.name:<48} expect {case.expect:<9} scene {case.scene.name}")
        return
    if plots is not None:
        write_atomic(plots, {})  # fail early, with one line, if plots is not writable
    compiled: dict[str, Compiled] = {}  # by build id: two scenes may share a name
    results = []
    with tempfile.TemporaryDirectory(prefix="gyrogen-check-") as tmp:
        for case in progress("checking", suite):
            key = build_id(case.scene)
            if key not in compiled and not case.refused_by:
                built = build_scene(case.scene, Path(tmp) / key, ["c"])
                compiled[key] = built["c"]
            res = engine.run_case(case, compiled.get(key))
            results.append(res)
            if plots is not None:
                from gyrogen.analysis.check.plots import png  # matplotlib: only for plots

                write_atomic(plots, {f"{_slug(case.name)}.png": png(res)})
    _table(results)
    failed = [r for r in results if not r.passed]
    if failed:
        raise GyrogenError(f"{len(failed)} of {len(results)} cases did not behave as expected")


def _slug(name: str) -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in name).strip("_")


def _table(results: list[Result]) -> None:
    click.echo(
        f"{'case':<46} {'result':<9} {'drift':>8} {'stiff':>8} {'cond':>8} "
        f"{'method':<7} {'steps':>9} {'rhs':>10}"
    )
    for r in results:
        drift = max(r.drift.values()) if r.drift else float("nan")
        mark = "ok" if r.passed else "FAIL"
        steps = r.stats.get("accepted", 0)
        click.echo(
            f"{r.case.name[:46]:<46} {r.verdict:<9} {drift:8.1e} {r.stiffness:8.1e} "
            f"{r.condition:8.1e} {r.method:<7} {steps:>9} {r.stats.get('rhs_calls', 0):>10} {mark}"
        )
        for line in (r.recommended if r.recommended.startswith("implicit") else "", r.diagnosis):
            if line:
                click.echo(f"    {line}")


command = check
