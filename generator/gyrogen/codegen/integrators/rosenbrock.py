"""Rosenbrock methods (rodas4), described once: the stages on the LU
factors of E = I/(h gamma) - J, and Hairer's rodas.f step-size control with
Gustafsson's predictive controller."""

from __future__ import annotations

from gyrogen import methods as registry
from gyrogen.codegen.integrators.common import (
    NX,
    STATS,
    TOLERANCES,
    code,
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
    Ref,
    Return,
    Row,
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


def trial(m: Method, uses_time: bool) -> Func:
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
        Return(fn("error_norm", Row("k", Int(last)), x, xnew, Var("rtol"), Var("atol"))),
    ]
    params = (
        real("t"), real("h"), arr("x"), arr("f0"), *((arr("ft"),) if uses_time else ()),
        Decl("lu", "double", ("NX2",)), Decl("piv", "int", ("NX",)), Decl("c", "double", ("NC",)),
        *TOLERANCES, arr("comp"), Decl("k", "double", (R.stages, "NX"), "inout"),
        arr("dx", "inout"), arr("xnew", "inout"),
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
    return Func(f"{m.name}_trial", params, tuple(body), "double", locals_, doc)


def integrate(m: Method, quaternion: bool, uses_time: bool) -> Func:
    R, ctl = m.tableau, m.control
    assert isinstance(R, Rosenbrock) and isinstance(ctl, registry.RosenbrockControl)
    J, lu, piv, fnew, t0, t1 = (Var(n) for n in ("J", "lu", "piv", "fnew", "t0", "t1"))
    err, fac, gus, h_acc, err_acc = (Var(n) for n in ("err", "fac", "gus", "h_acc", "err_acc"))
    last, rejected_last, nonfinite = Var("last"), Var("rejected_last"), Var("nonfinite")
    singular, new_point, start, delta = (
        Var("singular"),
        Var("new_point"),
        Var("start"),
        Var("delta"),
    )
    st = Var("stats")
    low, high = Num(1.0 / ctl.facmax), Num(1.0 / ctl.facmin)
    reject: list[S] = [inc(Var("stats.rejected"), 1), assign(rejected_last, True)]
    point: list[S] = [
        Call("jac", (t, x, c, J)),
        inc(Var("stats.jac_calls"), 1),
        If(not_(fn("all_finite", J, Const("NX2"))), (Return(code("ERR_NONFINITE")),)),
    ]
    if uses_time:
        point += [
            Comment("f depends on t (the torque table): f_t by a forward difference"),
            assign(delta, fn("sqrt", Const("EPSILON") * fn("max", 1e-5, fn("abs", t)))),
            Call("rhs", (t + delta, x, c, ft)),
            inc(Var("stats.rhs_calls"), 1),
            For("i", NX, (assign(ft[i], (ft[i] - f0[i]) / delta),)),
        ]
    args = (t, h, x, f0, *((ft,) if uses_time else ()), lu, piv, c, Var("rtol"), Var("atol"),
            comp, k, dx, xnew)  # fmt: skip
    lock: list[S] = [] if quaternion else [If(fn("gimbal_lock", x, xnew), (
        Return(code("ERR_ATTITUDE_SINGULAR"), "x: the state before this step"),))]  # fmt: skip
    gustafsson = (h_acc / h) * fn("pow", err * err / err_acc, ctl.exponent) / Num(ctl.safety)
    accept: list[S] = [
        *lock,
        If(cmp(Var("stats.accepted"), ">", 0), (
            assign(gus, gustafsson),
            assign(fac, fn("max", fac, fn("max", low, fn("min", high, gus)))),
        )),
        assign(h_acc, h),
        assign(err_acc, fn("max", ctl.err_floor, err)),
        Call("accept_step", (x, xnew, dx, comp)),
        assign(t, sel(last, t1, t + h)),
        assign(Var("stats.t"), t),
        inc(Var("stats.accepted"), 1),
        If(last, (Return(code("OK")),)),
        For("i", NX, (assign(f0[i], fnew[i]),)),
        assign(new_point, True),
        If(rejected_last, (assign(fac, fn("max", fac, 1.0)),)),
        assign(rejected_last, False),
    ]  # fmt: skip
    ii = lu[i * NX + i]
    loop: list[S] = [
        If(new_point, (*point, assign(new_point, False))),
        If(fn("step_underflow", h, t), (
            Return(sel(nonfinite, code("ERR_NONFINITE"), code("ERR_STEP_UNDERFLOW"))),)),
        If(cmp(Var("stats.accepted") + Var("stats.rejected"), ">=", Var("max_steps")), (
            Return(code("ERR_MAX_STEPS")),)),
        assign(last, cmp(t + Num(registry.LAST_STEP_SLACK) * h, ">=", t1)),
        If(last, (assign(h, t1 - t),)),
        assign(Var("stats.h"), h),
        Comment("E = I/(h gamma) - J"),
        For("i", Const("NX2"), (assign(lu[i], -J[i]),)),
        For("i", NX, (assign(ii, ii + Num(1.0) / (h * Num(R.gamma))),)),
        inc(Var("stats.decompositions"), 1),
        If(fn("lu_decompose", lu, piv), (
            *reject,
            inc(singular, 1),
            If(cmp(singular, "==", ctl.singular_tries), (Return(code("ERR_SINGULAR")),)),
            assign(h, h * Num(ctl.singular_shrink)),
            Continue(),
        )),
        assign(singular, 0),
        assign(err, fn(f"{m.name}_trial", *args)),
        inc(Var("stats.rhs_calls"), R.stages - 1),
        assign(nonfinite, or_(not_(fn("finite", err)), not_(finite_state(xnew, quaternion)))),
        If(and_(not_(nonfinite), cmp(err, "<=", 1.0), not_(last)), (
            Call("rhs", (t + h, xnew, c, fnew), "where the next step starts"),
            inc(Var("stats.rhs_calls"), 1),
            assign(nonfinite, not_(fn("all_finite", fnew, NX))),
        )),
        If(nonfinite, (*reject, assign(h, h * Num(ctl.nonfinite_shrink)), Continue())),
        assign(fac, fn("max", low, fn("min", high, fn("pow", err, ctl.exponent) / Num(ctl.safety))),
               "h / h_new"),
        If(cmp(err, "<=", 1.0), tuple(accept), tuple(reject)),
        assign(h, h / fac),
    ]  # fmt: skip
    body = (
        assign(start, fn("ode_start", Int(R.order), Const(m.min_rtol), t0, t1, x, c, Var("rtol"),
                         Var("atol"), Var("h0"), Var("max_steps"), f0, Ref("h"), st)),
        If(cmp(start, ">=", 0), (Return(start),)),
        assign(t, t0),
        assign(h_acc, 0.0),
        assign(err_acc, ctl.err_floor),
        assign(rejected_last, False),
        assign(nonfinite, False),
        assign(singular, 0),
        assign(new_point, True),
        For("i", NX, (assign(comp[i], 0.0),)),
        Loop(tuple(loop)),
    )  # fmt: skip
    params = (real("t0"), real("t1"), arr("x", "inout"), Decl("c", "double", ("NC",)),
              *TOLERANCES, real("h0"), Decl("max_steps", "long"), STATS)  # fmt: skip
    doubles = ["t", "h", "err", "fac", "gus", "h_acc", "err_acc"] + ["delta"] * uses_time
    locals_ = (
        Decl("J", "double", ("NX2",), "inout"), Decl("lu", "double", ("NX2",), "inout"),
        Decl("k", "double", (R.stages, "NX"), "inout"),
        *(arr(n, "inout") for n in ["f0", "fnew", "xnew", "dx", "comp"] + ["ft"] * uses_time),
        Decl("piv", "int", ("NX",), "inout"), *(real(n, "inout") for n in doubles),
        *(Decl(n, "bool") for n in ("last", "rejected_last", "nonfinite", "new_point")),
        Decl("singular", "int"), Decl("start", "int"),
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
    return Func(f"{m.name}_integrate", params, body, "int", locals_, doc)


__all__ = ["Bool", "integrate", "trial"]
