"""sin and cos for the generated code, described once and printed to C and
Fortran: inline in C and within 1 ulp of the correctly rounded value
(measured: tests/test_lanes.py), the same bits in both languages.

x = n pi/2 + r, |r| <= pi/4 (a little more when x 2/pi is near a half
integer), r as r + tail to about 2^-118 |x|, and quad = n mod 4 (0..3, as a
double): the reduction of fdlibm's __rem_pio2 for "medium" |x| (pi/2 in
three pieces of 33 bits and their tails), all three rounds taken every time.
n pio2_1 is exact for |n| < 2^20, so r is accurate for |x| <= 2^20 pi/2 =
1.6e6; beyond, the result is sin or cos of a point within half an ulp of x;
beyond 2^50 (1.1e15) n is no longer exact and the functions return NaN, as
they do for an infinite or NaN x. The kernels are fdlibm's __kernel_sin and
__kernel_cos (musl's form), errors below 1 ulp.

Two variants give the same bits: <P>_sin and <P>_cos return at once for
|x| <= pi/4 and evaluate only the quadrant's kernel (branches, cheap in
scalar code: 3-6 % off dop853's single call on the default scene, against
both kernels and a select); <P>_sin_lanes and
<P>_cos_lanes (C only) are branch-free, so that a loop over lanes
vectorizes.
"""

from __future__ import annotations

from gyrogen.codegen.ir.nodes import (
    Const,
    E,
    Func,
    If,
    Num,
    Ref,
    Return,
    Var,
    and_,
    assign,
    cmp,
    fn,
    or_,
    real,
    reals,
    sel,
)
from gyrogen.codegen.ir.nodes import S as Stmt

TOINT = 6755399441055744.0
"""1.5 2^52: adding it to a double of magnitude below 2^51, then subtracting it,
rounds that double to an integer (to nearest)."""
TRIG_MAX = 1125899906842624.0
"""The largest |x| the reduction takes (2^50); past it, NaN."""
VARIANTS = ("sin", "cos", "sin_lanes", "cos_lanes")
"""The functions a file may call, in the order a file defines them."""


def reduce(prefix: str) -> Func:
    x, n, r, t, w, y = (Var(v) for v in ("x", "n", "r", "t", "w", "y"))
    toint = Num(TOINT)
    pio2 = [Num(v) for v in (1.57079632673412561417e00, 6.07710050630396597660e-11,
                             2.02226624879595063154e-21, 2.02226624871116645580e-21,
                             8.47842766036889956997e-32)]  # fmt: skip
    body = (
        assign(n, (x * Num(6.36619772367581382433e-01) + toint) - toint),
        assign(r, x - n * pio2[0]),
        assign(t, r),
        assign(w, n * pio2[1]),
        assign(r, t - w),
        assign(w, n * pio2[2] - ((t - r) - w)),
        assign(t, r),
        assign(w, n * pio2[3]),
        assign(r, t - w),
        assign(w, n * pio2[4] - ((t - r) - w)),
        assign(y, r - w),
        assign(Var("tail"), (r - y) - w),
        assign(Var("quad"), n - Num(4.0) * (((n - 1.5) * Num(0.25) + toint) - toint),
               "n - 4 floor(n/4): (n - 1.5)/4 is never within 1/8 of a half integer"),
        Return(y),
    )  # fmt: skip
    params = (real("x"), real("tail", "out"), real("quad", "out"))
    doc = ("x = n pi/2 + r + tail, |r| <= pi/4, quad = n mod 4: fdlibm's medium reduction.",)
    return Func(f"{prefix}_reduce", params, body, "double",
                reals("n", "r", "t", "w", "y"), doc, inline=True)  # fmt: skip


def ksin(prefix: str) -> Func:
    x, y, z, w, v, r = (Var(n) for n in ("x", "y", "z", "w", "v", "r"))
    S = [Num(s) for s in (-1.66666666666666324348e-01, 8.33333333332248946124e-03,
                          -1.98412698298579493134e-04, 2.75573137070700676789e-06,
                          -2.50507602534068634195e-08, 1.58969099521155010221e-10)]  # fmt: skip
    body = (
        assign(z, x * x),
        assign(w, z * z),
        assign(v, z * x),
        assign(r, S[1] + z * (S[2] + z * S[3]) + z * w * (S[4] + z * S[5])),
        Return(x - ((z * (Num(0.5) * y - v * r) - y) - v * S[0])),
    )
    doc = ("sin(x + y) for |x| <= pi/4, |y| < ulp(x): fdlibm's __kernel_sin.",)
    return Func(f"{prefix}_ksin", (real("x"), real("y")), body, "double",
                reals("z", "w", "v", "r"), doc, inline=True)  # fmt: skip


