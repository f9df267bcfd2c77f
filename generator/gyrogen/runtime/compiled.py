"""One backend loaded in this process (`Compiled`): setup, rhs, the outputs,
the Jacobian and the integrators, called through cffi on numpy arrays."""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Literal, TypedDict, Unpack

import numpy as np

from gyrogen import abi, methods
from gyrogen.errors import BuildError

Language = Literal["c", "fortran"]


class Controls(TypedDict, total=False):
    """What a compiled integration takes besides the states and times: the
    fixed-step methods (rk4) `steps`; the others rtol, atol, h0 (<= 0:
    automatic) and max_steps."""

    rtol: float
    atol: float
    h0: float
    max_steps: int
    steps: int | None


DEFAULT_CONTROLS = Controls(rtol=1e-8, atol=1e-8, h0=0.0, max_steps=abi.MAX_STEPS, steps=None)
_STATS_NAMES = tuple(f.name for f in abi.STATS_FIELDS)


def controls(method: str, *, steps: int, rtol: float, atol: float, max_steps: int) -> Controls:
    """The controls method takes: steps for a fixed-step method, the
    tolerances and the step budget for the others."""
    if methods.get(method).fixed_step:
        return Controls(steps=steps)
    return Controls(rtol=rtol, atol=atol, max_steps=max_steps)


