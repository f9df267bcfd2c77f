"""The pieces every integrator shares, described once: statistics, the
finiteness and attitude checks, the compensated accept, the arguments,
Hairer's first step and the adaptive start-up.

The attitude check of 3-1-2 angles: a step that ends at gimbal lock (|cos
q2| below abi.GIMBAL_LOCK_COS) or passes a point of it (its ends in two
intervals between the points pi/2 + k pi), as expressions the methods'
steps use and as the functions gimbal_interval, gimbal_lock_at and
gimbal_lock (the Euler parameters' is quaternion.py)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from gyrogen import abi
from gyrogen import methods as registry
from gyrogen.abi_groups import ANGLE_SCALE, StateKind
from gyrogen.codegen.integrators import quaternion as euler_parameters
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

NX = Const("NX")
NE = Const("NE")
"""The states the error norms measure, 0 .. NE-1: NX, or an augmented
system's x alone (the scene's sensitivities.error; program.program sets it)."""
i = Var("i")
x, xnew, dx, comp = Var("x"), Var("xnew"), Var("dx"), Var("comp")
t0, t1, h, h0, c = Var("t0"), Var("t1"), Var("h"), Var("h0"), Var("c")
rtol, atol, stats = Var("rtol"), Var("atol"), Var("stats")


STATS = Decl("stats", "stats", (), "inout")
TOLERANCES = (real("rtol"), real("atol"))


def code(name: str) -> Const:
    """The integrators' return code ODE_name (abi.ODE_CODES)."""
    assert any(c.name == f"ODE_{name}" for c in abi.ODE_CODES), name
    return Const(f"ODE_{name}")


def stats_start() -> Func:
    body: list[S] = [assign(Var("stats.t"), t0)]
    for f in abi.STATS_FIELDS[1:]:
        body.append(assign(Var(f"stats.{f.name}"), Num(0.0) if f.ctype == "double" else Int(0)))
    doc = ("Counters at zero, at the start time (also the time reached if nothing is).",)
    return Func("stats_start", (STATS, real("t0")), tuple(body), doc=doc)


def all_finite() -> Func:
    v, n, ok = Var("v"), Var("n"), Var("ok")
    body = (
        assign(ok, Bool(True)),
        For("i", n, (assign(ok, sel(fn("finite", v[i]), ok, Bool(False))),)),
        Return(ok),
    )
    params = (Decl("v", "double", ("n",)), Decl("n", "int"))
    doc = (
        "1 when no element of v is NaN or Inf. The whole of v by selection, no",
        "early exit: a loop the compiler vectorizes (an implicit method checks",
        "its NX x NX Jacobian at every step).",
    )
    return Func("all_finite", params, body, "bool", (Decl("ok", "bool"),), doc)


def finite_state(v: Var, quaternion: bool) -> E:
    """v has no NaN or Inf, and (quaternion) its attitude a direction."""
    ok = fn("all_finite", v, NX)
    return and_(ok, fn("attitude_ok", v)) if quaternion else ok


def attitude_checked(quaternion: bool) -> list[S]:
    """A step's check of xnew's |e| (quaternion scenes): norm := |e|, and a
    lost one counts as non-finite (accepted(known=True) reads norm)."""
    if not quaternion:
        return []
    norm, nonfinite = Var("norm"), Var("nonfinite")
    return [
        assign(norm, euler_parameters.norm_of(xnew)),
        assign(nonfinite, or_(nonfinite, euler_parameters.lost(norm)), "no direction"),
    ]


def accepted(quaternion: bool, known: bool = False) -> list[S]:
    """x := xnew with the compensated sum (and the attitude projected; known:
    norm is already xnew's |e|, attitude_checked)."""
    body: list[S] = [
        For("i", NX, (assign(comp[i], (xnew[i] - x[i]) - dx[i]), assign(x[i], xnew[i]))),
    ]
    if quaternion:
        norm = Var("norm")
        body += [
            Comment("the attitude, Euler parameters x[0..3], projected back onto |e| = 1"),
            *([] if known else [assign(norm, euler_parameters.norm_of(x))]),
            For(
                "i",
                Int(4),
                (
                    assign(x[i], x[i] / norm),
                    assign(comp[i], 0.0, "the projection moved e: its rounding is not the add's"),
                ),
            ),
        ]
    return body


