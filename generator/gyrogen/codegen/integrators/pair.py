"""An explicit embedded pair's step: Hairer's step-size control, described
once, as the scalar integrator and as one step of every SIMD lane.

The step is five parts, each straight-line code on one trajectory's values:
begin (the step's size and the codes that stop), trial (the stages and the
error, gyrogen.codegen.integrators.explicit), check (non-finite values, f at
the new point), control (accept or reject, the new h, by selection) and
accept (x := xnew). The scalar integrator loops over them; the lanes print
the same parts over lanes (gyrogen.codegen.ir.lanes), so a batch (over an
output grid too) equals its single calls bit for bit.
"""

from __future__ import annotations

from gyrogen import methods as registry
from gyrogen.codegen.integrators import common, driver
from gyrogen.codegen.integrators.common import (
    NX,
    accepted,
    attitude_checked,
    h,
    i,
    locked,
    x,
    xnew,
)
from gyrogen.codegen.integrators.explicit import combo, trial
from gyrogen.codegen.ir.nodes import (
    Bool,
    Call,
    Comment,
    Decl,
    E,
    For,
    Func,
    If,
    Int,
    Loop,
    Num,
    Row,
    S,
    Var,
    and_,
    arr,
    assign,
    cmp,
    fn,
    not_,
    or_,
    sel,
)
from gyrogen.methods import Method
from gyrogen.tableaus import Explicit

t, k, y, c = Var("t"), Var("k"), Var("y"), Var("c")


def interpolant(m: Method) -> driver.Interpolant:
    """Hairer's dense output of pair m (tableaus.DenseRK; dopri5.f's CONTD5,
    dop853.f's CONTD8): its extra stages and rows from the accepted step
    (told, hs; x still its start, k[fnew] f at its end), and the nested
    value r1 + theta (r2 + (1 - theta) (r3 + theta (r4 + ...))). y (the
    extra stages' points, the trial's next) and the coefficients are its
    scratch: set on every lane where any needs them (the extra stages' k
    rows are, as every rhs call over lanes)."""
    tab = m.tableau
    assert isinstance(tab, Explicit) and tab.dense is not None
    dense, r, hs, told = tab.dense, Var("dense"), Var("hs"), Var("told")
    out: list[S] = [Comment(f"the dense output of order {dense.order}")]
    for s, node in enumerate(dense.nodes):
        row = m.fnew + 1 + s
        out += [
            For("i", NX, (assign(y[i], x[i] + hs * combo(dense.stage(s))),)),
            Call("rhs", (told + Num(node) * hs, y, c, Row("k", Int(row)))),
        ]
    if dense.nodes:
        out.append(driver.count("rhs_calls", len(dense.nodes)))
    out.append(For("i", NX, (
        assign(r[0, i], xnew[i] - x[i]),
        assign(r[1, i], hs * k[0, i] - r[0, i]),
        assign(r[2, i], (r[0, i] - hs * k[m.fnew, i]) - r[1, i]),
        *(assign(r[3 + j, i], hs * combo(dense.row(j))) for j in range(len(dense.d))),
    )))  # fmt: skip

    def value(theta: E, i: E) -> E:
        terms: list[E] = [x[i], *(r[j, i] for j in range(3 + len(dense.d)))]
        acc = terms[-1]
        for j in range(len(terms) - 2, -1, -1):
            acc = terms[j] + (theta if j % 2 == 0 else Num(1.0) - theta) * acc
        return acc

    slopes = (lambda i: k[0, i], lambda i: k[m.fnew, i])
    return driver.Interpolant(
        tuple(out), driver.by_state(value), scratch=("y", "dense"), slopes=slopes
    )


def dense_rows(m: Method) -> int:
    """The rows of an interpolant's coefficients (r2, r3, r4 and the d rows)."""
    tab = m.tableau
    assert isinstance(tab, Explicit) and tab.dense is not None
    return 3 + len(tab.dense.d)


def grid_krows(m: Method, krows: int) -> int:
    """k's rows for m's grid: the stages, fnew and the interpolant's stages."""
    tab = m.tableau
    assert isinstance(tab, Explicit) and tab.dense is not None
    return max(krows, m.fnew + 1 + len(tab.dense.nodes))


