"""The explicit methods' stages and error estimates, described once from
their tableaus, and the fixed-step methods (rk4). The embedded pairs' step
control is gyrogen.codegen.integrators.pair.

A pair's step is five parts, each straight-line code on one trajectory's
values: begin (the step's size and the codes that stop), trial (the stages
and the error), check (non-finite values, f at the new point), control
(accept or reject, the new h, by selection) and accept (x := xnew). The
scalar integrator loops over them; the lanes print the same parts over SIMD
lanes (gyrogen.codegen.ir.lanes), so a batch equals its single calls bit
for bit.
"""

from __future__ import annotations

from gyrogen.codegen.integrators import driver
from gyrogen.codegen.integrators.common import (
    NE,
    NX,
    STATS,
    code,
    comp,
    dx,
    finite_state,
    h,
    i,
    scaled,
    start_checks,
    x,
    xnew,
)
from gyrogen.codegen.ir.nodes import (
    At,
    Call,
    Comment,
    Decl,
    E,
    For,
    Func,
    If,
    Int,
    Num,
    Return,
    Row,
    S,
    Var,
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
from gyrogen.tableaus import Explicit, Terms

t, k, y, c = Var("t"), Var("k"), Var("y"), Var("c")


def linear(terms: list[tuple[float, E]], onto: E | None = None) -> E:
    """a_1 v_1 + a_2 v_2 ..., left to right: zeros left out, ones written as
    v. With onto: onto + a_1 v_1 + ..., each term added in turn."""
    out: E | None = onto
    for a, v in terms:
        if a == 0.0:
            continue
        if out is None:
            out = v if a == 1.0 else -v if a == -1.0 else Num(a) * v
        else:
            term = v if abs(a) == 1.0 else Num(abs(a)) * v
            out = out - term if a < 0 else out + term
    assert out is not None
    return out


def combo(terms: Terms, onto: E | None = None) -> E:
    """a_1 k[j_1][i] + a_2 k[j_2][i] ... (see linear)."""
    return linear([(a, k[j, i]) for j, a in terms], onto)


def at(node: float) -> E:
    return t + h if node == 1.0 else t + Num(node) * h


def stages(tab: Explicit) -> list[S]:
    """The stages s >= 1; k[0] = f(t, x) is given. The new solution is x +
    dx, dx less what the last step's add lost (comp); the last stage of an
    FSAL pair is that new solution."""
    out: list[S] = []
    for s in range(1, tab.stages):
        where = "t + h" if tab.nodes[s] == 1.0 else f"t + {tab.nodes[s]!r} h"
        if tab.fsal and s == tab.stages - 1:
            out += [
                Comment(f"stage {s + 1}: {where}, the new solution"),
                For(
                    "i",
                    NX,
                    (
                        assign(dx[i], h * combo(tab.stage(s)) - comp[i]),
                        assign(xnew[i], x[i] + dx[i]),
                    ),
                ),
                Call("rhs", (at(tab.nodes[s]), xnew, c, Row("k", Int(s)))),
            ]
        else:
            out += [
                Comment(f"stage {s + 1}: {where}"),
                For("i", NX, (assign(y[i], x[i] + h * combo(tab.stage(s))),)),
                Call("rhs", (at(tab.nodes[s]), y, c, Row("k", Int(s)))),
            ]
    if not tab.fsal:
        out += [
            Comment("the new solution"),
            For(
                "i",
                NX,
                (assign(dx[i], h * combo(tab.weights()) - comp[i]), assign(xnew[i], x[i] + dx[i])),
            ),
        ]
    return out


def fixed(m: Method, quaternion: bool) -> Func:
    """m.name_integrate: `steps` equal steps from t0 to t1."""
    tab = m.tableau
    assert isinstance(tab, Explicit)
    t0, t1, steps, n = Var("t0"), Var("t1"), Var("steps"), Var("n")
    bad = or_(
        not_(cmp(t1, ">=", t0)), not_(fn("finite", t0)), not_(fn("finite", t1)), cmp(steps, "<", 1)
    )
    body: list[S] = [
        Call("stats_start", (Var("stats"), t0)),
        If(bad, (Return(code("ERR_ARGUMENT")),)),
        *start_checks(quaternion),
    ]
    step: list[S] = [assign(t, t0 + fn("real", n) * h), Call("rhs", (t, x, c, Row("k", Int(0))))]
    step += stages(tab)
    step += [
        driver.count("rhs_calls", tab.stages),
        If(not_(finite_state(xnew, quaternion)), (Return(code("ERR_NONFINITE")),)),
    ]
    step += [
        *driver.attitude_stop(quaternion),
        Call("accept_step", (x, xnew, dx, comp)),
        driver.count("accepted", 1),
        assign(driver.stat("t"), sel(cmp(n + 1, "==", steps), t1, t + h)),
    ]
    body += [
        assign(h, (t1 - t0) / fn("real", steps)),
        assign(driver.stat("h"), h),
        For("n", steps, tuple(step), type="long"),
        Return(code("OK")),
    ]
    params = (
        real("t0"),
        real("t1"),
        Decl("steps", "long"),
        arr("x", "inout"),
        Decl("c", "double", ("NC",)),
        STATS,
    )
    locals_ = (
        Decl("k", "double", (tab.stages, "NX"), "inout"),
        arr("y", "inout"),
        arr("xnew", "inout"),
        arr("dx", "inout"),
        Decl("comp", "double", ("NX",), "inout", Num(0.0)),
        real("t", "inout"),
        real("h", "inout"),
    )
    return Func(f"{m.name}_integrate", params, tuple(body), "int", locals_, m.notes)


def rows(pairs: list[Method]) -> int:
    """Rows of k: the stages, and f(t + h, xnew) when it is not the last one."""
    return max(m.fnew + 1 for m in pairs)


def trial(m: Method) -> list[S]:
    tab = m.tableau
    assert isinstance(tab, Explicit)
    err = Var("err")
    out = stages(tab)
    if tab.e3:
        err5, err3, deno, e5, e3 = (Var(n) for n in ("err5", "err3", "deno", "e5", "e3"))
        return [
            *out,
            Comment("the error: DOP853's two estimates, combined"),
            assign(err5, 0.0),
            assign(err3, 0.0),
            For(
                "i",
                NE,
                (
                    assign(e5, scaled(combo(tab.error()), i)),
                    assign(e3, scaled(combo(tab.error3()), i)),
                    assign(err5, err5 + e5 * e5),
                    assign(err3, err3 + e3 * e3),
                ),
                ("e5", "e3"),
            ),
            assign(deno, err5 + Num(0.01) * err3),
            assign(err, sel(cmp(deno, ">", 0.0), fn("abs", h) * err5 / fn("sqrt", NE * deno), 0.0)),
        ]
    total, e = Var("total"), Var("e")
    return [
        *out,
        Comment("the error norm (see error_norm)"),
        assign(total, 0.0),
        For(
            "i",
            NE,
            (assign(e, scaled(h * combo(tab.error()), i)), assign(total, total + e * e)),
            ("e",),
        ),
        assign(err, fn("sqrt", total / NE)),
    ]


__all__ = ["At", "combo", "fixed", "linear", "rows", "stages", "trial"]