def start_state() -> list[S]:
    """What every adaptive method's trajectory starts with after ode_start
    (code -1: going on; nothing lost to rounding yet)."""
    return [
        assign(Var("code"), Int(-1)),
        assign(Var("t"), t0),
        assign(Var("nonfinite"), Bool(False)),
        For("i", NX, (assign(comp[i], 0.0),)),
    ]


def accept_step(quaternion: bool) -> Func:
    body = accepted(quaternion)
    doc = (
        "x := xnew, the step's x + dx. Every method sums its steps with Kahan's",
        "compensation: comp keeps what this add lost and the next step takes it",
        "back from its dx, so the rounding of 1e7 adds does not pile up in the",
        "invariants (a build with -ffast-math may optimize it away).",
    )
    params = (arr("x", "inout"), arr("xnew"), arr("dx"), arr("comp", "inout"))
    locals_ = (real("norm", "inout"),) if quaternion else ()
    return Func("accept_step", params, tuple(body), None, locals_, doc)


def declare(name: str, bools: set[str], init: E | None = None) -> Decl:
    """A method's value from step to step: code an int, the names in bools
    flags, the rest doubles."""
    kind = "int" if name == "code" else "bool" if name in bools else "double"
    return Decl(name, kind, (), "inout", init)  # type: ignore[arg-type]


def bad_arguments() -> Func:
    ms = Var("max_steps")
    bad = or_(
        not_(cmp(t1, ">=", t0)),
        not_(fn("finite", t0)),
        not_(fn("finite", t1)),
        not_(cmp(rtol, ">", Var("rtol_min"))),
        not_(fn("finite", rtol)),
        not_(cmp(atol, ">", 0.0)),
        not_(fn("finite", atol)),
        not_(fn("finite", h0)),
        cmp(ms, "<", 1),
    )
    params = (real("t0"), real("t1"), *TOLERANCES, real("rtol_min"), real("h0"),
              Decl("max_steps", "long"))  # fmt: skip
    doc = (
        "The arguments every adaptive method refuses: t1 < t0, a tolerance it",
        "cannot meet (rtol <= rtol_min, the method's ODE_MIN_RTOL or",
        "ODE_TAYLOR_MIN_RTOL; atol <= 0), max_steps < 1, and NaN or Inf in t0,",
        "t1, rtol, atol or h0 (h0 <= 0: automatic).",
    )
    return Func("bad_arguments", params, (Return(bad),), "bool", doc=doc)


def step_underflow() -> Func:
    t = Var("t")
    small = or_(
        cmp(h, "<", Num(registry.STEP_UNDERFLOW) * Const("EPSILON") * fn("abs", t)),
        cmp(h, "<", Const("TINY")),
    )
    doc = ("h is lost in the rounding of t: the solution cannot be resolved further.",)
    return Func("step_underflow", (real("h"), real("t")), (Return(small),), "bool", doc=doc)


def larger(a: E, b: E) -> E:
    """max(a, b) for an a that is never NaN; a when b is NaN. One compare and
    a select (vmaxpd over lanes), where max ignores a NaN on either side: two
    compares in C's dmax, and gfortran's max takes NaN or not by -O level."""
    return sel(cmp(b, ">", a), b, a)


ANGLE = Var("is_angle")
"""Each state's 1.0 when it is an angle, else 0.0 (angle_table): the error
scales cap an angle's size at ANGLE_SCALE (size)."""


def angle_table(kinds: Sequence[StateKind]) -> Decl:
    """ANGLE's constant table for states of these kinds (abi_groups.state_kind);
    program.program declares it in every function that reads ANGLE."""
    flags = tuple(1.0 if k == "angle" else 0.0 for k in kinds)
    return Decl(ANGLE.name, "double", (len(flags),), values=flags)


