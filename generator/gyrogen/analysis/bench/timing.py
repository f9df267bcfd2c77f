"""Best-of timing: the minimum of several repeats is the time least
disturbed by other load on the machine. The clock is the wall clock
(time.perf_counter) unless told: time.thread_time counts only the time this
thread ran, so that a repeat cut by another process's time slice still
times the call (on a machine with more runnable processes than cores)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any

Clock = Callable[[], float]


def best_of(body: Callable[[], object], repeats: int, clock: Clock = time.perf_counter) -> float:
    """Shortest time of ``repeats`` runs of body (at least one), in seconds."""
    best = math.inf
    for _ in range(max(repeats, 1)):
        t0 = clock()
        body()
        best = min(best, clock() - t0)
    return best


def best_time(
    fn: Callable[[], Any], repeats: int, min_total: float = 0.02, clock: Clock = time.perf_counter
) -> float:
    """Best time of one call: each repeat runs fn often enough to last
    min_total seconds, so microsecond runs are timed as well as long ones."""
    t0 = clock()
    fn()
    once = clock() - t0
    loops = max(1, int(min_total / max(once, 1e-9)))
    return min(once, per_call_ns(fn, (), loops, repeats, clock) * 1e-9)


# One loop per arity: unpacking *args inside the loop would add its own cost to every call.
def _loop0(f: Callable[..., object], a: Sequence[Any], n: int) -> None:
    for _ in range(n):
        f()


def _loop2(f: Callable[..., object], a: Sequence[Any], n: int) -> None:
    a0, a1 = a
    for _ in range(n):
        f(a0, a1)


def _loop3(f: Callable[..., object], a: Sequence[Any], n: int) -> None:
    a0, a1, a2 = a
    for _ in range(n):
        f(a0, a1, a2)


def _loop4(f: Callable[..., object], a: Sequence[Any], n: int) -> None:
    a0, a1, a2, a3 = a
    for _ in range(n):
        f(a0, a1, a2, a3)


_LOOPS = {0: _loop0, 2: _loop2, 3: _loop3, 4: _loop4}


def per_call_ns(
    f: Callable[..., object],
    args: Sequence[Any],
    calls: int,
    repeats: int,
    clock: Clock = time.perf_counter,
) -> float:
    """ns per call of f(*args) in a plain Python loop (the loop's own cost included:
    it is what any Python caller pays)."""
    loop = _LOOPS[len(args)]
    calls = max(calls, 1)
    return best_of(lambda: loop(f, args, calls), repeats, clock) / calls * 1e9
