"""The adaptive driver, described once: what every adaptive method's loop
shares. A method supplies its trial step and its error estimate (and, where
it has one, its interpolant); the driver holds the rest:

- the codes a loop stops with, and its stop tests (a step size lost in t,
  no steps left), as statements (If) and as one selection;
- the bookkeeping of a step: the statistics, a rejection, an acceptance
  (the attitude check, x := xnew, t, the last step's OK), the interpolant's
  place, f at the new point;
- the output grid (a method's _grid twin of _integrate): its arguments and
  their checks, and the states written at each grid time a step passes, from
  the method's interpolant (Interpolant: its coefficients, computed only on
  the grid's accepted steps, and its value), or the step's end state itself
  at a grid time the step ends on;
- the step-size controllers, a strategy per family: Hairer's PI controller
  of the explicit pairs (PI), Gustafsson's predictive controller of the
  implicit methods, rodas4 and radau5 (Gustafsson), and Jorba and Zou's
  step size of the Taylor method (JorbaZou), with their constants from
  gyrogen.methods.

rodas4's and radau5's loops are written with If and else from these parts;
a branch-free step (a pair's, printed over lanes too) takes the same
expressions and selects: stop_code, ended, counted and the PI and Jorba-Zou
controllers (every lane of a batch then takes the scalar path bit for bit).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Protocol

from gyrogen import abi
from gyrogen import methods as registry
from gyrogen.codegen.integrators.common import NX, STATS, TOLERANCES, code, x, xnew
from gyrogen.codegen.ir.nodes import (
    At,
    Bool,
    Break,
    Call,
    Const,
    Continue,
    Decl,
    E,
    For,
    Func,
    If,
    Int,
    Loop,
    Num,
    Ref,
    Return,
    S,
    Var,
    and_,
    arr,
    assign,
    cmp,
    fn,
    inc,
    not_,
    or_,
    real,
    sel,
)
from gyrogen.methods import Method, PairControl, RadauControl, RosenbrockControl, TaylorControl

OK = code("OK")
ERR_GRID = code("ERR_GRID")
ERR_STEP_UNDERFLOW = code("ERR_STEP_UNDERFLOW")
ERR_MAX_STEPS = code("ERR_MAX_STEPS")
ERR_NONFINITE = code("ERR_NONFINITE")
ERR_SINGULAR = code("ERR_SINGULAR")
ERR_ATTITUDE_SINGULAR = code("ERR_ATTITUDE_SINGULAR")
GOING_ON = Int(-1)
"""A step's code while the trajectory goes on (every stop code is >= 0)."""

t, t0, t1, h, c = Var("t"), Var("t0"), Var("t1"), Var("h"), Var("c")

PARAMS = (real("t0"), real("t1"), arr("x", "inout"), Decl("c", "double", ("NC",)), *TOLERANCES,
          real("h0"), Decl("max_steps", "long"), STATS)  # fmt: skip
"""<method>_integrate's arguments, every adaptive method's."""
GRID_PARAMS = (Decl("ntimes", "long"), Decl("times", "double", ("ntimes",)), arr("x", "inout"),
               Decl("c", "double", ("NC",)), *TOLERANCES, real("h0"), Decl("max_steps", "long"),
               Decl("out", "double", ("ntimes", "NX"), "inout"), STATS)  # fmt: skip
"""<method>_grid's arguments, every adaptive method's: from times[0] to
times[ntimes - 1], out[g] the state at times[g]."""
GRID_DOC = (
    "The output grid: one integration from times[0] to times[ntimes - 1], the steps",
    "not cut at the grid times; out[g] is the state at times[g], from the accepted",
    "step's interpolant, or its end state where a step ends on times[g] (the last",
    "one: x at t1, bit for bit _integrate's). A failure leaves the rows past the",
    "time reached unwritten; a bad grid (ERR_GRID) writes none.",
)
GRID_LOCALS = (real("t0", "inout"), real("t1", "inout"), Decl("g", "long"),
               real("told", "inout"), real("hs", "inout"), real("frac", "inout"),
               Decl("due", "bool", (), "inout"))  # fmt: skip
"""What a _grid integration adds to its method's locals: t0 and t1 (the
grid's ends), g (the next grid time to write), told and hs (the accepted
step's start and size), frac (a grid time within it, scaled) and due (a
branch-free step passes a grid time, passed)."""
LANE_PARAMS = (Decl("c", "double", ("NC",)), *TOLERANCES, real("t1"), Decl("max_steps", "long"))
"""<method>_step_lanes's arguments (a lane's t0, x and h0 live in its struct lanes)."""


def stat(field: str) -> Var:
    """stats.field, a field of abi.STATS_FIELDS."""
    assert field in {f.name for f in abi.STATS_FIELDS}, field
    return Var(f"stats.{field}")


def count(field: str, by: E | int) -> S:
    """stats.field += by."""
    return inc(stat(field), by)


def lane_stats_start(kept: Sequence[str], given: str) -> list[S]:
    """A lane's statistics as it takes a trajectory (kept: the fields struct
    lanes holds per lane; given: the statistics ode_start set): the start
    time, ode_start's h and calls, no step counted yet."""
    first: list[S] = [assign(stat("t"), Var("t0")), assign(stat("h"), Var(f"{given}.h")),
                      assign(stat("accepted"), 0), assign(stat("rejected"), 0),
                      assign(stat("rhs_calls"), Var(f"{given}.rhs_calls"))]  # fmt: skip
    done = ("t", "h", "accepted", "rejected", "rhs_calls")
    return first + [assign(stat(n), Var(f"{given}.{n}")) for n in kept if n not in done]


def started(m: Method, f0: E, into: Var, grid: bool | Grid = False) -> list[S]:
    """ode_start (common.ode_start): into := its code, returned when it stops.
    grid: first the grid's checks and ends (t0, t1), and then out[0] := x
    (the start as ode_start leaves it: Euler parameters normalized) unless
    the start is refused."""
    args = (Int(m.start_order), Const(m.min_rtol), t0, t1, x, c, Var("rtol"), Var("atol"),
            Var("h0"), Var("max_steps"), f0, Ref("h"), Var("stats"))  # fmt: skip
    if not grid:
        return [assign(into, fn("ode_start", *args)), stopped(into)]
    first = grid_first(Int(0))
    if isinstance(grid, Grid) and grid.events:  # g at the start: a crossing's first side
        ne = Int(len(grid.events))  # no rate seen before the first step
        first += [
            Call("events", (t0, x, c, EV_OLD)),
            For(
                "ev_k", ne, (assign(EV_RATE[Var("ev_k")], 0.0), assign(EV_DOLD[Var("ev_k")], -1.0))
            ),
        ]
    return [
        *grid_start(),
        *([assign(NLOG, 0)] if isinstance(grid, Grid) and grid.events else []),
        assign(into, fn("ode_start", *args)),
        If(
            cmp(into, "<=", OK),
            tuple(first),
            (),
        ),
        stopped(into),
    ]


# The output grid

G, OUT, TIMES, NTIMES = Var("g"), Var("out"), Var("times"), Var("ntimes")
i = Var("i")


BASE, DUE = Var("base"), Var("due")
"""Over lanes: a lane's first row in out (its trajectory's), and whether
its accepted step passes a grid time (its interpolant is then due)."""


def grid_first(row: E) -> list[S]:
    """out[row] := x, the start as ode_start leaves it; the next row g = 1."""
    return [For("i", NX, (assign(OUT[row, i], x[i]),)), assign(G, 1)]


def lane_grid_state() -> tuple[Decl, ...]:
    """What struct lanes holds for an output grid: per lane g and base (its
    trajectory's rows of out are base .. base + ntimes - 1), and the same on
    every lane (intent "in"): the grid's times and the batch's out."""
    return (Decl("g", "long", (), "inout"), Decl("base", "long", (), "inout"),
            Decl("ntimes", "long"), Decl("times", "double", ("ntimes",)),
            Decl("out", "double", ("ntimes", "NX")))  # fmt: skip


