"""The Taylor series method, described once: Jorba and Zou's order, the
scene's jet (gyrogen.codegen.integrators.taylor_jet) and the bounds its
last two coefficients set on the step in each group of states by the
group's own scale (bounds, the method's error estimate), on the adaptive
driver (gyrogen.codegen.integrators.driver: the stop codes, the statistics
and Jorba and Zou's step size, JorbaZou), as one step of straight-line code
with selections: the scalar integrator loops over it, the lanes print it
over every lane (gyrogen.codegen.ir.lanes), so a batch equals its single
calls bit for bit. No step is rejected for its error; a step whose new
state is not finite, or that passes a point of gimbal lock, is retried with
h halved.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

from gyrogen import methods as registry
from gyrogen.abi_groups import StateKind, state_group, state_kind
from gyrogen.codegen.integrators import common, driver
from gyrogen.codegen.integrators.common import (
    NX,
    accepted,
    attitude_checked,
    comp,
    dx,
    gimbal_at,
    gimbal_jump,
    h,
    i,
    x,
    xnew,
)
from gyrogen.codegen.integrators.taylor_jet import (
    T,
    c,
    coefficients,
    jet_function,
    order,
    reads_constants,
)
from gyrogen.codegen.ir.nodes import (
    At,
    Bool,
    Call,
    Comment,
    Const,
    Decl,
    E,
    For,
    Func,
    If,
    Int,
    Loop,
    Num,
    S,
    Unused,
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
from gyrogen.methods import Method
from gyrogen.symbolic.jet import Jet
from gyrogen.tableaus import Series


def state_scales(names: Sequence[str]) -> tuple[tuple[str, StateKind], ...]:
    """Each state's group (gyrogen.abi_groups.state_group) and how it enters its
    group's scale xmax (abi_groups.state_kind: a magnitude, or an angle at
    most ANGLE_SCALE). Jorba and Zou
    scale the tolerance by the largest state of all; the step here meets it
    in each group by the group's own largest state (bounds), so neither a
    wheel at 1e6 rad/s (it made the body rates err by 3e7 times the
    tolerance) nor a satellite's 7e6 m (the attitude's, 1e5 times) loosens
    the other groups' tolerance. Translation is a polynomial in t in every
    scene, stepped exactly: it sets no bound."""
    return tuple((state_group(n), state_kind(n)) for n in names)


def uniform(m: Method, jet: Jet) -> list[S]:
    """What every trajectory of a call shares (it depends on rtol and atol
    only): the order, the step's safety factor, atol/rtol."""
    series = m.tableau
    assert isinstance(series, Series)
    return [
        Comment("the order: min_order plus the thresholds e^(-2 (q - 1)) above rtol"),
        assign(order, Int(series.min_order)),
        *(
            inc(order, sel(cmp(Num(v), ">", Var("rtol")), Int(1), Int(0)))
            for v in series.thresholds()
        ),
        control(m).factor(order),
        assign(Var("scale"), Var("atol") / Var("rtol")),
    ]


def control(m: Method) -> driver.JorbaZou:
    """m's step-size controller (gyrogen.codegen.integrators.driver)."""
    assert isinstance(m.control, registry.TaylorControl)
    return driver.JorbaZou(m.control)


def tables(m: Method) -> tuple[Decl, Decl]:
    """1/k by order k (the jet's and the step size's), as constants (the
    divisions were part of 4 % of the Taylor batch at 1e-6), and the step's
    safety factor by order (JorbaZou.table)."""
    series = m.tableau
    assert isinstance(series, Series)
    inv = tuple(1.0 / k if k else 0.0 for k in range(series.order + 1))
    return Decl("inv", "double", (len(inv),), values=inv), control(m).table(series.order)


STATE = ("code", "t", "h", "cap", "nonfinite")
"""A trajectory's values that live from step to step (besides x, comp, stats)."""
LOCALS = ("last", "run", "take", "ok", "at", "jump", "retry", "xmax", "dp", "dq", "rp", "rq",
          "rho", "h2")  # fmt: skip
