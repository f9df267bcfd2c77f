"""Simulate a scene: generate, build, integrate with scipy's solve_ivp through
the compiled RHS (or with a compiled integrator: by default the best
implicit one for a stiff scene, analysis/check/stiffness.py), check the invariants with
the numpy reference (analysis/simulate/invariants.py), and write the trajectory (CSV,
npz), a summary and a figure (analysis/simulate/files.py), all or nothing.

The run is one function of time: its states on the output grid and, for
the quadrature of the balances, anywhere between (analysis/simulate/trajectory.py).
A compiled integrator runs from each grid time (and each torque table's
point) to the next, so every grid state is a step end; the quadrature
samples a segment by running it again as a `_grid` call (the same steps,
their dense output). solve_ivp runs from each table's point to the next,
its dense output kept, the grid read from it: between steps it is less
accurate than the steps themselves (DOP853 in a long step: 1e-7 mid-step on
speed_controlled), and the residuals show it: they measure the trajectory
as written, not only the steps.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

from gyrogen import methods
from gyrogen.abi import ODE_CODES, ODE_EVENT, ODE_LOG_FULL, message
from gyrogen.analysis.check import stiffness
from gyrogen.analysis.simulate import files
from gyrogen.analysis.simulate.invariants import along_trajectory, words
from gyrogen.analysis.simulate.result import Result, Settings
from gyrogen.analysis.simulate.trajectory import Trajectory, output_grid
from gyrogen.errors import GyrogenError, SceneError
from gyrogen.files import can_write, transaction, write_atomic
from gyrogen.oracle import scene_view
from gyrogen.runtime.compiled import Compiled, Controls, EventLog, controls
from gyrogen.runtime.rhs import RawRhs
from gyrogen.runtime.scene_build import build_files, scene_sources
from gyrogen.runtime.segment import ERR_MAX_STEPS, integrate_segments, resampled
from gyrogen.scene import Scene

Advance = Callable[[int], None]
"""Told how many more percent of the simulated time are done."""
Progress = Callable[[str], AbstractContextManager[Advance]]
"""label -> a context holding an Advance (a progress bar)."""


def _no_progress(label: str) -> AbstractContextManager[Advance]:
    return nullcontext(lambda n: None)


def runtime_values(scene: Scene) -> np.ndarray:
    """simulate.parameters in p[] order; every runtime parameter needs one."""
    given = scene.simulate.parameters
    missing = [n for n in scene.runtime if n not in given]
    if missing:
        raise SceneError(
            f"{scene.name}: simulate.parameters: no value for runtime parameter "
            f"{', '.join(missing)} (set it under [simulate] parameters)"
        )
    return np.array([given[n] for n in scene.runtime], dtype=np.float64)


class _Exhausted(Exception):
    pass


class _Rhs(RawRhs):
    """The raw rhs for solve_ivp, advancing the progress bar by simulated
    time at most once per percent (the bookkeeping adds ~0.1 us a call), and
    giving up after budget calls."""

    def __init__(self, comp: Compiled, c: np.ndarray, t_end: float, advance: Advance, budget: int):
        super().__init__(comp, c)
        self.t_end, self.advance = t_end, advance
        self.shown, self.mark, self.t_max = 0, t_end / 100, 0.0
        self.calls, self.budget = 0, budget

    def __call__(self, t: float, x: np.ndarray) -> np.ndarray:
        out = super().__call__(t, x)
        self.calls += 1
        if self.calls > self.budget:
            raise _Exhausted
        if t > self.t_max:
            self.t_max = t
            if t >= self.mark:
                self._tick(t)
        return out

    def _tick(self, t: float) -> None:
        pct = min(int(100 * t / self.t_end), 100)
        self.advance(pct - self.shown)
        self.shown = pct
        self.mark = (pct + 1) * self.t_end / 100

    def finish(self) -> None:
        self.advance(100 - self.shown)
        self.shown = 100


@dataclass(frozen=True)
class Start:
    """What an integration starts from: the backend and its constants, the
    state at t = 0, the scene's (rtol, atol), and the times the run stops
    and starts again at (its torque tables' points, where the rhs is not
    smooth in t: a step across one loses its order, or steps over a narrow
    pulse unseen)."""

    comp: Compiled
    c: np.ndarray
    x0: np.ndarray
    tol: tuple[float, float]
    breaks: np.ndarray = field(default_factory=lambda: np.empty(0))


def integrate(start: Start, settings: Settings, advance: Advance) -> Trajectory:
    """From 0 to the grid's end by solve_ivp or a compiled integrator
    (settings.method): the states on the grid, and the same run's at any
    other times (its dense output, for the quadrature); a failure is one
    line with the time reached."""
    grid = output_grid(settings.t_end, settings.dt)
    compiled = settings.method in methods.NAMES
    return (_by_integrator if compiled else _by_solve_ivp)(start, grid, settings, advance)


def _controls(start: Start, settings: Settings) -> Controls:
    """A compiled integrator's controls: 100 steps per segment for rk4."""
    rtol, atol = start.tol
    return controls(settings.method, steps=100, rtol=rtol, atol=atol, max_steps=settings.max_nfev)