def grid_locals(body: object, grid: bool | Grid = True) -> tuple[Decl, ...]:
    """The GRID_LOCALS body reads (an unused local is an error under -Werror),
    and with events theirs (event_locals)."""
    return read_by(body, (*GRID_LOCALS, *event_locals(grid)))


def read_by(body: object, decls: tuple[Decl, ...]) -> tuple[Decl, ...]:
    """The decls body names."""
    text = repr(body)
    return tuple(d for d in decls if f"name='{d.name}'" in text)


def lane_grid_locals(body: object) -> tuple[Decl, ...]:
    """grid_locals of a step over lanes: g and the grid's ends are the
    struct's and the step's arguments. frac starts at 0 on every lane: a
    lane not due keeps its frac by selection, which reads it."""
    return tuple(
        replace(d, init=Num(0.0)) if d.name == "frac" else d
        for d in grid_locals(body)
        if d.name not in ("g", "t0", "t1")
    )


def step_lanes(
    m: Method, body: tuple[S, ...], locals_: tuple[Decl, ...], grid: bool | Grid
) -> Func:
    """m's loop turned once on every lane: m.name_step_lanes, or with a grid
    m.name_grid_step_lanes (with events m.name_events_step_lanes), its
    locals joined by the grid's (lane_grid_locals, lane_event_locals)."""
    if grid:
        locals_ += lane_grid_locals(body)
        if isinstance(grid, Grid) and grid.events:
            locals_ += lane_event_locals(grid, body)
        name = f"{m.name}_{variant(grid)}"
        doc = (f"One turn of {name}'s loop on every lane.",)
        return Func(f"{name}_step_lanes", LANE_PARAMS, body, None, locals_, doc)
    doc = (f"One turn of {m.name}_integrate's loop on every lane.",)
    return Func(f"{m.name}_step_lanes", LANE_PARAMS, body, None, locals_, doc)


def rows(name: str, count: int) -> Decl:
    """An interpolant's coefficients: count rows of NX."""
    return Decl(name, "double", (count, "NX"), "inout")


def grid_checks() -> Func:
    """grid_ok: at least one time, each finite, each above the one before."""
    n, v, k = Var("n"), Var("v"), Var("k")
    body = (
        If(cmp(n, "<", 1), (Return(Bool(False)),)),
        For("k", n, (If(not_(fn("finite", v[k])), (Return(Bool(False)),)),), type="long"),
        For("k", n, (If(not_(cmp(v[k - 1], "<", v[k])), (Return(Bool(False)),)),),
            type="long", start=Int(1)),
        Return(Bool(True)),
    )  # fmt: skip
    params = (Decl("n", "long"), Decl("v", "double", ("n",)))
    doc = ("1 when the n grid times v are at least one, finite and strictly increasing.",)
    return Func("grid_ok", params, body, "bool", doc=doc)


def grid_start() -> list[S]:
    """A bad grid stops (ERR_GRID, nothing written, stats at NaN time); else
    t0 and t1 are its first and last times."""
    return [
        If(not_(fn("grid_ok", NTIMES, TIMES)), (
            Call("stats_start", (Var("stats"), Const("NAN"))), Return(ERR_GRID))),
        assign(t0, TIMES[Int(0)]),
        assign(t1, TIMES[NTIMES - 1]),
        assign(G, 0),
    ]  # fmt: skip


@dataclass(frozen=True)
class Interpolant:
    """A method's dense output on an accepted step: coefficients, the
    statements that set its coefficients from the step (before x moves;
    computed by the grid alone), and points(theta, at, only): the statements
    that set at(i) (out[g][i], a state of the events' search) to state i at
    origin + theta step (by_state: one value per state), for the states
    only lists (every one when empty).
    origin is the step's start unless at_end (radau5's collocation
    polynomial, which Hairer writes from the step's end); unscaled: theta
    is the time from origin (the Taylor series), else over the step."""

    coefficients: tuple[S, ...]
    points: Points
    at_end: bool = False
    scaled: bool = True
    scratch: tuple[str, ...] = ()
    """The arrays the coefficients set that only points reads, or that the
    method sets again before it reads them (If.own: over lanes, set on
    every lane with no selection, their values on a lane with no grid time
    in its step never read)."""
    buffer: str = "y"
    """An array of NX the method sets again before it reads it, which a
    branch-free step's grid values go through on their way to out (swept)."""
    slopes: tuple[Callable[[E], E], Callable[[E], E]] | None = None
    """f at the step's start and at its end, state i (an explicit pair's
    k[0] and k[fnew]): the events' rates at the step's ends are then taken
    on the line through each end along f, with no interpolant, and its
    coefficients are computed only in a step whose search reads them
    (events_ends)."""
    only: tuple[int, ...] = ()
    """The states the events' g reads (every one when empty): the search's
    points on the interpolant set these alone (searched)."""

    @property
    def lazy(self) -> bool:
        """Its coefficients computed, with events, only where read."""
        return bool(self.coefficients) and self.slopes is not None

    def searched(self, grid: Grid) -> Interpolant:
        """This interpolant with only the states grid's events read."""
        return replace(self, only=grid.reads)


class Points(Protocol):
    """points(theta, at, only): the statements that set at(i) to state i at
    theta, for each state i in only (every one when empty)."""

    def __call__(
        self, theta: E, at: Callable[[E], At], only: tuple[int, ...] = (), /
    ) -> list[S]: ...


def spans(states: Sequence[int]) -> list[tuple[int, int]]:
    """The runs [a, b) of consecutive states in increasing states."""
    out: list[tuple[int, int]] = []
    for k in states:
        if out and out[-1][1] == k:
            out[-1] = (out[-1][0], k + 1)
        else:
            out.append((k, k + 1))
    return out


def each(only: tuple[int, ...], body: Callable[[E], tuple[S, ...]]) -> list[S]:
    """body(i) for every state i (a loop over NX), or for those only lists
    (a loop over each run of them)."""
    if not only:
        return [For("i", NX, body(i))]
    return [For("i", Int(b), body(i), start=Int(a)) for a, b in spans(only)]


def by_state(value: Callable[[E, E], E]) -> Points:
    """at(i) := value(theta, i) for every state i (those only lists)."""

    def points(theta: E, at: Callable[[E], At], only: tuple[int, ...] = ()) -> list[S]:
        return each(only, lambda i: (assign(at(i), value(theta, i)),))

    return points


def grid_step(start: E, step: E | None) -> list[S]:
    """Before a step whose start and size are gone when it is accepted (the
    branch-free steps): told and hs (unless step is None) remember them for
    the grid."""
    return [assign(Var("told"), start), *([] if step is None else [assign(Var("hs"), step)])]


def inside(
    dense: Interpolant, end: E, start: E, step: E, grid: bool | Grid = True, counted: bool = False
) -> list[S]:
    """An accepted step's grid times before its end: out[g] := the
    interpolant there, g moved on; the coefficients first, when the step
    passes a grid time. With events (grid a Grid with events): g at the
    step's end and the coefficients when needed reads them, then the step's
    crossings, located and logged in time order (events_in_step), and the
    grid only up to a stop there (counted: the step is in the statistics
    already, t its end)."""
    at = theta_at(dense, end, start, step)
    if not (isinstance(grid, Grid) and grid.events):
        return [If(due(end), (*dense.coefficients, writes(dense, at, end, G)))]
    lazy, probe = grid.pieces == 1 and dense.lazy, dense.searched(grid)
    return [
        Call("events", (end, xnew, c, Var("ev_end")), "g at the step's end: no interpolant"),
        *events_ends(grid, probe, at, start, end),
        *([If(EV_NEED, dense.coefficients)] if lazy else dense.coefficients),
        *events_in_step(grid, probe, at, start, end),
        writes(dense, at, EV_STOP, G),
        *events_stop(dense, at, counted),
    ]


