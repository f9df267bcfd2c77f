"""Rosenbrock methods (rodas4), described once: the stages on the LU
factors of E = I/(h gamma) - J, and Hairer's rodas.f step-size control with
Gustafsson's predictive controller."""

from __future__ import annotations

from collections.abc import Callable

from gyrogen import methods as registry
from gyrogen.codegen.integrators import driver, linear
from gyrogen.codegen.integrators import quaternion as euler_parameters
from gyrogen.codegen.integrators.common import (
    NX,
    TOLERANCES,
    accepted,
    comp,
    dx,
    finite_state,
    h,
    i,
    locked,
    mean_square,
    x,
    xnew,
)
from gyrogen.codegen.integrators.explicit import at, combo
from gyrogen.codegen.ir.nodes import (
    Bool,
    Call,
    Comment,
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
    Return,
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
    real,
    sel,
)
from gyrogen.methods import Method
from gyrogen.tableaus import Rosenbrock

t, k, y, c = Var("t"), Var("k"), Var("y"), Var("c")
ft, f0, fy = Var("ft"), Var("f0"), Var("fy")


def with_ft(value: E, d: float, uses_time: bool) -> E:
    """value + d h f_t, when f depends on t."""
    if not uses_time or not d:
        return value
    term = Num(abs(d)) * h * ft[i]
    return value - term if d < 0 else value + term


Solve = Callable[[int], list[S]]
"""The statements that solve E k_s = (row s of k) in place."""


def stages(R: Rosenbrock, uses_time: bool, solve: Solve) -> list[S]:
    """The stages, dx and xnew: what one trajectory's trial and a lane's
    step share (solve: by lu_solve, or its statements over lanes)."""
    inv_h = Var("inv_h")
    last = R.stages - 1
    body: list[S] = [
        assign(inv_h, Num(1.0) / h),
        Comment("stage 1: t"),
        For("i", NX, (assign(k[0, i], with_ft(f0[i], R.d[0], uses_time)),)),
        *solve(0),
    ]
    for s in range(1, R.stages):
        where = "t + h" if R.nodes[s] == 1.0 else f"t + {R.nodes[s]!r} h"
        if s == last:
            body += [
                Comment(f"stage {s + 1}: {where}, on the embedded solution"),
                For("i", NX, (assign(dx[i], combo(R.stage(s))), assign(y[i], x[i] + dx[i]))),
            ]
        else:
            body += [
                Comment(f"stage {s + 1}: {where}"),
                For("i", NX, (assign(y[i], combo(R.stage(s), x[i])),)),
            ]
        feedback = with_ft(fy[i] + inv_h * combo(R.feedback(s)), R.d[s], uses_time)
        body += [
            Call("rhs", (at(R.nodes[s]), y, c, fy)),
            For("i", NX, (assign(k[s, i], feedback),)),
            *solve(s),
        ]
    return [
        *body,
        Comment(f"the new solution x + dx: the embedded one plus k_{R.stages}"),
        For(
            "i", NX, (assign(dx[i], (dx[i] + k[last, i]) - comp[i]), assign(xnew[i], x[i] + dx[i]))
        ),
    ]


def trial(m: Method, uses_time: bool, grid: bool = False) -> Func:
    """m.name_trial; with grid m.name_grid_trial, which also sets the
    interpolant's rows from the stages (dense: its own function, so that
    m.name_trial keeps one caller, which gcc inlines)."""
    R = m.tableau
    assert isinstance(R, Rosenbrock)
    lu, piv = Var("lu"), Var("piv")
    last = R.stages - 1
    body: list[S] = [
        *stages(R, uses_time, lambda s: [Call("lu_solve", (lu, piv, Row("k", Int(s))))]),
        *([dense_rows(R)] if grid else []),
        Return(fn("error_norm", Row("k", Int(last)), x, xnew, Var("rtol"), Var("atol"))),
    ]
    params = (
        real("t"), real("h"), arr("x"), arr("f0"), *((arr("ft"),) if uses_time else ()),
        Decl("lu", "double", ("NX2",)), Decl("piv", "int", ("NX",)), Decl("c", "double", ("NC",)),
        *TOLERANCES, arr("comp"), Decl("k", "double", (R.stages, "NX"), "inout"),
        arr("dx", "inout"), arr("xnew", "inout"),
        *((driver.rows("dense", len(R.dense)),) if grid else ()),
    )  # fmt: skip
    locals_ = (arr("y", "inout"), arr("fy", "inout"), real("inv_h", "inout"))
    doc = (
        *m.notes[:-1], m.notes[-1] + ": with E = I/(h gamma) - J, stage s solves",
        "E k_s = f(t + c_s h, x + sum_j a_sj k_j) + sum_j (g_sj/h) k_j"
        + (" + h d_s f_t." if uses_time else "."),
        f"Stiffly accurate: stage {R.stages} sits on the embedded solution and the step",
        f"is that plus k_{R.stages}, the error estimate. Returns its norm (NaN or Inf",
        "when a stage is).",
    )  # fmt: skip
    name = f"{m.name}_grid_trial" if grid else f"{m.name}_trial"
    return Func(name, params, tuple(body), "double", locals_, doc)


