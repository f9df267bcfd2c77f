"""What a simulation is asked (Settings, checked) and what it made
(Result): the values engine.py runs on and files.py writes."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from gyrogen import methods
from gyrogen.abi import MAX_STEPS
from gyrogen.analysis.simulate.invariants import Invariants
from gyrogen.analysis.simulate.trajectory import Trajectory
from gyrogen.errors import SceneError
from gyrogen.runtime.compiled import EventLog
from gyrogen.scene import Scene, check_output_grid

MAX_NFEV = MAX_STEPS
"""RHS calls before giving up: a run that blows up can crawl for hours
without solve_ivp ever failing (its steps shrink as the state grows)."""


@dataclass(frozen=True)
class Settings:
    t_end: float
    dt: float
    method: str = methods.AUTO
    plot: bool = True
    max_nfev: int = MAX_NFEV


def checked(settings: Settings) -> Settings:
    """settings, or a one-line SceneError: t_end and dt finite and positive,
    the output grid within its limit, a method simulate knows (what the
    command line's option types check, for the Python API)."""
    for name, v in (("t_end", settings.t_end), ("dt", settings.dt)):
        if not (isinstance(v, int | float) and 0 < v < float("inf")):
            raise SceneError(f"{name} = {v!r}: must be a finite number of seconds above 0")
    try:
        check_output_grid(settings.t_end, settings.dt)
    except ValueError as exc:
        raise SceneError(str(exc)) from None
    known = (methods.AUTO, *methods.SCIPY, *methods.NAMES)
    if settings.method not in known:
        raise SceneError(f"method {settings.method!r}: not one of {', '.join(known)}")
    return settings


@dataclass(frozen=True)
class Result:
    scene: Scene
    out: Path
    language: str
    build_id: str
    settings: Settings
    trajectory: Trajectory
    invariants: Invariants
    files: tuple[Path, ...]
    events: EventLog | None = None
    """The scene's events along the run (a compiled adaptive method's
    _events call over the output grid), or None (no events, or a method
    without that call)."""
    stopped: bool = False
    """A terminal event ended the run: the output grid stops at its time."""
    full: float | None = None
    """The time of the first crossing the event log had no room for (the
    events from it on are not located), or None: the log holds them all."""