def theta_at(dense: Interpolant, end: E, start: E, step: E) -> Callable[[E], E]:
    """A time as dense's theta on the step from start to end of size step."""
    origin = end if dense.at_end else start
    return lambda time: (time - origin) / step if dense.scaled else time - origin


def due(until: E) -> E:
    """A grid time before until: a step to until passes one."""
    return and_(cmp(G, "<", NTIMES), cmp(TIMES[G], "<", until))


def writes(dense: Interpolant, at: Callable[[E], E], until: E, row: E) -> S:
    """out[row] := the interpolant at each grid time g before until, g moved on."""
    return Loop((
        If(not_(cmp(G, "<", NTIMES)), (Break(),)),
        If(not_(cmp(TIMES[G], "<", until)), (Break(),)),
        assign(Var("frac"), at(TIMES[G])),
        *dense.points(Var("frac"), lambda i: OUT[row, i]),
        inc(G, 1),
    ))  # fmt: skip


def passed(ok: E, dense: Interpolant, end: E, start: E, step: E, row: E = G) -> list[S]:
    """inside for a branch-free step (a pair's, the Taylor method's), after
    its selections, t its end: statements each under ok, as the lanes print
    them (values by selection, the rhs when any lane needs it): due := ok
    and a grid time inside the step, the coefficients when due, then the
    grid times (swept; row: out's row of g, BASE + g over lanes). The step's
    acceptance and reached follow."""
    at = theta_at(dense, end, start, step)
    own = dense.scratch
    coefficients = [If(DUE, dense.coefficients, own=own)] if dense.coefficients else []
    return [assign(DUE, and_(ok, due(end))), *coefficients, swept(dense, at, end, row)]


def swept(dense: Interpolant, at: Callable[[E], E], until: E, row: E) -> S:
    """writes for a branch-free step, one grid time a turn while due (due
    := due and a grid time before until): the interpolant there into its
    buffer, then the buffer into out[row], g moved on. Over lanes a turn
    runs while any lane is due: the interpolant at every lane's time at
    once (a lane not due keeps its frac by selection; the buffer is set on
    every lane), the rows written lane by lane (out is every lane's)."""
    y = Var(dense.buffer)
    return Loop((
        assign(DUE, and_(DUE, due(until))),
        If(not_(DUE), (Break(),)),
        If(DUE, (assign(Var("frac"), at(TIMES[G])), *dense.points(Var("frac"), lambda i: y[i])),
           own=(y.name,)),
        If(DUE, (For("i", NX, (assign(OUT[row, i], y[i]),)), inc(G, 1))),
    ))  # fmt: skip


# Events


@dataclass(frozen=True)
class Event:
    """An event as the integrators see it: which crossings count (1: g
    rising through 0, -1: falling, 0: either) and whether it stops the run."""

    direction: int
    terminal: bool


@dataclass(frozen=True)
class Grid:
    """A method's output grid (its _grid twin); with events, the _events
    twin, which also locates the scene's events on the interpolant."""

    events: tuple[Event, ...] = ()
    pieces: int = 1
    """The fewest pieces each accepted step is searched in, each at most
    this fraction of it (EV_SUBINTERVALS where an event reads the time,
    else 1: from the whole step); halved from there (events_in_step)."""
    reads: tuple[int, ...] = ()
    """The states g reads, in x's order (every one when empty): the search
    sets these alone on the interpolant (Interpolant.searched)."""

    @property
    def floor_exponent(self) -> int:
        """EV_FLOOR as a power of 2 (for the header's text)."""
        return round(math.log2(EV_FLOOR))


EV_OLD, EV_NEW, EV_G, EV_T, EV_Y = (Var(n) for n in ("ev_old", "ev_new", "ev_g", "ev_t", "ev_y"))
EV_A, EV_B, EV_GA, EV_GB, EV_M, EV_GM = (Var(f"ev_{n}") for n in ("a", "b", "ga", "gb", "m", "gm"))
EV_SIDE, EV_BEST, EV_STOP, EV_HALT, EV_IT = (
    Var(f"ev_{n}") for n in ("side", "best", "stop", "halt", "it")
)
EV_F, EV_GF, EV_NUD = Var("ev_f"), Var("ev_gf"), Var("ev_nud")
NLOG, CAPACITY = Var("nlog"), Var("capacity")
EV_ITERATIONS = 200
"""A crossing's search stops after this many evaluations, or sooner where
no double lies between its bracket's ends."""
EV_NUDGE = 2.0**-50
"""The search's first step from a bracket's end its point fell on, as a
fraction of t (4 to 8 of t's ulps)."""
EVENT, ERR_EVENT_LOG_FULL = code("EVENT"), code("ERR_EVENT_LOG_FULL")


def variant(grid: bool | Grid) -> str:
    """The twin's name: grid, or events."""
    return "events" if isinstance(grid, Grid) and grid.events else "grid"


def grid_params(grid: bool | Grid) -> tuple[Decl, ...]:
    """GRID_PARAMS; with events, the log before the statistics: capacity
    entries of log_t (the time), log_k (the event, from 0) and log_x (the
    state), nlog of them written."""
    if not (isinstance(grid, Grid) and grid.events):
        return GRID_PARAMS
    log = (Decl("capacity", "long"), Decl("log_t", "double", ("capacity",), "out"),
           Decl("log_k", "int", ("capacity",), "out"),
           Decl("log_x", "double", ("capacity", "NX"), "out"),
           Decl("nlog", "long", (), "out"))  # fmt: skip
    return (*GRID_PARAMS[:-1], *log, GRID_PARAMS[-1])


SEARCH_REALS = (
    "a",
    "b",
    "ga",
    "gb",
    "m",
    "gm",
    "f",
    "gf",
    "stop",
    "ta",
    "tb",
    "dt",
    "del",
    "cap",
    "nud",
)
SEARCH_INTS = ("side", "best", "halt", "it", "last", "res")
"""The scalars of a step's search for crossings (ev_ and these names)."""


def event_locals(grid: bool | Grid) -> tuple[Decl, ...]:
    """What an _events twin adds to its locals: the events' tables (their
    directions and terminal flags), g at the step's two ends, the crossings'
    times, a state on the interpolant, the search's bracket."""
    if not (isinstance(grid, Grid) and grid.events):
        return ()
    ne = len(grid.events)
    return (
        Decl("ev_dir", "int", (ne,), values=tuple(e.direction for e in grid.events)),
        Decl("ev_term", "int", (ne,), values=tuple(int(e.terminal) for e in grid.events)),
        *(Decl(f"ev_{n}", "double", (ne,), "inout") for n in ("old", "new", "end", "g", "t")),
        *(Decl(f"ev_{n}", "double", (ne,), "inout") for n in ("rate", "dold", "dend", "seen")),
        Decl("ev_dnew", "double", (ne,), "inout"),
        Decl("ev_need", "bool", (), "inout"),
        Decl("ev_y", "double", ("NX",), "inout"),
        *(real(f"ev_{n}", "inout") for n in SEARCH_REALS),
        *(Decl(f"ev_{n}", "int", (), "inout") for n in SEARCH_INTS),
    )


def _state_at(dense: Interpolant, at: Callable[[E], E], time: E) -> list[S]:
    """ev_y := the interpolant at time, every state."""
    return dense.points(at(time), lambda i: EV_Y[i])


def _g_at(dense: Interpolant, at: Callable[[E], E], time: E) -> list[S]:
    """ev_g := every event's g at time, on the interpolant (ev_y: the states
    g reads, dense.only)."""
    return [*dense.points(at(time), lambda i: EV_Y[i], dense.only),
            Call("events", (time, EV_Y, c, EV_G))]  # fmt: skip