def interpolant(R: Rosenbrock) -> driver.Interpolant:
    """rodas.f's dense output (CONTRO): x (1 - theta) + theta (xnew + (1 -
    theta) (r3 + theta r4)), r3 and r4 the D2 and D3 rows' sums of the stages
    k_1 .. k_5 (dense_rows, in the grid's trial); x is the step's start (the
    grid writes before x moves)."""
    r = Var("dense")

    def value(theta: E, i: E) -> E:
        rest = Num(1.0) - theta
        inner = xnew[i] + rest * (r[0, i] + theta * r[1, i])
        return x[i] * rest + theta * inner

    return driver.Interpolant((), driver.by_state(value))


def dense_rows(R: Rosenbrock) -> S:
    """The interpolant's rows r3 and r4 from the stages (in the grid's trial)."""
    r = Var("dense")
    return For("i", NX, tuple(assign(r[j, i], combo(R.dense_row(j))) for j in range(len(R.dense))))


def time_derivative(into: Var) -> list[S]:
    """f_t by a forward difference, into ft (f at t + delta into into first:
    over lanes a scratch row, which the call writes on every lane)."""
    delta = Var("delta")
    return [
        Comment("f depends on t (the torque table): f_t by a forward difference"),
        assign(delta, fn("sqrt", Const("EPSILON") * fn("max", 1e-5, fn("abs", t)))),
        Call("rhs", (t + delta, x, c, into)),
        driver.count("rhs_calls", 1),
        For("i", NX, (assign(ft[i], (into[i] - f0[i]) / delta),)),
    ]


def matrix(R: Rosenbrock) -> list[S]:
    """lu := E = I/(h gamma) - J."""
    J, lu = Var("J"), Var("lu")
    ii = lu[i * NX + i]
    return [
        Comment("E = I/(h gamma) - J"),
        For("i", Const("NX2"), (assign(lu[i], -J[i]),)),
        For("i", NX, (assign(ii, ii + Num(1.0) / (h * Num(R.gamma))),)),
    ]