def _by_integrator(
    start: Start, grid: np.ndarray, settings: Settings, advance: Advance
) -> Trajectory:
    """The generated integrator from each time of the grid and start.breaks
    to the next: every grid state a step end (rk4: 100 steps a segment).
    Its states anywhere else: the segment run again (runtime.segment.resampled:
    the same steps, their dense output)."""
    comp, method = start.comp, settings.method
    if method not in comp.manifest["integrators"]:
        raise SceneError(
            f"{comp.manifest['prefix']}: method {method} is not among the scene's integrators "
            f"({', '.join(comp.manifest['integrators']) or 'none'})"
        )
    ends = _edges(start, grid)
    shown = [0]

    def reached(t: float) -> None:
        pct = int(100 * t / ends[-1])
        advance(pct - shown[0])
        shown[0] = pct

    given = _controls(start, settings)
    t0 = time.perf_counter()
    budget = settings.max_nfev
    seg = integrate_segments(comp, method, start.x0, start.c, ends, given, reached, budget)
    wall = time.perf_counter() - t0
    if seg.code != 0:
        why = message(ODE_CODES, seg.code)
        if seg.code == ERR_MAX_STEPS:
            why = f"{budget} RHS calls (--max-nfev) spent" + methods.instead(
                method, comp.manifest["integrators"]
            )
        raise GyrogenError(f"{method} failed at t = {seg.totals['t']:.6g} s: {why}")
    sample = resampled(comp, method, start.c, given, ends, seg.states)
    x = seg.states[np.isin(ends, grid)]
    steps = np.diff(ends) / np.maximum([s["accepted"] for s in seg.intervals], 1)
    nfev = int(seg.totals["rhs_calls"])
    return Trajectory(grid, x, nfev, wall, sample, start.tol, (ends, steps))


def _by_solve_ivp(
    start: Start, grid: np.ndarray, settings: Settings, advance: Advance
) -> Trajectory:
    """solve_ivp through the raw rhs from each of start.breaks to the next,
    its dense output kept: the states on the grid, and at any other times
    from the same interpolants."""
    t_end = grid[-1]
    f = _Rhs(start.comp, start.c, t_end, advance, settings.max_nfev)
    rtol, atol = start.tol
    edges = _edges(start, grid[[0, -1]])
    x, dense, nfev, done = start.x0, [], 0, [np.zeros(1)]
    t0 = time.perf_counter()
    for a, b in itertools.pairwise(edges):
        try:
            sol = solve_ivp(f, (a, b), x, settings.method, dense_output=True, rtol=rtol, atol=atol)
        except _Exhausted:
            sol = None
        check_solution(sol, settings.method, f.t_max, t_end, settings.max_nfev)
        dense.append(sol.sol)
        x, nfev = sol.y[:, -1], nfev + int(sol.nfev)
        done.append(sol.t[1:])
    wall = time.perf_counter() - t0
    f.finish()

    def sample(times: np.ndarray) -> np.ndarray:
        which = np.clip(np.searchsorted(edges, times, "right") - 1, 0, len(dense) - 1)
        out = np.empty((len(times), len(start.x0)))
        for k in np.unique(which):
            out[which == k] = dense[k](times[which == k]).T
        return out

    ends = np.concatenate(done)  # every step's end
    return Trajectory(grid, sample(grid), nfev, wall, sample, start.tol, (ends, np.diff(ends)))


