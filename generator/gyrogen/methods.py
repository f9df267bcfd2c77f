"""The compiled integrators, in one registry: each method's name, what it
is, its coefficients (gyrogen.tableaus) and its step-size control. The scene
validator, the command line, simulate, workprec, check and both languages'
templates read it: a method is added here, once.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable
from dataclasses import dataclass
from typing import Literal

from gyrogen import abi
from gyrogen.abi import SIGNATURES, Signature
from gyrogen.tableaus import (
    DOP853,
    DOPRI5,
    RADAU5,
    RK4,
    RODAS4,
    TAYLOR,
    Explicit,
    Radau,
    Rosenbrock,
    Series,
)


@dataclass(frozen=True)
class PairControl:
    """An explicit pair's step size: h_new / h = safety err^-alpha
    err_old^beta within [facmin, facmax] (Hairer's PI controller; beta = 0 is
    the classic one)."""

    alpha: float
    beta: float
    safety: float
    facmin: float
    facmax: float
    note: str = ""
    """Where the values come from (a comment above them in the code)."""


@dataclass(frozen=True)
class RosenbrockControl:
    """A Rosenbrock method's step size, as Hairer's rodas.f: h_new / h =
    safety err^-exponent within [facmin, facmax], with Gustafsson's
    predictive controller after an accepted step."""

    safety: float = 0.9
    exponent: float = 0.25
    """1 / the order of the embedded error estimate plus one (rodas4: 1/4)."""
    facmin: float = 0.2
    facmax: float = 6.0
    err_floor: float = 1e-2
    """The last accepted error in Gustafsson's formula is at least this."""
    nonfinite_shrink: float = 0.2
    """A trial with a NaN or Inf: h times this."""
    singular_shrink: float = 0.5
    """A singular iteration matrix: h times this, ..."""
    singular_tries: int = 5
    """... this many times in a row at most."""


@dataclass(frozen=True)
class RadauControl:
    """Radau IIA's step size and Newton iterations: the defaults of Hairer's
    radau5.f (RADCOR), whose names are in brackets."""

    safety: float = 0.9
    """[SAFE], lowered to (1 + 2 newton_max) safety / (iterations + 2 newton_max)
    when the Newton iterations took many."""
    facmin: float = 0.2
    """h_new/h >= this [1/FACL] ..."""
    facmax: float = 8.0
    """... and <= this [1/FACR]."""
    exponent: float = 0.25
    """h_new/h = safety err^-exponent: 1 / the order of the embedded error
    estimate plus one (3: 1/4)."""
    newton_max: int = 7
    """Simplified Newton iterations per step at most [NIT]."""
    jacobian_reuse: float = 1e-3
    """The next step keeps J when the Newton contraction rate was at most this [THET]."""
    keep_h: tuple[float, float] = (1.0, 1.2)
    """... and keeps h, E1 and E2 too when h_new/h is within this [QUOT1, QUOT2]."""
    newton_tol: tuple[float, float] = (10.0, 0.03)
    """Newton stops when its estimated error is below max(a eps/rtol, min(b, rtol^1/2))
    [FNEWT]. The error test runs at rtol and atol as given: radau5.f loosens
    them to 0.1 rtol^(2/3) (atol in proportion), which let the global error
    of a slow spin-up (wheel_spinup, 60 s, rtol 1e-9) reach 2,600 times rtol
    with code 0."""
    err_floor: float = 1e-2
    """The last accepted error in Gustafsson's formula is at least this."""
    err_min: float = 1e-10
    """The error estimate is at least this."""
    newton_diverged: float = 0.99
    """A contraction rate at least this: the iterations diverge."""
    newton_slow: tuple[float, float, float] = (0.8, 1e-4, 20.0)
    """Iterations that converge too slowly to meet the tolerance in newton_max:
    h times a qn^(-1/(4 + newton_max - 1 - n)), qn their predicted error over
    the tolerance within [b, c]."""
    rate_power: float = 0.8
    """The first iteration's rate estimate: the last step's, to this power."""
    first_reject: float = 0.1
    """A rejected first step: h times this."""
    newton_shrink: float = 0.5
    """Newton iterations that diverge or do not converge in newton_max: h times this."""
    singular_tries: int = 5
    """Singular E1 or E2 with h halved this many times in a row: an error."""


