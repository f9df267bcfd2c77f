"""Run a sweep on Dask: chunks of trajectories as tasks, each chunk's rows
one Parquet part (analysis/sweep/parts.py).

Engines: by default a local cluster in this process, one thread per core
(the compiled integrators release the GIL), with no set-up; or an existing
dask.distributed cluster (scheduler="tcp://HOST:PORT"). Either way the
client scatters the sweep and its generated sources to every worker once
(runtime/scene_build.py builds them once per worker process), and submits
chunk tasks a few at a time (so neither the client nor the scheduler holds
more than a window of results: memory stays flat whatever the sweep's
size). Who writes a part: the worker that computed it, when the output
(a directory or an fsspec URL: analysis/sweep/store.py) is one every
worker reaches (the local engine; shared=True on a cluster with a shared
file system or a URL), and then only each chunk's figures come back; else
the client, from the bytes the task returns. A worker that dies
loses nothing: Dask reschedules its chunks. A rerun of the same sweep into
the same directory, with any chunk size, computes only what is left
(resume after a crash or Ctrl-C); a directory holding another sweep, or
this one begun by another build, is refused, and so is one that another
sweep is writing (analysis/sweep/lock.py: a sweep holds its output's
lock until its summary is written).

The code is built for the workers' CPU (-march=native: 3.6x faster than
portable code here), which the identity records: workers of different CPUs
are refused at the start, and a worker on another CPU that joins later
refuses its tasks, so no sweep mixes code that may round differently.
portable=True builds for any CPU of the architecture (a mixed cluster).
"""

from __future__ import annotations

import json
import socket
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gyrogen import __version__
from gyrogen.analysis.sweep.columns import PARTS
from gyrogen.analysis.sweep.dask_client import engine
from gyrogen.analysis.sweep.lock import Lock, take
from gyrogen.analysis.sweep.metrics import column_docs, run_chunk
from gyrogen.analysis.sweep.parts import (
    check_out,
    claim,
    clean,
    left,
    parquet_bytes,
    part_name,
    read_state,
    summary_files,
    write_part,
    written,
)
from gyrogen.analysis.sweep.spec import Spec
from gyrogen.analysis.sweep.store import Store, store
from gyrogen.errors import GyrogenError
from gyrogen.runtime.flags import flags_for, native_target
from gyrogen.runtime.scene_build import Sources, code_digest, compiled, scene_sources