BOOLS = {"nonfinite", "last", "run", "take", "ok", "at", "jump", "retry"}


def declare(name: str) -> Decl:
    return common.declare(name, BOOLS)


def start_state() -> list[S]:
    """A trajectory's values at t0 after ode_start: h0 > 0 bounds the first step."""
    return [*common.start_state(), *driver.JorbaZou.start()]


def series_output(jet: Jet, exact: list[int]) -> driver.Interpolant:
    """The dense output: the series itself at tau = t - told, x + tau (x^[1]
    + tau (x^[2] + ... + tau x^[p])) by Horner's scheme, an order at a time
    for every state (acc: the states' chains side by side; a state at a
    time, its chain of multiplies and adds was about a third of
    taylor_grid_step_lanes's time at 21 grid times), and a state of degree
    min_order or less by its exact polynomial (its higher coefficients are
    never computed)."""
    deg = jet.degrees()

    def points(tau: E, at: Callable[[E], At], only: tuple[int, ...] = ()) -> list[S]:
        acc, q = Var("acc"), Var("q")
        skip = sorted(set(exact) | (set(range(jet.nx)) - set(only) if only else set()))
        out: list[S] = [
            *_over(jet.nx, skip, assign(acc[i], T[order, i])),
            For("q", order - 1, tuple(_over(jet.nx, skip, assign(
                acc[i], T[order - Int(1) - q, i] + tau * acc[i])))),
            *_over(jet.nx, skip, assign(at(i), x[i] + tau * acc[i])),
        ]  # fmt: skip
        for n in (n for n in exact if not only or n in only):
            low = T[Int(1), Int(n)] + tau * T[Int(2), Int(n)] if deg[n] == 2 else T[Int(1), Int(n)]
            out.append(assign(at(Int(n)), x[Int(n)] + tau * low))
        return out

    return driver.Interpolant((), points, scaled=False, buffer="acc")