@dataclass(frozen=True)
class TaylorControl:
    """A Taylor method's step size, after Jorba & Zou (2005), Sec. 3.3.1, with
    heyoka's safety factor: h = rho exp(-safety / (p - 1)) / e^2, rho the
    smaller of (s / |x^[p-1]|)^(1/(p-1)) and (s / |x^[p]|)^(1/p) over the
    last two normalized Taylor coefficients (infinity norms) of each group
    of states (abi_groups.state_group), s = max(atol / rtol, the group's
    largest |x|) (heyoka's rule when atol = rtol: absolute below |x| = 1,
    relative above), the smallest over the groups: the fastest wheel sets
    the scale of the rotor rates alone (taylor.bounds). No step is rejected
    for its error: a step whose new state is not finite is retried with h
    times nonfinite_shrink."""

    safety: float = 0.7
    nonfinite_shrink: float = 0.5


PAIR_ERR_FLOOR = 1e-4
"""Hairer's facold: an explicit pair's previous error starts at, and is never
taken below, this (the PI controller's err_old)."""
LAST_STEP_SLACK = 1.01
"""A step that would end within 1% of t1 is stretched to end on it."""
STEP_UNDERFLOW = 16.0
"""A step below this many DBL_EPSILON |t| is lost in the rounding of t: the
adaptive methods stop there (ERR_STEP_UNDERFLOW), and a torque table's
times closer than twice that cannot each end a step (scene rules)."""


def literal(value: float) -> str:
    """A control constant as the templates write it: a power of ten below
    0.1 as 1e-N, anything else as the shortest text that reads back."""
    for k in range(2, 20):
        if value == 10.0**-k:
            return f"1e-{k}"
    return repr(float(value))


Kind = Literal["fixed", "pair", "rosenbrock", "radau", "taylor"]
KINDS: dict[type, Kind] = {Rosenbrock: "rosenbrock", Radau: "radau", Series: "taylor"}
"""The kind of a method by its tableau, beyond the explicit ones (fixed or pair)."""


@dataclass(frozen=True)
class Method:
    """A compiled integrator a scene may ask for (scene key `integrators`)."""

    name: str
    doc: str
    tableau: Explicit | Rosenbrock | Radau | Series
    control: PairControl | RosenbrockControl | RadauControl | TaylorControl | None = None
    """The step-size control of an adaptive method; None for a fixed step."""
    notes: tuple[str, ...] = ()
    """What the method is and where it comes from: the comment lines above
    its code (the same in C and Fortran)."""

    @property
    def kind(self) -> Kind:
        """Its family: what describes its code (codegen/integrators/program.py
        reads one description per kind)."""
        if self.fixed_step:
            return "fixed"
        if self.pair:
            return "pair"
        return KINDS[type(self.tableau)]

    @property
    def batch_chunk(self) -> int:
        """Trajectories a thread takes at a time in a batch over every core
        (OpenMP's dynamic schedule, C and Fortran): a fixed step's cost is
        the same for each, an adaptive method's varies, so one at a time."""
        return 16 if self.fixed_step else 1

    @property
    def fixed_step(self) -> bool:
        """Takes a number of equal steps (steps=), not tolerances."""
        return isinstance(self.tableau, Explicit) and not self.tableau.e

    @property
    def implicit(self) -> bool:
        """Needs the scene's Jacobian."""
        return self.rosenbrock or self.radau

    @property
    def rosenbrock(self) -> bool:
        return isinstance(self.tableau, Rosenbrock)

    @property
    def radau(self) -> bool:
        """Radau IIA, by simplified Newton iterations."""
        return isinstance(self.tableau, Radau)

    @property
    def taylor(self) -> bool:
        """A Taylor series method: its code is the scene's own expansion."""
        return isinstance(self.tableau, Series)

    @property
    def pair(self) -> bool:
        """An explicit embedded pair (the adaptive explicit methods)."""
        return isinstance(self.control, PairControl)

    @property
    def lanes(self) -> bool:
        """Its batch can run trajectories in SIMD lanes (an explicit pair,
        Taylor, a Rosenbrock method, Radau IIA)."""
        return self.pair or self.taylor or self.rosenbrock or self.radau

    @property
    def lanes_asked(self) -> bool:
        """Its lanes are generated only for a scene that lists it under
        `lanes` (Radau IIA: they make the scene's C build slower and struct
        lanes larger); elsewhere its batch is a loop of single calls."""
        return self.radau

    def laned(self, asked: Collection[str]) -> bool:
        """Its batch runs in SIMD lanes in a scene whose `lanes` lists asked."""
        return self.lanes and (not self.lanes_asked or self.name in asked)

    @property
    def start_order(self) -> int:
        """The order ode_start estimates the first step for (Hairer's HINIT);
        0 for a Taylor method, whose every step, the first too, comes from
        its coefficients."""
        return 0 if self.taylor else self.tableau.order

    @property
    def min_rtol(self) -> str:
        """The named bound its rtol must exceed (ode_start refuses the rest):
        abi.TAYLOR_MIN_RTOL for a Taylor method, else abi.MIN_RTOL."""
        return "ODE_TAYLOR_MIN_RTOL" if self.taylor else "ODE_MIN_RTOL"

    @property
    def rtol_floor(self) -> float:
        """min_rtol's value."""
        return abi.TAYLOR_MIN_RTOL if self.taylor else abi.MIN_RTOL

    @property
    def trial_calls(self) -> int:
        """rhs calls of one trial step of a pair (the first stage is given)."""
        assert not isinstance(self.tableau, Series)
        return self.tableau.stages - 1

    @property
    def fnew(self) -> int:
        """The stage row that holds f(t + h, xnew): a first-same-as-last
        pair's last stage, else the row after the stages."""
        tab = self.tableau
        assert isinstance(tab, Explicit)
        return tab.stages - 1 if tab.fsal else tab.stages