def _search(dense: Interpolant, at: Callable[[E], E], k: E, start: E, end: E,
            g_end: E, g_start: E | None = None) -> list[S]:  # fmt: skip
    """ev_t[k] := where event k's g crosses 0 within [start, end] (g_end its
    g at end, g_start at start: ev_old[k] unless given): the Illinois method
    (regula falsi that halves the side it keeps), until the bracket holds no
    double between its ends or ev_iterations evaluations; the crossing is
    the bracket's right end, the first time g is on its new side (or 0).
    Where its point falls on an end (the root within that end's rounding,
    or g 0 there), a point ev_nud from that end instead (EV_NUDGE of t at
    first, 16 times more each time), and a bisection where that leaves the
    bracket: a bisection alone took a bracket's far end to the root that
    the near one had reached, 20 to 50 evaluations a crossing on the
    default scene, where 4 to 11 now reach the same double."""
    inner = and_(cmp(EV_M, ">", EV_A), cmp(EV_M, "<", EV_B))
    pos_m, pos_a = cmp(EV_GM, ">", 0.0), cmp(EV_GA, ">", 0.0)
    same = or_(and_(pos_m, pos_a), and_(not_(pos_m), not_(pos_a)))
    nudged = sel(cmp(EV_M, ">=", EV_B), EV_B - EV_NUD, EV_A + EV_NUD)
    return [
        assign(EV_A, start), assign(EV_B, end),
        assign(EV_GA, EV_OLD[k] if g_start is None else g_start),
        assign(EV_GB, g_end), assign(EV_SIDE, 0), assign(EV_IT, 0),
        assign(EV_NUD, EV_NUDGE * fn("max", fn("abs", EV_A), fn("abs", EV_B))),
        Loop((
            If(or_(cmp(fn("abs", EV_GB), "<=", 0.0), cmp(EV_IT, ">=", EV_ITERATIONS)), (Break(),)),
            inc(EV_IT, 1),
            assign(EV_M, EV_B - EV_GB * ((EV_B - EV_A) / (EV_GB - EV_GA))),
            If(not_(inner), (assign(EV_M, nudged), assign(EV_NUD, 16.0 * EV_NUD))),
            If(not_(inner), (assign(EV_M, EV_A + 0.5 * (EV_B - EV_A)),)),
            If(not_(inner), (Break(),)),
            *_g_at(dense, at, EV_M),
            assign(EV_GM, EV_G[k]),
            If(same, (
                assign(EV_A, EV_M), assign(EV_GA, EV_GM),
                If(cmp(EV_SIDE, "==", -1), (assign(EV_GB, 0.5 * EV_GB),)),
                assign(EV_SIDE, -1),
            ), (
                assign(EV_B, EV_M), assign(EV_GB, EV_GM),
                If(cmp(EV_SIDE, "==", 1), (assign(EV_GA, 0.5 * EV_GA),)),
                assign(EV_SIDE, 1),
            )),
        )),
        assign(EV_T[k], EV_B),
    ]  # fmt: skip


EV_SUBINTERVALS = 8
"""The pieces each accepted step is at least searched in when an event
reads the time (or a tabulated input): a crossing is seen where g changes
sign between two neighbouring points of the interpolant (DifferentialEquations.jl's
ContinuousCallback looks at 10). An event on the states alone starts from
the whole step. Either way a piece is then halved until it is resolved
(_resolved), so that an event faster than the motion the steps follow is
seen: sin(3 t) on dual_spin, whose steps span its period, or sin(q4) on
wheel_spinup, whose wheel turns 95 times in one of dop853's steps (with g
at the steps' ends alone, 9 of its 382 crossings were logged)."""
EV_FLOOR = 2.0**-16
"""The shortest piece a step is halved down to, as a fraction of the step:
there a piece is taken resolved or not (g touching 0 without crossing, or
a crossing pair narrower than this)."""
EV_DELTA = 2.0**-16
"""The difference that gives g's rate at a piece's end, as a fraction of
the step (a one-sided difference on the interpolant, inward): short
against g's period up to 2^16 periods a step, long enough that g's
rounding makes no rate (g resting at 0, a conserved quantity at its own
level, had its pieces halved to EV_FLOOR with 2^-24 of the step)."""
EV_RATE, EV_DOLD = Var("ev_rate"), Var("ev_dold")
EV_SEEN, EV_DNEW, EV_DEND = Var("ev_seen"), Var("ev_dnew"), Var("ev_dend")
EV_NEED = Var("ev_need")
EV_DT, EV_DEL, EV_CAP, EV_LAST, EV_RES = (
    Var(f"ev_{n}") for n in ("dt", "del", "cap", "last", "res")
)


def _rate(dense: Interpolant, at: Callable[[E], E], ne: E, time: E, g: E, step: E,
          line: tuple[Callable[[E], E], Callable[[E], E]] | None = None,
          seen: bool = True) -> list[S]:  # fmt: skip
    """ev_dnew[k] := event k's rate at time in size (g: every event's g
    there), by the difference to g at time + step (step < 0: before it), on
    the interpolant, or given line (the state at time and f there, state i)
    on the line x + step f; seen: ev_seen[k] := the larger of it and
    ev_seen[k] (a NaN rate is never larger)."""
    k = Var("ev_k")
    if line is None:
        there = _g_at(dense, at, time + step)
    else:
        origin, slope = line
        there = [*each(dense.only, lambda i: (assign(EV_Y[i], origin(i) + step * slope(i)),)),
                 Call("events", (time + step, EV_Y, c, EV_G))]  # fmt: skip
    return [
        *there,
        For("ev_k", ne, (
            assign(EV_DNEW[k], fn("abs", EV_G[k] - g[k]) / fn("abs", step)),
            *((If(cmp(EV_DNEW[k], ">", EV_SEEN[k]), (assign(EV_SEEN[k], EV_DNEW[k]),)),)
              if seen else ()),
        )),
    ]  # fmt: skip


def _resolved(ne: E) -> list[S]:
    """ev_res := 1 unless some event's g may cross 0 twice more within the
    piece from ev_ta to ev_tb: the piece's length times g's largest rate
    seen (within this step, at every point g was looked at, or in the step
    before, ev_rate) exceeds what g must travel (|g| at both ends for a g
    of one sign there, twice that for one that changes sign). A NaN at an
    end leaves the piece resolved (_finite_edge's work). The largest rate
    seen, not the rates at the ends alone: g = sin(q4) on a wheel that
    turns many times a step has near 0 rates at ends near its extrema."""
    k = Var("ev_k")
    length = Var("ev_tb") - Var("ev_ta")
    opposite = or_(and_(cmp(EV_OLD[k], "<", 0.0), cmp(EV_NEW[k], ">", 0.0)),
                   and_(cmp(EV_OLD[k], ">", 0.0), cmp(EV_NEW[k], "<", 0.0)))  # fmt: skip
    travel = sel(opposite, Num(2.0), Num(1.0)) * (fn("abs", EV_OLD[k]) + fn("abs", EV_NEW[k]))
    fast = or_(cmp(length * EV_SEEN[k], ">", travel), cmp(length * EV_RATE[k], ">", travel))
    return [assign(EV_RES, 1), For("ev_k", ne, (If(fast, (assign(EV_RES, 0),)),))]


def _finite_edge(
    dense: Interpolant, at: Callable[[E], E], k: E, start: E, end: E, last: bool
) -> list[S]:
    """ev_f, ev_gf := the edge within [start, end] where event k's g turns
    NaN (last: the last time found where g is finite, g finite at start,
    ev_old[k], and not at end) or turns finite (not last: the first such
    time, g not finite at start and finite at end, ev_new[k]), and g there,
    by bisection until no double lies between or ev_iterations evaluations.
    A crossing is then searched in [start, ev_f] (last) or [ev_f, end]."""
    other = EV_B if last else EV_A  # the bracket's end where g is not finite
    lo, hi = (EV_F, other) if last else (other, EV_F)
    ends = (
        [assign(EV_F, start), assign(EV_GF, EV_OLD[k]), assign(EV_B, end)]
        if last
        else [assign(EV_A, start), assign(EV_F, end), assign(EV_GF, EV_NEW[k])]
    )
    return [
        *ends, assign(EV_IT, 0),
        Loop((
            If(cmp(EV_IT, ">=", EV_ITERATIONS), (Break(),)),
            inc(EV_IT, 1),
            assign(EV_M, lo + 0.5 * (hi - lo)),
            If(not_(and_(cmp(EV_M, ">", lo), cmp(EV_M, "<", hi))), (Break(),)),
            *_g_at(dense, at, EV_M),
            If(fn("finite", EV_G[k]), (assign(EV_F, EV_M), assign(EV_GF, EV_G[k])), (
                assign(other, EV_M),)),
        )),
    ]  # fmt: skip


