"""An explicit embedded pair's step: Hairer's step-size control, described
once, as the scalar integrator and as one step of every SIMD lane.

The step is five parts, each straight-line code on one trajectory's values:
begin (the step's size and the codes that stop), trial (the stages and the
error, gyrogen.codegen.integrators.explicit), check (non-finite values, f at
the new point), control (accept or reject, the new h, by selection) and
accept (x := xnew). The scalar integrator loops over them; the lanes print
the same parts over lanes (gyrogen.codegen.ir.lanes), so a batch equals its
single calls bit for bit.
"""

from __future__ import annotations

from gyrogen import methods as registry
from gyrogen.codegen.integrators import common
from gyrogen.codegen.integrators.common import (
    NX,
    STATS,
    TOLERANCES,
    accepted,
    attitude_checked,
    code,
    h,
    i,
    locked,
    x,
    xnew,
)
from gyrogen.codegen.integrators.explicit import trial
from gyrogen.codegen.ir.nodes import (
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
from gyrogen.tableaus import Explicit

t, k, y, c = Var("t"), Var("k"), Var("y"), Var("c")


def parts(m: Method, quaternion: bool) -> tuple[list[S], list[S]]:
    """One step of pair m on one trajectory, as the five parts: begin, and
    the other four."""
    ctl = m.control
    assert isinstance(ctl, registry.PairControl)
    tab = m.tableau
    assert isinstance(tab, Explicit)
    cd, err, err_old, last = Var("code"), Var("err"), Var("err_old"), Var("last")
    nonfinite, rejected_last, ok, run = (
        Var("nonfinite"),
        Var("rejected_last"),
        Var("ok"),
        Var("run"),
    )
    take, lock, fac, grow, t1 = Var("take"), Var("lock"), Var("fac"), Var("grow"), Var("t1")
    spent = cmp(Var("stats.accepted") + Var("stats.rejected"), ">=", Var("max_steps"))
    stop = sel(
        fn("step_underflow", h, t),
        sel(nonfinite, code("ERR_NONFINITE"), code("ERR_STEP_UNDERFLOW")),
        sel(spent, code("ERR_MAX_STEPS"), Int(-1)),
    )
    begin: list[S] = [
        Comment("begin: a step size lost in t, or no steps left, stops; a last step ends on t1"),
        assign(cd, sel(cmp(cd, "<", 0), stop, cd)),
        assign(last, cmp(t + Num(registry.LAST_STEP_SLACK) * h, ">=", t1)),
        assign(h, sel(and_(cmp(cd, "<", 0), last), t1 - t, h)),
        assign(Var("stats.h"), sel(cmp(cd, "<", 0), h, Var("stats.h"))),
    ]
    check: list[S] = [
        Comment("check: a NaN or Inf rejects the step; f(t + h, xnew) where it is taken"),
        inc(Var("stats.rhs_calls"), sel(cmp(cd, "<", 0), Int(m.trial_calls), Int(0))),
        assign(nonfinite, not_(fn("finite", err))),
        For("i", NX, (assign(nonfinite, or_(nonfinite, not_(fn("finite", xnew[i])))),)),
        *attitude_checked(quaternion),
    ]
    if not tab.fsal:
        fnew = k[m.fnew, i]
        check += [
            assign(ok, and_(cmp(cd, "<", 0), not_(nonfinite), cmp(err, "<=", 1.0), not_(last))),
            If(
                ok,
                (
                    Call(
                        "rhs", (t + h, xnew, c, Row("k", Int(m.fnew))), "where the next step starts"
                    ),
                ),
            ),
            For("i", NX, (assign(nonfinite, or_(nonfinite, and_(ok, not_(fn("finite", fnew))))),)),
            inc(Var("stats.rhs_calls"), sel(ok, Int(1), Int(0))),
        ]
    roots = next((j for j in range(1, 7) if ctl.alpha == 0.5**j), 0)
    power: E = err
    for _ in range(roots):
        power = fn("sqrt", power)
    if not roots:
        power = fn("pow", err, ctl.alpha)
    grown = fac if ctl.beta == 0.0 else fac / fn("pow", err_old, ctl.beta)
    reject = and_(run, not_(take))
    control: list[S] = [
        Comment("control: accept or reject by selection, and the next h"),
        assign(run, cmp(cd, "<", 0)),
        assign(take, and_(run, not_(nonfinite), cmp(err, "<=", 1.0))),
        assign(lock, Bool(False) if quaternion else locked(x, xnew)),
        assign(ok, and_(take, not_(lock))),
        assign(fac, power / Num(ctl.safety), "h / h_new, in Hairer's form"),
        assign(grow, fn("max", Num(1.0 / ctl.facmax), fn("min", Num(1.0 / ctl.facmin), grown))),
        assign(grow, sel(rejected_last, fn("max", grow, 1.0), grow), "no growth after a rejection"),
        assign(
            cd,
            sel(
                and_(take, lock), code("ERR_ATTITUDE_SINGULAR"), sel(and_(ok, last), code("OK"), cd)
            ),
        ),
        assign(t, sel(ok, sel(last, t1, t + h), t)),
        assign(Var("stats.t"), t),
        inc(Var("stats.accepted"), sel(ok, Int(1), Int(0))),
        inc(Var("stats.rejected"), sel(reject, Int(1), Int(0))),
        assign(err_old, sel(ok, fn("max", err, registry.PAIR_ERR_FLOOR), err_old)),
        assign(rejected_last, sel(ok, Bool(False), sel(reject, Bool(True), rejected_last))),
        assign(
            h,
            sel(
                or_(not_(run), and_(take, lock)),
                h,
                sel(
                    nonfinite,
                    h * Num(ctl.facmin),
                    sel(ok, h / grow, h / fn("min", Num(1.0 / ctl.facmin), fac)),
                ),
            ),
        ),
    ]
    first: list[S] = [For("i", NX, (assign(k[0, i], k[m.fnew, i]),))]
    accept: list[S] = [
        Comment("accept: x := xnew; f(t + h, xnew) is the next step's first stage"),
        If(ok, (*accepted(quaternion, known=True), *first)),
    ]
    return begin, [Comment("trial"), *trial(m), *check, *control, *accept]


STATE = ("code", "t", "h", "err_old", "nonfinite", "rejected_last")
"""A pair's values that live from step to step (besides x and stats)."""
LOCALS = (
    "last",
    "err",
    "run",
    "take",
    "lock",
    "ok",
    "fac",
    "grow",
    "total",
    "err5",
    "err3",
    "deno",
    "norm",
)
BOOLS = {"nonfinite", "rejected_last", "last", "run", "take", "lock", "ok"}


def declare(name: str) -> Decl:
    return common.declare(name, BOOLS)


def state_arrays(krows: int) -> tuple[Decl, ...]:
    """The arrays of a trajectory: x, its stages, the new point, Kahan's comp."""
    rows = (Decl("k", "double", (krows, "NX"), "inout"),) if krows else ()
    return (
        arr("x", "inout"),
        *rows,
        arr("y", "inout"),
        arr("xnew", "inout"),
        arr("dx", "inout"),
        arr("comp", "inout"),
    )


def used_locals(body: list[S]) -> tuple[Decl, ...]:
    text = repr(body)
    return tuple(declare(n) for n in LOCALS if f"Var(name='{n}')" in text)


def start_state() -> list[S]:
    """A trajectory's values at t0, after ode_start (code -1: going on)."""
    return [
        *common.start_state(),
        assign(Var("err_old"), registry.PAIR_ERR_FLOOR),
        assign(Var("rejected_last"), Bool(False)),
    ]


def integrate(m: Method, quaternion: bool, krows: int) -> Func:
    """m.name_integrate: pair m from t0 to t1 on one trajectory."""
    begin, rest = parts(m, quaternion)
    t0, cd = Var("t0"), Var("code")
    args = (
        Int(m.start_order),
        Const(m.min_rtol),
        t0,
        Var("t1"),
        x,
        c,
        Var("rtol"),
        Var("atol"),
        Var("h0"),
        Var("max_steps"),
        Row("k", Int(0)),
        Ref("h"),
        Var("stats"),
    )
    stop = If(cmp(cd, ">=", 0), (Return(cd),))
    body: list[S] = [
        assign(cd, fn("ode_start", *args)),
        stop,
        *start_state(),
        Loop((*begin, stop, *rest, stop)),
    ]
    params = (
        real("t0"),
        real("t1"),
        arr("x", "inout"),
        Decl("c", "double", ("NC",)),
        *TOLERANCES,
        real("h0"),
        Decl("max_steps", "long"),
        STATS,
    )
    locals_ = (*state_arrays(krows)[1:], *(declare(n) for n in STATE), *used_locals(begin + rest))
    doc = (
        f"{m.name} to t1, with Hairer's step-size strategy: the last step clipped",
        "to end on t1, no growth right after a rejection, and a non-finite trial",
        "rejected with h shrunk by facmin.",
        *((m.control.note,) if isinstance(m.control, registry.PairControl) else ()),
    )
    return Func(f"{m.name}_integrate", params, tuple(body), "int", locals_, doc)


def lanes_step(m: Method, quaternion: bool) -> Func:
    """m.name_step_lanes: one step of every lane of a struct lanes."""
    begin, rest = parts(m, quaternion)
    step = begin + rest
    params = (Decl("c", "double", ("NC",)), *TOLERANCES, real("t1"), Decl("max_steps", "long"))
    doc = (f"One step of {m.name}_integrate on every lane.",)
    return Func(f"{m.name}_step_lanes", params, tuple(step), None, used_locals(step), doc)


def lane_state(krows: int) -> dict[str, Decl]:
    """What struct lanes holds per lane: a trajectory's arrays and values."""
    values = [declare(n) for n in STATE]
    stats = [
        Decl(f"stats.{n}", "double" if n in ("t", "h") else "long", (), "inout")
        for n in ("t", "h", "accepted", "rejected", "rhs_calls")
    ]
    return {d.name: d for d in (*state_arrays(krows), *values, *stats)}


__all__ = ["integrate", "lane_state", "lanes_step"]