def parts(
    m: Method,
    quaternion: bool,
    grid: bool | driver.Grid = False,
    row: E = driver.G,
    knots: driver.Knots = (),
    lanes: bool = False,
) -> tuple[list[S], list[S]]:
    """One step of pair m on one trajectory, as the five parts: begin, and
    the other four. grid: the output grid's too (grid_step, f at the last
    step's end, and the grid times an accepted step passes; row: out's row
    of grid time g). knots: the table times a step ends on (driver.knot_clip).
    lanes: the step over lanes (with events, driver.lane_events)."""
    ctl = m.control
    assert isinstance(ctl, registry.PairControl)
    tab = m.tableau
    assert isinstance(tab, Explicit)
    names = "code err err_old last nonfinite rejected_last ok run take lock t1".split()
    cd, err, err_old, last, nonfinite, rejected_last, ok, run, take, lock, t1 = map(Var, names)
    begin: list[S] = [
        Comment("begin: a step size lost in t, or no steps left, stops; a last step ends on t1"),
        assign(cd, sel(cmp(cd, "<", 0), driver.stop_code(nonfinite), cd)),
        *driver.next_knot(knots),
        assign(last, driver.final_step(knots)),
        assign(h, sel(and_(cmp(cd, "<", 0), last), t1 - t, h)),
        *driver.knot_clip(knots, last, cmp(cd, "<", 0)),
        assign(driver.stat("h"), sel(cmp(cd, "<", 0), h, driver.stat("h"))),
        *(driver.grid_step(t, h) if grid else []),
    ]
    check: list[S] = [
        Comment("check: a NaN or Inf rejects the step; f(t + h, xnew) where it is taken"),
        driver.count("rhs_calls", sel(cmp(cd, "<", 0), Int(m.trial_calls), Int(0))),
        assign(nonfinite, not_(fn("finite", err))),
        For("i", NX, (assign(nonfinite, or_(nonfinite, not_(fn("finite", xnew[i])))),)),
        *attitude_checked(quaternion),
    ]
    if not tab.fsal:
        fnew = k[m.fnew, i]
        check += [
            assign(ok, and_(cmp(cd, "<", 0), not_(nonfinite), cmp(err, "<=", 1.0),
                            *([] if grid else [not_(last)]))),
            If(ok, (Call("rhs", (t + h, xnew, c, Row("k", Int(m.fnew))),
                         "where the next step starts"),)),
            For("i", NX, (assign(nonfinite, or_(nonfinite, and_(ok, not_(fn("finite", fnew))))),)),
            driver.count("rhs_calls", sel(ok, Int(1), Int(0))),
        ]  # fmt: skip
    pi = driver.PI(ctl)
    reject = and_(run, not_(take))
    control: list[S] = [
        Comment("control: accept or reject by selection, and the next h"),
        assign(run, cmp(cd, "<", 0)),
        assign(take, and_(run, not_(nonfinite), cmp(err, "<=", 1.0))),
        assign(lock, Bool(False) if quaternion else locked(x, xnew)),
        assign(ok, and_(take, not_(lock))),
        *pi.factors(err, err_old, rejected_last),
        assign(cd, driver.ended(and_(take, lock), ok, last, cd)),
        *driver.counted(ok, reject, last),
        *pi.remember(ok, reject, err, err_old, rejected_last),
        pi.next_h(or_(not_(run), and_(take, lock)), nonfinite, ok),
    ]
    first: list[S] = [For("i", NX, (assign(k[0, i], k[m.fnew, i]),))]
    accept: list[S] = [
        Comment("accept: x := xnew; f(t + h, xnew) is the next step's first stage"),
        *_accept(m, quaternion, grid, ok, first, row, cd if lanes else None),
    ]
    return begin, [Comment("trial"), *trial(m), *check, *control, *accept]


def _accept(
    m: Method,
    quaternion: bool,
    grid: bool | driver.Grid,
    ok: Var,
    first: list[S],
    row: E,
    lanes: Var | None = None,
) -> list[S]:
    """accept, under ok: with the grid, the grid times the step passes first
    and its end after (driver.passed; with events, driver.inside, or over
    lanes driver.lane_events, which stops a lane with its code, lanes)."""
    taken = (*accepted(quaternion, known=True), *first)
    if not grid:
        return [If(ok, taken)]
    told, hs = Var("told"), Var("hs")
    if isinstance(grid, driver.Grid) and grid.events and lanes is not None:
        events = driver.lane_events(grid, interpolant(m), ok, lanes, t, told, hs, row)
        return [*events, If(ok, taken), *driver.reached(row, ok)]
    if isinstance(grid, driver.Grid) and grid.events:
        inside = driver.inside(interpolant(m), t, told, hs, grid, counted=True)
        return [If(ok, (*inside, *taken, *driver.reached()))]
    passed = driver.passed(ok, interpolant(m), t, told, hs, row)
    return [*passed, If(ok, taken), *driver.reached(row, ok)]


STATE = ("code", "t", "h", "err_old", "nonfinite", "rejected_last")
"""A pair's values that live from step to step (besides x and stats)."""
LOCALS = tuple("last err run take lock ok fac grow total err5 err3 deno norm".split())
BOOLS = {"nonfinite", "rejected_last", "last", "run", "take", "lock", "ok"}


