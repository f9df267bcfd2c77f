"""One backend loaded in this process (`Compiled`): setup, rhs, the outputs,
the Jacobian and the integrators, called through cffi on numpy arrays."""

from __future__ import annotations

import itertools
import os
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Literal, TypedDict

import numpy as np

from gyrogen import abi, methods
from gyrogen.errors import BuildError, SetupRefused
from gyrogen.runtime.call_checks import (
    THREADS_MAX,
    controls_error,
    grid_times,
    real_only,
    receiver,
)
from gyrogen.runtime.variational import Layout

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
_F64 = np.dtype(np.float64)
_DOUBLES, _STATS, _INTS = "double[]", "gyrogen_stats[]", "int[]"
_STATS_PTR = "gyrogen_stats *"
_NOTHING: tuple[Any, Any] = (object(), None)


class Stats(Mapping[str, float | int]):
    """One integration's statistics (abi.STATS_FIELDS), read from its C
    struct when asked for: a mapping, equal to the dict of its values."""

    __slots__ = ("_struct",)

    def __init__(self, struct: Any) -> None:
        self._struct = struct

    def __getitem__(self, name: str) -> float | int:
        if name not in _STATS_NAMES:
            raise KeyError(name)
        return getattr(self._struct, name)

    def __iter__(self) -> Iterator[str]:
        return iter(_STATS_NAMES)

    def __len__(self) -> int:
        return len(_STATS_NAMES)

    def __repr__(self) -> str:
        return repr(dict(self))


def _bad(a: np.ndarray) -> int:
    """The first index of a whose value is not finite."""
    return int(np.flatnonzero(~np.isfinite(a))[0])


def _within(
    stretches: list[tuple[int, int, Any]], lo: int, hi: int
) -> Iterator[tuple[int, int, Any]]:
    """The stretches (start, stop, constants) cut to the states lo..hi-1."""
    for a, b, cb in stretches:
        if max(a, lo) < min(b, hi):
            yield max(a, lo), min(b, hi), cb


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
class EventLog:
    """The events an `integrate_events` run located, in time order."""

    times: np.ndarray
    """When each happened (s)."""
    names: list[str]
    """Which event, by its name in the scene."""
    states: np.ndarray
    """The state at each, shape (events, nx)."""

    def __len__(self) -> int:
        return len(self.names)


@dataclass(frozen=True)
class EventLogs:
    """The events an `integrate_events_batch` run located: a log per state,
    each of `capacity` entries of which the first counts[i] are state i's,
    in time order (the rest are not written)."""

    times: np.ndarray
    """When each happened (s), shape (n, capacity)."""
    which: np.ndarray
    """Which event, by its index in names, shape (n, capacity)."""
    states: np.ndarray
    """The state at each, shape (n, capacity, nx)."""
    counts: np.ndarray
    """How many events each state's log holds, shape (n,)."""
    names: list[str]
    """The scene's events by name."""

    def __len__(self) -> int:
        return len(self.counts)

    def __getitem__(self, i: int) -> EventLog:
        """State i's log, as `integrate_events` gives it."""
        k = int(self.counts[i])
        return EventLog(self.times[i, :k].copy(), [self.names[j] for j in self.which[i, :k]],
                        self.states[i, :k].copy())  # fmt: skip