def kcos(prefix: str) -> Func:
    x, y, z, w, hz, u, r = (Var(n) for n in ("x", "y", "z", "w", "hz", "u", "r"))
    C = [Num(c) for c in (4.16666666666666019037e-02, -1.38888888888741095749e-03,
                          2.48015872894767294178e-05, -2.75573143513906633035e-07,
                          2.08757232129817482790e-09, -1.13596475577881948265e-11)]  # fmt: skip
    body = (
        assign(z, x * x),
        assign(w, z * z),
        assign(hz, Num(0.5) * z),
        assign(u, Num(1.0) - hz),
        assign(r, z * (C[0] + z * (C[1] + z * C[2])) + w * w * (C[3] + z * (C[4] + z * C[5]))),
        Return(u + (((Num(1.0) - u) - hz) + (z * r - x * y))),
    )
    doc = ("cos(x + y) for |x| <= pi/4, |y| < ulp(x): fdlibm's __kernel_cos.",)
    return Func(f"{prefix}_kcos", (real("x"), real("y")), body, "double",
                reals("z", "w", "hz", "u", "r"), doc, inline=True)  # fmt: skip


def between(q: E, low: float, high: float) -> E:
    return and_(cmp(q, ">", low), cmp(q, "<", high))


def function(prefix: str, variant: str) -> Func:
    """sin or cos (variant "sin", "cos", or their branch-free "_lanes")."""
    name = variant.split("_")[0]
    x, y, q, r, s, c, v, f = (Var(n) for n in ("x", "y", "q", "r", "s", "c", "v", "f"))
    odd = or_(between(q, 0.5, 1.5), cmp(q, ">", 2.5))  # quad 1 or 3
    negative = cmp(q, ">=", 2.0) if name == "sin" else between(q, 0.5, 2.5)
    early = [] if variant != name else [
        If(cmp(fn("abs", x), "<=", 0.78539816339744828), (
            Return(fn(f"{prefix}_k{name}", x, x - x), "the reduction's r and tail: x, +0"),))
    ]  # fmt: skip
    ks, kc = fn(f"{prefix}_ksin", r, y), fn(f"{prefix}_kcos", r, y)
    if variant == name:  # the quadrant's kernel alone (scalar: a branch)
        pick: tuple[Stmt, ...] = (
            If(odd, (assign(v, kc if name == "sin" else ks),),
               (assign(v, ks if name == "sin" else kc),)),
        )  # fmt: skip
    else:  # both kernels, then a select (lanes: no branch)
        pick = (assign(s, ks), assign(c, kc), assign(v, sel(odd, c, s) if name == "sin"
                                                      else sel(odd, s, c)))  # fmt: skip
    body = (
        *early,
        assign(r, fn(f"{prefix}_reduce", x, Ref("y"), Ref("q"))),
        *pick,
        assign(f, sel(negative, -v, v)),
        Return(sel(cmp(fn("abs", x), "<=", TRIG_MAX), f, Const("NAN"))),
    )
    doc = (
        f"{name}(x) within 1 ulp for |x| <= 1.6e6 (see {prefix}_reduce for beyond): "
        + ("the quadrant's kernel and sign." if variant == name else
           "both kernels, then the quadrant picks one and its sign. Branch-free."),
    )  # fmt: skip
    locals_ = reals("y", "q", "r", "v", "f", *(("s", "c") if variant != name else ()))
    return Func(f"{prefix}_{variant}", (real("x"),), body, "double", locals_, doc, inline=True)


def functions(prefix: str, used: list[str]) -> list[Func]:
    """The reduction, the kernels and the variants in used, in VARIANTS order."""
    if not used:
        return []
    return [reduce(prefix), ksin(prefix), kcos(prefix),
            *(function(prefix, v) for v in VARIANTS if v in used)]  # fmt: skip
