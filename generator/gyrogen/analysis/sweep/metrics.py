"""One chunk of a sweep: its trajectories integrated by the compiled batch
integrator (Compiled.integrate_batch) and reduced to one row each.

The trajectories are grouped by their runtime parameters: setup runs once
per parameter set (a Monte Carlo over parameters makes sets of one). The
sampled metrics look at the states at metrics.samples equal intervals of
t_end. An adaptive method reads them from its dense output, one
integration per trajectory whose steps are not cut at the samples
(`_grid_batch`; `_events_batch` when the scene's events are located, in
the same run); a fixed-step method is restarted at each sample (every sample a step
end, as in runtime/segment.py), and a sweep with nothing to sample is one
batch call per parameter set (over SIMD lanes).

The columns (one row per trajectory):

- sample, then each swept name: the inputs;
- setup_code (abi.SETUP_CODES), code (abi.ODE_CODES; -1: not integrated,
  setup refused the parameters), t: the time reached;
- stats: the counters of abi.STATS_FIELDS summed over the intervals;
- final_state: final_<state> for each state (the last good one on failure);
- max_nutation: the largest angle (rad) between the carrier's axis a2 and
  the angular momentum H about AB*, from H's A components (I~ omega + J u4
  a2, physics.body_momentum): 0 for a pure spin about a2, pi/2 when H is
  transverse; nutation_0 the angle at the start; max_rate: the largest
  |omega| of the carrier (rad/s);
- invariant_drift: H_drift, the largest | |H| - |H(0)| | / |H(0)| (|H| is
  conserved for every torque law: the motor's torque is internal and
  gravity acts at AB*);
- time_to: time_to_<quantity>, the first time at which the quantity
  (nutation, rate, or a state) is on the other side of its threshold from
  where it started (0 if it starts on it; NaN if never): with an adaptive
  method located on the dense output as an event the sweep adds to its
  scene (spec.threshold_events), with a fixed step the first sample time;
- pointing: the angle (rad) between the carrier's a3 (a boresight) at the
  end and at the start, in N (any scene, either attitude).

A failed run's metrics cover the samples it reached.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyrogen import methods
from gyrogen.abi import ODE_LOG_FULL
from gyrogen.analysis.sweep.draws import inputs
from gyrogen.analysis.sweep.spec import SAMPLED, THRESHOLD, Spec
from gyrogen.oracle.reference import N_STATES, direction_cosines
from gyrogen.oracle.scene_view import quaternion_dcm
from gyrogen.physics import LUMPED_FROM, body_momentum, lumped_inertias
from gyrogen.runtime.compiled import Compiled, EventLogs, controls
from gyrogen.runtime.segment import COUNTERS

NOT_RUN = -1
"""code of a trajectory whose parameters setup refused."""


def columns(spec: Spec) -> dict[str, np.dtype]:
    """The name and type of every column a chunk of this sweep has."""
    keep = spec.sweep.metrics.keep
    cols: dict[str, np.dtype] = {"sample": np.dtype(np.int64)}
    cols |= dict.fromkeys(spec.variables, np.dtype(np.float64))
    cols |= {"setup_code": np.dtype(np.int32), "code": np.dtype(np.int32)}
    cols["t"] = np.dtype(np.float64)
    if "stats" in keep:
        cols |= dict.fromkeys(COUNTERS, np.dtype(np.int64))
    if "final_state" in keep:
        cols |= {f"final_{s}": np.dtype(np.float64) for s in spec.scene.states}
    names = {
        "max_nutation": ("nutation_0", "max_nutation"),
        "max_rate": ("max_rate",),
        "invariant_drift": ("H_drift",),
    }
    cols |= {col: np.dtype(np.float64) for key in keep for col in names.get(key, ())}
    cols |= {f"time_to_{q}": np.dtype(np.float64) for q in spec.sweep.metrics.time_to}
    if "pointing" in keep:
        cols["pointing"] = np.dtype(np.float64)
    for e in located(spec):
        cols |= {f"first_{e}": np.dtype(np.float64), f"count_{e}": np.dtype(np.int64)}
    return cols


def located(spec: Spec) -> list[str]:
    """The scene's events the sweep locates (their first time and count
    columns): all of them with an adaptive method, none with a fixed step;
    not the ones the sweep added for its time_to thresholds (spec.THRESHOLD)."""
    if methods.get(spec.sweep.method).fixed_step:
        return []
    return [e.name for e in spec.scene.events if not e.name.startswith(THRESHOLD)]


EVENT_CAPACITY = 100_000
"""Events logged per trajectory: a count at it means at least as many."""
FIRST_CAPACITY = 64
"""The log a trajectory is run with first: one that fills it is run again
alone with EVENT_CAPACITY (a batch's logs are allocated for every state it
holds, EVENT_CAPACITY's ~100 us and ~10 MB each)."""


_METRIC_DOCS = {
    "sample": ("1", "the trajectory's index in the sweep (its draws depend on seed and it alone)"),
    "setup_code": ("1", "setup's return code (0: accepted)"),
    "code": ("1", "the integrator's return code (-1: not run, setup refused the parameters)"),
    "t": ("s", "the time reached"),
    "nutation_0": ("rad", "angle between a2 and H at the start"),
    "max_nutation": ("rad", "largest angle between a2 and H over the samples"),
    "max_rate": ("rad/s", "largest |omega| of the carrier over the samples"),
    "H_drift": ("1", "largest relative change of |H| over the samples"),
    "pointing": ("rad", "angle between the carrier's a3 at the end and at the start (in N)"),
}


def column_docs(spec: Spec) -> dict[str, tuple[str, str]]:
    """Each column's unit and meaning (the Parquet fields carry them)."""
    docs = {}
    for name in columns(spec):
        if name in _METRIC_DOCS:
            docs[name] = _METRIC_DOCS[name]
        elif name in COUNTERS:
            docs[name] = ("1", f"{name} of the integrator (a fixed-step method's summed "
                          "over the samples' intervals)")  # fmt: skip
        elif name.startswith("final_"):
            unit, doc = spec.scene.unit_and_doc(name[len("final_") :])
            docs[name] = (unit, f"final value (the last good one on failure) of: {doc}")
        elif name.startswith("first_") and name[len("first_") :] in located(spec):
            docs[name] = (
                "s",
                f"the first time event {name[len('first_') :]} happened (NaN: never)",
            )
        elif name.startswith("count_") and name[len("count_") :] in located(spec):
            docs[name] = ("1", f"how often event {name[len('count_') :]} happened, up to a "
                          f"terminal event and at most {EVENT_CAPACITY} events in all")  # fmt: skip
        elif name.startswith("time_to_"):
            docs[name] = ("s", f"first time {name[len('time_to_') :]} crossed its threshold "
                          "(located; a fixed-step method's: the first sample past it)")  # fmt: skip
        else:
            docs[name] = spec.scene.unit_and_doc(name)  # an input: a state or a runtime parameter
    return docs


def _filled(spec: Spec, n: int, every: dict[str, np.ndarray], ran: np.ndarray | None,
            found: dict[str, np.ndarray]) -> dict[str, np.ndarray]:  # fmt: skip
    """The chunk's columns: every (values of all n rows: the inputs) and
    found (values of the rows ran, None: all of them) as they are when they
    cover every row (no copy), else in columns filled for the rows not run
    (code NOT_RUN, NaN, 0)."""
    out = {}
    for name, dtype in columns(spec).items():
        if name in every or (ran is None and name in found):
            out[name] = np.asarray(every[name] if name in every else found[name], dtype=dtype)
            continue
        fill = NOT_RUN if name == "code" else np.nan if dtype.kind == "f" else 0
        out[name] = np.full(n, fill, dtype=dtype)
        if name in found:
            out[name][ran] = found[name]
    return out


def run_chunk(comp: Compiled, spec: Spec, start: int, stop: int) -> dict[str, np.ndarray]:
    """The rows of trajectories start..stop-1, as columns."""
    inp = inputs(spec, start, stop)
    n = len(inp.sample)
    groups, which = parameter_sets(inp.p)
    setups = [comp.setup_code(p) for p in groups]
    codes = np.array([code for code, _ in setups], dtype=np.int32)[which]
    every = {"sample": inp.sample, **inp.values, "setup_code": codes}
    ran = np.flatnonzero(codes == 0)
    if not ran.size:
        return _filled(spec, n, every, ran, {})
    members = [np.flatnonzero(which[ran] == g) for g in range(len(groups))]
    batches = [(c, m) for (code, c), m in zip(setups, members, strict=True) if code == 0]
    all_ran = ran.size == n  # the usual case: no gather, no scatter
    runtime = dict(zip(spec.scene.runtime, (inp.p if all_ran else inp.p[ran]).T, strict=True))
    known = {**spec.scene.folded(), **runtime}
    x0 = inp.x0 if all_ran else inp.x0[ran]
    aim = boresight(spec, x0) if "pointing" in columns(spec) else None  # x0 is integrated in place
    runs = _integrate(comp, spec, batches, known, x0)
    found = _found(spec, runs, aim)
    return _filled(spec, n, every, None if all_ran else ran, found)


def parameter_sets(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct rows of p (n, np), and which of them each row is."""
    if not p.size or (p == p[0]).all():
        return p[:1].reshape(1, -1), np.zeros(len(p), dtype=np.intp)
    groups, which = np.unique(p, axis=0, return_inverse=True)
    return groups, which.reshape(-1)


class _Watch:
    """The sampled metrics of a chunk's trajectories, updated sample by
    sample; values: each parameter, a number or one per trajectory;
    located: the time_to thresholds are located as events (their columns
    are the events' first times: see does not look for crossings). The
    metrics the sweep does not keep are not updated."""

    def __init__(self, spec: Spec, values: dict[str, Any], x0: np.ndarray,
                 located: bool = False) -> None:  # fmt: skip
        states = spec.scene.states
        self.u = [states.index(f"u{i}") for i in range(1, 5)]
        self.lumped = lumped_inertias(*(values[n] for n in LUMPED_FROM))
        self.J = values["J"]
        self.thresholds = spec.sweep.metrics.time_to
        self.kept = set(spec.sweep.metrics.keep)  # see computes no other
        self.located = located
        self.states = states
        every = np.arange(len(x0))
        self.nutation, self.rate, self.h0 = self._look(x0, every)
        self.nutation_0 = self.nutation.copy()
        self.drift = np.zeros(len(x0))
        looked = {"nutation": self.nutation, "rate": self.rate}  # at x0
        self.start = {q: (looked[q] if q in looked else x0[:, states.index(q)]) - thr
                      for q, thr in self.thresholds.items()}  # fmt: skip
        self.time_to = {q: np.where(d == 0, 0.0, np.nan) for q, d in self.start.items()}

    def _rates(self, x: np.ndarray) -> np.ndarray:
        """(4, N) u1..u4 at the states x (N, nx), each row contiguous."""
        first = self.u[0]
        if self.u == list(range(first, first + 4)):
            return np.ascontiguousarray(x[:, first : first + 4].T)  # one copy, no gather
        return np.ascontiguousarray(x[:, self.u].T)

    def _momentum(self, u: np.ndarray, rows: np.ndarray) -> tuple[tuple[np.ndarray, ...], Any]:
        """H at the rates u (4, N) of rows over a power of two per row, and that power: 1
        unless the rates reach 2^600 (inertias to 1e50 times rates to 1e300
        overflowed the products, an arctan2 of infinities then 45 degrees)."""
        scale: Any = 1.0
        if not np.fmax.reduce(np.abs(u), axis=None, initial=0.0) < 2.0**600:  # rare: scale
            big = np.max(np.abs(u), axis=0, initial=0.0, where=np.isfinite(u))
            scale = np.ldexp(1.0, np.where(big >= 2.0**600, np.frexp(big)[1], 0))
            u = u / scale  # exact: a power of two
        lumped = tuple(v[rows] if np.ndim(v) else v for v in self.lumped)  # per row, or shared
        J = self.J[rows] if np.ndim(self.J) else self.J
        return body_momentum(lumped, J, *u), scale

    def _look(self, x: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The nutation angle, |omega| and |H| at the states x of rows (|H|
        inf where it is beyond doubles)."""
        u = self._rates(x)
        nutation, norm = self._attitude(u, rows)
        return nutation, _speed(u), norm

    def _attitude(self, u: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The nutation angle and |H| at the rates u (4, N) of rows."""
        h, scale = self._momentum(u, rows)
        transverse = np.hypot(h[0], h[2])
        with np.errstate(over="ignore"):
            norm = np.hypot(transverse, h[1]) * scale
        return np.arctan2(transverse, h[1]), norm

    def see(self, times: np.ndarray, xs: np.ndarray, rows: np.ndarray, begun: int = 0) -> None:
        """The states xs[i, k] of row rows[i] at times[k] (NaN where its run
        did not reach: a failed run's metrics cover the samples it reached),
        all in one look; the first begun columns are the rows' starts (seen
        already: no crossing there)."""
        n, m, nx = xs.shape
        flat = xs.reshape(n * m, nx)  # a view where xs is a whole grid
        u = self._rates(flat)  # row by row: hypot is fastest on neighbouring values
        crossings = not self.located and bool(self.thresholds)
        looked = {}
        if self.kept & {"max_nutation", "invariant_drift"} or (
            crossings and "nutation" in self.thresholds
        ):
            nutation, norm = (v.reshape(n, m) for v in self._attitude(u, np.repeat(rows, m)))
            self.nutation[rows] = np.fmax(self.nutation[rows], _largest(nutation))
            h0 = self.h0[rows, None]
            with np.errstate(invalid="ignore"):  # |H| beyond doubles: no drift (nan: fmax skips)
                drift = np.abs(norm - h0) / np.where(h0 == 0, 1.0, h0)
            self.drift[rows] = np.fmax(self.drift[rows], _largest(drift))
            looked["nutation"] = nutation
        if crossings and "rate" in self.thresholds:
            rate = _speed(u).reshape(n, m)
            self.rate[rows] = np.fmax(self.rate[rows], _largest(rate))
            looked["rate"] = rate
        elif "max_rate" in self.kept:
            self.rate[rows] = np.fmax(self.rate[rows], _fastest(u, n, m))
        if not crossings:
            return
        reached = ~np.isnan(xs[:, begun:, 0])
        for q, thr in self.thresholds.items():
            value = looked[q] if q in looked else xs[:, :, self.states.index(q)]
            crossed = np.sign(value[:, begun:] - thr) != np.sign(self.start[q][rows, None])
            crossed &= reached
            first = crossed.any(axis=1) & np.isnan(self.time_to[q][rows])
            self.time_to[q][rows[first]] = times[begun:][np.argmax(crossed[first], axis=1)]


def _speed(u: np.ndarray) -> np.ndarray:
    """|omega| from the rates u (4, N): no square to overflow, |u| to 1e308."""
    return np.hypot(np.hypot(u[0], u[1]), u[2])


_MARGIN = 2.0**-40
"""How far below its row's largest sum of squares u1^2 + u2^2 + u3^2 a
sample's may be and still be a candidate for the largest |omega|: the sum's
rounding (3 units of 2^-53) and hypot's (one ulp each) stay below 2^-48."""
_FEW = 4
"""Samples per row below which every one's |omega| is computed (the
candidates' passes would cost more)."""
_TINY, _HUGE = 2.0**-900, 2.0**450
"""A sum of squares below _TINY may have lost its relative accuracy to
underflow (the candidates' absolute slack); rates within _HUGE cannot
overflow it."""


def _largest(a: np.ndarray) -> np.ndarray:
    """Each row's largest value of a (n, m), NaN skipped (all NaN: NaN):
    over a transposed copy, whose reduction runs across the rows (one over
    each row of a few samples costs 3 times the copy and it)."""
    return np.fmax.reduce(np.ascontiguousarray(a.T), axis=0)


def _fastest(u: np.ndarray, n: int, m: int) -> np.ndarray:
    """Each row's largest |omega| (NaN where none was reached) over the rates
    u (4, n m) of its m samples: _speed, bit for bit, at the samples whose
    sum of squares is within _MARGIN of their row's largest (the others'
    |omega| are smaller), not at every one (hypot costs 10-15 ns a value;
    the nutation and |H| need theirs at every sample). At every sample where
    a sum could overflow (or a rate is infinite), or a row has few samples."""
    w = u[:3]  # an infinite rate where another is NaN is a sample whose sum of squares is NaN
    if (
        m < _FEW
        or not -_HUGE <= np.fmin.reduce(w, axis=None) <= np.fmax.reduce(w, axis=None) <= _HUGE
    ):
        return _largest(_speed(u).reshape(n, m))  # NaN: nothing reached
    r2 = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).reshape(n, m)
    top = _largest(r2) * (1 - _MARGIN) - _TINY  # NaN: no sample reached
    with np.errstate(invalid="ignore"):
        pick = np.flatnonzero(r2 >= top[:, None])
    rate = np.full(n * m, np.nan)
    rate[pick] = _speed(u[:, pick])
    return _largest(rate.reshape(n, m))


@dataclass
class _Runs:
    """The trajectories setup accepted, run so far."""

    x: np.ndarray
    code: np.ndarray
    reached: np.ndarray
    totals: dict[str, np.ndarray]
    watch: _Watch | None
    """None when the sweep keeps no sampled metric: nothing to look at."""
    events: dict[str, np.ndarray]
    """first_<event> and count_<event> (empty when none is located)."""

    def ended(self, rows: Any, x: np.ndarray, code: Any, stats: Any) -> None:
        """Rows' runs ended at x with code and their statistics."""
        self.x[rows], self.reached[rows], self.code[rows] = x, stats["t"], code
        for name in COUNTERS:
            self.totals[name][rows] += stats[name]

    def look(self, times: np.ndarray, rows: np.ndarray, out: np.ndarray) -> None:
        """The sampled metrics at times[1:] from rows' states there (out[i, k]
        row rows[i] at times[k]; NaN past a failure: a run's metrics cover
        the samples it reached)."""
        if self.watch is not None:
            self.watch.see(times, out, rows, begun=1)


GRID_BLOCK = 1 << 21
"""The most doubles of sampled states one grid call holds (16 MB): a
chunk's rows are run in blocks of this many states times samples."""


def _integrate(
    comp: Compiled,
    spec: Spec,
    batches: list[tuple[np.ndarray, np.ndarray]],
    values: dict[str, Any],
    x0: np.ndarray,
) -> _Runs:
    """Every trajectory from 0 to t_end. An adaptive method samples the
    metrics on its dense output: one integration per trajectory over the
    samples' grid (`_grid_batch`, or `_events_batch` when the scene's events
    are located, which gives both); a fixed-step one is restarted at each
    sample, as is a sweep with nothing to sample (the batch call, over SIMD
    lanes). x0 becomes the runs' states (integrated in place)."""
    sweep = spec.sweep
    times = np.linspace(0.0, sweep.t_end, sweep.metrics.points + 1)
    n = len(x0)
    with_events = bool(spec.scene.events) and not methods.get(sweep.method).fixed_step
    runs = _Runs(
        x0, np.zeros(n, dtype=np.int32), np.zeros(n),
        {name: np.zeros(n, dtype=np.int64) for name in COUNTERS},
        _Watch(spec, values, x0, located=with_events)
        if set(sweep.metrics.keep) & set(SAMPLED)
        else None,
        {},
    )  # fmt: skip
    if with_events:
        _with_events(comp, spec, batches, runs, times)
    elif methods.get(sweep.method).fixed_step or len(times) == 2:
        _restarted(comp, spec, batches, runs, times)
    else:
        _on_grid(comp, spec, batches, runs, times)
    return runs


def _adaptive(spec: Spec) -> dict[str, Any]:
    sweep = spec.sweep
    return {"rtol": sweep.rtol, "atol": sweep.atol, "max_steps": sweep.max_steps}


Sets = list[tuple[np.ndarray, np.ndarray]]
"""Parameter sets: (constants from setup, the rows that share them)."""


def _blocks(batches: Sets, n: int, size: int) -> Iterator[tuple[np.ndarray, Sets]]:
    """The rows 0..n-1 in blocks of size, each with its parameter sets'
    (constants, rows) within it (where one look at a block's samples
    covers many sets: a Monte Carlo's set per trajectory)."""
    which = np.empty(n, dtype=np.intp)
    for b, (_, rows) in enumerate(batches):
        which[rows] = b
    for at in range(0, n, size):
        rows = np.arange(at, min(at + size, n))
        order = np.argsort(which[rows], kind="stable")
        cut = np.flatnonzero(np.diff(which[rows][order])) + 1
        yield rows, [(batches[which[part[0]]][0], part) for part in np.split(rows[order], cut)]


def _gathered(sets: Sets) -> tuple[np.ndarray, np.ndarray]:
    """A block's rows set by set, and their constants: the one set's, or a
    row per state (the compiled batch runs each set's stretch in one call)."""
    order = np.concatenate([part for _, part in sets])
    if len(sets) == 1:
        return order, sets[0][0]
    return order, np.repeat([c for c, _ in sets], [len(part) for _, part in sets], axis=0)


def _on_grid(comp: Compiled, spec: Spec, batches: list[tuple[np.ndarray, np.ndarray]],
             runs: _Runs, times: np.ndarray) -> None:  # fmt: skip
    """One `_grid_batch` call per block of rows."""
    size = max(1, GRID_BLOCK // (len(times) * comp.nx))
    for _, sets in _blocks(batches, len(runs.x), size):
        rows, c = _gathered(sets)
        ends = np.empty((len(rows), comp.nx))
        # one core: Dask runs one chunk per core already (OpenMP inside would oversubscribe)
        out, stats, codes = comp.integrate_grid_batch(
            spec.sweep.method, runs.x[rows], c, times, threads=1, ends=ends, **_adaptive(spec),
        )  # fmt: skip
        runs.ended(rows, ends, codes, stats)
        runs.look(times, rows, out)


def _with_events(comp: Compiled, spec: Spec, batches: list[tuple[np.ndarray, np.ndarray]],
                 runs: _Runs, times: np.ndarray) -> None:  # fmt: skip
    """One `_events_batch` call per block of rows over the samples' grid (a
    state whose log fills run again alone, with room): their states there,
    their events (first time and count: up to a terminal event, which ends
    the run with code ODE_EVENT), their time_to crossings (the first of each
    threshold's event) and their ends."""
    names = [e.name for e in spec.scene.events]
    first = {e: np.full(len(runs.x), np.nan) for e in names}
    count = {e: np.zeros(len(runs.x), dtype=np.int64) for e in names}
    per_row = len(times) * comp.nx + FIRST_CAPACITY * (comp.nx + 2)  # the grid's and the log's
    for _, sets in _blocks(batches, len(runs.x), max(1, GRID_BLOCK // per_row)):
        rows, c = _gathered(sets)
        starts, ends = runs.x[rows], np.empty((len(rows), comp.nx))
        # one core: Dask runs one chunk per core already (OpenMP inside would oversubscribe)
        out, logs, stats, codes = comp.integrate_events_batch(
            spec.sweep.method, starts, c, times, threads=1, capacity=FIRST_CAPACITY, ends=ends,
            **_adaptive(spec),
        )  # fmt: skip
        full = codes == ODE_LOG_FULL
        _tally(logs, ~full, rows, first, count)
        for j in np.flatnonzero(full):
            one = slice(j, j + 1)
            out[one], again, stats[one], codes[one] = comp.integrate_events_batch(
                spec.sweep.method, starts[one], c if c.ndim == 1 else c[one], times, threads=1,
                capacity=EVENT_CAPACITY, ends=ends[one], **_adaptive(spec),
            )  # fmt: skip
            _tally(again, np.ones(1, dtype=bool), rows[one], first, count)
        runs.ended(rows, ends, codes, stats)
        runs.look(times, rows, out)
    runs.events = {**{f"first_{e}": first[e] for e in located(spec)},
                   **{f"count_{e}": count[e] for e in located(spec)}}  # fmt: skip
    if runs.watch is not None:
        for q, t in runs.watch.time_to.items():
            at = first[THRESHOLD + q]
            t[...] = np.where(t == 0.0, 0.0, at)  # 0: it starts on its threshold


def _tally(logs: EventLogs, kept: np.ndarray, rows: np.ndarray, first: dict[str, np.ndarray],
           count: dict[str, np.ndarray]) -> None:  # fmt: skip
    """Each event's first time and count in the logs kept, rows' (in order)."""
    counts, rows = logs.counts[kept], rows[kept]
    width = max(1, int(np.max(counts, initial=0)))  # what the logs hold: a few of their capacity
    which, times = logs.which[kept, :width], logs.times[kept, :width]
    held = np.arange(width) < counts[:, None]
    for k, e in enumerate(logs.names):
        hit = held & (which == k)
        count[e][rows] = hit.sum(axis=1)
        seen = hit.any(axis=1)
        first[e][rows[seen]] = times[seen, np.argmax(hit[seen], axis=1)]


def _restarted(comp: Compiled, spec: Spec, batches: list[tuple[np.ndarray, np.ndarray]],
               runs: _Runs, times: np.ndarray) -> None:  # fmt: skip
    """Interval by interval: each parameter set's live rows in one batch
    call, then the metrics of all rows at the interval's end in one look."""
    sweep = spec.sweep
    per_interval = -(-(sweep.steps or 1) // (len(times) - 1))
    given = controls(
        sweep.method, steps=per_interval, rtol=sweep.rtol, atol=sweep.atol,
        max_steps=sweep.max_steps,
    )  # fmt: skip
    n = len(runs.x)
    alive = np.ones(n, dtype=bool)
    for t0, t1 in itertools.pairwise(times):
        for c, rows in batches:
            live: Any = rows[alive[rows]]
            if not live.size:
                continue
            if live.size == n:  # every row: a slice reads and writes in place
                live = slice(None)
            # one core: Dask runs one chunk per core already (OpenMP inside would oversubscribe)
            xl, stats, codes = comp.integrate_batch(
                sweep.method, runs.x[live], c, t0, t1, threads=1, **given
            )
            runs.ended(live, xl, codes, stats)
        alive &= runs.code == 0
        if not alive.any():
            break
        if runs.watch is not None:
            idx = np.flatnonzero(alive)
            runs.watch.see(np.array([t1]), runs.x[idx, None], idx)


def boresight(spec: Spec, x: np.ndarray) -> np.ndarray:
    """(n, 3) the carrier's a3 in N-components at the states x (n, nx)."""
    states = spec.scene.states
    if spec.scene.attitude == "quaternion":
        return quaternion_dcm(x[:, [states.index(f"e{i}") for i in range(4)]])[:, 2, :]
    angles = np.zeros((len(x), N_STATES))
    angles[:, :3] = x[:, [states.index(f"q{i}") for i in (1, 2, 3)]]
    return direction_cosines(angles)[:, 2, :]


def pointing(spec: Spec, x0: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The angle between a3 at x and at x0 (atan2: exact for small angles)."""
    return _angle(boresight(spec, x0), boresight(spec, x))


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row by row, the angle between unit vectors a and b."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, axis=1))


def _found(spec: Spec, runs: _Runs, aim: np.ndarray | None) -> dict[str, np.ndarray]:
    """The columns the runs give, for the rows that ran; aim: a3 at their
    start (boresight), when the spec keeps the pointing error."""
    watch = runs.watch
    found = {
        **runs.events,
        "code": runs.code,
        "t": runs.reached,
        **{f"final_{s}": runs.x[:, i] for i, s in enumerate(spec.scene.states)},
        **runs.totals,
    }
    if aim is not None:
        found["pointing"] = _angle(aim, boresight(spec, runs.x))
    if watch is not None:
        found |= {
            "nutation_0": watch.nutation_0,
            "max_nutation": watch.nutation,
            "max_rate": watch.rate,
            "H_drift": watch.drift,
            **{f"time_to_{q}": t for q, t in watch.time_to.items()},
        }
    return found