def _edges(start: Start, times: np.ndarray) -> np.ndarray:
    """times and start.breaks between the first and the last."""
    inside = (start.breaks > times[0]) & (start.breaks < times[-1])
    return np.union1d(times, start.breaks[inside])


def given_constants(scene: Scene, comp: Compiled, p: np.ndarray) -> np.ndarray:
    """setup's constants for the scene's [simulate] parameters p; one line
    (SceneError) when setup refuses them (code 9, their constants overflow,
    is setup's alone: the scene validator cannot see it)."""
    try:
        return comp.setup(p)
    except ValueError as exc:
        raise SceneError(f"{scene.name}: simulate.parameters: {exc}") from exc


def check_start(scene: Scene, start: Start) -> None:
    """One line (SceneError) when the derivatives at simulate.initial are not
    finite (states whose products overflow doubles): no method can take a
    step from there, and the stiffness estimate would read nothing."""
    if np.all(np.isfinite(start.comp.rhs(start.x0, start.c))):
        return
    largest = sorted(scene.simulate.initial.items(), key=lambda kv: -abs(kv[1]))[:3]
    raise SceneError(
        f"{scene.name}: simulate.initial: the derivatives at the start state are not finite "
        f"({', '.join(f'{n} = {v:g}' for n, v in largest)}: together they overflow doubles)"
    )


def check_solution(sol: Any, method: str, t_max: float, t_end: float, max_nfev: int) -> None:
    """One line for a run that gave up (sol None: the RHS budget ran out),
    failed, or left non-finite states behind; t_max: the latest time tried."""
    at = f"{method} failed at t = {t_max:.6g} s of {t_end:g}"
    if sol is None:
        raise GyrogenError(
            f"{at}: {max_nfev} RHS calls (--max-nfev) spent; the state may be blowing up"
            + (
                ""
                if method in ("Radau", "LSODA")
                else ", or the scene is stiff (try --method Radau)"
            )
        )
    if sol.status < 0:
        raise GyrogenError(f"{at}: {sol.message}")
    bad = ~np.all(np.isfinite(sol.y), axis=0)
    if bad.any():
        raise GyrogenError(f"{method}: non-finite state at t = {sol.t[np.argmax(bad)]:.6g} s")


def run(
    scene: Scene,
    out: Path,
    settings: Settings,
    progress: Progress = _no_progress,
    echo: Callable[[str], None] = lambda s: None,
) -> Result:
    """Integrate and write out/ (the files of files.file_names, and
    the sources, kept beside the trajectory they made, in out/src), all at
    the end: a refused scene or parameter set, a failed run or anything in
    the way (checked before any work) leaves nothing behind."""
    from gyrogen.files import claim

    p = runtime_values(scene)  # first: a scene error must leave nothing behind
    names = files.file_names(settings.plot, bool(scene.events))
    claim(out / "src", scene.name)
    can_write(out, names)
    can_write(out / "src", [])  # a file named src is in the way too
    echo(f"generating and building {scene.name} (sources to {out / 'src'}) ...")
    sources = scene_sources(scene)  # the C backend, or Fortran when the scene builds no C
    can_write(out / "src", sources.files)
    comp = build_files(sources.files, [sources.language])[sources.language]
    c = given_constants(scene, comp, p)
    tol = (scene.simulate.rtol, scene.simulate.atol)
    start = Start(comp, c, np.array(scene.initial_state()), tol, scene_view.table_times(scene))
    check_start(scene, start)
    end = output_grid(settings.t_end, settings.dt)[-1]
    if settings.method == methods.AUTO:
        choice = stiffness.choose(comp, c, start.x0, end)
        # the scene's best compiled integrator of the kind the problem calls
        # for (its steps end on the output grid); scipy's only without one
        method = choice.method or ("Radau" if choice.stiff else "DOP853")
        echo(f"method {method}: {choice.why}")
        settings = replace(settings, method=method)
    log, stopped, full = None, False, None
    if (
        scene.events
        and settings.method in methods.NAMES
        and not methods.get(settings.method).fixed_step
    ):
        log, stopped, full = located(start, settings)
        if stopped:  # the output grid ends at the event (its last time clipped to it)
            t_event = float(log.times[-1])
            settings = replace(settings, t_end=t_event, dt=min(settings.dt, t_event))
            end = output_grid(settings.t_end, settings.dt)[-1]
    elif scene.events:
        echo(f"events not located: {settings.method} has no _events call (use a compiled "
             "adaptive method)")  # fmt: skip
        names = [n for n in names if n != "events.csv"]
    with progress(f"integrating {scene.name} to t = {end:g} s") as advance:
        traj = integrate(start, settings, advance)
    inv = along_trajectory(scene, p, traj)
    paths = tuple(out / n for n in names)
    res = Result(
        scene, out, comp.language, sources.build_id, settings, traj, inv, paths, log, stopped, full
    )
    contents = files.contents(res, p)
    with transaction():  # the sources and the results, all or nothing
        write_atomic(out / "src", sources.files)
        write_atomic(out, contents)
    return res


