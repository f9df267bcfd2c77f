"""A compiled integrator run from each of a list of times to the next:
every time is a step end (no interpolation), the statistics are totalled,
and the run stops at the first failure code; and the states of one run at
any times (`run_at`: an adaptive method's dense output)."""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from gyrogen import abi, methods
from gyrogen.errors import GyrogenError
from gyrogen.runtime.compiled import Compiled, Controls

ERR_MAX_STEPS = next(c.value for c in abi.ODE_CODES if c.name == "ODE_ERR_MAX_STEPS")
COUNTERS = tuple(f.name for f in abi.STATS_FIELDS if f.ctype == "long")
"""The statistics that add up over segments (steps, calls, decompositions)."""


@dataclass(frozen=True)
class Segments:
    states: np.ndarray
    """(k, nx): the initial state, then the state at each time reached
    (a failed segment's is left out)."""
    totals: dict[str, float | int]
    """The COUNTERS summed over the segments run, and t, the time reached."""
    code: int
    """0, or the return code (abi.ODE_CODES) of the segment that failed."""
    intervals: tuple[Mapping[str, float | int], ...] = ()
    """Each segment's own statistics (abi.STATS_FIELDS), the failed one last."""
    stopped: np.ndarray | None = None
    """On failure: the last good state, at totals["t"]."""


def integrate_segments(
    comp: Compiled,
    method: str,
    x0: np.ndarray,
    c: np.ndarray,
    times: Sequence[float] | np.ndarray,
    given: Controls,
    reached: Callable[[float], None] = lambda t: None,
    rhs_budget: int | None = None,
) -> Segments:
    """comp's integrator method from x0 at times[0] to each later time in
    turn; reached(t) after each time reached. rhs_budget: the rhs calls the
    whole run may make (a step makes one at least, so a segment may take at
    most as many steps as are left); spent, the run stops with
    ODE_ERR_MAX_STEPS."""
    x = np.array(x0, dtype=np.float64)
    states = [x.copy()]
    totals: dict[str, float | int] = dict.fromkeys(COUNTERS, 0)
    intervals: list[Mapping[str, float | int]] = []
    for a, b in itertools.pairwise(times):
        kw = given.copy()
        if rhs_budget is not None:
            left = rhs_budget - int(totals["rhs_calls"])
            if left <= 0:
                return Segments(np.array(states), totals, ERR_MAX_STEPS, tuple(intervals), x.copy())
            if "max_steps" in given:  # rk4's fixed steps take none
                kw["max_steps"] = min(given["max_steps"], left)
        x, stats, code = comp.integrate(method, x, c, float(a), float(b), **kw)
        intervals.append(stats)
        for name in COUNTERS:
            totals[name] += stats[name]
        totals["t"] = stats["t"]
        if code != 0:
            return Segments(np.array(states), totals, code, tuple(intervals), x.copy())
        states.append(x.copy())
        reached(float(b))
    return Segments(np.array(states), totals, 0, tuple(intervals))


def run_at(
    comp: Compiled,
    method: str,
    x0: np.ndarray,
    c: np.ndarray,
    times: np.ndarray,
    given: Controls,
) -> Segments:
    """The states at times (increasing) of one run from x0 at times[0] to
    times[-1]: an adaptive method's `_grid` call (the steps of `integrate`
    over the same ends, bit for bit, whatever the times between: its dense
    output there), or a fixed-step method's segments (every time a step
    end). Segments.intervals holds the calls' statistics."""
    times = np.asarray(times, dtype=np.float64)
    if methods.get(method).fixed_step:
        return integrate_segments(comp, method, x0, c, times, given)
    states, stats, code = comp.integrate_grid(
        method, x0, c, times, rtol=given["rtol"], atol=given["atol"], max_steps=given["max_steps"]
    )
    totals: dict[str, float | int] = {name: stats[name] for name in COUNTERS}
    totals["t"] = stats["t"]
    return Segments(states[np.all(np.isfinite(states), axis=1)], totals, code, (stats,))


def resampled(
    comp: Compiled, method: str, c: np.ndarray, given: Controls, ends: np.ndarray,
    states: np.ndarray,
) -> Callable[[np.ndarray], np.ndarray]:  # fmt: skip
    """The states at any times (within ends, any order) of a run from each
    of ends to the next (integrate_segments': states[k] at ends[k]): each
    segment holding some of the times run again from its start (run_at,
    all its times at once: its own steps, its dense output between them)."""

    def at(times: np.ndarray) -> np.ndarray:
        times = np.asarray(times, dtype=np.float64)
        order = np.argsort(times, kind="stable")
        sorted_times = times[order]
        which = np.clip(np.searchsorted(ends, sorted_times, "right") - 1, 0, len(ends) - 2)
        cuts = np.flatnonzero(np.diff(which)) + 1
        out = np.empty((times.size, states.shape[1]))
        for lo, hi in itertools.pairwise([0, *cuts, times.size]):
            k = which[lo]
            a, b, inner = ends[k], ends[k + 1], sorted_times[lo:hi]
            every = np.unique(np.concatenate([[a], inner, [b]]))
            seg = run_at(comp, method, states[k], c, every, given)
            if seg.code != 0:
                why = abi.message(abi.ODE_CODES, seg.code)
                raise GyrogenError(f"{method} run again from t = {a:.17g} s failed: {why}")
            out[order[lo:hi]] = seg.states[np.searchsorted(every, inner)]
        return out

    return at