def step(
    m: Method, jet: Jet, quaternion: bool, grid: bool | driver.Grid = False, lanes: bool = False
) -> list[S]:
    """One step of one trajectory, straight-line with selections (the scalar
    integrator loops over it; the lanes print it over every lane). grid: the
    output grid's too (driver.grid_step, and the grid times an accepted step
    passes, from the series; lanes: out's rows from the lane's base)."""
    t, t1, cd = Var("t"), Var("t1"), Var("code")
    last, run, take, ok, at, jump, retry = (
        Var(n) for n in ("last", "run", "take", "ok", "at", "jump", "retry")
    )
    nonfinite, h2 = Var("nonfinite"), Var("h2")
    jz = control(m)
    q = Var("q")
    pairs = (order - Int(1)) / Int(2)  # Horner's turns of two orders; then one more if odd

    def two(i: Var) -> E:
        """Orders k - 1 and k of state i, k = order - 2 q - 1, onto xnew[i]."""
        return (
            T[order - Int(2) * q - Int(2), i] + h * T[order - Int(2) * q - Int(1), i]
        ) + h2 * xnew[i]

    def one(i: Var) -> E:
        return T[Int(1), i] + h * xnew[i]

    events = isinstance(grid, driver.Grid) and bool(grid.events)
    ks, fend = Var("ks"), Var("fend")

    def slope_two(i: Var) -> E:
        """two's for x'(t + h): each order k's coefficient times k, onto fend[i]."""
        lo, hi = order - Int(2) * q - Int(2), order - Int(2) * q - Int(1)
        return (ks[lo] * T[lo, i] + h * (ks[hi] * T[hi, i])) + h2 * fend[i]

    def slope(n: int) -> E:
        """x'(t + h) of a state of degree <= min_order."""
        return (
            T[Int(1), Int(n)] + (2.0 * h) * T[Int(2), Int(n)] if deg[n] == 2 else T[Int(1), Int(n)]
        )

    series = m.tableau
    assert isinstance(series, Series)
    deg = jet.degrees()
    exact = [n for n in range(jet.nx) if deg[n] <= series.min_order]

    def series_states(*body: S) -> list[S]:
        """body for each state that is not a polynomial of degree min_order
        or less."""
        return _over(jet.nx, exact, *body)

    def polynomial(n: int) -> E:
        """xnew of a state of degree <= min_order: exact at any order and h."""
        return T[Int(1), Int(n)] + h * T[Int(2), Int(n)] if deg[n] == 2 else T[Int(1), Int(n)]

    args = (order, x, *([c] if reads_constants(jet) else []), Var("inv"), T)
    body: list[S] = [
        Comment("the coefficients at x, and the step they allow (Jorba and Zou)"),
        assign(run, cmp(cd, "<", 0)),
        *(jet_function(series, jet).body if grid and not lanes else [Call("taylor_jet", args)]),
        driver.count("rhs_calls", sel(run, Int(1), Int(0))),
        *bounds(jet, exact),
        *jz.next_h(order, Var("inv"), Var("rp"), Var("rq")),
        assign(last, driver.last_step()),
        assign(h, sel(last, t1 - t, h)),
        *(driver.grid_step(t, None) if grid else []),
        assign(driver.stat("h"), sel(run, h, driver.stat("h"))),
        assign(cd, sel(run, driver.stop_code(nonfinite), cd), "lost in t, or no steps left"),
        assign(run, cmp(cd, "<", 0)),
        Comment("x(t + h) by Horner's scheme two orders a turn, less what the last add lost"),
        assign(h2, h * h),
        *series_states(
            assign(xnew[i], T[order, i]),
            *([assign(fend[i], ks[order] * T[order, i])] if events else []),
        ),
        For(
            "q",
            pairs,
            tuple(
                series_states(
                    assign(xnew[i], two(i)), *([assign(fend[i], slope_two(i))] if events else [])
                )
            ),
        ),
        For(
            "q",
            order - 1 - Int(2) * pairs,
            tuple(
                series_states(
                    assign(xnew[i], one(i)),
                    *([assign(fend[i], T[Int(1), i] + h * fend[i])] if events else []),
                )
            ),
        ),
        *(assign(xnew[Int(n)], polynomial(n)) for n in exact),
        *(assign(fend[Int(n)], slope(n)) for n in (exact if events else [])),
        For("i", NX, (assign(dx[i], h * xnew[i] - comp[i]), assign(xnew[i], x[i] + dx[i]))),
        assign(nonfinite, Bool(False)),
        For("i", NX, (assign(nonfinite, or_(nonfinite, not_(fn("finite", xnew[i])))),)),
        *attitude_checked(quaternion),
        Comment("accept, or retry with h halved: a NaN or Inf, or a step past gimbal lock"),
        assign(take, and_(run, not_(nonfinite))),
        assign(at, Bool(False) if quaternion else gimbal_at(xnew)),
        assign(jump, Bool(False) if quaternion else gimbal_jump(x, xnew)),
        assign(ok, and_(take, not_(at), not_(jump))),
        assign(retry, and_(run, or_(nonfinite, jump)), "past gimbal lock, or not finite"),
        assign(cd, driver.ended(and_(take, at, not_(jump)), ok, last, cd)),
        *driver.counted(ok, retry, last),
        jz.remember(ok, retry),
    ]
    if not grid:
        return [*body, If(ok, tuple(accepted(quaternion, known=True)))]
    taken = tuple(accepted(quaternion, known=True))
    dense, told, hs = series_output(jet, exact), Var("told"), Var("hs")
    row = driver.BASE + driver.G if lanes else driver.G
    if isinstance(grid, driver.Grid) and grid.events:  # g's rates at the ends from x' there
        dense = replace(dense, slopes=(lambda i: T[Int(1), i], lambda i: fend[i]))
        if lanes:  # a stop at an event sets the lane's code and clears ok
            located = driver.lane_events(grid, dense, ok, cd, t, told, hs, row)
            return [*body, *located, If(ok, taken), *driver.reached(row, ok)]
        inside = driver.inside(dense, t, told, hs, grid, counted=True)
        return [*body, If(ok, (*inside, *taken, *driver.reached()))]
    passed = driver.passed(ok, dense, t, told, hs, row)
    return [*body, *passed, If(ok, taken), *driver.reached(row, ok)]


