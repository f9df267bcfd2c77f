"""A sweep's output directory: its state file (sweep.json), and its parts,
each the rows of the samples start..stop as one Parquet file named by them
(parts/part-<start>-<stop>.parquet), so that any chunk size can resume what
another began: what is left is the gaps between the parts that are whole,
cut at multiples of this run's chunk (a clean run's parts are the same
whatever was done before).

A part is what its footer says, not its name: a resume keeps a part only
when its footer records the samples of its name, as many rows, and the
sweep's fingerprint and identity as sweep.json has them, and its sample
column (read alone, not the other rows) is those samples, each once, in
order (verdict), and it overlaps no part kept before it; any other is
removed with a note saying which, why, and what of it is computed again
(claim), and a reader (api.read) refuses it. A part is written all or
nothing (Store.write: locally a temporary name, fsynced, renamed; store.py
says what holds for each URL protocol), by the client or by the worker
that computed it. A directory in the parts folder, or a part named for
samples outside the sweep's, is refused before any work (strays).
"""

from __future__ import annotations

import json
import re
import sys
from collections.abc import Iterator
from contextlib import suppress
from typing import Any

import numpy as np

from gyrogen.analysis.sweep.columns import PARTS, numpy_of, part_name, samples_of, written
from gyrogen.analysis.sweep.lock import LOCK
from gyrogen.analysis.sweep.spec import Spec
from gyrogen.analysis.sweep.store import Store
from gyrogen.errors import GyrogenError

STATE_FILE = "sweep.json"
STATE_KEYS = ("sweep", "fingerprint", "trajectories", "scene")
"""What check_out writes in STATE_FILE (and the identity, which a sweep
begun before it was recorded lacks: another build's); a file without them
is no sweep's."""
SUMMARY_JSON, SUMMARY_MD, HISTOGRAMS_PNG, MAP_PNG = (
    "summary.json",
    "summary.md",
    "histograms.png",
    "map.png",
)
SUMMARY_FILES = (SUMMARY_JSON, SUMMARY_MD, HISTOGRAMS_PNG, MAP_PNG)
"""What the sweep writes at its end (report.write; FIGURES only with
plots): nothing may be in their way, checked before any work with
sweep.json's and parts' places (summary_files)."""
FIGURES = (HISTOGRAMS_PNG, MAP_PNG)


def summary_files(plots: bool) -> tuple[str, ...]:
    """The SUMMARY_FILES a sweep writes, with its FIGURES or without (--no-plots)."""
    return SUMMARY_FILES if plots else tuple(n for n in SUMMARY_FILES if n not in FIGURES)


_STAGED = re.compile(r"\.part-.*\.(new|old)")
"""The temporary names of a part being written (files.write_atomic's, and
a URL store's): what a writer killed mid-write leaves."""


def write_part(out: Store, start: int, stop: int, data: bytes) -> None:
    out.write({part_name(start, stop): data}, PARTS)


def verdict(out: Store, start: int, stop: int, state: dict[str, Any]) -> str | None:
    """Why the part of samples start..stop is not this sweep's (None: it
    is), from its footer: the samples it records and its rows' count
    against its name, its fingerprint and identity against state
    (sweep.json's); then from its sample column alone (int64, 8 bytes a
    row): its rows are those samples, each once, in order."""
    import pyarrow.parquet as pq

    try:
        with out.open(PARTS, part_name(start, stop)) as source, pq.ParquetFile(source) as f:
            return _footer_verdict(f.metadata, start, stop, state) or _sample_verdict(
                f, start, stop
            )
    except Exception:  # pyarrow's errors for a damaged file vary: ArrowInvalid, OSError
        return "damaged or cut short"


def _footer_verdict(meta: Any, start: int, stop: int, state: dict[str, Any]) -> str | None:
    held = _recorded(meta)
    says = held.get("samples")
    if says != [start, stop]:
        if not (isinstance(says, list) and len(says) == 2):
            return "its footer records no samples"
        if all(type(n) is int for n in says):
            return f"holds samples {says[0]} to {says[1]} (its footer), not {start} to {stop}"
        shown = json.dumps(says)
        shown = shown if len(shown) <= 60 else shown[:57] + "..."
        return f"its footer records its samples as {shown}, not [{start}, {stop}]"
    if meta.num_rows != stop - start:
        return f"holds {meta.num_rows} rows (its footer), not {stop - start}"
    if held.get("fingerprint") != state["fingerprint"]:
        return "computed for another sweep (its footer)"
    if held.get("identity") != state["identity"]:
        return "computed with another build (its footer)"
    return None


