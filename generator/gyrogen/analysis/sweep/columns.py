"""A sweep's Parquet parts read back for its summary, streamed: one part
open at a time, a few columns of it in memory, so that memory and open
files do not grow with the number of parts (10^4 parts are summarized
under `ulimit -n 256`).

A metric's spread (count, min, mean, max, its histogram, and the exact
median and p99 as numpy's default quantile gives them) takes a few passes
over the parts whatever their number: the first finds each column's range
and counts, the second bins the histogram and locates each wanted order
statistic's leading 16 bits (a radix select on the doubles' order-keeping
keys), and the next collects the few values that share those bits (or
narrows them by 16 more bits while too many do).

Columns in sample order (the map of a 2-D grid) are the one thing read
whole: the map has a cell per trajectory."""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gyrogen.analysis.sweep.store import Store, store

BINS = 50
LOG_SPAN = 100.0
"""A positive metric spanning more than this factor is binned on a log scale."""
PARTS = "parts"
NUMPY: dict[str, np.dtype[Any]] = {
    "double": np.dtype(np.float64),
    "int64": np.dtype(np.int64),
    "int32": np.dtype(np.int32),
}
"""The Arrow types of a part's columns (analysis/sweep/metrics.columns) as numpy's."""
QUANTILES = {"median": 0.5, "p99": 0.99}
RADIX = 16
"""Bits of an order statistic's key settled per counting pass."""
COLLECT = 1 << 20
"""An order statistic whose candidates are at most this many is collected and
selected in memory (8 MB), else narrowed by RADIX more bits."""
_SIGN = np.uint64(1 << 63)


DIGITS = 11
"""Sample indices in a part's name (MAX_SWEEP_TRAJECTORIES = 10^10 fits)."""
_PART = re.compile(rf"part-(\d{{{DIGITS}}})-(\d{{{DIGITS}}})\.parquet")


def part_name(start: int, stop: int) -> str:
    """The part of the rows of samples start..stop (analysis/sweep/parts.py)."""
    return f"part-{start:0{DIGITS}d}-{stop:0{DIGITS}d}.parquet"


def samples_of(name: str) -> tuple[int, int] | None:
    """The (start, stop) a part's name says (None: not a part's name)."""
    m = _PART.fullmatch(name)
    return (int(m[1]), int(m[2])) if m else None


def written(out: Store | Path) -> list[tuple[int, int]]:
    """The (start, stop) the names of the parts in out say, in order (what
    each holds is its footer's word: parts.verdict)."""
    return sorted(filter(None, map(samples_of, store(out).listdir(PARTS))))


def scan(out: Store | Path, parts: list[str], names: list[str]) -> Iterator[dict[str, np.ndarray]]:
    """The named columns of each of the parts in turn (one file open at a time)."""
    import pyarrow.parquet as pq

    where = store(out)
    for part in parts:
        with where.open(PARTS, part) as source, pq.ParquetFile(source) as f:
            table = f.read(columns=names)  # ParquetFile, not read_table: no pandas
        yield {n: numpy_of(table.column(n)) for n in names}


def column(out: Store | Path, parts: list[str], name: str) -> np.ndarray:
    """The column name of the parts, in their order."""
    return np.concatenate([part[name] for part in scan(out, parts, [name])])


def numpy_of(chunked: Any) -> np.ndarray:
    """A column read back (a pyarrow ChunkedArray of numbers, no nulls) as
    numpy, from its buffers: to_numpy would import pandas (0.17 s)."""
    dtype = NUMPY[str(chunked.type)]
    pieces = [
        np.frombuffer(c.buffers()[1], dtype=dtype, count=len(c), offset=c.offset * dtype.itemsize)
        for c in chunked.chunks
    ]
    if not pieces:
        return np.zeros(0, dtype)
    return pieces[0] if len(pieces) == 1 else np.concatenate(pieces)


def in_order(out: Store | Path, parts: list[str], names: list[str]) -> dict[str, np.ndarray]:
    """Columns of the parts in sample order."""
    order = np.argsort(column(out, parts, "sample"), kind="stable")
    return {n: column(out, parts, n)[order] for n in names}


@dataclass(frozen=True)
class Histogram:
    edges: np.ndarray
    counts: np.ndarray
    log: bool
    finite: int
    total: int


def log_scale(low: float, high: float) -> bool:
    return bool(low > 0 and high > LOG_SPAN * low)


def edges_of(low: float, high: float) -> tuple[np.ndarray, bool]:
    log = log_scale(low, high)
    if log:
        return np.logspace(np.log10(low), np.log10(high), BINS + 1), True
    return np.linspace(low, high if high > low else low + 1.0, BINS + 1), False


def keys(values: np.ndarray) -> np.ndarray:
    """Finite doubles as unsigned integers in the same order."""
    bits = values.view(np.uint64)
    return np.where(bits & _SIGN, ~bits, bits | _SIGN)


def value_of(key: int) -> float:
    bits = np.uint64(key)
    return float((~bits if not bits & _SIGN else bits & ~_SIGN).view(np.float64))