UNMEASURED = "unmeasured"
"""The group of states that sets no bound on the step: an augmented
system's variational part when its error is not measured (it rides on x's
steps)."""

SIZES = {"magnitude": fn("abs", x[i]), "angle": common.capped(fn("abs", x[i]))}
"""How a state of each kind (state_scales) enters its group's xmax."""


def bounds(jet: Jet, exact: list[int]) -> list[S]:
    """Jorba and Zou's bounds on the step, rho <= (xmax / |x^[p]|)^(1/p) and
    (xmax / |x^[p-1]|)^(1/(p-1)), met in each group of states
    (state_scales) by its own largest state xmax = max(atol / rtol, |x_i|)
    and its own largest coefficients: rp and rq, the smallest xmax / dp and
    xmax / dq over the groups (the powers are monotone: the smallest ratio
    gives the smallest step). A group whose states are all polynomials of
    degree <= min_order sets no bound (their step is exact)."""
    xmax, dp, dq, rp, rq = (Var(n) for n in ("xmax", "dp", "dq", "rp", "rq"))
    scales = jet.scales or (("", "magnitude"),) * jet.nx
    out: list[S] = [assign(rp, Const("HUGE")), assign(rq, Const("HUGE"))]
    for group in dict.fromkeys(g for g, _ in scales):
        members = [n for n in range(jet.nx) if scales[n][0] == group]
        if set(members) <= set(exact) or group == UNMEASURED:
            continue
        left_out = [n for n in range(jet.nx) if n not in members]
        out += [Comment(f"the bound the {group or 'states'} set"), assign(xmax, 0.0)]
        for kind, size in SIZES.items():
            others = [n for n in range(jet.nx) if n in left_out or scales[n][1] != kind]
            out += _over(jet.nx, others, assign(xmax, common.larger(xmax, size)))
        out += [
            assign(dp, 0.0),
            assign(dq, 0.0),
            *_over(
                jet.nx,
                sorted(set(left_out) | set(exact)),
                assign(dp, common.larger(dp, fn("abs", T[order, i]))),
                assign(dq, common.larger(dq, fn("abs", T[order - 1, i]))),
            ),
            assign(xmax, fn("max", Var("scale"), xmax), "the absolute and relative modes in one"),
            assign(rp, smaller(rp, xmax / dp)),
            assign(rq, smaller(rq, xmax / dq)),
        ]
    return out


def smaller(a: E, b: E) -> E:
    """min(a, b) for an a that is never NaN; a when b is NaN (common.larger's
    mirror)."""
    return sel(cmp(b, "<", a), b, a)


def _over(n: int, left_out: list[int], *body: S) -> list[S]:
    """body for each of the states 0 .. n-1 but those left out, in loops
    over their runs."""
    return [For("i", Int(b), body, start=Int(a)) for a, b in _runs(n, left_out)]


def _runs(n: int, left_out: list[int]) -> list[tuple[int, int]]:
    """The runs [a, b) of 0 .. n-1 without left_out."""
    return driver.spans([k for k in range(n) if k not in left_out])


