"""The `gyrogen` command line: each command parses options and calls one
function; errors are one line on stderr and a non-zero exit."""

from __future__ import annotations

import sys
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import click
import numpy as np

from gyrogen import __version__
from gyrogen.errors import GyrogenError
from gyrogen.scene import DEFAULT

_OUT_HELP = "Directory for <prefix>.h, <prefix>.c, <prefix>.f90 and manifest.json."


def _default_out() -> Path:
    return Path("generated") / DEFAULT.name


out_option = click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help=_OUT_HELP + " [default: generated/gyrostat]",
)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="gyrogen")
def cli() -> None:
    """Equations of motion of a gyrostat (carrier + axisymmetric rotor) from
    Kane's method, as fast, verified C and Fortran right-hand sides."""


@cli.command()
@out_option
def generate(out: Path | None) -> None:
    """Write the default scene's C, Fortran and manifest.json."""
    from gyrogen.generate import generate as run_generate

    out = out or _default_out()
    unit = run_generate(DEFAULT, out)
    click.echo(f"wrote {out}/: {', '.join(_file_names(unit.prefix))}")
    click.echo(f"ops: setup {unit.ops['setup']}, rhs {unit.ops['rhs']} per call; nc = {unit.nc}")


def _file_names(prefix: str) -> list[str]:
    return [f"{prefix}.h", f"{prefix}.c", f"{prefix}.f90", "manifest.json"]


@cli.command()
def prove() -> None:
    """Show that the lumped formulation equals the separate-body one."""
    from gyrogen.proof import prove as run_prove

    click.echo("Substituting the lumped inertia scalars into formulation (b), lumped carrier")
    click.echo("+ massless rotor, and subtracting formulation (a), two separate bodies:")
    results = run_prove()
    for c in results:
        verdict = "equal" if c.equal else f"DIFFERENT at {', '.join(c.nonzero)}"
        click.echo(f"  {c.what:<26} {c.entries:3d} entries: difference simplifies to 0: {verdict}")
    if not all(c.equal for c in results):
        raise GyrogenError("the two formulations differ")
    click.echo("The two formulations are identical.")


@cli.command()
@click.option("--latex", is_flag=True, help="Print LaTeX (align environments) instead of text.")
def equations(latex: bool) -> None:
    """Print both sets of equations of motion and the lumped scalars."""
    from gyrogen import show

    click.echo(show.latex() if latex else show.text())


@cli.command()
def ops() -> None:
    """Op counts of the raw, CSE-only and lumped + hoisted + CSE variants."""
    from gyrogen.opcounts import variants

    _print_ops(variants())


def _print_ops(rows: Iterable[Any]) -> None:
    click.echo(f"{'variant':<8} {'ops':>6}  what")
    for v in rows:
        click.echo(f"({v.key}){'':<{6 - len(v.key)}} {v.ops:6d}  {v.what}")


def _progress(label: str, items: Iterable[np.ndarray]) -> Iterable[np.ndarray]:
    with click.progressbar(list(items), label=f"comparing, {label}", file=sys.stderr) as bar:
        yield from bar


def _verify(source: Path, states: int, params: int, seed: int) -> bool:
    from gyrogen import build
    from gyrogen.verify import compare

    click.echo("building C (gcc) and Fortran (gfortran) through cffi ...")
    backends = [build.build(source, "c"), build.build(source, "fortran")]
    report = compare(backends, states, params, seed=seed, progress=_progress)
    click.echo(
        f"{states} random states x {report.n_params['well']} well-conditioned and "
        f"{report.n_params['ill']} ill-conditioned parameter sets; scaled error |a-b|/(1+|b|):"
    )
    for r in report.rows:
        mark = "ok" if r.passed else "FAIL"
        click.echo(
            f"  {r.group:<12} {r.pair:<22} {r.error:9.2e}  (bar {r.bar:8.2e}, "
            f"cond {r.worst_condition:8.3g})  {mark}"
        )
    click.echo(
        f"setup refusals: {report.refusals_checked - len(report.refusal_failures)}"
        f"/{report.refusals_checked} invalid parameter vectors refused with the documented code"
    )
    for f in report.refusal_failures:
        click.echo(f"  FAIL {f}")
    return report.passed


verify_options = [
    click.option("--states", default=10_000, show_default=True, help="Random states."),
    click.option("--params", default=100, show_default=True, help="Random parameter sets."),
    click.option("--seed", default=0, show_default=True, help="Random seed."),
]


def _with(options: list[Any]) -> Any:
    def deco(f: Any) -> Any:
        for opt in reversed(options):
            f = opt(f)
        return f

    return deco


@cli.command()
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), help=_OUT_HELP)
@_with(verify_options)
def verify(out: Path | None, states: int, params: int, seed: int) -> None:
    """Generate, build C and Fortran, compare both with the numpy reference."""
    from gyrogen.generate import generate as run_generate

    with tempfile.TemporaryDirectory(prefix="gyrogen-") as tmp:
        source = out or Path(tmp)
        run_generate(DEFAULT, source)
        if not _verify(source, states, params, seed):
            raise GyrogenError("verification failed: see the table above")


@cli.command()
@out_option
@_with(verify_options)
def run(out: Path | None, states: int, params: int, seed: int) -> None:
    """The main job: generate, build, verify, and summarize the default scene."""
    from gyrogen.generate import generate as run_generate
    from gyrogen.opcounts import variants

    out = out or _default_out()
    unit = run_generate(DEFAULT, out)
    click.echo(f"generated {out}/ ({', '.join(_file_names(unit.prefix))})")
    ok = _verify(out, states, params, seed)
    click.echo("op counts of the full model (sympy.count_ops, temporaries included):")
    _print_ops(variants())
    if not ok:
        raise GyrogenError("verification failed: see the table above")
    click.echo(f"all checks passed; sources in {out}/")


@cli.command("bench-rhs")
@click.option(
    "--out", type=click.Path(file_okay=False, path_type=Path), help="Write bench.json here."
)
@click.option("--repeats", default=5, show_default=True, help="Repeats per timing (best is kept).")
def bench_rhs(out: Path | None, repeats: int) -> None:
    """Time the RHS: cffi calls, batched C, numpy, and PyDy's cython."""
    from gyrogen import bench

    bench.run(out=out, repeats=repeats, echo=click.echo)


def main(argv: list[str] | None = None) -> None:
    """Entry point: one line per error, exit 1 for failures, 2 for usage."""
    try:
        cli.main(args=argv, prog_name="gyrogen", standalone_mode=False)
    except click.UsageError as exc:
        where = exc.ctx.command_path if exc.ctx else "gyrogen"
        click.echo(f"{where}: error: {exc.format_message()} (see --help)", err=True)
        sys.exit(2)
    except click.Abort:
        click.echo("gyrogen: aborted", err=True)
        sys.exit(130)
    except GyrogenError as exc:
        click.echo(f"gyrogen: error: {exc}", err=True)
        sys.exit(exc.exit_code)
