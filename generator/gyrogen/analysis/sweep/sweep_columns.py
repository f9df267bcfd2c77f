"""A sweep's Parquet parts read back for its summary, one column at a time:
a column as one array (filled part by part: no second copy), columns in
sample order (for a grid's map), the counts of a code, and a metric's
spread and histogram in one pass over its values.

A sweep of 10^7 trajectories is summarized holding one column (80 MB) at a
time, never its rows."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

BINS = 50
LOG_SPAN = 100.0
"""A positive metric spanning more than this factor is binned on a log scale."""
PARTS = "parts"
NUMPY: dict[str, np.dtype[Any]] = {
    "double": np.dtype(np.float64),
    "int64": np.dtype(np.int64),
    "int32": np.dtype(np.int32),
}
"""The Arrow types of a part's columns (analysis/sweep_metrics.columns) as numpy's."""


def part_files(out: Path) -> list[Path]:
    return sorted((out / PARTS).glob("part-*.parquet"))


def column(out: Path, name: str) -> np.ndarray:
    """The column name of every part in out, in the parts' order."""
    import pyarrow.parquet as pq

    files = [pq.ParquetFile(f) for f in part_files(out)]
    values = np.empty(sum(f.metadata.num_rows for f in files), dtype=NUMPY[
                      str(files[0].schema_arrow.field(name).type)])  # fmt: skip
    at = 0
    for f in files:
        piece = numpy_of(f.read(columns=[name]).column(name))
        values[at : at + len(piece)] = piece
        at += len(piece)
    return values


def numpy_of(chunked: Any) -> np.ndarray:
    """A column read back (a pyarrow ChunkedArray of numbers, no nulls) as
    numpy, from its buffers: to_numpy would import pandas (0.17 s)."""
    dtype = NUMPY[str(chunked.type)]
    pieces = [
        np.frombuffer(c.buffers()[1], dtype=dtype, count=len(c), offset=c.offset * dtype.itemsize)
        for c in chunked.chunks
    ]
    return pieces[0] if len(pieces) == 1 else np.concatenate(pieces)


def in_order(out: Path, names: list[str]) -> dict[str, np.ndarray]:
    """Columns in sample order."""
    order = np.argsort(column(out, "sample"), kind="stable")
    return {n: column(out, n)[order] for n in names}


def counts(out: Path, name: str) -> dict[str, int]:
    """How many rows hold each value of an integer column (a code)."""
    import pyarrow.parquet as pq

    total: dict[int, int] = {}
    for path in part_files(out):
        # ParquetFile, not read_table: pyarrow.dataset would import pandas
        piece = numpy_of(pq.ParquetFile(path).read(columns=[name]).column(name))
        keys, found = np.unique(piece, return_counts=True)
        for k, c in zip(keys.tolist(), found.tolist(), strict=True):
            total[k] = total.get(k, 0) + c
    return {str(k): total[k] for k in sorted(total)}


@dataclass(frozen=True)
class Histogram:
    edges: np.ndarray
    counts: np.ndarray
    log: bool
    finite: int
    total: int


def log_scale(low: float, high: float) -> bool:
    return bool(low > 0 and high > LOG_SPAN * low)


def spread(values: np.ndarray) -> tuple[dict[str, float | int], Histogram]:
    """min, median, p99, max and mean of the finite values, and their
    histogram; values is reordered in place."""
    mask = np.isfinite(values)
    finite = values if mask.all() else values[mask]
    stats: dict[str, float | int] = {"finite": int(finite.size)}
    if not finite.size:
        return stats, Histogram(np.zeros(0), np.zeros(0), False, 0, values.size)
    low, high = float(finite.min()), float(finite.max())
    log = log_scale(low, high)
    if log:
        edges = np.logspace(np.log10(low), np.log10(high), BINS + 1)
    else:
        edges = np.linspace(low, high if high > low else low + 1.0, BINS + 1)
    histogram = Histogram(edges, np.histogram(finite, edges)[0], log, finite.size, values.size)
    stats["mean"] = float(finite.mean())
    q = np.quantile(finite, [0.5, 0.99], overwrite_input=True)
    stats |= {"min": low, "median": float(q[0]), "p99": float(q[1]), "max": high}
    return stats, histogram
