"""Checks of what a Python caller hands Compiled (gyrogen.runtime.compiled)
that numpy and cffi would otherwise take silently or report in their own
words: complex arrays, integers too large for C, a thread count past reason.
Each is a one-line ValueError naming the argument."""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np

THREADS_MAX = 4096
"""The most threads integrate_batch takes (an int the C side can hold, and
more than any machine here has)."""
LONG_MAX = 2**63 - 1
INTEGERS = ("max_steps", "steps")
CONTROLS = ("t0", "t1", "rtol", "atol", "h0", *INTEGERS)
"""The controls of an integrator call, in the order controls_error takes them."""


def real_only(a: Any, what: str) -> Any:
    """a itself; a one-line ValueError when it holds complex numbers (numpy
    would drop their imaginary parts with only a warning)."""
    if np.iscomplexobj(a):
        raise ValueError(f"{what} must be real, not complex")
    return a


def _fits(name: str, v: Any) -> bool:
    """Whether cffi takes v for the control name (a C long or a double)."""
    if v is None:
        return True
    if name in INTEGERS:
        return isinstance(v, (int, np.integer)) and abs(int(v)) <= LONG_MAX
    if not isinstance(v, numbers.Real):
        return False
    try:
        float(v)
    except OverflowError:  # an int past the doubles
        return False
    return True


def controls_error(exc: Exception, *controls: Any) -> ValueError:
    """The one-line error for cffi's OverflowError or TypeError on a call:
    the controls it could not take, by name."""
    bad = [f"{n}={v!r}" for n, v in zip(CONTROLS, controls, strict=True) if not _fits(n, v)]
    return ValueError(
        f"{', '.join(bad) or 'a control'}: the times and tolerances must be real numbers, "
        f"max_steps and steps integers that fit a C long ({exc})"
    )


def grid_times(times: Any) -> np.ndarray:
    """times as the doubles a _grid call takes: a one-line ValueError unless
    they are a non-empty 1-D array of finite, strictly increasing reals (the
    C and Fortran calls return ODE_ERR_GRID for the same)."""
    t = np.array(real_only(times, "the grid times"), dtype=np.float64, ndmin=1)
    if t.ndim != 1 or t.size == 0:
        raise ValueError(
            f"the grid times must be a 1-D array of at least one time, not shape {t.shape}"
        )
    finite = np.isfinite(t)
    if not finite.all():
        k = int(np.argmin(finite))
        raise ValueError(f"the grid times must be finite (times[{k}] = {float(t[k])!r})")
    steps = np.diff(t) > 0
    if not steps.all():
        k = int(np.argmin(steps)) + 1
        raise ValueError(
            f"the grid times must be strictly increasing (times[{k}] = {float(t[k])!r} "
            f"after times[{k - 1}] = {float(t[k - 1])!r})"
        )
    return t


def receiver(a: Any, shape: tuple[int, ...], what: str) -> None:
    """A one-line ValueError unless a (an array a call writes its result
    into) is a writable float64 numpy array of shape: numpy would cast the
    doubles into another dtype (an int array truncates them) or fail to
    broadcast only after the run."""
    if a is None:
        return
    if not isinstance(a, np.ndarray) or a.dtype != np.float64 or a.shape != shape:
        got = (
            f"{a.dtype} array of shape {a.shape}" if isinstance(a, np.ndarray) else type(a).__name__
        )
        raise ValueError(f"{what} must be a float64 numpy array of shape {shape} (got: {got})")
    if not a.flags.writeable:
        raise ValueError(f"{what} must be writable")