_NOTES = {
    "rk4": ("Classic Runge-Kutta (Kutta 1901): four stages, order 4, `steps` equal steps.",),
    "dopri5": (
        "Dormand-Prince 5(4) (Dormand & Prince 1980; Hairer, Norsett & Wanner,",
        "Solving ODEs I, Table II.5.2): seven stages, the seventh at the new",
        "solution (FSAL); the error is h sum_j e_j k_j with e = b - bhat.",
    ),
    "dop853": (
        "DOP853 (Hairer's dop853.f): twelve stages of an 8th-order method; the",
        "error combines a 5th-order estimate err5 = h sum_j e5_j k_j and a",
        "3rd-order one err3 = h sum_j e3_j k_j as",
        "|h| |err5|^2 / sqrt(n (|err5|^2 + 0.01 |err3|^2)) in the scaled norm.",
    ),
    "rodas4": (
        "Rodas4 (Hairer & Wanner, Solving ODEs II, Sec. IV.7; the coefficients of",
        "Hairer's rodas.f)",
    ),
    "radau5": (
        "Radau IIA of order 5, three implicit stages (Hairer & Wanner, Solving ODEs II,",
        "Sec. IV.8): Hairer's radau5.f for an ODE without mass matrix",
    ),
    "taylor": (
        "Taylor series (Jorba & Zou, Experiment. Math. 14 (2005); the order and step",
        "size of heyoka's taylor_adaptive): the normalized Taylor coefficients of",
        "every state by the automatic-differentiation recurrences over the scene's",
        "own expression DAG, order p = ceil(-ln(rtol)/2 + 1), the step from the",
        "last two coefficients of each group of states, each by its own scale,",
        "the new state by Horner's scheme.",
    ),
}
_DOPRI5_DEFAULTS = "Hairer's DOPRI5 defaults: beta = 0.04, alpha = 1/5 - 0.75 beta."
_DOP853_DEFAULTS = "Hairer's DOP853 defaults: beta = 0 (alpha = 1/8), h_new/h in [0.333, 6]."

# fmt: off
METHODS: dict[str, Method] = {m.name: m for m in (
    Method("rk4", "Classic Runge-Kutta, order 4, fixed step.", RK4, notes=_NOTES["rk4"]),
    Method("dopri5", "Dormand-Prince 5(4), adaptive, PI step-size control.", DOPRI5,
           PairControl(0.17, 0.04, 0.9, 0.2, 10.0, _DOPRI5_DEFAULTS), _NOTES["dopri5"]),
    Method("dop853", "DOP853 (Hairer's coefficients and error estimator), adaptive.", DOP853,
           PairControl(0.125, 0.0, 0.9, 0.333, 6.0, _DOP853_DEFAULTS), _NOTES["dop853"]),
    Method("rodas4", "Rodas4, a stiffly accurate Rosenbrock method using the analytic Jacobian.",
           RODAS4, RosenbrockControl(), _NOTES["rodas4"]),
    Method("radau5", "Radau IIA of order 5 (three implicit stages, analytic Jacobian), adaptive.",
           RADAU5, RadauControl(), _NOTES["radau5"]),
    Method("taylor", "Taylor series of variable order from the tolerance (Jorba-Zou), adaptive; "
           "for smooth scenes.", TAYLOR, TaylorControl(), _NOTES["taylor"]),
)}
# fmt: on
"""Every compiled integrator, in the order scenes list them by default."""