@dataclass(frozen=True)
class Job:
    """What every worker gets once: the sweep, its sources, the chunk size,
    and the identity each part records."""

    spec: Spec
    sources: Sources
    chunk: int
    identity: dict[str, str] = field(default_factory=dict)
    parts: Store | None = None
    """The sweep's store when the workers write the parts into it (None: the client does)."""

    @property
    def chunks(self) -> int:
        return -(-self.spec.size // self.chunk)


def identity(spec: Spec, sources: Sources, cpu: str | None) -> dict[str, str]:
    """What a sweep's rows depend on besides its spec: gyrogen's version and
    code (the metrics, the draws), the generated sources (the integrators)
    and the flags they are built with (with -march=native, the CPU it means:
    cpu, the workers'). A resume continues only the same."""
    used = flags_for(sources.language, sources.portable)
    found = {
        "gyrogen": __version__,
        "code": code_digest(),
        "build_id": sources.build_id,
        "sources": sources.digest,
        "flags": " ".join(used),
    }
    return found | ({"cpu": cpu} if "-march=native" in used and cpu else {})


@dataclass(frozen=True)
class Done:
    """What a chunk task returns: its samples, the seconds they took (the
    build excluded: once per process), and the part's bytes when the client
    writes it (None: the worker wrote it)."""

    start: int
    stop: int
    seconds: float
    data: bytes | None


def chunk_task(job: Job, start: int, stop: int) -> Done:
    """On a worker: the rows of samples start..stop as a Parquet part,
    written into job.parts or returned."""
    if "cpu" in job.identity and (cpu := native_target()) != job.identity["cpu"]:
        raise GyrogenError(
            f"a worker's CPU is {cpu}, the sweep's {job.identity['cpu']}: code built with "
            "-march=native may round differently on each; --portable builds for any"
        )
    comp = compiled(job.sources)
    t0 = time.perf_counter()
    data = parquet_bytes(run_chunk(comp, job.spec, start, stop), part_metadata(job, start, stop))
    if (where := job.parts) is not None:
        if where.has_dirs and where.kind(PARTS) != "dir":  # the client made it: not seen here
            raise GyrogenError(
                f"{where.show(PARTS)} is not on the worker at {socket.gethostname()}: --shared "
                "needs --out on a file system every worker reaches at the same path or URL"
            )
        write_part(where, start, stop, data)
        return Done(start, stop, time.perf_counter() - t0, None)
    return Done(start, stop, time.perf_counter() - t0, data)


def part_metadata(job: Job, start: int, stop: int) -> dict[str, Any]:
    """What the part of samples start..stop says of itself (Parquet schema
    metadata, readable without gyrogen): each column's unit and meaning, and
    its samples, the sweep's fingerprint and identity (what a resume checks
    against its name and sweep.json: parts.verdict), spec, seed and
    scene."""
    spec = job.spec
    return {
        "columns": {n: {"unit": u, "meaning": m} for n, (u, m) in column_docs(spec).items()},
        "gyrogen": {
            "samples": [start, stop],
            "fingerprint": spec.fingerprint(),
            "identity": job.identity,
            "sweep": spec.name,
            "spec": json.loads(spec.sweep.model_dump_json()),
            "seed": spec.sweep.draws.seed if spec.sweep.draws else None,
            "scene": spec.scene.name,
            "chunk": job.chunk,
        },
    }


@dataclass
class Run:
    """How a sweep ran: what was skipped and computed, the times, and its
    parts; while open (with run(...) as record:), out's lock is held."""

    out: Store
    job: Job
    engine: str
    threads: int
    skipped: int = 0
    startup: float = 0.0
    """Seconds before the first task: sources, engine start, scatter."""
    wall: float = 0.0
    """Seconds from the first task submitted to the last part written."""
    task_seconds: list[float] = field(default_factory=list)
    rows: int = 0
    """Trajectories computed by this run."""
    parts: list[str] = field(default_factory=list)
    """The names of the sweep's parts in sample order: those found whole and
    those made (what its summary reads)."""
    lock: Lock | None = None

    def __enter__(self) -> Run:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """out's lock released: another sweep may write there."""
        if self.lock is not None:
            self.lock.release()
            self.lock = None


def run(
    spec: Spec,
    out: Path | Store,
    *,
    scheduler: str | None = None,
    threads: int | None = None,
    chunk: int | None = None,
    progress: bool = True,
    restart: bool = False,
    shared: bool = False,
    portable: bool = False,
    plots: bool = True,
    meanwhile: Callable[[], object] | None = None,
) -> Run:
    """Every sample of spec not yet in out, computed and written, out's
    lock held until the Run returned is closed (its summary written under
    it: with run(...) as record); restart:
    begin anew where out holds this sweep begun by another build; shared:
    the cluster's workers reach out at the same path and write the parts;
    portable: build for any CPU rather than the workers' (-march=native);
    plots: the summary's figures will be written (their places kept clear);
    meanwhile: run in a thread of its own once the first tasks are out (what
    the end will need: matplotlib's import)."""
    began = time.perf_counter()
    chunk = chunk or spec.sweep.chunk
    out, ends = store(out), summary_files(plots)
    read_state(out, ends)  # obstacles first, before the seconds of deriving the sources
    sources = scene_sources(spec.scene, portable)
    if scheduler is None:  # pyarrow's first write loads its codecs: not on the tasks' path
        threading.Thread(target=parquet_bytes, args=({"warm": np.zeros(1)},), daemon=True).start()
    writers = out.absolute() if scheduler is None or shared else None
    cpu = None if portable or scheduler else native_target()
    if scheduler is None:  # refusals first, before any work (a cluster's CPU is asked below)
        check_out(out, spec, identity(spec, sources, cpu), restart, ends)
    lock: Lock | None = None
    try:
        with engine(scheduler, threads, progress) as (client, name, n):
            if scheduler is not None and not portable:
                cpu = _cpu(client, scheduler)
            ident = identity(spec, sources, cpu)
            lock = take(out)
            state = check_out(out, spec, ident, restart, ends)  # again, under the lock
            job = Job(spec, sources, chunk, ident, writers)
            out.make_dir(PARTS)
            done = claim(out, state)
            record = Run(out, job, name, n, skipped=len(done), lock=lock)
            scattered = client.scatter(job, broadcast=True, hash=False)
            record.startup = time.perf_counter() - began
            started = time.perf_counter()
            todo = left(done, spec.size, chunk)
            made = _compute(client, scattered, record, done, todo, progress, meanwhile)
            record.wall = time.perf_counter() - started
        kept = sorted({*done, *made})
        _strays(out, set(kept))
    except BaseException:
        if lock is not None:
            lock.release()
        raise
    record.parts = [part_name(a, b) for a, b in kept]
    return record


def _compute(
    client: Any,
    scattered: Any,
    record: Run,
    done: list[tuple[int, int]],
    todo: Iterator[tuple[int, int]],
    progress: bool,
    meanwhile: Callable[[], object] | None = None,
) -> set[tuple[int, int]]:
    """The chunks of todo, a window at a time; the (start, stop) of the parts made."""
    from distributed import as_completed
    from tqdm import tqdm

    job, out, made = record.job, record.out, set()
    futures = as_completed()
    # unique to this run: two clients on one scheduler never share a task
    key = f"gyrogen-sweep-{job.spec.fingerprint()}-{uuid.uuid4().hex[:12]}"

    def submit() -> None:
        if (chunk := next(todo, None)) is not None:
            futures.add(client.submit(chunk_task, scattered, *chunk, key=f"{key}-{chunk[0]}"))

    for _ in range(2 * record.threads + 2):
        submit()
    if meanwhile is not None:
        threading.Thread(target=meanwhile, daemon=True).start()
    with tqdm(
        total=job.spec.size, initial=sum(b - a for a, b in done), unit="traj", unit_scale=True,
        file=sys.stderr, disable=not progress, mininterval=0.5, smoothing=0.1,
    ) as bar:  # fmt: skip
        for future in futures:
            got = _result(future)
            if got.data is not None:
                write_part(out, got.start, got.stop, got.data)
            made.add((got.start, got.stop))
            record.task_seconds.append(got.seconds)
            record.rows += got.stop - got.start
            bar.update(got.stop - got.start)
            future.release()
            submit()
    return made


def _result(future: Any) -> Done:
    try:
        got = future.result()
    except GyrogenError:
        raise
    except Exception as exc:
        start = future.key.rsplit("-", 1)[1]
        raise GyrogenError(
            f"the chunk from sample {start} failed: {type(exc).__name__}: {exc}"
        ) from exc
    assert isinstance(got, Done)
    return got


def _cpu(client: Any, scheduler: str) -> str:
    """The CPU every worker of the cluster has (what -march=native means
    there); workers of different CPUs refused."""
    cpus = set(client.run(native_target).values())
    if len(cpus) != 1:
        raise GyrogenError(
            f"--scheduler {scheduler}: the workers' CPUs differ ({', '.join(sorted(cpus))}): "
            "code built with -march=native may round differently on each; --portable builds "
            "for any"
        )
    return cpus.pop()


def _strays(out: Store, kept: set[tuple[int, int]]) -> None:
    """After the run: every part it made is in out (a worker that wrote
    elsewhere is refused), only this sweep's parts are (a task of an
    earlier, interrupted run on a cluster may have finished since), and no
    temporary of a worker killed mid-write."""
    found = written(out)
    if missing := kept - set(found):
        a, b = min(missing)
        raise GyrogenError(
            f"{out.show(PARTS, part_name(a, b))} and {len(missing) - 1} other parts are not "
            "there: a worker wrote them where this machine does not see (is --out shared?)"
        )
    for a, b in found:
        if (a, b) not in kept:
            print(f"{out.show(PARTS, part_name(a, b))}: not this run's: removed", file=sys.stderr)
            out.remove(PARTS, part_name(a, b))
    clean(out)
