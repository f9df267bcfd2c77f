"""sweep: many trajectories of a scene over grids and Monte Carlo draws, on
this machine's cores or an existing Dask cluster, into Parquet."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import click

from gyrogen.commands.options import NO_STDOUT_DIRECTORY, STDOUT
from gyrogen.limits import MAX_SWEEP_CHUNK

ADDRESS = re.compile(r"tcp://[^\s:/]+:\d{1,5}")


class SweepType(click.ParamType):
    """A built-in sweep name or a path to a sweep file (.toml)."""

    name = "SWEEP"

    def convert(self, value: Any, param: Any, ctx: Any) -> Any:
        from gyrogen.analysis.sweep.spec import load

        return load(str(value))


class OutType(click.ParamType):
    """A directory, or an fsspec URL (PROTOCOL://PATH) checked before any work."""

    name = "DIR|URL"

    def convert(self, value: Any, param: Any, ctx: Any) -> Any:
        from gyrogen.analysis.sweep.store import store
        from gyrogen.errors import GyrogenError

        if value == STDOUT:
            self.fail(NO_STDOUT_DIRECTORY, param, ctx)
        try:
            where = store(value)  # what is a URL and what a path: decided there alone
        except GyrogenError as exc:
            self.fail(str(exc), param, ctx)
        if where.local:
            return click.Path(file_okay=False, path_type=Path).convert(value, param, ctx)
        return where


def _address(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    if value is not None and not ADDRESS.fullmatch(value):
        raise click.BadParameter(f"{value!r} is not tcp://HOST:PORT", ctx, param)
    if value is not None and not 1 <= int(value.rsplit(":", 1)[1]) <= 65535:
        raise click.BadParameter(f"{value!r}: the port must be 1 to 65535", ctx, param)
    return value


@click.command()
@click.argument("spec", metavar="SWEEP", type=SweepType())
@click.option(
    "--out",
    type=OutType(),
    help="Directory or fsspec URL (file:///PATH, s3://BUCKET/PATH) for the Parquet parts, "
    "summary and figures [default: sweep/<name>].",
)
@click.option(
    "--scheduler",
    callback=_address,
    help="Run on this dask.distributed scheduler (tcp://HOST:PORT) [default: this machine].",
)
@click.option(
    "--workers",
    type=click.IntRange(1, 1024),
    help="Threads of the local engine [default: one per core].",
)
@click.option(
    "--chunk",
    type=click.IntRange(1, MAX_SWEEP_CHUNK),
    help="Trajectories per task [default: the sweep's chunk].",
)
@click.option("--no-plots", is_flag=True, help="Skip histograms.png and map.png.")
@click.option("--quiet", is_flag=True, help="No progress bar, and no dashboard.")
@click.option(
    "--restart",
    is_flag=True,
    help="Compute anew where --out holds this sweep begun by another build (another gyrogen, "
    "generated code or flags): a resume continues only the same.",
)
@click.option(
    "--shared",
    is_flag=True,
    help="With --scheduler: every worker reaches --out (a shared file system at the same path, "
    "or a URL); each worker writes its parts there, and only each chunk's figures reach this "
    "process.",
)
@click.option(
    "--portable",
    is_flag=True,
    help="Build for any CPU of the architecture (no -march=native), for a cluster of mixed "
    "CPUs: slower [default: for the workers' CPU, recorded; workers of another are refused].",
)
def sweep(
    spec: Any,
    out: Any,
    scheduler: str | None,
    workers: int | None,
    chunk: int | None,
    no_plots: bool,
    quiet: bool,
    restart: bool,
    shared: bool,
    portable: bool,
) -> None:
    """Integrate every trajectory of SWEEP (a built-in sweep's name, such as
    stability_map: an unknown name lists them all; or a sweep file naming a
    scene) with the scene's compiled
    batch integrator, one Parquet row per trajectory with its inputs and
    metrics, written chunk by chunk; then summary.json, summary.md and
    figures. Rerun into the same --out to resume, with any --chunk: only
    what is left is computed, if this gyrogen, its generated code and its
    build flags are those that began the sweep (else refused: --restart);
    a part is kept only when its footer says it holds the samples of its
    name, of this sweep and build. One sweep writes an --out at a time: a
    second is refused while the first runs.
    Unless --quiet, the local engine serves a dashboard on 127.0.0.1 and
    prints its address on stderr."""
    from gyrogen.analysis.sweep import engine, report

    if scheduler is not None and workers is not None:
        raise click.UsageError("--workers sizes the local engine: not with --scheduler")
    if shared and scheduler is None:
        raise click.UsageError("--shared is for --scheduler: the local engine writes its parts")
    out = out or Path("sweep") / spec.name
    plots = None if no_plots else report.load_plots  # matplotlib while the chunks run
    with engine.run(
        spec,
        out,
        scheduler=scheduler,
        threads=workers,
        chunk=chunk,
        progress=not quiet,
        restart=restart,
        shared=shared,
        portable=portable,
        plots=not no_plots,
        meanwhile=plots,
    ) as record:  # out's lock held until the summary is written
        data = report.write(spec, record, plots=not no_plots)
    for line in report.markdown(data).splitlines()[2:]:
        if line and not line.startswith("|"):
            click.echo(line)
    shown = record.out.show()
    click.echo(f"wrote {shown}/ ({', '.join(data['files'])}; rows in {engine.PARTS}/)")


command = sweep