def cores() -> int:
    """The cores this process may run on."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


@dataclass(frozen=True)
class Compiled:
    """One backend loaded in this process: setup and rhs on numpy arrays."""

    language: Language
    manifest: dict[str, Any]
    ffi: Any
    lib: Any

    @cached_property
    def nx(self) -> int:
        return int(self.manifest["nx"])

    @cached_property
    def nc(self) -> int:
        return int(self.manifest["nc"])

    def symbol(self, name: str) -> str:
        """The exported name of a function: setup, rhs, jac, an output or an
        integrator (rk4, dop853_batch, ...), as the manifest lists it."""
        return str(self.manifest["functions"][self.language][name])

    def function(self, name: str) -> Any:
        """That function, callable through cffi."""
        return getattr(self.lib, self.symbol(name))

    def doubles(self, a: np.ndarray) -> Any:
        """A cffi double[] on the memory of a (C-contiguous float64)."""
        return self.ffi.from_buffer("double[]", a)

    def setup_code(self, p: np.ndarray) -> tuple[int, np.ndarray]:
        p = np.ascontiguousarray(p, dtype=np.float64)
        c = np.zeros(self.nc)
        code = self.function("setup")(self.doubles(p), self.doubles(c))
        return int(code), c

    def setup(self, p: np.ndarray) -> np.ndarray:
        code, c = self.setup_code(p)
        if code != 0:
            why = self.manifest["setup_codes"][str(code)]
            raise ValueError(f"setup refused the parameters (code {code}): {why}")
        return c

    def output(self, name: str, x: np.ndarray, c: np.ndarray, t: float = 0.0) -> np.ndarray:
        """An output function (kinetic_energy, angular_momentum, power) for a
        batch of states (n, nx): shape (n, size)."""
        return self._apply(name, int(self.manifest["outputs"][name]), x, c, t)

    def jacobian(self, x: np.ndarray, c: np.ndarray, t: float = 0.0) -> np.ndarray:
        """d(dx/dt)/dx at one state: shape (nx, nx) (scenes with an implicit
        integrator, gyrogen.methods.IMPLICIT)."""
        if "jac" not in self.manifest["functions"][self.language]:
            raise BuildError(
                f"scene {self.manifest['prefix']} has no Jacobian (add one of "
                f"{', '.join(methods.IMPLICIT)} to its integrators)"
            )
        return self._apply("jac", self.nx * self.nx, x, c, t).reshape(self.nx, self.nx)

    def _apply(self, name: str, size: int, x: np.ndarray, c: np.ndarray, t: float) -> np.ndarray:
        x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, self.nx)
        out = np.empty((x.shape[0], size))
        fn = self.ffi.addressof(self.lib, self.symbol(name))
        c = np.ascontiguousarray(c, dtype=np.float64)
        self.lib.gyrogen_batch(
            fn, x.shape[0], size, t, self.doubles(x), self.doubles(c), self.doubles(out)
        )
        return out

    def rhs(self, x: np.ndarray, c: np.ndarray, t: float = 0.0) -> np.ndarray:
        """dx/dt for a batch of states x (n, nx) or one state (nx,)."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        out = np.empty_like(x)
        c = np.ascontiguousarray(c, dtype=np.float64)
        n = x.size // self.nx
        self.lib.gyrogen_rhs_batch(n, t, self.doubles(x), self.doubles(c), self.doubles(out))
        return out

    def integrate(
        self,
        method: str,
        x0: np.ndarray,
        c: np.ndarray,
        t0: float,
        t1: float,
        **given: Unpack[Controls],
    ) -> tuple[np.ndarray, dict[str, float | int], int]:
        """One compiled integration of x0 (nx,) from t0 to t1 by the single
        trajectory's function: the final state (the last good one on
        failure), the statistics (abi.STATS_FIELDS) and the return code
        (abi.ODE_CODES). The controls (Controls) as keywords.

        The method's function and kind are looked up once per build
        (_integrators), so a call costs little more than the C call itself."""
        try:
            fn, fixed = self._integrators[method]
        except KeyError:
            self._check_method(method, given.get("steps"))  # raises, saying why
            raise
        steps = given.get("steps")
        if (steps is None) == fixed:
            self._check_method(method, steps)
        x = np.array(x0, dtype=np.float64).reshape(-1)  # a copy: integrated in place
        if x.shape != (self.nx,):
            raise ValueError(f"the initial state must have shape ({self.nx},), not {x.shape}")
        if not (type(c) is np.ndarray and c.dtype == np.float64 and c.flags.c_contiguous):
            c = np.ascontiguousarray(c, dtype=np.float64)
        stats = self.ffi.new("gyrogen_stats *")
        if fixed:
            code = fn(t0, t1, steps, self.doubles(x), self.doubles(c), stats)
        else:
            get = given.get
            d = DEFAULT_CONTROLS
            code = fn(t0, t1, self.doubles(x), self.doubles(c), get("rtol", d["rtol"]),
                      get("atol", d["atol"]), get("h0", d["h0"]),
                      get("max_steps", d["max_steps"]), stats)  # fmt: skip
        return x, {name: getattr(stats, name) for name in _STATS_NAMES}, int(code)

    @cached_property
    def _integrators(self) -> dict[str, tuple[Any, bool]]:
        """Each integrator of this build: its cffi function, and whether it
        is a fixed-step method."""
        return {
            m: (self.function(m), methods.get(m).fixed_step) for m in self.manifest["integrators"]
        }

    def integrate_batch(
        self,
        method: str,
        x0s: np.ndarray,
        c: np.ndarray,
        t0: float,
        t1: float,
        threads: int | None = None,
        **given: Unpack[Controls],
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """integrate() for many initial states (n, nx): final states (n, nx),
        statistics as a structured array (n,) with the fields of
        abi.STATS_FIELDS, and return codes (n,). threads: how many cores
        (None: every one, 1: this one); a build with OpenMP splits the batch
        in C, one without it in slices called from Python threads (cffi
        releases the GIL). The results do not depend on it, bit for bit."""
        fixed = self._check_method(method, given.get("steps"))
        ctl = Controls(**{**DEFAULT_CONTROLS, **given})
        x = np.array(x0s, dtype=np.float64, order="C", ndmin=2)  # a copy: integrated in place
        if x.ndim != 2 or x.shape[1] != self.nx:
            raise ValueError(f"initial states must have shape (n, {self.nx}), not {x.shape}")
        n = x.shape[0]
        stats = np.zeros(n, dtype=self._stats_dtype)
        codes = np.zeros(n, dtype=np.intc)
        cb = self.doubles(np.ascontiguousarray(c, dtype=np.float64))
        fn = self.function(f"{method}_batch")
        tolerances = (ctl["rtol"], ctl["atol"], ctl["h0"], ctl["max_steps"])

        def run(lo: int, hi: int) -> None:
            tail = (self.doubles(x[lo:hi]), cb)
            args = (hi - lo, t0, t1, ctl["steps"], *tail) if fixed else (hi - lo, t0, t1, *tail)
            fn(
                *args,
                *(() if fixed else tolerances),
                self.ffi.from_buffer("gyrogen_stats[]", stats[lo:hi]),
                self.ffi.from_buffer("int[]", codes[lo:hi]),
            )

        count = cores() if threads is None else threads
        if count < 1:
            raise ValueError(f"threads must be at least 1, not {count}")
        if self.lib.gyrogen_threads(count) or count == 1 or n < 2:
            run(0, n)  # OpenMP, or one thread
        else:
            edges = np.linspace(0, n, min(count, n) + 1).astype(int)
            with ThreadPoolExecutor(len(edges) - 1) as pool:
                list(pool.map(run, edges[:-1], edges[1:]))
        return x, stats, codes

    def _check_method(self, method: str, steps: int | None) -> bool:
        """Whether method is a fixed-step one; ValueError unless this build
        has it and steps is given exactly when it is."""
        if method not in self.manifest["integrators"]:
            raise ValueError(
                f"no integrator {method!r} in this build "
                f"(scene integrators: {', '.join(self.manifest['integrators'])})"
            )
        fixed = methods.get(method).fixed_step
        if (steps is None) == fixed:
            raise ValueError(
                f"{method}: steps= goes with the fixed-step methods, and only with them"
            )
        return fixed

    @cached_property
    def _stats_dtype(self) -> np.dtype:
        """gyrogen_stats as numpy sees it, offsets and size from cffi."""
        long = f"i{self.ffi.sizeof('long')}"
        fields = abi.STATS_FIELDS
        return np.dtype(
            {
                "names": [f.name for f in fields],
                "formats": ["f8" if f.ctype == "double" else long for f in fields],
                "offsets": [self.ffi.offsetof("gyrogen_stats", f.name) for f in fields],
                "itemsize": self.ffi.sizeof("gyrogen_stats"),
            }
        )
