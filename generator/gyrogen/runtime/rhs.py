"""The generated rhs as f(t, x) for a Python solver: the raw cffi function
on buffers made once, the cheapest path from Python into the compiled code
(0.6 us a call here, Compiled.rhs 1.4 us)."""

from __future__ import annotations

from typing import Any

import numpy as np

from gyrogen.runtime.compiled import Compiled


class RawRhs:
    """f(t, x) -> dx/dt with the constants c fixed. x is copied into a
    buffer of its own, so any view a solver passes will do; the result is a
    copy, since the output buffer is reused."""

    def __init__(self, comp: Compiled, c: np.ndarray):
        self.function = comp.function("rhs")
        self.c = np.ascontiguousarray(c, dtype=np.float64)
        self.x, self.out = np.empty(comp.nx), np.empty(comp.nx)
        self.pointers: tuple[Any, Any, Any] = (
            comp.doubles(self.x),
            comp.doubles(self.c),
            comp.doubles(self.out),
        )
        """x, c, out as cffi pointers: the function's arguments after t."""

    def __call__(self, t: float, x: np.ndarray) -> np.ndarray:
        self.x[:] = x
        self.function(t, *self.pointers)
        return self.out.copy()
