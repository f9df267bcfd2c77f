"""Run a sweep on Dask: chunks of trajectories as tasks, each chunk's rows
written as one Parquet file as soon as it comes back.

Engines: by default a local cluster in this process, one thread per core
(the compiled integrators release the GIL), with no set-up; or an existing
dask.distributed cluster (scheduler="tcp://HOST:PORT"). Either way the
client scatters the sweep and its generated sources to every worker once
(runtime/scene_build.py), submits chunk tasks a few at a time (so
neither the client nor the scheduler holds more than a window of results:
memory stays flat whatever the sweep's size), and writes each result as
<out>/parts/part-NNNNNN.parquet, atomically. A worker that dies loses
nothing: Dask reschedules its chunks. A rerun of the same sweep into the
same directory skips the parts already there (resume after a crash or
Ctrl-C); a directory holding another sweep is refused.
"""

from __future__ import annotations

import json
import os
import re
import sys
import threading
import time
import uuid
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gyrogen import __version__
from gyrogen.analysis.sweep.sweep_columns import PARTS
from gyrogen.analysis.sweep.sweep_dask import engine
from gyrogen.analysis.sweep.sweep_metrics import column_docs, run_chunk
from gyrogen.analysis.sweep.sweep_spec import Spec
from gyrogen.errors import GyrogenError
from gyrogen.files import can_write, make_dir, write_atomic
from gyrogen.runtime.flags import flags_for
from gyrogen.runtime.scene_build import Sources, code_digest, compiled, scene_sources

STATE_FILE = "sweep.json"
_PART = re.compile(r"part-(\d+)\.parquet")