def _turned_finite(k: E, new: E) -> E:
    """Event k's g was not finite at a piece's start (ev_old[k]) and is at
    its end (new)."""
    return and_(not_(fn("finite", EV_OLD[k])), fn("finite", new))


def _crossed_from(k: E, old: E, new: E) -> E:
    """_crossed with g at the start given (old), not ev_old[k]."""
    up = and_(cmp(Var("ev_dir")[k], "!=", -1), cmp(old, "<", 0.0), cmp(new, ">=", 0.0))
    down = and_(cmp(Var("ev_dir")[k], "!=", 1), cmp(old, ">", 0.0), cmp(new, "<=", 0.0))
    return or_(up, down)


def _turned_nan(k: E, new: E) -> E:
    """Event k's g was finite at a piece's start (ev_old[k]) and is not at
    its end (new)."""
    return and_(fn("finite", EV_OLD[k]), not_(fn("finite", new)))


def _crossed(k: E, new: E) -> E:
    """Event k's g went from ev_old[k] to new across 0 as its direction asks
    (from a g other than 0: a g of 0 at a piece's end is that piece's
    crossing, never the next one's too)."""
    return _crossed_from(k, EV_OLD[k], new)


def _first_piece(grid: Grid, start: E, end: E) -> list[S]:
    """The search's first piece from start (ev_ta), at most a grid.pieces-th
    of the step (ev_cap, ev_dt), and the rates' difference (ev_del)."""
    return [
        assign(Var("ev_ta"), start),
        assign(EV_CAP, (end - start) * (1.0 / grid.pieces)), assign(EV_DT, EV_CAP),
        assign(EV_DEL, (end - start) * EV_DELTA),
    ]  # fmt: skip


def events_ends(grid: Grid, dense: Interpolant, at: Callable[[E], E], start: E,
                end: E) -> list[S]:  # fmt: skip
    """After g at the step's end (ev_end): g's rates at the step's ends, at
    its start in the first step (ev_dold, which a step's end gives the next
    one) and at its end (ev_dend), on the line along f there where dense
    has its slopes (no interpolant), else on the interpolant; then, where
    its coefficients are lazy and the events read the states alone,
    ev_need: whether the search reads the interpolant in this step (a grid
    time in it, or its first piece, the whole step, not resolved or with a
    sign change, a NaN edge, or rounded short of the end). Over lanes, each
    lane's on that lane alone (ev_dold, ev_dend and ev_need are the
    lane's)."""
    ne, k, g_end = Int(len(grid.events)), Var("ev_k"), Var("ev_end")
    lines = dense.slopes
    at_start = None if lines is None else (lambda i: x[i], lines[0])
    at_end = None if lines is None else (lambda i: xnew[i], lines[1])
    out: list[S] = [
        *_first_piece(grid, start, end),
        If(cmp(EV_DOLD[0], "<", 0.0), (  # the first step: no rate at its start yet
            *_rate(dense, at, ne, start, EV_OLD, EV_DEL, at_start, seen=False),
            For("ev_k", ne, (assign(EV_DOLD[k], EV_DNEW[k]),)),
        )),
        *_rate(dense, at, ne, end, g_end, -EV_DEL, at_end, seen=False),
        For("ev_k", ne, (assign(EV_DEND[k], EV_DNEW[k]),)),
    ]  # fmt: skip
    if not (grid.pieces == 1 and dense.lazy):
        return out
    ta, tb = Var("ev_ta"), Var("ev_tb")
    sign = or_(_crossed(k, g_end[k]), _turned_nan(k, g_end[k]), _turned_finite(k, g_end[k]))
    return [
        *out,
        assign(tb, ta + EV_DT),
        assign(EV_NEED, or_(due(end), not_(or_(cmp(tb, ">=", end), cmp(tb, "<=", ta))))),
        For("ev_k", ne, (
            assign(EV_NEW[k], g_end[k]), assign(EV_SEEN[k], 0.0),
            If(cmp(EV_DOLD[k], ">", EV_SEEN[k]), (assign(EV_SEEN[k], EV_DOLD[k]),)),
            If(cmp(EV_DEND[k], ">", EV_SEEN[k]), (assign(EV_SEEN[k], EV_DEND[k]),)),
        )),
        *_resolved(ne),
        assign(EV_NEED, or_(EV_NEED, cmp(EV_RES, "==", 0))),
        For("ev_k", ne, (If(sign, (assign(EV_NEED, Bool(True)),)),)),
    ]  # fmt: skip


def events_in_step(grid: Grid, dense: Interpolant, at: Callable[[E], E], start: E,
                   end: E, base: E | None = None) -> list[S]:  # fmt: skip
    """The step from start to end in pieces, from the first to the last: a
    piece as long as the last one taken, twice that after a resolved one,
    never longer than a grid.pieces-th of the step, halved until g at its
    ends and their rates say no event crossed 0 twice unseen within it
    (_resolved, down to EV_FLOOR of the step, or to where half the piece
    is lost in the rounding of t: a piece that ends on its start is the
    rest of the step instead, so the loop always moves on); g on the interpolant (at the
    step's end and its rate there, events_ends's); in each piece, each event whose g changed sign
    as its direction asks (_crossed), located (or whose g turned NaN or
    infinite there: a crossing before its last finite point, _finite_edge);
    the piece's crossings in time order into the log, up to the first
    terminal one or a full log, where the step stops (ev_stop, ev_halt its
    code). base: the log's first row (LBASE over lanes: the lane's
    trajectory's)."""
    ne, k = Int(len(grid.events)), Var("ev_k")
    entry = NLOG if base is None else base + NLOG
    ta, tb, g_end = Var("ev_ta"), Var("ev_tb"), Var("ev_end")
    best = EV_T[EV_BEST]
    earlier = or_(cmp(EV_BEST, "<", 0), cmp(EV_T[k], "<", best))
    log = [
        *_state_at(dense, at, best),
        assign(Var("log_t")[entry], best),
        assign(Var("log_k")[entry], EV_BEST),
        For("i", NX, (assign(Var("log_x")[entry, i], EV_Y[i]),)),
        inc(NLOG, 1),
    ]
    return [
        assign(EV_STOP, end), assign(EV_HALT, -1), *_first_piece(grid, start, end),
        For("ev_k", ne, (
            assign(EV_SEEN[k], 0.0),
            If(cmp(EV_DOLD[k], ">", EV_SEEN[k]), (assign(EV_SEEN[k], EV_DOLD[k]),)),
        )),
        Loop((
            assign(tb, ta + EV_DT), assign(EV_LAST, 0),
            If(or_(cmp(tb, ">=", end), cmp(tb, "<=", ta)), (assign(tb, end), assign(EV_LAST, 1))),
            If(cmp(EV_LAST, "==", 0), (
                *_g_at(dense, at, tb), For("ev_k", ne, (assign(EV_NEW[k], EV_G[k]),)),
                *_rate(dense, at, ne, tb, EV_NEW, -EV_DEL),
            ), (
                For("ev_k", ne, (
                    assign(EV_NEW[k], g_end[k]), assign(EV_DNEW[k], EV_DEND[k]),
                    If(cmp(EV_DNEW[k], ">", EV_SEEN[k]), (assign(EV_SEEN[k], EV_DNEW[k]),)),
                )),
            )),
            *_resolved(ne),
            If(and_(cmp(EV_RES, "==", 0), cmp(EV_DT, ">", (end - start) * EV_FLOOR),
                    cmp(ta + 0.5 * EV_DT, ">", ta)), (assign(EV_DT, 0.5 * EV_DT), Continue())),
            For("ev_k", ne, (
                assign(EV_T[k], Const("HUGE")),
                If(_crossed(k, EV_NEW[k]), tuple(_search(dense, at, k, ta, tb, EV_NEW[k])), (
                    If(_turned_nan(k, EV_NEW[k]), (
                        *_finite_edge(dense, at, k, ta, tb, last=True),
                        If(_crossed(k, EV_GF), tuple(_search(dense, at, k, ta, EV_F, EV_GF))),
                    ), (
                        If(_turned_finite(k, EV_NEW[k]), (
                            *_finite_edge(dense, at, k, ta, tb, last=False),
                            If(_crossed_from(k, EV_GF, EV_NEW[k]), tuple(
                                _search(dense, at, k, EV_F, tb, EV_NEW[k], EV_GF))),
                        )),
                    )),
                )),
            )),
            Loop((
                assign(EV_BEST, -1),
                For("ev_k", ne, (
                    If(and_(cmp(EV_T[k], "<", Const("HUGE")), earlier), (assign(EV_BEST, k),)),)),
                If(cmp(EV_BEST, "<", 0), (Break(),)),
                If(cmp(NLOG, ">=", CAPACITY), (
                    assign(EV_STOP, best), assign(EV_HALT, ERR_EVENT_LOG_FULL), Break())),
                *log,
                If(cmp(Var("ev_term")[EV_BEST], "!=", 0), (
                    assign(EV_STOP, best), assign(EV_HALT, EVENT), Break())),
                assign(best, Const("HUGE")),
            )),
            If(cmp(EV_HALT, ">=", 0), (Break(),)),
            For("ev_k", ne, (assign(EV_OLD[k], EV_NEW[k]), assign(EV_DOLD[k], EV_DNEW[k]))),
            If(cmp(EV_LAST, "!=", 0), (
                For("ev_k", ne, (assign(EV_RATE[k], EV_SEEN[k]),)), Break())),
            assign(ta, tb),
            If(cmp(EV_RES, "!=", 0), (assign(EV_DT, fn("min", 2.0 * EV_DT, EV_CAP)),)),
        )),
    ]  # fmt: skip