def _sample_verdict(f: Any, start: int, stop: int) -> str | None:
    """Why the rows of the Parquet file f are not the samples start..stop,
    each once and in order (None: they are), from its sample column."""
    import pyarrow as pa

    if "sample" not in f.schema_arrow.names:
        return "holds no sample column"
    samples = f.read(columns=["sample"], use_threads=False).column(0)
    if samples.type != pa.int64() or samples.null_count:
        return f"its sample column is not integers (it is {samples.type})"
    if not np.array_equal(numpy_of(samples), np.arange(start, stop)):
        return f"its rows are not samples {start} to {stop}, each once, in order"
    return None


def _recorded(meta: Any) -> dict[str, Any]:
    """What a part's footer records of it (engine.part_metadata; {}: nothing)."""
    try:
        held = json.loads((meta.metadata or {})[b"gyrogen"])
    except (KeyError, ValueError):
        return {}
    return held if isinstance(held, dict) else {}


def strays(out: Store, size: int) -> None:
    """Before any work: a one-line GyrogenError for what the parts folder
    may not hold: anything but files (a directory, whatever its name), and
    a part whose name says samples not within the sweep's 0..size."""
    for name, kind in sorted(out.entries(PARTS).items()):
        if kind != "file":
            what = "a directory" if kind == "dir" else "not a file"
            raise GyrogenError(
                f"{out.show(PARTS, name)}: {what}, and the parts folder holds files only: "
                "remove it or use another --out"
            )
        if (said := samples_of(name)) and not 0 <= said[0] < said[1] <= size:
            raise GyrogenError(
                f"{out.show(PARTS, name)}: names samples {said[0]} to {said[1]}, not within "
                f"this sweep's 0 to {size}: not its part: remove it or use another --out"
            )


def trusted(out: Store) -> list[str]:
    """The names of the parts of the sweep in out, in sample order, each
    checked as a resume checks it (strays, overlaps, verdict) against
    out's sweep.json: a one-line GyrogenError for the first that fails."""
    state = read_state(out, ())
    if state is None:
        raise GyrogenError(f"{out.show()}: holds no sweep (no {STATE_FILE})")
    strays(out, state["trajectories"])
    names: list[str] = []
    end = 0
    for a, b in written(out):
        if a < end:
            raise GyrogenError(
                f"{out.show(PARTS, part_name(a, b))}: overlaps {names[-1]}: rerun the sweep to "
                "remove it (and compute what of it no other part holds)"
            )
        if (why := verdict(out, a, b, state)) is not None:
            raise GyrogenError(
                f"{out.show(PARTS, part_name(a, b))}: {why}: rerun the sweep to compute it again"
            )
        names.append(part_name(a, b))
        end = b
    return names


def read_state(out: Store, ends: tuple[str, ...] = SUMMARY_FILES) -> dict[str, Any] | None:
    """The sweep state out holds (None: none yet); obstacles refused: a
    parts that is no directory, a directory (or FIFO) where a file goes
    (the state file, the lock, and ends: the summary files the sweep will
    write)."""
    if out.kind(PARTS) not in ("absent", "dir"):
        raise GyrogenError(f"{out.show(PARTS)}: not a directory: remove it or use another --out")
    for name in (STATE_FILE, LOCK, *ends):
        if out.kind(name) not in ("absent", "file"):
            raise GyrogenError(
                f"{out.show(name)}: not a file, and the sweep writes one there: remove it or use "
                "another --out"
            )
    if out.kind(STATE_FILE) == "absent":
        return None
    path = out.show(STATE_FILE)
    try:
        held = json.loads(out.read_text(STATE_FILE))
    except (OSError, ValueError, RecursionError) as exc:  # RecursionError: [[[[... nested
        why = getattr(exc, "strerror", None) or exc
        raise GyrogenError(f"{path}: unreadable ({why}): remove it or use another --out") from exc
    missing = [k for k in STATE_KEYS if k not in held] if isinstance(held, dict) else None
    size = held.get("trajectories") if isinstance(held, dict) else None
    count = isinstance(size, int) and not isinstance(size, bool) and size >= 0
    if missing is None or missing or not isinstance(held.get("identity", {}), dict) or not count:
        why = ("not a JSON object" if missing is None else f"no {', '.join(missing)}" if missing
               else "its trajectories is not a count" if not count
               else "its identity is not a JSON object")  # fmt: skip
        raise GyrogenError(
            f"{path}: not a gyrogen sweep state ({why}): remove it or use another --out"
        )
    return held