def capped(size: E, flag: E | None = None) -> E:
    """size at most ANGLE_SCALE where flag is 1 (an angle), size itself where
    it is 0 (0 size is never above it; 0 Inf is NaN, not above it either): a
    NaN or an Inf magnitude is kept, one multiply, compare and select. No
    flag: an angle."""
    scale = Num(ANGLE_SCALE)
    return sel(cmp(size if flag is None else flag * size, ">", scale), scale, size)


def size(at: E, *of: Var) -> E:
    """State at's size in an error scale: the largest |v[at]| of the vectors
    of (NaN where the last is), an angle's at most ANGLE_SCALE (ANGLE)."""
    out: E = fn("abs", of[0][at])
    for v in of[1:]:
        out = larger(out, fn("abs", v[at]))
    return capped(out, ANGLE[at])


def scaled(e: E, at: E) -> E:
    """e / (atol + rtol max(|x_i|, |xnew_i|)), an angle's max at most
    ANGLE_SCALE; x is finite, xnew may not be."""
    return e / (atol + rtol * size(at, x, xnew))


def mean_square(err: Callable[[E], E]) -> tuple[list[S], E]:
    """The standard error norm of the estimates err(i): the statements that
    sum their squares in total, and the norm from it."""
    total, e = Var("total"), Var("e")
    return [
        assign(total, 0.0),
        For("i", NE, (assign(e, scaled(err(i), i)), assign(total, total + e * e)), ("e",)),
    ], fn("sqrt", total / NE)


def error_norm() -> Func:
    err = Var("err")
    sums, norm = mean_square(lambda at: err[at])
    body = (*sums, Return(norm))
    doc = (
        "The standard error norm: sqrt(mean((err_i / sk_i)^2)) with",
        "sk_i = atol + rtol max(|x_i|, |xnew_i|), an angle's max at most pi",
        "(is_angle); a step is accepted when <= 1.",
    )
    params = (arr("err"), arr("x"), arr("xnew"), *TOLERANCES)
    return Func("error_norm", params, body, "double", (real("total"),), doc)


def initial_step() -> Func:
    f0, f1, x1 = Var("f0"), Var("f1"), Var("x1")
    dnf, dny, der2, der12, h1, sk, d, xs = (
        Var(n) for n in ("dnf", "dny", "der2", "der12", "h1", "sk", "d", "xs")
    )
    order = Var("order")
    body = (
        assign(dnf, 0.0),
        assign(dny, 0.0),
        For(
            "i",
            NX,
            (
                assign(xs, size(i, x)),
                assign(sk, atol + rtol * xs),
                assign(dnf, dnf + (f0[i] / sk) * (f0[i] / sk)),
                assign(dny, dny + (xs / sk) * (xs / sk)),
            ),
            ("xs", "sk"),
        ),
        assign(
            h,
            sel(
                or_(cmp(dnf, "<=", 1e-10), cmp(dny, "<=", 1e-10)),
                1e-6,
                Num(0.01) * fn("sqrt", dny / dnf),
            ),
        ),
        assign(h, fn("min", h, t1 - t0)),
        For("i", NX, (assign(x1[i], x[i] + h * f0[i]),)),
        Call("rhs", (t0 + h, x1, c, f1)),
        inc(Var("stats.rhs_calls"), 1),
        assign(der2, 0.0),
        For(
            "i",
            NX,
            (
                assign(d, (f1[i] - f0[i]) / (atol + rtol * size(i, x))),
                assign(der2, der2 + d * d),
            ),
            ("d",),
        ),
        assign(der2, fn("sqrt", der2) / h),
        If(
            not_(fn("finite", der2)),
            (assign(der2, 0.0, "the Euler step left the domain of f: trust |f| alone"),),
        ),
        assign(der12, fn("max", der2, fn("sqrt", dnf))),
        assign(
            h1,
            sel(
                cmp(der12, "<=", 1e-15),
                fn("max", 1e-6, h * 1e-3),
                fn("pow", Num(0.01) / der12, Num(1.0) / order),
            ),
        ),
        Return(fn("min", fn("min", Num(100.0) * h, h1), t1 - t0)),
    )
    params = (
        Decl("order", "int"),
        real("t0"),
        real("t1"),
        arr("x"),
        arr("f0"),
        Decl("c", "double", ("NC",)),
        *TOLERANCES,
        STATS,
    )
    locals_ = (
        arr("x1", "inout"),
        arr("f1", "inout"),
        *(real(n, "inout") for n in ("dnf", "dny", "der2", "der12", "h", "h1")),
    )
    doc = (
        "Hairer's HINIT (dopri5.f): the first step h such that",
        "h^order max(|f|, |f'|) = 0.01 in the scaled norm, f' by an Euler step;",
        "|x| and the scale read an angle's size at most pi (is_angle).",
    )
    return Func("initial_step", params, body, "double", locals_, doc)