def events_stop(dense: Interpolant, at: Callable[[E], E], counted: bool, row: E = G,
                stop: tuple[S, ...] | None = None) -> list[S]:  # fmt: skip
    """A step that stops at an event (or a full log): x := the state there
    (on the interpolant), t and the statistics, the grid time there (row:
    out's row of g), the code (returned; over lanes, stop: the statements
    that end the lane's trajectory with ev_halt instead)."""
    there: list[S] = [For("i", NX, (assign(OUT[row, i], x[i]),)), inc(G, 1)]
    return [
        If(cmp(EV_HALT, ">=", 0), (
            *_state_at(dense, at, EV_STOP),
            For("i", NX, (assign(x[i], EV_Y[i]),)),
            assign(t, EV_STOP), assign(stat("t"), t), *([] if counted else [count("accepted", 1)]),
            If(cmp(G, "<", NTIMES), (If(cmp(TIMES[G], "<=", t), tuple(there)),)),
            *((Return(EV_HALT),) if stop is None else stop),
        )),
    ]  # fmt: skip


LBASE = Var("lbase")
"""Over lanes: a lane's first entry in the log (its trajectory's)."""


def lane_event_state(grid: Grid) -> tuple[Decl, ...]:
    """What struct lanes holds for the events: per lane g at the step's
    start and end (ev_old, ev_end), g's largest rate seen in the step
    before (ev_rate) and its rate at the step's start (ev_dold, < 0 before
    the first step), the entries logged (nlog) and the
    first one's row (lbase); the same on every lane: capacity (intent "in")
    and what the lanes write (intent "out"), the log (capacity entries a
    trajectory) and each trajectory's count (nlogs)."""
    ne = len(grid.events)
    return (Decl("ev_old", "double", (ne,), "inout"), Decl("ev_end", "double", (ne,), "inout"),
            Decl("ev_rate", "double", (ne,), "inout"), Decl("ev_dold", "double", (ne,), "inout"),
            Decl("ev_dend", "double", (ne,), "inout"),
            Decl("nlog", "long", (), "inout"), Decl("lbase", "long", (), "inout"),
            Decl("capacity", "long"), Decl("log_t", "double", ("capacity",), "out"),
            Decl("log_k", "int", ("capacity",), "out"),
            Decl("log_x", "double", ("capacity", "NX"), "out"),
            Decl("nlogs", "long", ("capacity",), "out"))  # fmt: skip


def lane_event_locals(grid: Grid, body: object) -> tuple[Decl, ...]:
    """event_locals of a step over lanes (body's): the search runs lane by
    lane, so its values are one lane's at a time (intent "in": one of each,
    not one per lane), but ev_need, the lane's; ev_old, ev_end and the rates
    are the struct's."""
    ne = len(grid.events)
    return read_by(
        body,
        (
            *(d for d in event_locals(grid) if d.values),
            Decl("ev_need", "bool", (), "inout", init=Num(0.0)),
            *(Decl(f"ev_{n}", "double", (ne,), "in") for n in ("new", "g", "t", "seen", "dnew")),
            Decl("ev_y", "double", ("NX",), "in"),
            *(real(f"ev_{n}", "in") for n in SEARCH_REALS),
            *(Decl(f"ev_{n}", "int", (), "in") for n in SEARCH_INTS),
        ),
    )


def lane_events(grid: Grid, dense: Interpolant, ok: Var, cd: Var, end: E, start: E, step: E,
                row: E) -> list[S]:  # fmt: skip
    """inside with events for a branch-free step over lanes, after its
    selections (t its end, the step counted), each lane as _events runs it:
    g at the step's end and the rates there (events_ends), lane by lane on
    the scalar <prefix>_events; the coefficients on the lanes taken that
    need them (the rhs when any lane does, counted on those alone); the
    search, the log and the grid lane by lane on the lanes taken. A stop at
    an event sets the lane's code and ok := 0 (the step's end is not
    taken)."""
    ne, k, g_end = Int(len(grid.events)), Var("ev_k"), Var("ev_end")
    at, probe = theta_at(dense, end, start, step), dense.searched(grid)
    ends = If(ok, (
        For("i", NX, (assign(EV_Y[i], xnew[i]),)),
        Call("events", (end, EV_Y, c, EV_G)),
        For("ev_k", ne, (assign(g_end[k], EV_G[k]),)),
        *events_ends(grid, probe, at, start, end),
    ))  # fmt: skip
    halt = (assign(cd, EV_HALT), assign(ok, Bool(False)))
    search = If(ok, (
        *events_in_step(grid, probe, at, start, end, LBASE),
        writes(dense, at, EV_STOP, row),
        *events_stop(dense, at, True, row, halt),
    ))  # fmt: skip
    taken = and_(ok, EV_NEED) if grid.pieces == 1 and dense.lazy else ok
    coefficients = [If(taken, dense.coefficients, own=dense.scratch)] if dense.coefficients else []
    return [ends, *coefficients, search]


def reached(row: E = G, ok: E | None = None) -> list[S]:
    """After the step, x and t its end: a grid time there gets x itself (the
    last one, t1, so equals _integrate's end state bit for bit; the times
    before it were written by inside, so <= is ==); row: out's row of g.
    ok: only after a step taken (a branch-free step's, one test)."""
    there: list[S] = [For("i", NX, (assign(OUT[row, i], x[i]),)), inc(G, 1)]
    if ok is not None:
        return [If(and_(ok, cmp(G, "<", NTIMES), cmp(TIMES[G], "<=", t)), tuple(there))]
    return [If(cmp(G, "<", NTIMES), (If(cmp(TIMES[G], "<=", t), tuple(there)),))]