def integrate(
    m: Method,
    quaternion: bool,
    uses_time: bool,
    grid: bool | driver.Grid = False,
    knots: driver.Knots = (),
) -> Func:
    """m.name_integrate, or with grid m.name_grid (the states at the grid's
    times, from the interpolant); knots: the table times a step ends on."""
    R, ctl = m.tableau, m.control
    assert isinstance(R, Rosenbrock) and isinstance(ctl, registry.RosenbrockControl)
    J, lu, piv, fnew, t1 = (Var(n) for n in ("J", "lu", "piv", "fnew", "t1"))
    err, fac, start = Var("err"), Var("fac"), Var("start")
    last, rejected_last, nonfinite = Var("last"), Var("rejected_last"), Var("nonfinite")
    singular, new_point = Var("singular"), Var("new_point")
    control = driver.Gustafsson(ctl)
    reject = driver.rejected(rejected_last)
    point = driver.jacobian(J) + (time_derivative(ft) if uses_time else [])
    args = (t, h, x, f0, *((ft,) if uses_time else ()), lu, piv, c, Var("rtol"), Var("atol"),
            comp, k, dx, xnew, *((Var("dense"),) if grid else ()))  # fmt: skip
    dense = interpolant(R) if grid else None
    taken = driver.accepted(quaternion, last, control.predictive(fac, err), [], dense, grid)
    accept: list[S] = [
        *taken,
        For("i", NX, (assign(f0[i], fnew[i]),)),
        assign(new_point, True),
        If(rejected_last, (assign(fac, fn("max", fac, 1.0)),)),
        assign(rejected_last, False),
    ]
    loop: list[S] = [
        If(new_point, (*point, assign(new_point, False))),
        *driver.stop_tests(nonfinite),
        *driver.next_knot(knots),
        assign(last, driver.final_step(knots)),
        If(last, (assign(h, t1 - t),)),
        *driver.knot_clip(knots, last),
        assign(driver.stat("h"), h),
        Comment("E = I/(h gamma) - J"),
        Call("lu_shift", (J, Num(1.0) / (h * Num(R.gamma)), lu)),
        driver.count("decompositions", 1),
        If(fn("lu_decompose", lu, piv), (
            *reject, *driver.singular_stop(singular, ctl.singular_tries),
            assign(h, h * Num(ctl.singular_shrink)), Continue())),
        assign(singular, 0),
        assign(err, fn(f"{m.name}_grid_trial" if grid else f"{m.name}_trial", *args)),
        driver.count("rhs_calls", R.stages - 1),
        assign(nonfinite, or_(not_(fn("finite", err)), not_(finite_state(xnew, quaternion)))),
        If(and_(not_(nonfinite), cmp(err, "<=", 1.0), not_(last)),
           tuple(driver.next_f(fnew, nonfinite))),
        If(nonfinite, (*reject, assign(h, h * Num(ctl.nonfinite_shrink)), Continue())),
        assign(fac, control.quotient(err, Num(ctl.safety)), "h / h_new"),
        If(cmp(err, "<=", 1.0), tuple(accept), tuple(reject)),
        assign(h, h / fac),
    ]  # fmt: skip
    body = (
        *driver.started(m, f0, start, grid),
        assign(t, Var("t0")),
        *control.start(),
        *(assign(v, False) for v in (rejected_last, nonfinite)),
        assign(singular, 0),
        assign(new_point, True),
        For("i", NX, (assign(comp[i], 0.0),)),
        Loop(tuple(loop)),
    )  # fmt: skip
    doubles = ["t", "h", "err", "fac", "gus", "h_acc", "err_acc"] + ["delta"] * uses_time
    locals_ = (
        Decl("J", "double", ("NX2",), "inout"), Decl("lu", "double", ("NX2",), "inout"),
        Decl("k", "double", (R.stages, "NX"), "inout"),
        *(arr(n, "inout") for n in ["f0", "fnew", "xnew", "dx", "comp"] + ["ft"] * uses_time),
        Decl("piv", "int", ("NX",), "inout"), *(real(n, "inout") for n in doubles),
        *(Decl(n, "bool") for n in ("last", "rejected_last", "nonfinite", "new_point")),
        Decl("singular", "int"), Decl("start", "int"), *driver.knot_locals(knots),
        *((driver.rows("dense", len(R.dense)), *driver.grid_locals(body, grid)) if grid else ()),
    )  # fmt: skip
    doc = (
        m.doc,
        "J and f are evaluated once per accepted step; a rejected step only",
        f"refactors E with the new h. Step size as Hairer's rodas.f: h_new/h = {ctl.safety:g}",
        f"err^-{ctl.exponent:g} within [{ctl.facmin:g}, {ctl.facmax:g}], and Gustafsson's"
        " predictive controller after an accepted step.",
        f"A singular E is retried with h times {ctl.singular_shrink:g},"
        f" {ctl.singular_tries} times in a row at most.",
        *driver.knot_doc(knots),
    )
    if grid:
        params, name = driver.grid_params(grid), f"{m.name}_{driver.variant(grid)}"
        return Func(name, params, body, "int", locals_, (*doc, *driver.GRID_DOC))
    return Func(f"{m.name}_integrate", driver.PARAMS, body, "int", locals_, doc)


# Over SIMD lanes: one step of m.name_integrate's loop on every lane, the
# loop's branches as selections (gyrogen.codegen.ir.lanes)

STATE_BOOLS = ("nonfinite", "rejected_last", "new_point")
STATE_REALS = ("t", "h", "h_acc", "err_acc")
STEP_BOOLS = ("go", "fresh", "bad", "last", "retry", "ok", "take", "lock", "rej")


def any_nonfinite(flag: Var, values: Var, n: E) -> list[S]:
    """flag := flag or a NaN or Inf among values[0..n-1] (all_finite, over lanes)."""
    return [For("i", n, (assign(flag, or_(flag, not_(fn("finite", values[i])))),))]