@dataclass(frozen=True)
class Compiled:
    """One backend (C or Fortran) of a scene, loaded in this process.

    Its methods call the generated functions through cffi on numpy arrays:
    `setup` turns parameters into constants once, then `rhs`, `jacobian`,
    `output`, `integrate` and `integrate_batch` take those constants. Get
    one from `gyrogen.api.compile`.

    Examples
    --------
    >>> from gyrogen import api
    >>> model = api.compile("dual_spin")
    >>> model.language, model.nx, model.nc > 0
    ('c', 7, True)
    """

    language: Language
    manifest: dict[str, Any]
    ffi: Any
    lib: Any

    _c_held: tuple[Any, Any] = field(default=_NOTHING, init=False, repr=False, compare=False)
    """The last c array given (by identity) and its cffi buffer."""

    @cached_property
    def nx(self) -> int:
        """The number of states, the length of a state x."""
        return int(self.manifest["nx"])

    @cached_property
    def nc(self) -> int:
        """The number of constants setup computes, the length of c."""
        return int(self.manifest["nc"])

    def symbol(self, name: str) -> str:
        """The exported name of one of the build's functions.

        Parameters
        ----------
        name : str
            Its key in the manifest: setup, rhs, jac, an output
            (kinetic_energy, ...) or an integrator (rk4, dop853_batch, ...).

        Returns
        -------
        str
            The symbol the library exports.

        Raises
        ------
        ValueError
            The build has no such function (the message lists those it has).

        Examples
        --------
        >>> from gyrogen import api
        >>> api.compile("dual_spin").symbol("rhs")
        'dual_spin_rhs'
        """
        names = self.manifest["functions"][self.language]
        if name not in names:
            raise ValueError(f"this build has no function {name!r} (it has {', '.join(names)})")
        return str(names[name])

    def function(self, name: str) -> Any:
        """One of the build's functions, to call through cffi.

        Parameters
        ----------
        name : str
            Its key in the manifest, as for `symbol`.

        Returns
        -------
        cffi function
            Takes cffi pointers (see `doubles`) and C scalars.

        Raises
        ------
        ValueError
            The build has no such function.

        Examples
        --------
        >>> import numpy as np
        >>> from gyrogen import api
        >>> model = api.compile("dual_spin")
        >>> c = np.zeros(model.nc)
        >>> model.function("setup")(model.doubles(np.zeros(0)), model.doubles(c))
        0
        """
        return getattr(self.lib, self.symbol(name))

    def doubles(self, a: np.ndarray) -> Any:
        """A cffi `double[]` on an array's memory, with no copy.

        Parameters
        ----------
        a : numpy.ndarray
            A C-contiguous float64 array; it must outlive the pointer.

        Returns
        -------
        cffi buffer
            To hand to a function from `function`.

        Examples
        --------
        >>> import numpy as np
        >>> from gyrogen import api
        >>> len(api.compile("dual_spin").doubles(np.zeros(3)))
        3
        """
        return self.ffi.from_buffer("double[]", a)

    @cached_property
    def n_params(self) -> int:
        """The number of runtime parameters, the length of p."""
        return int(self.manifest["np"])

    def _vector(self, a: Any, size: int, what: str) -> np.ndarray:
        """a as a contiguous float64 array of shape (size,); a one-line
        ValueError otherwise (the C functions read exactly size values)."""
        arr = np.ascontiguousarray(real_only(a, what), dtype=np.float64)
        if arr.shape != (size,):
            raise ValueError(f"{what} must have shape ({size},), not {arr.shape}")
        return arr

    def _states(self, x: Any) -> np.ndarray:
        """x as contiguous float64 states, shape (nx,) or (n, nx)."""
        arr = np.ascontiguousarray(real_only(x, "states"), dtype=np.float64)
        if arr.ndim not in (1, 2) or arr.shape[-1] != self.nx:
            raise ValueError(
                f"states must have shape ({self.nx},) or (n, {self.nx}), not {arr.shape}"
            )
        return arr

    def setup_code(self, p: np.ndarray) -> tuple[int, np.ndarray]:
        """Run setup on a parameter vector and return its code, refused or not.

        Parameters
        ----------
        p : array_like, shape (n_params,)
            The runtime parameters in the scene's order (the header's, and
            `manifest["parameters"]`).

        Returns
        -------
        code : int
            0 if setup accepted p, else the first check that failed (the C
            interface's setup codes, `manifest["setup_codes"]`).
        c : numpy.ndarray, shape (nc,)
            The constants (meaningful only when code is 0).

        Raises
        ------
        ValueError
            p is not of shape (n_params,) or not real numbers.

        Examples
        --------
        >>> from gyrogen import api
        >>> model = api.compile("speed_controlled")
        >>> model.setup_code([0.3, 200.0])[0], model.setup_code([0.3, float("nan")])[0]
        (0, 1)
        """
        p = self._vector(p, self.n_params, "the parameters p")
        c = np.zeros(self.nc)
        code = self.function("setup")(self.doubles(p), self.doubles(c))
        return int(code), c

    def setup(self, p: np.ndarray) -> np.ndarray:
        """Check a parameter vector and compute the constants the other calls take.

        Parameters
        ----------
        p : array_like, shape (n_params,)
            The runtime parameters in the scene's order (empty for a scene
            that folds every parameter).

        Returns
        -------
        numpy.ndarray, shape (nc,)
            The constants c.

        Raises
        ------
        SetupRefused
            Setup refused p: one line with its code and reason (also when
            each value is valid and a derived constant overflows, code 9).
            It is a ValueError too.
        ValueError
            p is not of shape (n_params,) or not real numbers.

        Examples
        --------
        >>> from gyrogen import api
        >>> model = api.compile("speed_controlled")
        >>> c = model.setup([0.3, 200.0])
        >>> c.shape == (model.nc,)
        True
        """
        code, c = self.setup_code(p)
        if code != 0:
            why = self.manifest["setup_codes"][str(code)]
            raise SetupRefused(f"setup refused the parameters (code {code}): {why}")
        return c

    def output(self, name: str, x: np.ndarray, c: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Evaluate an output function of the scene at states.

        Parameters
        ----------
        name : str
            One of the scene's outputs: kinetic_energy, angular_momentum or
            power.
        x : array_like, shape (nx,) or (n, nx)
            The states.
        c : array_like, shape (nc,)
            The constants from `setup`.
        t : float, default 0.0
            The time (a torque table reads it).

        Returns
        -------
        numpy.ndarray, shape (n, size)
            One row per state (n = 1 for a single state); size 3 for the
            angular momentum, one per motor for a cluster's power.

        Raises
        ------
        ValueError
            The build has no such output, or x or c has the wrong shape.

        Examples
        --------
        >>> import numpy as np
        >>> from gyrogen import api
        >>> model = api.compile("dual_spin")
        >>> model.output("angular_momentum", np.zeros(model.nx), model.setup([])).shape
        (1, 3)
        """
        outputs = self.manifest["outputs"]
        if name not in outputs:
            have = ", ".join(outputs) or "none"
            raise ValueError(f"this build has no output {name!r} (its outputs: {have})")
        return self._apply(name, int(outputs[name]), x, c, t)

    @property
    def event_names(self) -> list[str]:
        """The scene's events by name, in the order of `events`' columns."""
        return [e["name"] for e in self.manifest.get("events", [])]

    def events(self, x: np.ndarray, c: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Evaluate the scene's event functions g(t, x) at states.

        Parameters
        ----------
        x : array_like, shape (nx,) or (n, nx)
            The states.
        c : array_like, shape (nc,)
            The constants from `setup`.
        t : float, default 0.0
            The time (an event may read it).

        Returns
        -------
        numpy.ndarray, shape (n, number of events)
            Column k is event k's g (`event_names`); an event happens where
            its g crosses zero.

        Raises
        ------
        ValueError
            The scene declares no events, or x or c has the wrong shape.
        """
        names = self.event_names
        if not names:
            raise ValueError("this build's scene declares no [[events]]")
        return self._apply("events", len(names), x, c, t)

    def jacobian(self, x: np.ndarray, c: np.ndarray, t: float = 0.0) -> np.ndarray:
        """The Jacobian of the right-hand side at one state.

        Parameters
        ----------
        x : array_like, shape (nx,)
            The state.
        c : array_like, shape (nc,)
            The constants from `setup`.
        t : float, default 0.0
            The time.

        Returns
        -------
        numpy.ndarray, shape (nx, nx)
            J[i, j] = d f_i / d x_j.

        Raises
        ------
        BuildError
            The scene compiled no Jacobian (it comes with an implicit
            integrator, rodas4 or radau5).
        ValueError
            x or c has the wrong shape.

        Examples
        --------
        >>> import numpy as np
        >>> from gyrogen import api
        >>> model = api.compile("dual_spin")
        >>> model.jacobian(np.zeros(model.nx), model.setup([])).shape
        (7, 7)
        """
        self._has_jacobian()
        x = self._vector(x, self.nx, "the state x (one state)")
        return self._apply("jac", self.nx * self.nx, x, c, t).reshape(self.nx, self.nx)

    def jacobians(self, x: np.ndarray, c: np.ndarray, t: float = 0.0) -> np.ndarray:
        """The Jacobian of the right-hand side at many states, in one call.

        Parameters
        ----------
        x : array_like, shape (n, nx)
            The states.
        c : array_like, shape (nc,)
            The constants from `setup`.
        t : float, default 0.0
            The time.

        Returns
        -------
        numpy.ndarray, shape (n, nx, nx)
            Row k is `jacobian` at x[k], the same numbers.

        Raises
        ------
        BuildError
            The scene compiled no Jacobian.
        ValueError
            x or c has the wrong shape.
        """
        self._has_jacobian()
        x = self._states(x)
        if x.ndim != 2:
            raise ValueError(f"states must have shape (n, {self.nx}), not {x.shape}")
        return self._apply("jac", self.nx * self.nx, x, c, t).reshape(-1, self.nx, self.nx)

    def _has_jacobian(self) -> None:
        if "jac" not in self.manifest["functions"][self.language]:
            raise BuildError(
                f"scene {self.manifest['prefix']} has no Jacobian (add one of "
                f"{', '.join(methods.IMPLICIT)} to its integrators)"
            )

    def _apply(self, name: str, size: int, x: np.ndarray, c: np.ndarray, t: float) -> np.ndarray:
        x = self._states(x).reshape(-1, self.nx)
        out = np.empty((x.shape[0], size))
        fn = self.ffi.addressof(self.lib, self.symbol(name))
        c = self._vector(c, self.nc, "the constants c")
        self.lib.gyrogen_batch(
            fn, x.shape[0], size, t, self.doubles(x), self.doubles(c), self.doubles(out)
        )
        return out

    def rhs(self, x: np.ndarray, c: np.ndarray, t: float = 0.0) -> np.ndarray:
        """The right-hand side dx/dt at one state or many.

        Parameters
        ----------
        x : array_like, shape (nx,) or (n, nx)
            The states.
        c : array_like, shape (nc,)
            The constants from `setup`.
        t : float, default 0.0
            The time (a torque table reads it).

        Returns
        -------
        numpy.ndarray
            dx/dt, of x's shape.

        Raises
        ------
        ValueError
            x or c has the wrong shape, or is not real.

        Examples
        --------
        >>> import numpy as np
        >>> from gyrogen import api
        >>> model = api.compile("dual_spin")
        >>> model.rhs(np.zeros((5, model.nx)), model.setup([])).shape
        (5, 7)
        """
        x = self._states(x)
        out = np.empty_like(x)
        c = self._vector(c, self.nc, "the constants c")
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
        *,
        rtol: float = DEFAULT_CONTROLS["rtol"],
        atol: float = DEFAULT_CONTROLS["atol"],
        h0: float = DEFAULT_CONTROLS["h0"],
        max_steps: int = DEFAULT_CONTROLS["max_steps"],
        steps: int | None = None,
    ) -> tuple[np.ndarray, Stats, int]:
        """Integrate one state with a compiled integrator.

        The call costs about a microsecond more than the C call itself
        (`make bench-call` measures it): the method's function is looked up
        once per build and c's buffer once per array.

        Parameters
        ----------
        method : str
            One of the scene's integrators: rk4, dopri5, dop853, rodas4,
            radau5, taylor.
        x0 : array_like, shape (nx,)
            The start state; it is not changed.
        c : array_like, shape (nc,)
            The constants from `setup`.
        t0, t1 : float
            Start and end time, t1 >= t0.
        rtol, atol : float, default 1e-8
            Tolerances of the adaptive methods (rtol above 10 DBL_EPSILON,
            DBL_EPSILON for taylor; atol above 0).
        h0 : float, default 0.0
            The first step size; 0 or less: chosen by the method.
        max_steps : int, default gyrogen.abi.MAX_STEPS
            The step budget of the adaptive methods.
        steps : int, optional
            The number of equal steps: given for rk4, and only for it.

        Returns
        -------
        x : numpy.ndarray, shape (nx,)
            The state at t1 (a new array), or the last good state on failure.
        stats : Stats
            The step statistics, a read-only mapping (t, h, accepted,
            rejected, rhs_calls, jac_calls, decompositions).
        code : int
            0 on success, else the integrator's return code (1 step size
            underflow, 2 max_steps reached, 3 non-finite state, 4 singular
            iteration matrix, 5 bad argument, 6 gimbal lock).

        Raises
        ------
        ValueError
            The build has no such integrator, steps is given for an adaptive
            method or missing for rk4, or an argument has the wrong shape or
            a value C cannot hold.

        Examples
        --------
        >>> from gyrogen import api
        >>> model = api.compile("dual_spin")
        >>> x0 = [0, 0, 0, 0.001, 0.05, 0.0, 600.0]
        >>> x, stats, code = model.integrate("dop853", x0, model.setup([]), 0.0, 10.0)
        >>> code, x.shape, stats["t"]
        (0, (7,), 10.0)
        """
        try:
            call = self._single[method]
        except KeyError:
            self._check_method(method, steps)  # raises, saying why
            raise
        return call(x0, c, t0, t1, rtol, atol, h0, max_steps, steps)

    @cached_property
    def _integrators(self) -> dict[str, tuple[Any, bool]]:
        """Each integrator of this build: its cffi function, and whether it
        is a fixed-step method."""
        return {
            m: (self.function(m), methods.get(m).fixed_step) for m in self.manifest["integrators"]
        }

    @cached_property
    def _single(self) -> dict[str, Callable[..., tuple[np.ndarray, Stats, int]]]:
        """integrate()'s work for each integrator, bound once per build."""
        return {m: self._bind(m, fn, fixed) for m, (fn, fixed) in self._integrators.items()}

    def _bind(self, method: str, fn: Any, fixed: bool) -> Callable[..., Any]:
        """The single-trajectory call of one integrator: everything it can
        look up is looked up here, once; a new state and stats struct per
        call (calls may run at once on several threads: cffi releases the
        GIL)."""
        shape, new, buffer = (self.nx,), self.ffi.new, self.ffi.from_buffer

        def call(
            x0: Any, c: Any, t0: float, t1: float, rtol: float, atol: float, h0: float,
            max_steps: int, steps: int | None,
        ) -> tuple[np.ndarray, Stats, int]:  # fmt: skip
            if (steps is None) == fixed:
                self._check_method(method, steps)  # raises, saying why
            if x0.__class__ is np.ndarray and x0.dtype is _F64 and x0.shape == shape:
                x = x0.copy()  # integrated in place
            else:
                x = self._state(x0)
            held = self._c_held
            cb = held[1] if held[0] is c else self._c_buffer(c)
            stats = new(_STATS_PTR)
            try:
                if fixed:
                    code = fn(t0, t1, steps, buffer(_DOUBLES, x), cb, stats)
                else:
                    code = fn(t0, t1, buffer(_DOUBLES, x), cb, rtol, atol, h0, max_steps, stats)
            except (OverflowError, TypeError) as exc:
                raise controls_error(exc, t0, t1, rtol, atol, h0, max_steps, steps) from None
            return x, Stats(stats), code

        return call

    def _c_buffer(self, c: Any) -> Any:
        """c's cffi buffer, kept for the next call with the same array (a
        one-line ValueError for a wrong length or a non-finite value)."""
        arr = self._vector(c, self.nc, "the constants c")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"the constants c are not all finite (index {_bad(arr)})")
        buf = self.doubles(arr)
        if arr is c:  # a later call with this array reuses the buffer
            object.__setattr__(self, "_c_held", (c, buf))
        return buf

    def _state(self, x0: Any) -> np.ndarray:
        # a copy: integrated in place
        x = np.array(real_only(x0, "the initial state"), dtype=np.float64)
        if x.shape != (self.nx,):
            raise ValueError(f"the initial state must have shape ({self.nx},), not {x.shape}")
        return x

    def integrate_batch(
        self,
        method: str,
        x0s: np.ndarray,
        c: np.ndarray,
        t0: float,
        t1: float,
        threads: int | None = None,
        *,
        rtol: float = DEFAULT_CONTROLS["rtol"],
        atol: float = DEFAULT_CONTROLS["atol"],
        h0: float = DEFAULT_CONTROLS["h0"],
        max_steps: int = DEFAULT_CONTROLS["max_steps"],
        steps: int | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Integrate many states with one set of constants.

        The explicit pairs, the Taylor method, rodas4 and radau5 where the
        scene asks (its `lanes`) run the states in SIMD lanes, each equal
        bit for bit to `integrate`'s result. A build with
        OpenMP splits the batch over the cores in C, one without it in
        slices called from Python threads (cffi releases the GIL); the
        results do not depend on the thread count.

        Parameters
        ----------
        method : str
            One of the scene's integrators.
        x0s : array_like, shape (n, nx)
            The start states; not changed.
        c : array_like, shape (nc,)
            The constants from `setup`, shared by every state.
        t0, t1 : float
            Start and end time.
        threads : int, optional
            How many cores: None for every one, 1 for this one.
        rtol, atol, h0, max_steps, steps
            As for `integrate`.

        Returns
        -------
        x : numpy.ndarray, shape (n, nx)
            The final states (the last good state where one failed).
        stats : numpy.ndarray, shape (n,)
            A structured array with the statistics' fields.
        codes : numpy.ndarray, shape (n,)
            Each state's return code, as `integrate`'s.

        Raises
        ------
        ValueError
            As for `integrate`, or threads is not an integer from 1 to 4096.

        Examples
        --------
        >>> import numpy as np
        >>> from gyrogen import api
        >>> model = api.compile("dual_spin")
        >>> x0s = np.tile([0, 0, 0, 0.001, 0.05, 0.0, 600.0], (16, 1))
        >>> x, stats, codes = model.integrate_batch("dop853", x0s, model.setup([]), 0.0, 10.0)
        >>> x.shape, bool((codes == 0).all()), stats["accepted"].shape
        ((16, 7), True, (16,))
        """
        try:
            fn, fixed = self._batches[method]
        except KeyError:
            self._check_method(method, steps)  # raises, saying why
            raise
        if (steps is None) == fixed:
            self._check_method(method, steps)
        if x0s.__class__ is np.ndarray and x0s.dtype is _F64 and x0s.ndim == 2:
            x = x0s.copy()  # C order; integrated in place
        else:
            x = np.array(real_only(x0s, "initial states"), dtype=np.float64, order="C", ndmin=2)
            if x.size == 0:  # an empty batch: [] or (0, nx)
                x = x.reshape(0, self.nx)
        if x.ndim != 2 or x.shape[1] != self.nx:
            raise ValueError(f"initial states must have shape (n, {self.nx}), not {x.shape}")
        n = x.shape[0]
        stats = np.zeros(n, dtype=self._stats_dtype)
        codes = np.zeros(n, dtype=np.intc)
        held = self._c_held
        cb = held[1] if held[0] is c else self._c_buffer(c)
        buf = self.ffi.from_buffer
        count = self._cores if threads is None else threads
        if not isinstance(count, (int, np.integer)) or not 1 <= count <= THREADS_MAX:
            raise ValueError(f"threads must be an integer from 1 to {THREADS_MAX}, not {count!r}")

        def run(lo: int, hi: int) -> None:
            xb, sb = buf(_DOUBLES, x[lo:hi]), buf(_STATS, stats[lo:hi])
            kb = buf(_INTS, codes[lo:hi])
            if fixed:
                fn(hi - lo, t0, t1, steps, xb, cb, sb, kb)
            else:
                fn(hi - lo, t0, t1, xb, cb, rtol, atol, h0, max_steps, sb, kb)

        try:
            self._spread(run, count, n)
        except (OverflowError, TypeError) as exc:
            raise controls_error(exc, t0, t1, rtol, atol, h0, max_steps, steps) from None
        return x, stats, codes

    def integrate_var(
        self,
        method: str,
        x0: np.ndarray,
        c: np.ndarray,
        t0: float,
        t1: float,
        **kwargs: Any,
    ) -> tuple[np.ndarray, np.ndarray, Stats, int]:
        """Integrate one state with its state transition matrix and
        sensitivities (the scene's [sensitivities]).

        The augmented system y = (x, Phi's entries that can be nonzero) is
        integrated by the method's own code instantiated for it
        (<prefix>_var_<method>): Phi' = J_x Phi from Phi(t0) = I, S' = J_x S
        + J_p from S(t0) = 0. Phi is the derivative of the flow of the ODE:
        a quaternion start is normalized by the integrator, but Phi does not
        differentiate that normalization.

        Parameters
        ----------
        method : str
            One of the augmented system's integrators (the scene's explicit
            ones: rk4, dopri5, dop853, taylor).
        x0 : array_like, shape (nx,)
            The start state; not changed.
        c : array_like, shape (nc,)
            The constants from `setup` (they include the variational
            system's).
        t0, t1 : float
            Start and end time.
        rtol, atol, h0, max_steps, steps
            As for `integrate`; the step control measures x and Phi, or x
            alone (the scene's sensitivities.error).

        Returns
        -------
        x : numpy.ndarray, shape (nx,)
            The state at t1.
        Phi : numpy.ndarray, shape (nx, ncol)
            dx(t1)/dx0 in the first nx columns (when wrt has "state"), then
            dx(t1)/dp for each parameter of wrt, in wrt's order.
        stats : Stats
            The step statistics.
        code : int
            As for `integrate`.

        Raises
        ------
        ValueError
            The scene declares no sensitivities, or as for `integrate`.
        """
        var, layout = self._variational
        y, stats, code = var.integrate(method, layout.pack(self._state(x0)), c, t0, t1, **kwargs)
        x, phi = layout.unpack(y)
        return x, phi, stats, code

    def integrate_var_batch(
        self,
        method: str,
        x0s: np.ndarray,
        c: np.ndarray,
        t0: float,
        t1: float,
        threads: int | None = None,
        **kwargs: Any,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """`integrate_var` for many states with one set of constants, as
        `integrate_batch` (SIMD lanes for the pairs, the Taylor method, rodas4
        and an asked-for radau5).

        Returns
        -------
        x : numpy.ndarray, shape (n, nx)
        Phi : numpy.ndarray, shape (n, nx, ncol)
        stats : numpy.ndarray, shape (n,)
        codes : numpy.ndarray, shape (n,)
        """
        var, layout = self._variational
        x0 = np.array(real_only(x0s, "initial states"), dtype=np.float64, ndmin=2)
        if x0.ndim != 2 or x0.shape[1] != self.nx:
            raise ValueError(f"initial states must have shape (n, {self.nx}), not {x0.shape}")
        y, stats, codes = var.integrate_batch(method, layout.pack(x0), c, t0, t1, threads, **kwargs)
        x, phi = layout.unpack(y)
        return x, phi, stats, codes

    def integrate_var_grid(
        self,
        method: str,
        x0: np.ndarray,
        c: np.ndarray,
        times: np.ndarray,
        **kwargs: Any,
    ) -> tuple[np.ndarray, np.ndarray, Stats, int]:
        """`integrate_var` on an output grid, as `integrate_grid`: one
        integration of x with Phi, both read at each time from the method's
        dense output (Phi(times[0]) = I: the grid's first time is the start).

        Returns
        -------
        x : numpy.ndarray, shape (n, nx)
        Phi : numpy.ndarray, shape (n, nx, ncol)
            Rows past the time a failure reached are NaN in both.
        stats : Stats
        code : int
        """
        var, layout = self._variational
        y0 = layout.pack(self._state(x0))
        y, stats, code = var.integrate_grid(method, y0, c, times, **kwargs)
        x, phi = layout.unpack(y)
        phi[np.isnan(x[:, 0])] = np.nan
        return x, phi, stats, code

    @cached_property
    def _variational(self) -> tuple[Compiled, Layout]:
        """The augmented system's functions in this build, and its layout."""
        var = self.manifest.get("variational")
        if var is None:
            raise ValueError(
                f"scene {self.manifest['prefix']} declares no sensitivities: add a "
                '[sensitivities] table (wrt = ["state", ...]) and generate it again'
            )
        return Compiled(self.language, var, self.ffi, self.lib), Layout.of(var)

    @cached_property
    def _batches(self) -> dict[str, tuple[Any, bool]]:
        """Each integrator's _batch function, and whether it is fixed-step."""
        return {
            m: (self.function(f"{m}_batch"), fixed) for m, (_, fixed) in self._integrators.items()
        }

    def integrate_grid(
        self,
        method: str,
        x0: np.ndarray,
        c: np.ndarray,
        times: np.ndarray,
        *,
        rtol: float = DEFAULT_CONTROLS["rtol"],
        atol: float = DEFAULT_CONTROLS["atol"],
        h0: float = DEFAULT_CONTROLS["h0"],
        max_steps: int = DEFAULT_CONTROLS["max_steps"],
    ) -> tuple[np.ndarray, Stats, int]:
        """The states at each of an output grid's times, from one integration.

        As heyoka's propagate_grid: the first grid time is the start time
        (x0's), the last the end time; the run is one adaptive integration
        whose steps are not cut at the grid times, each state between the
        ends read from the method's dense output (dopri5: order 4, dop853:
        7, rodas4: 3, radau5: its collocation polynomial, taylor: its
        series; Euler parameters as interpolated, |e| = 1 within the
        interpolation's error). The last state equals `integrate`'s from times[0] to
        times[-1] bit for bit, and so do the step statistics but for the
        explicit pairs' and Taylor's rhs_calls (the interpolant's stages).

        Parameters
        ----------
        method : str
            One of the scene's adaptive integrators.
        x0 : array_like, shape (nx,)
            The state at times[0]; it is not changed.
        c : array_like, shape (nc,)
            The constants from `setup`.
        times : array_like, shape (n,)
            At least one time, finite and strictly increasing.
        rtol, atol, h0, max_steps
            As for `integrate`.

        Returns
        -------
        states : numpy.ndarray, shape (n, nx)
            states[g] at times[g]; rows past the time a failure reached are NaN.
        stats : Stats
            The step statistics, as `integrate`'s.
        code : int
            0 on success, else the integrator's return code, as `integrate`'s.

        Raises
        ------
        ValueError
            As for `integrate`, or the times are not a non-empty 1-D array of
            finite, strictly increasing reals (unsorted, repeated, NaN).

        Examples
        --------
        >>> import numpy as np
        >>> from gyrogen import api
        >>> model = api.compile("dual_spin")
        >>> x0 = [0, 0, 0, 0.001, 0.05, 0.0, 600.0]
        >>> states, stats, code = model.integrate_grid("dop853", x0, model.setup([]),
        ...                                            np.linspace(0.0, 10.0, 11))
        >>> code, states.shape
        (0, (11, 7))
        """
        fn = self._grid(method, "_grid")
        t = grid_times(times)
        x = self._state(x0)
        out = np.full((t.size, self.nx), np.nan)
        stats = self.ffi.new(_STATS_PTR)
        buf, held = self.ffi.from_buffer, self._c_held
        cb = held[1] if held[0] is c else self._c_buffer(c)
        try:
            code = fn(t.size, buf(_DOUBLES, t), buf(_DOUBLES, x), cb, rtol, atol, h0, max_steps,
                      buf(_DOUBLES, out), stats)  # fmt: skip
        except (OverflowError, TypeError) as exc:
            raise controls_error(exc, t[0], t[-1], rtol, atol, h0, max_steps, None) from None
        return out, Stats(stats), code

    def integrate_events(
        self,
        method: str,
        x0: np.ndarray,
        c: np.ndarray,
        times: np.ndarray,
        *,
        rtol: float = DEFAULT_CONTROLS["rtol"],
        atol: float = DEFAULT_CONTROLS["atol"],
        h0: float = DEFAULT_CONTROLS["h0"],
        max_steps: int = DEFAULT_CONTROLS["max_steps"],
        capacity: int = 10_000,
        end: np.ndarray | None = None,
    ) -> tuple[np.ndarray, EventLog, Stats, int]:
        """`integrate_grid` with the scene's [[events]] located.

        After each accepted step the integrator searches the step's dense
        output in pieces, halved until the largest rate of g seen could not
        carry g to 0 and back within one (so an event faster than the
        motion the steps follow loses no crossing); an event whose g
        changed sign in a piece as its direction asks is located on the
        dense output (the Illinois method, until
        the bracket holds no double between its ends) and logged, the
        crossings of one step in time order. A terminal event stops the run
        there: x is the state at the event, the grid's rows past it stay
        NaN, and the code is 8 (ODE_EVENT). A crossing past `capacity`
        logged ones stops the run the same way with code 9.

        Limits: a g of 0 at times[0] is not a crossing (nor is one at a
        piece's start: it was the piece before's); two crossings of one
        event within 2^-16 of a step (a double root, a grazing touch)
        cancel and are not seen; a NaN g never crosses (a crossing before g turns NaN
        within a step is located: the step is searched up to g's last
        finite point, and one after g turns finite from its first finite
        point).

        Parameters
        ----------
        method, x0, c, times, rtol, atol, h0, max_steps
            As for `integrate_grid`.
        capacity : int, default 10000
            The most events the log holds.
        end : numpy.ndarray, shape (nx,), optional
            Receives the state the run ended at: times[-1]'s, a terminal
            event's, or on failure the last good one.

        Returns
        -------
        states : numpy.ndarray, shape (n, nx)
            As `integrate_grid`'s.
        log : EventLog
            The events in time order: their times, names and states.
        stats : Stats
        code : int
            0, or 8 at a terminal event, 9 for a full log, else as `integrate`'s.

        Raises
        ------
        ValueError
            As for `integrate_grid`, the scene declares no events,
            capacity is not an integer from 0 to 10^8, or end is not a
            writable float64 array of shape (nx,).
        """
        fn = self._events(method, "_events", capacity)
        t = grid_times(times)
        x = self._state(x0)
        receiver(end, (self.nx,), "end")
        out = np.full((t.size, self.nx), np.nan)
        log_t, log_k = np.zeros(max(capacity, 1)), np.zeros(max(capacity, 1), dtype=np.intc)
        log_x = np.zeros((max(capacity, 1), self.nx))
        nlog = self.ffi.new("long *")
        stats = self.ffi.new(_STATS_PTR)
        buf, held = self.ffi.from_buffer, self._c_held
        cb = held[1] if held[0] is c else self._c_buffer(c)
        try:
            code = fn(t.size, buf(_DOUBLES, t), buf(_DOUBLES, x), cb, rtol, atol, h0, max_steps,
                      buf(_DOUBLES, out), capacity, buf(_DOUBLES, log_t), buf(_INTS, log_k),
                      buf(_DOUBLES, log_x), nlog, stats)  # fmt: skip
        except (OverflowError, TypeError) as exc:
            raise controls_error(exc, t[0], t[-1], rtol, atol, h0, max_steps, None) from None
        if end is not None:
            end[...] = x
        n = int(nlog[0])
        names = self.event_names
        log = EventLog(log_t[:n].copy(), [names[k] for k in log_k[:n]], log_x[:n].copy())
        return out, log, Stats(stats), code

    def integrate_grid_batch(
        self,
        method: str,
        x0s: np.ndarray,
        c: np.ndarray,
        times: np.ndarray,
        threads: int | None = None,
        *,
        rtol: float = DEFAULT_CONTROLS["rtol"],
        atol: float = DEFAULT_CONTROLS["atol"],
        h0: float = DEFAULT_CONTROLS["h0"],
        max_steps: int = DEFAULT_CONTROLS["max_steps"],
        ends: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`integrate_grid` for many states over the same times; each
        state's rows equal its `integrate_grid` call's bit for bit, whatever
        the thread count. c, the constants from `setup`: shape (nc,), one
        set for every state, or (n, nc), a set per state (each stretch of
        states with equal rows one call of the compiled batch). ends, an
        (n, nx) array if given, receives the state each run ended at
        (times[-1]'s, or on failure the last good one).

        Returns
        -------
        states : numpy.ndarray, shape (n, len(times), nx)
        stats : numpy.ndarray, shape (n,)
            As `integrate_batch`'s.
        codes : numpy.ndarray, shape (n,)

        Raises
        ------
        ValueError
            As for `integrate_grid` and `integrate_batch`, or ends is not a
            writable float64 array of shape (n, nx).
        """
        fn = self._grid(method, "_grid_batch")
        t = grid_times(times)
        x = self._start_states(x0s)
        n = x.shape[0]
        receiver(ends, (n, self.nx), "ends")
        out = np.full((n, t.size, self.nx), np.nan)
        stats = np.zeros(n, dtype=self._stats_dtype)
        codes = np.zeros(n, dtype=np.intc)
        stretches = self._stretches(c, n)
        buf = self.ffi.from_buffer
        count = self._thread_count(threads)
        tb = buf(_DOUBLES, t)
        rows = (buf(_DOUBLES, x), buf(_DOUBLES, out), buf(_STATS, stats), buf(_INTS, codes))
        widths = (self.nx, t.size * self.nx, 1, 1)  # each array's elements per state

        def call(k: int, cb: Any, xb: Any, ob: Any, sb: Any, kb: Any) -> None:
            fn(k, t.size, tb, xb, cb, rtol, atol, h0, max_steps, ob, sb, kb)

        self._over_stretches(call, stretches, rows, widths, count, n,
                             (t[0], t[-1], rtol, atol, h0, max_steps))  # fmt: skip
        if ends is not None:
            ends[...] = x
        return out, stats, codes

    def integrate_events_batch(
        self,
        method: str,
        x0s: np.ndarray,
        c: np.ndarray,
        times: np.ndarray,
        threads: int | None = None,
        *,
        rtol: float = DEFAULT_CONTROLS["rtol"],
        atol: float = DEFAULT_CONTROLS["atol"],
        h0: float = DEFAULT_CONTROLS["h0"],
        max_steps: int = DEFAULT_CONTROLS["max_steps"],
        capacity: int = 100,
        ends: np.ndarray | None = None,
    ) -> tuple[np.ndarray, EventLogs, np.ndarray, np.ndarray]:
        """`integrate_events` for many states over the same times: each
        state's rows, log, statistics and code equal its `integrate_events`
        call's (with this capacity) bit for bit, whatever the thread count.
        c as for `integrate_grid_batch` (one set, or a set per state).
        ends, an (n, nx) array if given, receives the state each run ended
        at.

        Parameters
        ----------
        capacity : int, default 100
            The most events each state's log holds (its buffers are
            allocated for every state: n capacity (nx + 2) doubles).

        Returns
        -------
        states : numpy.ndarray, shape (n, len(times), nx)
        logs : EventLogs
            logs[i] is state i's EventLog.
        stats : numpy.ndarray, shape (n,)
            As `integrate_batch`'s.
        codes : numpy.ndarray, shape (n,)

        Raises
        ------
        ValueError
            As for `integrate_events` and `integrate_batch`, or ends is not a
            writable float64 array of shape (n, nx).
        """
        fn = self._events(method, "_events_batch", capacity)
        t = grid_times(times)
        x = self._start_states(x0s)
        n, room = x.shape[0], max(capacity, 1)
        receiver(ends, (n, self.nx), "ends")
        out = np.full((n, t.size, self.nx), np.nan)
        logs = EventLogs(np.empty((n, room)), np.empty((n, room), dtype=np.intc),
                         np.empty((n, room, self.nx)), np.zeros(n, dtype=np.dtype(self._long)),
                         self.event_names)  # fmt: skip
        stats = np.zeros(n, dtype=self._stats_dtype)
        codes = np.zeros(n, dtype=np.intc)
        stretches = self._stretches(c, n)
        buf = self.ffi.from_buffer
        count = self._thread_count(threads)
        tb = buf(_DOUBLES, t)
        rows = (buf(_DOUBLES, x), buf(_DOUBLES, out), buf(_DOUBLES, logs.times),
                buf(_INTS, logs.which), buf(_DOUBLES, logs.states), buf("long[]", logs.counts),
                buf(_STATS, stats), buf(_INTS, codes))  # fmt: skip
        widths = (self.nx, t.size * self.nx, room, room, room * self.nx, 1, 1, 1)

        def call(k: int, cb: Any, xb: Any, ob: Any, *rest: Any) -> None:  # rest: log, stats, codes
            fn(k, t.size, tb, xb, cb, rtol, atol, h0, max_steps, ob, capacity, *rest)

        self._over_stretches(call, stretches, rows, widths, count, n,
                             (t[0], t[-1], rtol, atol, h0, max_steps))  # fmt: skip
        if ends is not None:
            ends[...] = x
        return out, logs, stats, codes

    def _over_stretches(
        self,
        call: Callable[..., None],
        stretches: list[tuple[int, int, Any]],
        rows: tuple[Any, ...],
        widths: tuple[int, ...],
        count: int,
        n: int,
        limits: tuple[float, float, float, float, float, int],
    ) -> None:
        """call(k, c's buffer, *rows at the stretch's first state) for each
        stretch of k states with equal constants (rows: each array's buffer,
        widths: its elements per state), spread over count cores; a control
        the C call cannot take (limits: t0, t1, rtol, atol, h0, max_steps) is
        one line, as `integrate`'s."""

        def run(lo: int, hi: int) -> None:
            for a, b, cb in _within(stretches, lo, hi):
                call(b - a, cb, *(r + a * w for r, w in zip(rows, widths, strict=True)))

        try:
            self._spread(run, count, n)
        except (OverflowError, TypeError) as exc:
            raise controls_error(exc, *limits, None) from None

    def _spread(self, run: Callable[[int, int], None], count: int, n: int) -> None:
        """run(lo, hi) over states 0..n-1 on count cores: one call (OpenMP
        splits it in C, or one thread), or one per slice of the states from
        Python threads (cffi releases the GIL)."""
        if self.lib.gyrogen_threads(count) or count == 1 or n < 2:
            run(0, n)
        else:
            cuts = np.linspace(0, n, min(count, n) + 1).astype(int).tolist()
            with ThreadPoolExecutor(len(cuts) - 1) as pool:
                list(pool.map(run, cuts[:-1], cuts[1:]))

    def _stretches(self, c: Any, n: int) -> list[tuple[int, int, Any]]:
        """States 0..n-1 by the constants they share: (start, stop, c's
        cffi buffer), one stretch for c of shape (nc,), one per run of
        equal rows for c of shape (n, nc); a one-line ValueError otherwise."""
        if np.ndim(c) != 2:
            held = self._c_held
            return [(0, n, held[1] if held[0] is c else self._c_buffer(c))]
        arr = np.ascontiguousarray(real_only(c, "the constants c"), dtype=np.float64)
        if arr.shape != (n, self.nc):
            raise ValueError(f"the constants c must have shape ({self.nc},) or "
                             f"({n}, {self.nc}), not {arr.shape}")  # fmt: skip
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"the constants c are not all finite (row {_bad(arr) // self.nc})")
        cuts = np.flatnonzero((arr[1:] != arr[:-1]).any(axis=1)) + 1
        edges = [0, *cuts.tolist(), n]
        return [(a, b, self.doubles(arr[a])) for a, b in itertools.pairwise(edges)]

    @cached_property
    def _long(self) -> str:
        """C's long as numpy's dtype string."""
        return f"i{self.ffi.sizeof('long')}"

    def _events(self, method: str, kind: str, capacity: Any) -> Any:
        """method's _events or _events_batch function; a one-line ValueError
        as for `_grid`, for a scene without events, or a capacity not an
        integer from 0 to 10^8."""
        if not self.event_names:
            raise ValueError("this build's scene declares no [[events]]")
        if not isinstance(capacity, (int, np.integer)) or not 0 <= capacity <= 10**8:
            raise ValueError(f"capacity must be an integer from 0 to 10^8, not {capacity!r}")
        return self._grid(method, kind)

    def _grid(self, method: str, kind: str) -> Any:
        """method's function of an output grid by its kind (_grid,
        _grid_batch, _events, _events_batch); a one-line ValueError for a
        method this build lacks or one without an output grid (rk4)."""
        if method not in self.manifest["integrators"]:
            self._check_method(method, None)  # raises, saying why
        if methods.get(method).fixed_step:
            raise ValueError(f"{method} has no output grid: it is a fixed-step method")
        return self.function(method + kind)

    def _start_states(self, x0s: Any) -> np.ndarray:
        """x0s as a new (n, nx) C-order array (integrated in place)."""
        x = np.array(real_only(x0s, "initial states"), dtype=np.float64, order="C", ndmin=2)
        if x.size == 0:  # an empty batch: [] or (0, nx)
            x = x.reshape(0, self.nx)
        if x.ndim != 2 or x.shape[1] != self.nx:
            raise ValueError(f"initial states must have shape (n, {self.nx}), not {x.shape}")
        return x

    def _thread_count(self, threads: int | None) -> int:
        count = self._cores if threads is None else threads
        if not isinstance(count, (int, np.integer)) or not 1 <= count <= THREADS_MAX:
            raise ValueError(f"threads must be an integer from 1 to {THREADS_MAX}, not {count!r}")
        return int(count)

    @cached_property
    def _cores(self) -> int:
        return cores()

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
                f"{method} is a fixed-step method: give it steps= (the number of equal steps)"
                if fixed
                else f"{method} is adaptive: steps= goes with the fixed-step methods only"
            )
        return fixed

    @cached_property
    def _stats_dtype(self) -> np.dtype:
        """gyrogen_stats as numpy sees it, offsets and size from cffi."""
        fields = abi.STATS_FIELDS
        return np.dtype(
            {
                "names": [f.name for f in fields],
                "formats": ["f8" if f.ctype == "double" else self._long for f in fields],
                "offsets": [self.ffi.offsetof("gyrogen_stats", f.name) for f in fields],
                "itemsize": self.ffi.sizeof("gyrogen_stats"),
            }
        )