def stopped(cd: Var) -> S:
    """cd a stop code (not GOING_ON): return it."""
    return If(cmp(cd, ">=", 0), (Return(cd),))


# The stop tests


def spent() -> E:
    """No steps left: accepted and rejected ones count."""
    return cmp(stat("accepted") + stat("rejected"), ">=", Var("max_steps"))


def underflow_code(nonfinite: Var) -> E:
    """A step size lost in t: a step shrunk by non-finite trials says so."""
    return sel(nonfinite, ERR_NONFINITE, ERR_STEP_UNDERFLOW)


def stop_tests(nonfinite: Var) -> list[S]:
    """Before a step: h lost in the rounding of t, or no steps left, stops."""
    return [
        If(fn("step_underflow", h, t), (Return(underflow_code(nonfinite)),)),
        If(spent(), (Return(ERR_MAX_STEPS),)),
    ]


def stop_code(nonfinite: Var) -> E:
    """stop_tests as one selection: the code to stop with, or GOING_ON."""
    lost = fn("step_underflow", h, t)
    return sel(lost, underflow_code(nonfinite), sel(spent(), ERR_MAX_STEPS, GOING_ON))


def last_step(step: E = h, end: E = t1) -> E:
    """A step of step from t ends on end, t1 unless given (within
    registry.LAST_STEP_SLACK)."""
    return cmp(t + Num(registry.LAST_STEP_SLACK) * step, ">=", end)


# The table times a step stops at

Knots = tuple[float, ...]
"""The scene's table times (Scene.table_times): no step crosses one inside
(t0, t1), or it could pass a pulse narrower than itself with no error
estimate to see it (a 0.2 ms pulse among steps of seconds). Empty for a
scene without tables, whose loops print as they would without them."""
KNOTS, TK = Var("knots"), Var("tk")


def knot_doc(knots: Knots) -> tuple[str, ...]:
    """What a function that stops at the table times says of it."""
    if not knots:
        return ()
    return ("No step crosses a torque table's time inside (t0, t1): one that would",
            "ends on it instead, so that no pulse narrower than a step is passed.")  # fmt: skip


def knot_locals(knots: Knots) -> tuple[Decl, ...]:
    """tk, the next table time a step stops at."""
    return (real("tk", "inout"),) if knots else ()


def knot_function(knots: Knots) -> Func:
    """next_table_time(t, t1): the first table time after t that a step can
    reach (one lost in the rounding of t is passed: a step ends on a time to
    within an ulp), else t1; a forward scan of the sorted times. One copy of
    the times, called by every adaptive loop (over lanes, lane by lane)."""
    k, time, end = Var("k"), Var("t"), Var("t1")
    reachable = and_(cmp(KNOTS[k], "<", end), not_(fn("step_underflow", KNOTS[k] - time, time)))
    body = (
        For("k", Int(len(knots)), (If(reachable, (Return(KNOTS[k]),)),)),
        Return(end),
    )
    table = (Decl("knots", "double", (len(knots),), values=knots),)
    doc = ("The first torque-table time after t a step can reach, before t1; else t1.",)
    return Func("next_table_time", (real("t"), real("t1")), body, "double", table, doc)


def next_knot(knots: Knots) -> list[S]:
    """tk := next_table_time(t, t1) (knot_function)."""
    return [assign(TK, fn("next_table_time", t, t1))] if knots else []


def reaches_knot(step: E = h) -> E:
    """A step of step from t ends on tk, or past it (last_step's slack)."""
    return last_step(step, TK)


def final_step(knots: Knots, step: E = h) -> E:
    """A step of step from t is the last (last_step), unless it reaches a
    table time before t1 (tk < t1, after next_knot): it then ends there."""
    if not knots:
        return last_step(step)
    return and_(last_step(step), cmp(TK, ">=", t1))


def knot_clip(knots: Knots, last: E, go: E | None = None) -> list[S]:
    """After next_knot and the last step's h: a step that is not the last
    and reaches tk ends on tk, h := tk - t (where go, a step taken on this
    lane)."""
    if not knots:
        return []
    reach = and_(*([] if go is None else [go]), not_(last), reaches_knot())
    return [assign(h, sel(reach, TK - t, h))]


def ended(attitude: E, ok: E, last: E, cd: Var) -> E:
    """A step's code by selection: the attitude's stop, OK after the last
    step taken, else cd as it was."""
    return sel(attitude, ERR_ATTITUDE_SINGULAR, sel(and_(ok, last), OK, cd))


# A step's bookkeeping


def jacobian(J: Var) -> list[S]:
    """J := f_x(t, x), counted; a NaN or Inf in it stops."""
    return [
        Call("jac", (t, x, c, J)),
        count("jac_calls", 1),
        If(not_(fn("all_finite", J, Const("NX2"))), (Return(ERR_NONFINITE),)),
    ]


def singular_stop(singular: Var, tries: int) -> list[S]:
    """One more singular iteration matrix in a row; tries of them stop."""
    return [inc(singular, 1), If(cmp(singular, "==", tries), (Return(ERR_SINGULAR),))]


def singular_selected(singular: Var, retry: E, tried: E, cd: Var, tries: int) -> list[S]:
    """singular_stop by selection (over lanes): retry, a singular matrix,
    counts one more in a row and tries of them stop; tried, a decomposition
    that went through, starts the count again."""
    return [
        assign(singular, sel(retry, singular + 1, sel(tried, 0, singular))),
        assign(cd, sel(and_(retry, cmp(singular, "==", tries)), ERR_SINGULAR, cd)),
    ]


def next_f(fnew: Var, nonfinite: Var) -> list[S]:
    """f(t + h, xnew), where the next step starts; not finite: the step is not."""
    return [
        Call("rhs", (t + h, xnew, c, fnew), "where the next step starts"),
        count("rhs_calls", 1),
        assign(nonfinite, not_(fn("all_finite", fnew, NX))),
    ]


def rejected(flag: Var) -> list[S]:
    """A rejected step, counted; flag remembers it."""
    return [count("rejected", 1), assign(flag, True)]


def attitude_stop(quaternion: bool) -> list[S]:
    """3-1-2 angles: a step that ends at gimbal lock or passes a point of it
    stops, x the state before it (Euler parameters: nothing to check)."""
    return [] if quaternion else [If(fn("gimbal_lock", x, xnew), (
        Return(ERR_ATTITUDE_SINGULAR, "x: the state before this step"),))]  # fmt: skip


def accepted(
    quaternion: bool,
    last: Var,
    control: list[S],
    interpolant: list[S],
    dense: Interpolant | None = None,
    grid: bool | Grid = True,
) -> list[S]:
    """An accepted step: attitude_stop; then control (the next h),
    interpolant (what the method keeps of the step before x moves: radau5's
    collocation polynomial, the next Newton iterations' start; empty for the
    rest), with dense (the grid): the grid times inside the step from its
    interpolant; x := xnew, t, counted, the grid time at the step's end, and
    OK after the last step."""
    passed = inside(dense, sel(last, t1, t + h), t, h, grid) if dense is not None else []
    return [
        *attitude_stop(quaternion),
        *control,
        *interpolant,
        *passed,
        Call("accept_step", (x, xnew, Var("dx"), Var("comp"))),
        assign(t, sel(last, t1, t + h)),
        assign(stat("t"), t),
        count("accepted", 1),
        *(reached() if dense is not None else []),
        If(last, (Return(OK),)),
    ]


def counted(ok: E, retry: E, last: E) -> list[S]:
    """accepted's t and statistics by selection: ok taken, retry rejected."""
    return [
        assign(t, sel(ok, sel(last, t1, t + h), t)),
        assign(stat("t"), t),
        count("accepted", sel(ok, Int(1), Int(0))),
        count("rejected", sel(retry, Int(1), Int(0))),
    ]


# The step-size controllers


