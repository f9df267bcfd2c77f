"""Rosenbrock methods (rodas4), described once: the stages on the LU
factors of E = I/(h gamma) - J, and Hairer's rodas.f step-size control with
Gustafsson's predictive controller."""

from __future__ import annotations

from gyrogen import methods as registry
from gyrogen.codegen.integrators import driver
from gyrogen.codegen.integrators.common import (
    NX,
    TOLERANCES,
    comp,
    dx,
    finite_state,
    h,
    i,
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


def trial(m: Method, uses_time: bool, grid: bool = False) -> Func:
    """m.name_trial; with grid m.name_grid_trial, which also sets the
    interpolant's rows from the stages (dense: its own function, so that
    m.name_trial keeps one caller, which gcc inlines)."""
    R = m.tableau
    assert isinstance(R, Rosenbrock)
    inv_h, lu, piv = Var("inv_h"), Var("lu"), Var("piv")
    last = R.stages - 1
    body: list[S] = [
        assign(inv_h, Num(1.0) / h),
        Comment("stage 1: t"),
        For("i", NX, (assign(k[0, i], with_ft(f0[i], R.d[0], uses_time)),)),
        Call("lu_solve", (lu, piv, Row("k", Int(0)))),
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
            Call("lu_solve", (lu, piv, Row("k", Int(s)))),
        ]
    body += [
        Comment(f"the new solution x + dx: the embedded one plus k_{R.stages}"),
        For(
            "i", NX, (assign(dx[i], (dx[i] + k[last, i]) - comp[i]), assign(xnew[i], x[i] + dx[i]))
        ),
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


def integrate(
    m: Method, quaternion: bool, uses_time: bool, grid: bool | driver.Grid = False
) -> Func:
    """m.name_integrate, or with grid m.name_grid (the states at the grid's
    times, from the interpolant)."""
    R, ctl = m.tableau, m.control
    assert isinstance(R, Rosenbrock) and isinstance(ctl, registry.RosenbrockControl)
    J, lu, piv, fnew, t1 = (Var(n) for n in ("J", "lu", "piv", "fnew", "t1"))
    err, fac, delta, start = Var("err"), Var("fac"), Var("delta"), Var("start")
    last, rejected_last, nonfinite = Var("last"), Var("rejected_last"), Var("nonfinite")
    singular, new_point = Var("singular"), Var("new_point")
    control = driver.Gustafsson(ctl)
    reject = driver.rejected(rejected_last)
    point = driver.jacobian(J)
    if uses_time:
        point += [
            Comment("f depends on t (the torque table): f_t by a forward difference"),
            assign(delta, fn("sqrt", Const("EPSILON") * fn("max", 1e-5, fn("abs", t)))),
            Call("rhs", (t + delta, x, c, ft)),
            driver.count("rhs_calls", 1),
            For("i", NX, (assign(ft[i], (ft[i] - f0[i]) / delta),)),
        ]
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
        assign(last, driver.last_step()),
        If(last, (assign(h, t1 - t),)),
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
        Decl("singular", "int"), Decl("start", "int"),
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
    )
    if grid:
        params, name = driver.grid_params(grid), f"{m.name}_{driver.variant(grid)}"
        return Func(name, params, body, "int", locals_, (*doc, *driver.GRID_DOC))
    return Func(f"{m.name}_integrate", driver.PARAMS, body, "int", locals_, doc)


__all__ = ["Bool", "integrate", "trial"]