GIMBAL_NEAR = 1e-6
"""gimbal_at computes cos q2 only where q2 lies within GIMBAL_NEAR pi of a
point of gimbal lock, or beyond GIMBAL_FAR: elsewhere |cos q2| is at least
sin(pi GIMBAL_NEAR), far above the bar, and the cosine is not needed."""
GIMBAL_FAR = 1e6
assert math.sin(math.pi * GIMBAL_NEAR) > 1e3 * abi.GIMBAL_LOCK_COS


def gimbal_at(after: Var) -> E:
    """The step ends at gimbal lock: |cos q2| below the bar.

    With m = q2/pi + 1/2 and f = m - floor(m), |cos q2| = |sin(pi f)|: it
    is at least sin(pi GIMBAL_NEAR) unless f lies within GIMBAL_NEAR of 0 or
    1. For |q2| < GIMBAL_FAR, f is within 1e-9 of its exact value (q2/pi's
    rounding), so the cosine is computed only near those points (C's ?:
    skips it; the answer is the same either way). NaN and Inf fall to the
    cosine, which refuses them as before."""
    q2 = after[1]
    m = q2 * Num(abi.GIMBAL_INTERVALS) + 0.5
    f = m - fn("gimbal_interval", q2)
    near = or_(
        cmp(f, "<", Num(GIMBAL_NEAR)),
        cmp(f, ">", Num(1.0 - GIMBAL_NEAR)),
        not_(cmp(fn("abs", q2), "<", Num(GIMBAL_FAR))),
    )
    lock = cmp(fn("abs", fn("cos", q2)), "<", Const("ODE_GIMBAL_LOCK_COS"))
    return sel(near, lock, Bool(False))  # Fortran's merge evaluates both: gfortran needs that


def gimbal_jump(before: Var, after: Var) -> E:
    """The step passed a point of gimbal lock (its ends in two intervals)."""
    jump = fn("abs", fn("gimbal_interval", before[1]) - fn("gimbal_interval", after[1]))
    return cmp(jump, ">=", 1.0)


def locked(before: Var, after: Var) -> E:
    """The step from before to after ends at gimbal lock or passes a point of it."""
    return or_(gimbal_at(after), gimbal_jump(before, after))


def gimbal_functions() -> list[Func]:
    """gimbal_interval, gimbal_lock_at and gimbal_lock: the 3-1-2 attitude's
    checks as functions."""
    q2 = Var("q2")
    interval = Func(
        "gimbal_interval",
        (real("q2"),),
        (Return(fn("floor", q2 * Num(abi.GIMBAL_INTERVALS) + 0.5)),),
        "double",
        doc=(
            "The attitude is 3-1-2 angles, q2 = x[1]: their kinematics divide by",
            "cos(q2), which is zero at q2 = pi/2 + k pi for every integer k. Between",
            "two such points lies one interval ((j - 1/2) pi, (j + 1/2) pi), numbered",
            "j = floor(q2/pi + 1/2): the two ends of a step lie in the same interval",
            "unless the step passed a point of gimbal lock, however long the step",
            "(whole turns included). Where the rounding of q2/pi could misplace q2 by",
            "an interval, |cos q2| is below the lock's bar, for |q2| up to 1e6.",
        ),
    )
    at = Func(
        "gimbal_lock_at",
        (arr("x"),),
        (Return(gimbal_at(x)),),
        "bool",
        doc=("1 when x is at gimbal lock, |cos q2| below ODE_GIMBAL_LOCK_COS.",),
    )
    lock = Func(
        "gimbal_lock",
        (arr("x"), arr("xnew")),
        (Return(locked(x, xnew)),),
        "bool",
        doc=(
            "1 when the step from x to xnew ends at gimbal lock or passes a point of",
            "it (the path crossed q2 = pi/2 + k pi, where q1 and q3 jump).",
        ),
    )
    return [interval, at, lock]