def clamp(ctl: PairControl | RosenbrockControl | RadauControl, quot: E) -> E:
    """h / h_new within [1/facmax, 1/facmin]: h_new/h within [facmin, facmax]."""
    return fn("max", Num(1.0 / ctl.facmax), fn("min", Num(1.0 / ctl.facmin), quot))


@dataclass(frozen=True)
class PI:
    """Hairer's PI controller of the explicit pairs (dopri5.f, dop853.f):
    h_new/h = safety err^-alpha err_old^beta within [facmin, facmax], no
    growth right after a rejection, err_old the last accepted error (at
    least registry.PAIR_ERR_FLOOR); a non-finite trial: h times facmin."""

    ctl: PairControl

    @staticmethod
    def start() -> list[S]:
        err_old, rejected_last = Var("err_old"), Var("rejected_last")
        return [assign(err_old, registry.PAIR_ERR_FLOOR), assign(rejected_last, False)]

    def factors(self, err: Var, err_old: Var, rejected_last: Var) -> list[S]:
        """fac := h/h_new by err alone (a rejection's); grow := the PI
        controller's h/h_new (an acceptance's)."""
        ctl, fac, grow = self.ctl, Var("fac"), Var("grow")
        roots = next((j for j in range(1, 7) if ctl.alpha == 0.5**j), 0)
        power: E = err if roots else fn("pow", err, ctl.alpha)
        for _ in range(roots):  # err^(1/2^j) by square roots
            power = fn("sqrt", power)
        grown = fac if ctl.beta == 0.0 else fac / fn("pow", err_old, ctl.beta)
        return [
            assign(fac, power / Num(ctl.safety), "h / h_new, in Hairer's form"),
            assign(grow, clamp(ctl, grown)),
            assign(grow, sel(rejected_last, fn("max", grow, 1.0), grow),
                   "no growth after a rejection"),
        ]  # fmt: skip

    def remember(self, ok: E, reject: E, err: Var, err_old: Var, rejected_last: Var) -> list[S]:
        """After the step: err_old the accepted one's error, rejected_last."""
        return [
            assign(err_old, sel(ok, fn("max", err, registry.PAIR_ERR_FLOOR), err_old)),
            assign(rejected_last, sel(ok, False, sel(reject, True, rejected_last))),
        ]

    def next_h(self, keep: E, nonfinite: E, ok: E) -> S:
        """h unchanged (keep), shrunk by facmin (a non-finite trial), by the
        PI controller (ok) or by err alone (a rejection)."""
        fac, grow, facmin = Var("fac"), Var("grow"), self.ctl.facmin
        reject = h / fn("min", Num(1.0 / facmin), fac)
        return assign(h, sel(keep, h, sel(nonfinite, h * Num(facmin), sel(ok, h / grow, reject))))


@dataclass(frozen=True)
class Gustafsson:
    """The implicit methods' step size, as Hairer's rodas.f and radau5.f:
    h/h_new = err^exponent / safety within [1/facmax, 1/facmin]; after an
    accepted step, Gustafsson's predictive controller (Hairer & Wanner II,
    IV.8), h/h_new = (h_acc/h) (err^2/err_acc)^exponent / safety, h_acc and
    err_acc the last accepted step's (err_acc at least err_floor), takes the
    smaller h_new of the two."""

    ctl: RosenbrockControl | RadauControl
    h_acc = Var("h_acc")
    err_acc = Var("err_acc")

    def start(self) -> list[S]:
        return [assign(self.h_acc, 0.0), assign(self.err_acc, self.ctl.err_floor)]

    def quotient(self, err: Var, safety: E) -> E:
        """h / h_new by err alone."""
        return clamp(self.ctl, fn("pow", err, self.ctl.exponent) / safety)

    def predictive(self, quot: Var, err: Var, then: tuple[S, ...] = ()) -> list[S]:
        """After an accepted step: quot := the larger h/h_new (then then,
        after the first accepted step); h_acc and err_acc remembered."""
        ctl, gus = self.ctl, Var("gus")
        return [
            If(cmp(stat("accepted"), ">", 0), (
                assign(gus, self.ratio(err)),
                assign(quot, fn("max", quot, clamp(ctl, gus))),
                *then,
            )),
            assign(self.h_acc, h),
            assign(self.err_acc, fn("max", ctl.err_floor, err)),
        ]  # fmt: skip

    def ratio(self, err: Var) -> E:
        """Gustafsson's h/h_new, before the clamp."""
        ctl = self.ctl
        ratio = (self.h_acc / h) * fn("pow", err * err / self.err_acc, ctl.exponent)
        return ratio / Num(ctl.safety)

    def predictive_selected(self, ok: E, quot: Var, err: Var) -> list[S]:
        """predictive as selections, where ok (a step over lanes)."""
        ctl, gus = self.ctl, Var("gus")
        return [
            assign(gus, self.ratio(err)),
            assign(quot, sel(and_(ok, cmp(stat("accepted"), ">", 0)),
                             fn("max", quot, clamp(ctl, gus)), quot)),
            assign(self.h_acc, sel(ok, h, self.h_acc)),
            assign(self.err_acc, sel(ok, fn("max", ctl.err_floor, err), self.err_acc)),
        ]  # fmt: skip


@dataclass(frozen=True)
class JorbaZou:
    """The Taylor method's step size, after Jorba & Zou (2005), Sec. 3.3.1,
    with heyoka's safety factor: at order p, h = rho e^(-safety / (p - 1)) /
    e^2, rho = min(rp^(1/p), rq^(1/(p-1))) from the method's bounds rp and rq
    on its last two coefficients (its error estimate), within t1 - t and
    cap: h0 > 0 caps the first step, a retried step (not finite, or past
    gimbal lock) caps the next at h times nonfinite_shrink, and an accepted
    one lifts the cap. No step is rejected for its error."""

    ctl: TaylorControl
    cap = Var("cap")
    rhofac = Var("rhofac")

    def table(self, order: int) -> Decl:
        """The safety factor by order k <= order, as constants (the lanes set
        the uniform values at every step, where a call of exp and the
        divisions by k were 4 % of the Taylor batch at 1e-6): the same
        doubles as the C library's exp at run time."""
        fac = tuple(math.exp(-self.ctl.safety / (k - 1)) / math.e**2 if k > 1 else 0.0
                    for k in range(order + 1))  # fmt: skip
        return Decl("rhofacs", "double", (order + 1,), values=fac)

    def factor(self, order: E) -> S:
        """rhofac := the safety factor at this order (uniform over a call)."""
        return assign(self.rhofac, Var("rhofacs")[order])

    @classmethod
    def start(cls) -> list[S]:
        """h0 > 0 (ode_start's h) caps the first step."""
        return [assign(cls.cap, sel(cmp(Var("h0"), ">", 0.0), h, Const("HUGE")))]

    def next_h(self, order: E, inv: Var, rp: E, rq: E) -> list[S]:
        """h := rho rhofac within t1 - t and cap, rho by branch-free log2 and
        exp2 (over lanes, vectorized); inv[k] = 1/k."""
        rho = Var("rho")
        roots = fn("min", fn("step_log2", rp) * inv[order], fn("step_log2", rq) * inv[order - 1])
        return [
            assign(rho, fn("step_exp2", roots)),
            assign(h, fn("min", fn("min", rho * self.rhofac, t1 - t), self.cap)),
        ]

    def remember(self, ok: E, retry: E) -> S:
        """After the step: no cap after an accepted one; a retried one caps
        the next at h times nonfinite_shrink."""
        shrunk = h * Num(self.ctl.nonfinite_shrink)
        return assign(self.cap, sel(ok, Const("HUGE"), sel(retry, shrunk, self.cap)))


__all__ = [
    "GRID_LOCALS",
    "GRID_PARAMS",
    "PI",
    "Gustafsson",
    "Interpolant",
    "JorbaZou",
    "accepted",
    "counted",
    "grid_checks",
    "grid_step",
    "inside",
    "passed",
    "reached",
    "stop_code",
    "stop_tests",
]