@dataclass(frozen=True)
class Job:
    """What every worker gets once: the sweep, its sources, the chunk size,
    and the identity each part records."""

    spec: Spec
    sources: Sources
    chunk: int
    identity: dict[str, str] = field(default_factory=dict)

    @property
    def chunks(self) -> int:
        return -(-self.spec.size // self.chunk)

    def bounds(self, index: int) -> tuple[int, int]:
        return index * self.chunk, min(self.spec.size, (index + 1) * self.chunk)


def identity(spec: Spec, sources: Sources) -> dict[str, str]:
    """What a sweep's rows depend on besides its spec: gyrogen's version and
    code (the metrics, the draws), the generated sources (the integrators)
    and the flags they are built with. A resume continues only the same."""
    used = flags_for(sources.language, sources.portable)
    return {
        "gyrogen": __version__,
        "code": code_digest(),
        "build_id": sources.build_id,
        "sources": sources.digest,
        "flags": " ".join(used),
    }


def chunk_task(job: Job, index: int) -> tuple[bytes, float]:
    """On a worker: chunk index's rows as Parquet bytes, and the seconds
    they took (build excluded: it happens once per process)."""
    comp = compiled(job.sources)
    t0 = time.perf_counter()
    cols = run_chunk(comp, job.spec, *job.bounds(index))
    return parquet_bytes(cols, part_metadata(job)), time.perf_counter() - t0


def part_metadata(job: Job) -> dict[str, Any]:
    """What a part says of itself (Parquet schema metadata, readable without
    gyrogen): each column's unit and meaning, and the sweep's identity,
    spec, seed and scene."""
    spec = job.spec
    return {
        "columns": {n: {"unit": u, "meaning": m} for n, (u, m) in column_docs(spec).items()},
        "gyrogen": {
            "identity": job.identity,
            "sweep": spec.name,
            "spec": json.loads(spec.sweep.model_dump_json()),
            "seed": spec.sweep.draws.seed if spec.sweep.draws else None,
            "scene": spec.scene.name,
            "chunk": job.chunk,
        },
    }


def parquet_bytes(cols: dict[str, np.ndarray], metadata: dict[str, Any] | None = None) -> bytes:
    """The columns as one Parquet file (snappy, no dictionaries: a sweep's
    columns are mostly distinct doubles, whose dictionary pyarrow builds and
    then drops: 4x the write time, 12% larger); metadata (part_metadata):
    the fields' units and meanings, and the schema's "gyrogen" entry."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    names = list(cols)
    docs = (metadata or {}).get("columns", {})
    fields = [pa.field(n, pa.from_numpy_dtype(cols[n].dtype), metadata=docs.get(n)) for n in names]
    schema = pa.schema(fields, metadata={"gyrogen": json.dumps(metadata["gyrogen"])}
                       if metadata else None)  # fmt: skip
    table = pa.Table.from_arrays([arrow_array(cols[n]) for n in names], schema=schema)
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="snappy", use_dictionary=False)
    return bytes(sink.getvalue().to_pybytes())


def arrow_array(values: np.ndarray) -> Any:
    """A numeric numpy column as an Arrow array over its buffer (pa.array
    would import pandas to ask whether it is a Series: 0.5 s per process)."""
    import pyarrow as pa

    flat = np.ascontiguousarray(values)
    return pa.Array.from_buffers(
        pa.from_numpy_dtype(flat.dtype), len(flat), [None, pa.py_buffer(flat)]
    )


@dataclass
class Run:
    """How a sweep ran: what was skipped and computed, and the times."""

    out: Path
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


def part_name(index: int) -> str:
    return f"part-{index:06d}.parquet"


def written(out: Path) -> set[int]:
    """The chunks whose parts are in out."""
    try:
        names = os.listdir(out / PARTS)
    except FileNotFoundError:
        return set()
    except OSError as exc:
        raise GyrogenError(f"{out / PARTS}: cannot list it: {exc.strerror or exc}") from exc
    return {int(m.group(1)) for n in names if (m := _PART.fullmatch(n))}


def whole(path: Path, rows: int, ident: dict[str, str]) -> bool:
    """Whether the part at path is a complete Parquet file of rows rows (its
    footer read back) computed with this identity: a part cut short by a
    crash or a full disk is not."""
    import pyarrow.parquet as pq

    try:
        meta = pq.ParquetFile(path).metadata
        held = json.loads(meta.metadata[b"gyrogen"])["identity"]
        return bool(meta.num_rows == rows and held == ident)
    except Exception:  # pyarrow's errors for a damaged file vary: ArrowInvalid, OSError
        return False


def _state(out: Path) -> dict[str, Any] | None:
    """The sweep state out holds (None: none yet); obstacles refused."""
    parts, path = out / PARTS, out / STATE_FILE
    if os.path.lexists(parts) and not parts.is_dir():
        raise GyrogenError(f"{parts}: not a directory: remove it or use another --out")
    if not os.path.lexists(path):
        return None
    try:
        held = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        why = getattr(exc, "strerror", None) or exc
        raise GyrogenError(f"{path}: unreadable ({why}): remove it or use another --out") from exc
    if not isinstance(held, dict):
        raise GyrogenError(f"{path}: not a sweep's state: remove it or use another --out")
    return held


def _check_out(
    out: Path, spec: Spec, chunk: int, ident: dict[str, str], restart: bool
) -> dict[str, Any]:
    """Before any work: out can hold this sweep (nothing in the way, no other
    sweep in it, and a sweep begun there was computed with the same
    identity, unless restart); the state file to write."""
    state = {"sweep": spec.name, "fingerprint": spec.fingerprint(), "chunk": chunk}
    state |= {"trajectories": spec.size, "scene": spec.scene.name}
    held = _state(out)
    if held is None:
        if written(out):
            raise GyrogenError(f"{out / PARTS} holds parts but no {STATE_FILE}: remove it first")
        can_write(out, [STATE_FILE])
    elif {k: held.get(k) for k in state} != state:
        raise GyrogenError(
            f"{out} holds another sweep ({held.get('sweep')}, {held.get('trajectories')} "
            f"trajectories in chunks of {held.get('chunk')}): use another --out or remove it"
        )
    elif held.get("identity") != ident and not restart:
        was = held.get("identity") or {}
        changed = [k for k in ident if was.get(k) != ident[k]]
        raise GyrogenError(
            f"{out} holds this sweep begun with another build (changed: {', '.join(changed)}): "
            "its rows would mix two codes; --restart computes it anew, or use another --out"
        )
    return state | {"identity": ident}


def _claim(out: Path, job: Job, state: dict[str, Any]) -> set[int]:
    """out for this sweep: its state file written; the chunks whose parts
    are whole (a damaged one is removed, to be computed again)."""
    if _state(out) != state:  # new, or begun by another build and restarted
        for index in written(out):
            (out / PARTS / part_name(index)).unlink(missing_ok=True)
        write_atomic(out, {STATE_FILE: json.dumps(state, indent=1) + "\n"})
        return set()
    done = set()
    for index in written(out):
        a, b = job.bounds(index)
        path = out / PARTS / part_name(index)
        if index < job.chunks and whole(path, b - a, job.identity):
            done.add(index)
        else:
            print(f"{path}: damaged or cut short: computing it again", file=sys.stderr)
            path.unlink(missing_ok=True)
    return done


def run(
    spec: Spec,
    out: Path,
    *,
    scheduler: str | None = None,
    threads: int | None = None,
    chunk: int | None = None,
    progress: bool = True,
    restart: bool = False,
) -> Run:
    """Every chunk of spec not yet in out, computed and written; restart:
    begin anew where out holds this sweep begun by another build."""
    began = time.perf_counter()
    chunk = chunk or spec.sweep.chunk
    _state(out)  # obstacles first, before the seconds of deriving the sources
    sources = scene_sources(spec.scene)
    ident = identity(spec, sources)
    state = _check_out(out, spec, chunk, ident, restart)  # refusals first, before any work
    if scheduler is None:  # pyarrow's first write loads its codecs: not on the tasks' path
        threading.Thread(target=parquet_bytes, args=({"warm": np.zeros(1)},), daemon=True).start()
    job = Job(spec, sources, chunk, ident)
    with engine(scheduler, threads) as (client, name, n):
        make_dir(out)
        done = _claim(out, job, state)
        todo = (k for k in range(job.chunks) if k not in done)  # lazily: 10^9 chunks fit
        record = Run(out, job, name, n, skipped=len(done))
        shared = client.scatter(job, broadcast=True, hash=False)
        record.startup = time.perf_counter() - began
        started = time.perf_counter()
        _compute(client, shared, record, done, todo, progress)
        record.wall = time.perf_counter() - started
    return record


def _compute(
    client: Any, shared: Any, record: Run, done: set[int], todo: Iterator[int], progress: bool
) -> None:
    from distributed import as_completed
    from tqdm import tqdm

    job, parts = record.job, record.out / PARTS
    done_rows = sum(b - a for a, b in map(job.bounds, done))
    pending = todo
    futures = as_completed()
    # unique to this run: two clients on one scheduler never share a task
    key = f"gyrogen-sweep-{job.spec.fingerprint()}-{uuid.uuid4().hex[:12]}-{job.chunk}"

    def submit() -> None:
        index = next(pending, None)
        if index is not None:
            futures.add(client.submit(chunk_task, shared, index, key=f"{key}-{index}"))

    for _ in range(2 * record.threads + 2):
        submit()
    with tqdm(
        total=job.spec.size, initial=done_rows, unit="traj", unit_scale=True,
        file=sys.stderr, disable=not progress, mininterval=0.5, smoothing=0.1,
    ) as bar:  # fmt: skip
        for future in futures:
            index = int(future.key.rsplit("-", 1)[1])
            data, seconds = _result(future, index)
            write_atomic(parts, {part_name(index): data})
            record.task_seconds.append(seconds)
            a, b = job.bounds(index)
            record.rows += b - a
            bar.update(b - a)
            future.release()
            submit()


def _result(future: Any, index: int) -> tuple[bytes, float]:
    try:
        data, seconds = future.result()
    except GyrogenError:
        raise
    except Exception as exc:
        raise GyrogenError(f"chunk {index} failed: {type(exc).__name__}: {exc}") from exc
    return data, seconds