def start_checks(quaternion: bool) -> list[S]:
    """Every method's checks of its start state, after its arguments': x
    finite, then its attitude (3-1-2: not at gimbal lock; Euler parameters:
    normalized, or refused when |e| is lost). x as given on a code."""
    body: list[S] = [If(not_(fn("all_finite", x, NX)), (Return(code("ERR_NONFINITE")),))]
    if quaternion:
        return [*body, If(not_(fn("unit_start", x)), (Return(code("ERR_ARGUMENT")),))]
    return [
        *body,
        If(
            fn("gimbal_lock_at", x),
            (Return(code("ERR_ATTITUDE_SINGULAR"), "at the start: x as given"),),
        ),
    ]


def ode_start(quaternion: bool) -> Func:
    f0 = Var("f0")
    args = (t0, t1, rtol, atol, Var("rtol_min"), h0, Var("max_steps"))
    body: list[S] = [
        assign(h, 0.0),
        Call("stats_start", (stats, t0)),
        If(fn("bad_arguments", *args), (Return(code("ERR_ARGUMENT")),)),
    ]
    body += start_checks(quaternion)
    first = fn("initial_step", Var("order"), t0, t1, x, f0, c, rtol, atol, stats)
    body += [
        If(not_(cmp(t1, ">", t0)), (Return(code("OK")),)),
        Call("rhs", (t0, x, c, f0)),
        assign(Var("stats.rhs_calls"), Int(1)),
        If(not_(fn("all_finite", f0, NX)), (Return(code("ERR_NONFINITE")),)),
        If(
            cmp(h0, ">", 0.0),
            (assign(h, fn("min", h0, t1 - t0)),),
            (If(cmp(Var("order"), ">", 0), (assign(h, first),)),),
        ),
        Return(Int(-1)),
    ]
    params = (
        Decl("order", "int"),
        real("rtol_min"),
        real("t0"),
        real("t1"),
        arr("x", "inout" if quaternion else "in"),
        Decl("c", "double", ("NC",)),
        *TOLERANCES,
        real("h0"),
        Decl("max_steps", "long"),
        arr("f0", "out"),
        real("h", "out"),
        STATS,
    )
    doc = (
        "An adaptive method's start (every pair, rodas4, radau5, taylor): the",
        "arguments, x, the attitude (Euler parameters: normalized) and f0 = f(t0, x)",
        "checked, and the first step h. -1 to go on from there, else the code to",
        "return (x as given, or normalized). order: the method's,",
        "for the initial step estimate; 0 (Taylor): no estimate, h = h0 or 0.",
        "rtol_min: the method's bound on rtol (Method.min_rtol).",
    )
    return Func("ode_start", params, tuple(body), "int", doc=doc)


def shared(quaternion: bool, adaptive: bool, norm: bool) -> list[Func]:
    """The shared functions a file defines, in order: those of the adaptive
    methods when it has one, error_norm when a method uses it."""
    out = [stats_start(), all_finite(), accept_step(quaternion)]
    out += euler_parameters.functions() if quaternion else gimbal_functions()
    if adaptive:
        out += [bad_arguments(), step_underflow()] + [error_norm()] * norm
        out += [initial_step(), ode_start(quaternion)]
    return out


__all__ = ["Ref", "shared"]