def located(start: Start, settings: Settings) -> tuple[EventLog, bool, float | None]:
    """The scene's events over the output grid (one _events call with the
    run's method and tolerances), whether a terminal one stopped it, and
    the time of the first crossing a full log left out (None: the log
    holds every crossing)."""
    grid = output_grid(settings.t_end, settings.dt)
    rtol, atol = start.tol
    _, log, stats, code = start.comp.integrate_events(
        settings.method, start.x0, start.c, grid, rtol=rtol, atol=atol, capacity=EVENT_CAPACITY
    )
    if code not in (0, ODE_EVENT, ODE_LOG_FULL):
        why = message(ODE_CODES, code)
        raise SceneError(f"locating the events: {settings.method} stopped (code {code}: {why})")
    return log, code == ODE_EVENT, (float(stats["t"]) if code == ODE_LOG_FULL else None)


EVENT_CAPACITY = 100_000
"""The most events simulate logs; past them the log (and the run) stops."""
EVENTS_SHOWN = 10
"""Events the summary lists; events.csv holds them all."""


def event_lines(res: Result) -> list[str]:
    log = res.events
    if log is None:
        return []
    head = f"  events          {len(log)} located (events.csv)"
    if res.stopped:
        head += f"; terminal {log.names[-1]} at t = {log.times[-1]:.17g} s ended the run"
    if res.full is not None:
        head += (f"; the log is full (at most {EVENT_CAPACITY}): none located from "
                 f"t = {res.full:.17g} s on")  # fmt: skip
    shown = [f"    t = {t:<24.17g} {n}" for t, n in zip(log.times, log.names, strict=True)]
    more = [f"    ... {len(log) - EVENTS_SHOWN} more"] if len(log) > EVENTS_SHOWN else []
    return [head, *shown[:EVENTS_SHOWN], *more]


_LANGUAGE = {"c": "C", "fortran": "Fortran"}


def summary_lines(res: Result) -> list[str]:
    traj, worst, s = res.trajectory, res.invariants.worst(), res.scene.simulate
    said = words(res.scene)
    files = ", ".join(f.name for f in res.files)
    return [
        f"{res.scene.name}: {res.settings.method} (rtol {s.rtol:g}, atol {s.atol:g}) on the "
        f"{_LANGUAGE[res.language]} RHS, build {res.build_id}",
        f"  final time      {traj.t[-1]:g} s ({len(traj.t)} points, dt {res.settings.dt:g} s)",
        f"  nfev            {traj.nfev}",
        f"  wall time       {traj.wall:.3f} s "
        + ("(compiled integrator)" if res.settings.method in methods.NAMES else "(solve_ivp)"),
        f"  |H| in N        relative drift {worst['H_norm_relative_drift']:.2e} "
        f"(vector H: {worst['H_vector_relative_drift']:.2e})",
        f"  energy balance  K - K(0) - int P dt: {worst['energy_balance_relative_residual']:.2e}"
        " of max K (quadrature: Gauss-Legendre on the dense output, refined where it misses a "
        "transient)",
        f"  {said.rate} check        {said.balance}: {worst['u4_relative_residual']:.2e}"
        f" of max |{said.rate}|",
        *(f"  quadrature      NOT RESOLVED: {why}" for why in res.invariants.unresolved),
        *event_lines(res),
        f"wrote {res.out}/ ({files}; sources in src/)",
    ]