def check_out(
    out: Store, spec: Spec, ident: dict[str, str], restart: bool, ends: tuple[str, ...]
) -> dict[str, Any]:
    """Before any work: out can hold this sweep (nothing in the way of its
    state, parts or ends, the summary files it will write; no other sweep in
    it, and a sweep begun there was computed with the same identity, unless
    restart; nothing in its parts folder but files, and no part named for
    samples not its own: strays); the state file to write. The chunk size
    is not the sweep's: another resumes it."""
    state: dict[str, Any] = {"sweep": spec.name, "fingerprint": spec.fingerprint()}
    state |= {"trajectories": spec.size, "scene": spec.scene.name}  # and identity: STATE_KEYS
    held = read_state(out, ends)
    if held is None:
        if written(out):
            raise GyrogenError(
                f"{out.show(PARTS)} holds parts but no {STATE_FILE}: remove it first"
            )
        out.can_write(STATE_FILE)
    elif {k: held.get(k) for k in state} != state:
        raise GyrogenError(
            f"{out.show()} holds another sweep ({held.get('sweep')}, {held.get('trajectories')} "
            "trajectories): use another --out or remove it"
        )
    elif held.get("identity") != ident and not restart:
        was = held.get("identity") or {}
        changed = [k for k in {**ident, **was} if was.get(k) != ident.get(k)]
        raise GyrogenError(
            f"{out.show()} holds this sweep begun with another build (changed: "
            f"{', '.join(changed)}): its rows would mix two codes; --restart computes it anew, "
            "or use another --out"
        )
    strays(out, spec.size)
    return state | {"identity": ident}


def claim(out: Store, state: dict[str, Any]) -> list[tuple[int, int]]:
    """out for this sweep (its lock held, check_out passed): its state file
    written, what a killed writer left removed; the (start, stop) of the
    parts that are whole, in order. One overlapping a part kept before it,
    or that is not what its name says (verdict), is removed, with a note
    saying which, why, and what of its samples is computed again: those
    no part kept holds (all, some or none)."""
    if read_state(out, ()) != state:  # new, or begun by another build and restarted
        for a, b in written(out):
            out.remove(PARTS, part_name(a, b))
        out.write({STATE_FILE: json.dumps(state, indent=1) + "\n"})
        return []
    clean(out)
    done: list[tuple[int, int]] = []
    dropped: list[tuple[int, int, str]] = []
    for a, b in written(out):
        overlap = done and a < done[-1][1]
        why = f"overlaps {part_name(*done[-1])}" if overlap else verdict(out, a, b, state)
        if why is None:
            done.append((a, b))
            continue
        out.remove(PARTS, part_name(a, b))
        dropped.append((a, b, why))
    for a, b, reason in dropped:
        held = sum(max(0, min(b, d) - max(a, c)) for c, d in done)  # the parts kept are disjoint
        then = ("computing it again" if not held
                else "removed: the parts kept hold all its samples" if held == b - a
                else f"removed: computing again the {b - a - held} of its {b - a} samples no part "
                     "kept holds")  # fmt: skip
        print(f"{out.show(PARTS, part_name(a, b))}: {reason}: {then}", file=sys.stderr)
    return done


def clean(out: Store) -> None:
    """Remove what a writer killed mid-write left (the parts' temporaries)."""
    try:
        names = out.listdir(PARTS)
    except GyrogenError:
        return
    for name in names:
        if _STAGED.fullmatch(name):
            with suppress(GyrogenError):
                out.remove(PARTS, name)


def left(done: list[tuple[int, int]], size: int, chunk: int) -> Iterator[tuple[int, int]]:
    """The (start, stop) still to compute, lazily (10^9 chunks fit): the gaps
    between the parts done, cut at multiples of chunk."""
    at = 0
    for a, b in [*done, (size, size)]:
        while at < a:
            stop = min(a, (at // chunk + 1) * chunk)
            yield at, stop
            at = stop
        at = max(at, b)


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