def integrate(m: Method, jet: Jet, quaternion: bool, grid: bool | driver.Grid = False) -> Func:
    """taylor_integrate: from t0 to t1 on one trajectory; with grid,
    taylor_grid: over the output grid."""
    series = m.tableau
    assert isinstance(series, Series)
    cd = Var("code")
    body: list[S] = [
        *driver.started(m, Var("f0"), cd, grid),
        *uniform(m, jet),
        *start_state(),
        Loop((*step(m, jet, quaternion, grid), driver.stopped(cd))),
    ]
    locals_ = (
        coefficients(series, jet),
        *tables(m),
        arr("f0", "inout"),
        arr("xnew", "inout"),
        arr("dx", "inout"),
        arr("comp", "inout"),
        Decl("order", "int", (), "inout"),
        real("rhofac", "inout"),
        real("scale", "inout"),
        *(declare(n) for n in STATE),
        *(declare(n) for n in LOCALS),
        *([declare("norm")] if quaternion else []),
    )
    if grid:  # the jet's code in place: taylor_jet keeps one caller, which gcc inlines
        locals_ += (*jet_function(series, jet).locals, arr("acc", "inout"),
                    *driver.grid_locals(body, grid))  # fmt: skip
        if isinstance(grid, driver.Grid) and grid.events:  # x' at the step's end, k's as doubles
            locals_ += (arr("fend", "inout"), k_table(series))
        doc = (*m.notes, *driver.GRID_DOC)
        name, params = f"taylor_{driver.variant(grid)}", driver.grid_params(grid)
        return Func(name, params, tuple(body), "int", locals_, doc)
    return Func("taylor_integrate", driver.PARAMS, tuple(body), "int", locals_, m.notes)


def lanes_step(m: Method, jet: Jet, quaternion: bool, grid: bool | driver.Grid = False) -> Func:
    """taylor_step_lanes: one step of every lane of a struct lanes (the
    shared values computed first, the same on every lane); with grid,
    taylor_grid_step_lanes: one step of taylor_grid; with events,
    taylor_events_step_lanes: one step of taylor_events (the events' values
    and log in the struct, driver.lane_event_state; x' at the step's end,
    fend, the lane's: lane_state)."""
    series = m.tableau
    assert isinstance(series, Series)
    unused = [] if reads_constants(jet) else [Unused("c")]
    body = (*unused, *uniform(m, jet), *step(m, jet, quaternion, grid, lanes=True))
    locals_ = (
        *tables(m),
        Decl("order", "int", (), "in"),
        real("rhofac", "in"),
        real("scale", "in"),
        *(declare(n) for n in LOCALS),
        *([declare("norm")] if quaternion else []),
        *(driver.lane_grid_locals(body) if grid else ()),
    )
    if isinstance(grid, driver.Grid) and grid.events:
        locals_ += (k_table(series), *driver.lane_event_locals(grid, body))
    name = f"taylor_{driver.variant(grid)}" if grid else "taylor_integrate"
    doc = (f"One step of {name} on every lane.",)
    return Func(f"{name.removesuffix('_integrate')}_step_lanes", driver.LANE_PARAMS, body, None,
                locals_, doc)  # fmt: skip


def k_table(series: Series) -> Decl:
    """k by order k, as doubles: x' at the step's end from the series."""
    return Decl(
        "ks", "double", (series.order + 1,), values=tuple(map(float, range(series.order + 1)))
    )


def lane_state(m: Method, jet: Jet, events: bool = False) -> list[Decl]:
    """What struct lanes holds per lane for a Taylor method, beyond a pair's
    (with events, x' at the step's end)."""
    series = m.tableau
    assert isinstance(series, Series)
    fend = [arr("fend", "inout")] if events else []
    return [Decl("cap", "double", (), "inout"), coefficients(series, jet), arr("acc", "inout"),
            *fend]  # fmt: skip


def functions(
    m: Method, jet: Jet, quaternion: bool, events: driver.Grid | None = None
) -> list[Func]:
    """The jet, taylor_integrate, taylor_grid and with events taylor_events."""
    series = m.tableau
    assert isinstance(series, Series)
    return [
        jet_function(series, jet),
        integrate(m, jet, quaternion),
        integrate(m, jet, quaternion, grid=True),
        *([integrate(m, jet, quaternion, grid=events)] if events else []),
    ]