def lanes_point(uses_time: bool) -> list[S]:
    """driver.jacobian (and f_t) where a lane is at a new point: the calls run
    on every lane when any lane needs them (a lane elsewhere computes J at
    its own unchanged t and x again: the same bits), a NaN or Inf stops."""
    J, cd, fresh, bad, new_point = (Var(n) for n in ("J", "code", "fresh", "bad", "new_point"))
    return [
        assign(fresh, and_(cmp(cd, "<", 0), new_point)),
        assign(bad, False),
        If(
            fresh,
            (
                Call("jac", (t, x, c, J)),
                driver.count("jac_calls", 1),
                *any_nonfinite(bad, J, Const("NX2")),
                assign(cd, sel(bad, driver.ERR_NONFINITE, cd)),
                assign(new_point, False),
            ),
        ),
        *(
            [
                assign(fresh, and_(fresh, not_(bad))),
                assign(Var("delta"), 0.0),
                If(fresh, tuple(time_derivative(fy))),
            ]
            if uses_time
            else []
        ),
    ]


def lanes_step(
    m: Method,
    quaternion: bool,
    uses_time: bool,
    grid: bool | driver.Grid = False,
    knots: driver.Knots = (),
) -> Func:
    """m.name_step_lanes: one turn of m.name_integrate's loop on every lane,
    each branch a selection (a lane that stopped, or whose E is singular or
    whose trial is not finite, computes on and keeps nothing); E's LU and
    its solves by selection too (each lane its own pivots), out of line
    (linear.decompose_lanes, linear.solve_lanes), so each lane takes
    m.name_integrate's steps bit for bit. With grid,
    m.name_grid_step_lanes: m.name_grid's (the grid and the interpolant's
    rows in the struct, driver.lane_grid_state; the grid's writes lane by
    lane, driver.passed); with events, m.name_events_step_lanes:
    m.name_events's (_accepted: driver.lane_events)."""
    R, ctl = m.tableau, m.control
    assert isinstance(R, Rosenbrock) and isinstance(ctl, registry.RosenbrockControl)
    names = "code go bad last retry ok take lock rej err fac rejected_last singular t1"
    cd, go, bad, last, retry, ok, take, lock, rej, err, fac, rejected_last, singular, t1 = (
        Var(n) for n in names.split()
    )
    sing = linear.ZERO_PIVOT
    nonfinite, fnew, new_point = Var("nonfinite"), Var("fnew"), Var("new_point")
    final, row = R.stages - 1, driver.BASE + driver.G
    control = driver.Gustafsson(ctl)
    sums, norm = mean_square(lambda at: k[final, at])

    def rejected(when: E) -> list[S]:
        return [driver.count("rejected", sel(when, Int(1), Int(0))),
                assign(rejected_last, sel(when, True, rejected_last))]  # fmt: skip

    begin: list[S] = [
        *lanes_point(uses_time),
        assign(cd, sel(cmp(cd, "<", 0), driver.stop_code(nonfinite), cd)),
        assign(go, cmp(cd, "<", 0)),
        *driver.next_knot(knots),
        assign(last, driver.final_step(knots)),
        assign(h, sel(and_(go, last), t1 - t, h)),
        *driver.knot_clip(knots, last, go),
        assign(driver.stat("h"), sel(go, h, driver.stat("h"))),
        *matrix(R),
        driver.count("decompositions", sel(go, Int(1), Int(0))),
        Call("lu_decompose", (), "E's LU on every lane, each its own pivots"),
        Comment("a singular E: h shrunk, so many times in a row stop"),
        assign(retry, and_(go, sing)),
        *rejected(retry),
        *driver.singular_selected(singular, retry, go, cd, ctl.singular_tries),
        assign(h, sel(retry, h * Num(ctl.singular_shrink), h)),
        assign(go, and_(go, not_(sing))),
    ]
    trial: list[S] = [
        *stages(R, uses_time, lambda s: [Call("lu_solve", (Int(s),))]),
        *([dense_rows(R)] if grid else []),
        driver.count("rhs_calls", sel(go, Int(R.stages - 1), Int(0))),
        *sums,
        assign(err, norm),
        assign(bad, not_(fn("finite", err))),
        *any_nonfinite(bad, xnew, NX),
        *(
            [assign(bad, or_(bad, euler_parameters.lost(euler_parameters.norm_of(xnew))))]
            if quaternion
            else []
        ),
        assign(nonfinite, sel(go, bad, nonfinite)),
        assign(ok, and_(go, not_(nonfinite), cmp(err, "<=", 1.0), not_(last))),
        assign(bad, False),
        If(
            ok,
            (
                Call("rhs", (t + h, xnew, c, fnew), "where the next step starts"),
                driver.count("rhs_calls", 1),
                *any_nonfinite(bad, fnew, NX),
                assign(nonfinite, bad),
            ),
        ),
    ]
    control_: list[S] = [
        Comment("a NaN or Inf: h shrunk; else accept or reject"),
        assign(retry, and_(go, nonfinite)),
        *rejected(retry),
        assign(h, sel(retry, h * Num(ctl.nonfinite_shrink), h)),
        assign(go, and_(go, not_(nonfinite))),
        assign(fac, control.quotient(err, Num(ctl.safety)), "h / h_new"),
        assign(take, and_(go, cmp(err, "<=", 1.0))),
        assign(rej, and_(go, not_(cmp(err, "<=", 1.0)))),
        assign(lock, Bool(False) if quaternion else locked(x, xnew)),
        assign(ok, and_(take, not_(lock))),
        *control.predictive_selected(ok, fac, err),
        *_accepted(R, quaternion, grid, ok, rej, last, cd, row),
        *(driver.reached(row, ok) if grid else []),
        assign(cd, driver.ended(and_(take, lock), ok, last, cd)),
        Comment("a branch's locals are its own over lanes: fac by selection"),
        assign(fac, sel(and_(ok, rejected_last), fn("max", fac, 1.0), fac)),
        If(ok, (For("i", NX, (assign(f0[i], fnew[i]),)), assign(new_point, True))),
        assign(rejected_last, sel(ok, False, sel(rej, True, rejected_last))),
        assign(h, sel(go, h / fac, h)),
    ]
    body = (*begin, Comment("trial"), *trial, *control_)
    doubles = ["inv_h", "err", "fac", "gus", "total"] + ["delta"] * uses_time
    doubles += ["norm"] * quaternion
    locals_ = (*(real(n, "inout") for n in doubles),
               *(Decl(n, "bool", (), "inout") for n in STEP_BOOLS),
               *driver.knot_locals(knots))  # fmt: skip
    return driver.step_lanes(m, body, locals_, grid)