NAMES: tuple[str, ...] = tuple(METHODS)
ADAPTIVE: tuple[str, ...] = tuple(n for n, m in METHODS.items() if not m.fixed_step)
IMPLICIT: tuple[str, ...] = tuple(n for n, m in METHODS.items() if m.implicit)
"""The methods that need the scene's analytic Jacobian."""


def needs_jacobian(names: Iterable[str]) -> bool:
    """Whether a scene with these integrators renders its Jacobian."""
    return any(n in IMPLICIT for n in names)


STIFF_CHOICE: tuple[str, ...] = ("radau5", "rodas4")
"""The implicit methods gyrogen runs a stiff problem with, best first: radau5
is faster than rodas4 at every error from 1e-4 to 1e-13 on stiff_wheel
(`make report`, the stiff work-precision table)."""
EXPLICIT_CHOICE: tuple[str, ...] = ("taylor", "dop853", "dopri5")
"""The explicit methods for a problem that is not stiff, in the order they
are picked. The Taylor method, where the scene offers it (a smooth rhs), is
as fast as dop853 or faster at equal error on every built-in scene that
offers it, from 1e-4 to 1e-12, one trajectory (`make bench-auto` measures
it), and keeps its tolerance in each group of states."""


def pick(available: Iterable[str], stiff: bool) -> str | None:
    """The best of a build's integrators for a stiff problem or one that is
    not; None when it has none of that kind."""
    have = set(available)
    return next((m for m in (STIFF_CHOICE if stiff else EXPLICIT_CHOICE) if m in have), None)


def instead(method: str, available: Iterable[str]) -> str:
    """What a one-line error suggests when method spent its RHS budget (empty
    for an implicit one): the build's implicit methods by name (scipy's Radau
    without one); for a Taylor method also the build's explicit pairs, whose
    error is each state's: its error norm is the largest state of each group
    (taylor.state_scales), so a state far below the others of its group
    goes unresolved."""
    if METHODS[method].implicit:
        return ""
    have = set(available)
    stiff = [m for m in STIFF_CHOICE if m in have] or ["Radau"]
    said = (
        f"; the state may be blowing up, or the scene is stiff (try --method {' or '.join(stiff)})"
    )
    pairs = [m for m in EXPLICIT_CHOICE if m in have and METHODS[m].pair]
    if METHODS[method].taylor and pairs:
        said += (
            f", or its states differ too much in size for {method}'s error norm, the largest "
            f"state of each group (try --method {' or '.join(pairs)})"
        )
    return said


SCIPY: tuple[str, ...] = ("RK45", "DOP853", "Radau", "LSODA")
"""scipy's solve_ivp methods gyrogen drives with a compiled rhs (simulate, bench)."""
AUTO = "auto"
"""The method simulate picks itself: for a stiff scene (analysis/check/stiffness.py)
the build's best implicit integrator (scipy's Radau if it has none), else
the build's best explicit one (EXPLICIT_CHOICE; scipy's DOP853 if it has none)."""


def get(name: str) -> Method:
    """A method by name; ValueError naming the known ones otherwise."""
    try:
        return METHODS[name]
    except KeyError:
        raise ValueError(f"no integrator {name!r} (integrators: {', '.join(NAMES)})") from None


def signature_of(function: str) -> Signature:
    """The C signature of a function, by its key in a manifest's functions
    (codegen.context.SceneContext.functions): an integrator's by its kind."""
    batch = function.endswith("_batch")
    method = METHODS.get(function.removesuffix("_batch"))
    single = function.removesuffix("_batch")
    if single.endswith("_events") and single.removesuffix("_events") in METHODS:
        # an _events twin or its batch (the scene's events alone: "events")
        return SIGNATURES["grid_events" + "_batch" * batch]
    grid = METHODS.get(function.removesuffix("_batch").removesuffix("_grid"))
    if method is None and grid is not None and function.removesuffix("_batch").endswith("_grid"):
        return SIGNATURES["grid" + "_batch" * batch]
    if method is not None:
        kind = "fixed_step" if method.fixed_step else "adaptive"
        return SIGNATURES[kind + "_batch" * batch]
    if function.endswith("strerror"):
        return SIGNATURES["strerror"]
    return SIGNATURES.get(function) or SIGNATURES["output"]