def declare(name: str) -> Decl:
    return common.declare(name, BOOLS)


def state_arrays(krows: int) -> tuple[Decl, ...]:
    """The arrays of a trajectory: x, its stages, the new point, Kahan's comp."""
    rows = (Decl("k", "double", (krows, "NX"), "inout"),) if krows else ()
    return (arr("x", "inout"), *rows, *(arr(n, "inout") for n in ("y", "xnew", "dx", "comp")))


def used_locals(body: list[S]) -> tuple[Decl, ...]:
    text = repr(body)
    return tuple(declare(n) for n in LOCALS if f"Var(name='{n}')" in text)


def start_state() -> list[S]:
    """A trajectory's values at t0, after ode_start (code -1: going on)."""
    return [*common.start_state(), *driver.PI.start()]


def integrate(
    m: Method,
    quaternion: bool,
    krows: int,
    grid: bool | driver.Grid = False,
    knots: driver.Knots = (),
) -> Func:
    """m.name_integrate: pair m from t0 to t1 on one trajectory; with grid,
    m.name_grid: over the output grid."""
    begin, rest = parts(m, quaternion, grid, knots=knots)
    cd = Var("code")
    stop = driver.stopped(cd)
    start = driver.started(m, Row("k", Int(0)), cd, grid)
    body = [*start, *start_state(), Loop((*begin, stop, *rest, stop))]
    rows = grid_krows(m, krows) if grid else krows
    locals_ = (*state_arrays(rows)[1:], *(declare(n) for n in STATE), *used_locals(begin + rest),
               *driver.knot_locals(knots))  # fmt: skip
    if grid:
        locals_ += (driver.rows("dense", dense_rows(m)), *driver.grid_locals(body, grid))
    doc = (
        f"{m.name} to t1, with Hairer's step-size strategy: the last step clipped",
        "to end on t1, no growth right after a rejection, and a non-finite trial",
        "rejected with h shrunk by facmin.",
        *((m.control.note,) if isinstance(m.control, registry.PairControl) else ()),
        *driver.knot_doc(knots),
    )
    if grid:
        doc = (*doc, *driver.GRID_DOC)
        name, params = f"{m.name}_{driver.variant(grid)}", driver.grid_params(grid)
        return Func(name, params, tuple(body), "int", locals_, doc)
    return Func(f"{m.name}_integrate", driver.PARAMS, tuple(body), "int", locals_, doc)


def lanes_step(
    m: Method, quaternion: bool, grid: bool | driver.Grid = False, knots: driver.Knots = ()
) -> Func:
    """m.name_step_lanes: one step of every lane of a struct lanes; with
    grid, m.name_grid_step_lanes: one step of m.name_grid (its grid and
    dense rows in the struct, driver.lane_grid_state); with events,
    m.name_events_step_lanes: one step of m.name_events (the events' values
    and log in the struct too, driver.lane_event_state)."""
    begin, rest = parts(m, quaternion, grid, driver.BASE + driver.G, knots, lanes=True)
    step = begin + rest
    if not grid:
        doc = (f"One step of {m.name}_integrate on every lane.",)
        locals_ = (*used_locals(step), *driver.knot_locals(knots))
        return Func(f"{m.name}_step_lanes", driver.LANE_PARAMS, tuple(step), None, locals_, doc)
    locals_ = (*used_locals(step), *driver.knot_locals(knots), *driver.lane_grid_locals(step))
    variant = driver.variant(grid)
    if isinstance(grid, driver.Grid) and grid.events:
        locals_ += driver.lane_event_locals(grid, step)
    doc = (f"One step of {m.name}_{variant} on every lane.",)
    name = f"{m.name}_{variant}_step_lanes"
    return Func(name, driver.LANE_PARAMS, tuple(step), None, locals_, doc)


def lane_state(krows: int, pairs: list[Method]) -> dict[str, Decl]:
    """What struct lanes holds per lane: a trajectory's arrays and values
    (k's rows for the pairs' grids too, and their interpolants' rows)."""
    values = [declare(n) for n in STATE]
    stats = [
        Decl(f"stats.{n}", "double" if n in ("t", "h") else "long", (), "inout")
        for n in ("t", "h", "accepted", "rejected", "rhs_calls")
    ]
    rows = max([krows, *(grid_krows(m, krows) for m in pairs)])
    dense = [driver.rows("dense", max(dense_rows(m) for m in pairs))] if pairs else []
    return {d.name: d for d in (*state_arrays(rows), *values, *stats, *dense)}


__all__ = ["integrate", "lane_state", "lanes_step"]