def _accepted(R: Rosenbrock, quaternion: bool, grid: bool | driver.Grid, ok: Var, rej: Var,
              last: Var, cd: Var, row: E) -> list[S]:  # fmt: skip
    """A turn's acceptance over lanes: the grid times the step passes, x :=
    xnew and the step counted; with events, the step counted first (its
    start and size kept, driver.grid_step), then its events (a stop at one
    sets the lane's code and clears ok), then x := xnew."""
    if isinstance(grid, driver.Grid) and grid.events:
        told, hs = Var("told"), Var("hs")
        return [
            *driver.grid_step(t, h),
            *driver.counted(ok, rej, last),
            *driver.lane_events(grid, interpolant(R), ok, cd, t, told, hs, row),
            If(ok, tuple(accepted(quaternion))),
        ]
    end = sel(last, Var("t1"), t + h)
    passed = driver.passed(ok, interpolant(R), end, t, h, row) if grid else []
    return [*passed, If(ok, tuple(accepted(quaternion))), *driver.counted(ok, rej, last)]


def lane_state(m: Method, uses_time: bool) -> list[Decl]:
    """What struct lanes holds for m per lane, beyond a pair's."""
    R = m.tableau
    assert isinstance(R, Rosenbrock)
    square = [Decl("J", "double", ("NX2",), "inout"), *linear.lanes_state()]
    rows = [arr(n, "inout") for n in ["f0", "fnew", "fy"] + ["ft"] * uses_time]
    values = [Decl(n, "bool", (), "inout") for n in STATE_BOOLS]
    values += [real(n, "inout") for n in STATE_REALS] + [Decl("singular", "int", (), "inout")]
    stats = [Decl(f"stats.{n}", "long", (), "inout") for n in ("jac_calls", "decompositions")]
    stages = Decl("k", "double", (R.stages, "NX"), "inout")
    dense = driver.rows("dense", len(R.dense))
    return [*square, *rows, *values, *stats, stages, dense]


def lane_start(m: Method) -> list[S]:
    """A lane's values at t0 beyond common.start_state (m.name_integrate's)."""
    ctl = m.control
    assert isinstance(ctl, registry.RosenbrockControl)
    return [
        *driver.Gustafsson(ctl).start(),
        assign(Var("rejected_last"), False),
        assign(Var("singular"), 0),
        assign(Var("new_point"), True),
    ]


__all__ = ["Bool", "integrate", "lane_start", "lane_state", "lanes_step", "trial"]