@dataclass
class _Rank:
    """An order statistic being found: its rank among the finite values,
    the leading bits of its key settled so far, and how many values lie
    below the keys that share them."""

    rank: int
    prefix: int = 0
    bits: int = 0
    below: int = 0
    counts: np.ndarray = field(default_factory=lambda: np.zeros(1 << RADIX, np.int64))
    found: list[np.ndarray] | None = None
    value: float | None = None
    buckets: list[np.ndarray] = field(default_factory=list)
    held: int = 0

    def shares(self, k: np.ndarray) -> np.ndarray:
        return k if self.bits == 0 else k[(k >> np.uint64(64 - self.bits)) == self.prefix]

    def take(self, k: np.ndarray) -> None:
        mine = self.shares(k)
        if self.found is not None:
            self.found.append(mine)
            return
        shift = np.uint64(64 - self.bits - RADIX)
        self.buckets.append((mine >> shift) & np.uint64((1 << RADIX) - 1))
        self.held += mine.size
        if self.held >= 1 << RADIX:  # counted a batch at a time: small parts are many
            self.count()

    def count(self) -> None:
        if self.buckets:
            self.counts += np.bincount(np.concatenate(self.buckets), minlength=1 << RADIX)
        self.buckets, self.held = [], 0

    def settle(self) -> None:
        """After a pass: the value when collected, else RADIX more bits."""
        if self.found is not None:
            mine = np.sort(np.concatenate(self.found))
            self.value = value_of(int(mine[self.rank - self.below]))
            return
        self.count()
        cumulative = np.cumsum(self.counts)
        b = int(np.searchsorted(cumulative, self.rank - self.below, side="right"))
        self.below += int(cumulative[b - 1]) if b else 0
        self.prefix, self.bits = (self.prefix << RADIX) | b, self.bits + RADIX
        if self.bits == 64:
            self.value = value_of(self.prefix)
        elif self.counts[b] <= COLLECT:
            self.found = []
        self.counts[:] = 0


@dataclass
class _Column:
    """One column's spread as the passes find it."""

    total: int = 0
    finite: int = 0
    low: float = np.inf
    high: float = -np.inf
    sum: float = 0.0
    hist: np.ndarray | None = None
    edges: np.ndarray | None = None
    log: bool = False
    ranks: dict[str, tuple[_Rank, _Rank, float]] = field(default_factory=dict)

    def first(self, finite: np.ndarray, total: int) -> None:
        self.total, self.finite = self.total + total, self.finite + finite.size
        if finite.size:
            self.low, self.high = min(self.low, finite.min()), max(self.high, finite.max())
            self.sum += float(finite.sum())

    def plan(self) -> None:
        """After the first pass: the bins, and the ranks each quantile needs
        (numpy's default: linear between the values at floor and ceil of
        (n - 1) q)."""
        if not self.finite:
            return
        self.edges, self.log = edges_of(float(self.low), float(self.high))
        self.hist = np.zeros(BINS, np.int64)
        for name, q in QUANTILES.items():
            at = (self.finite - 1) * q
            lo = int(np.floor(at))
            self.ranks[name] = (_Rank(lo), _Rank(min(lo + 1, self.finite - 1)), at - lo)

    def pending(self) -> list[_Rank]:
        return [r for a, b, _ in self.ranks.values() for r in (a, b) if r.value is None]

    def result(self) -> tuple[dict[str, float | int], Histogram]:
        stats: dict[str, float | int] = {"finite": self.finite}
        if not self.finite:
            return stats, Histogram(np.zeros(0), np.zeros(0), False, 0, self.total)
        assert self.edges is not None and self.hist is not None
        stats["mean"] = self.sum / self.finite
        got = {n: _lerp(a.value, b.value, g) for n, (a, b, g) in self.ranks.items()}
        stats |= {"min": float(self.low), "median": got["median"], "p99": got["p99"]}
        stats["max"] = float(self.high)
        return stats, Histogram(self.edges, self.hist, self.log, self.finite, self.total)


def _lerp(a: float | None, b: float | None, t: float) -> float:
    """numpy's interpolation between two order statistics (exactly)."""
    assert a is not None and b is not None
    return float(np.quantile(np.array([a, b]), t)) if a != b else a


Spread = tuple[dict[str, float | int], Histogram]


def spreads(
    out: Store | Path, parts: list[str], names: list[str], counted: tuple[str, ...] = ()
) -> tuple[dict[str, dict[str, int]], dict[str, Spread]]:
    """How many rows hold each value of the counted (integer) columns, and
    each named column's min, median, p99, max and mean over its finite
    values, and its histogram, streamed over the parts (names in out)."""
    found = {n: _Column() for n in names}
    tallies: dict[str, dict[int, int]] = {n: {} for n in counted}
    for part in scan(out, parts, [*counted, *(n for n in names if n not in counted)]):
        for n, tally in tallies.items():
            keys_, seen = np.unique(part[n], return_counts=True)
            for k, c in zip(keys_.tolist(), seen.tolist(), strict=True):
                tally[k] = tally.get(k, 0) + c
        for n, c in found.items():
            v = part[n].astype(np.float64, copy=False)  # a count too
            c.first(v[np.isfinite(v)], v.size)
    for c in found.values():
        c.plan()
    first = bool(found)
    while first or any(c.pending() for c in found.values()):
        for part in scan(out, parts, names):
            for n, c in found.items():
                v = part[n].astype(np.float64, copy=False)
                v = v[np.isfinite(v)]
                if first and c.hist is not None and c.edges is not None:
                    c.hist += np.histogram(v, c.edges)[0]
                k = keys(v)
                for r in c.pending():
                    r.take(k)
        for c in found.values():
            for r in c.pending():
                r.settle()
        first = False
    counts = {n: {str(k): t[k] for k in sorted(t)} for n, t in tallies.items()}
    return counts, {n: c.result() for n, c in found.items()}
