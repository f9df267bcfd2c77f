"""log and exp for the Taylor method's step size, described once and
printed to C, lanes and Fortran: branch-free, so that a loop over lanes
vectorizes (libm's calls do not, and its vector versions would round
otherwise than the single trajectory's), the same bits in every target.

step_log(z): z = 2^e m, m in [1, 2), read from the double's bits (Fn
"exponent" and "significand": C reads the bits, Fortran calls exponent and
fraction; both exact), m > sqrt 2 halved; then fdlibm's __ieee754_log
kernel: log(1 + f) from s = f / (2 + f), within 1 ulp.
step_exp(y): y = k ln 2 + r, |r| <= ln 2 / 2, k rounded by 1.5 2^52;
fdlibm's __ieee754_exp kernel for e^r; then times 2^k (Fn "pow2", exact:
C writes the bits, Fortran calls scale), in two factors below 2^-1022.

Their special values are what the step needs, not all of libm's: a
positive infinite z gives +inf and a NaN gives NaN (the step's NaN paths
stay as they were); z = 0 gives -DBL_MAX, and a z below DBL_MIN is taken
as DBL_MIN; exp of y > 709 is DBL_MAX (a step
as long as it may be) and of y < -745 is 0 (a step too short: underflow).
"""

from __future__ import annotations

from gyrogen.codegen.integrators.common import real, reals
from gyrogen.codegen.integrators.trig import TOINT
from gyrogen.codegen.ir.nodes import (
    Const,
    E,
    Func,
    Num,
    Return,
    S,
    Var,
    and_,
    assign,
    cmp,
    fn,
    sel,
)

NAMES = ("step_log", "step_exp")
"""The functions, in the order a file defines them."""
LN2_HI, LN2_LO = 6.93147180369123816490e-01, 1.90821492927058770002e-10
SQRT2 = 1.4142135623730951
EXP_MIN = -1021.0
"""The least k with v 2^k normal for every v >= 1/sqrt 2 (e^r's least):
below it v 2^k is v 2^EXP_MIN 2^(k - EXP_MIN), rounded once, at the last."""


def log_function() -> Func:
    z, m, e, f, s, w, r, hf = (Var(n) for n in ("z", "m", "e", "f", "s", "w", "r", "hf"))
    lg = [Num(v) for v in (6.666666666666735130e-01, 3.999999999940941908e-01,
                           2.857142874366239149e-01, 2.222219843214978396e-01,
                           1.818357216161805012e-01, 1.531383769920937332e-01,
                           1.479819860511658591e-01)]  # fmt: skip
    z2 = Var("z2")
    finite = and_(cmp(z, ">", 0.0), cmp(z, "<=", Const("HUGE")))
    body: list[S] = [
        assign(m, sel(finite, fn("max", z, Const("TINY")), Num(1.0))),
        assign(e, fn("exponent", m)),
        assign(m, fn("significand", m)),
        assign(e, sel(cmp(m, ">", SQRT2), e + 1.0, e)),
        assign(m, sel(cmp(m, ">", SQRT2), m * Num(0.5), m)),
        assign(f, m - 1.0),
        assign(hf, Num(0.5) * f * f),
        assign(s, f / (Num(2.0) + f)),
        assign(z2, s * s),
        assign(w, z2 * z2),
        assign(r, z2 * (lg[0] + w * (lg[2] + w * (lg[4] + w * lg[6])))),
        assign(r, r + w * (lg[1] + w * (lg[3] + w * lg[5]))),
        assign(r, e * Num(LN2_HI) - ((hf - (s * (hf + r) + e * Num(LN2_LO))) - f)),
        Return(sel(finite, r, sel(cmp(z, "<=", 0.0), -Const("HUGE"), z))),  # inf, NaN: z
    ]  # fmt: skip
    doc = ("log z for the step size, branch-free (see gyrogen.codegen.integrators.elementary).",)
    locals_ = reals("m", "e", "f", "s", "w", "r", "hf", "z2")
    return Func("step_log", (real("z"),), tuple(body), "double", locals_, doc, inline=True)


def exp_function() -> Func:
    y, k, hi, lo, r, t, c, v = (Var(n) for n in ("y", "k", "hi", "lo", "r", "t", "c", "v"))
    p = [Num(v) for v in (1.66666666666666019037e-01, -2.77777777770155933842e-03,
                          6.61375632143793436117e-05, -1.65339022054652515390e-06,
                          4.13813679705723846039e-08)]  # fmt: skip
    yy = Var("yy")
    body: list[S] = [
        assign(yy, fn("min", fn("max", y, Num(-745.0)), Num(709.0))),
        assign(k, (yy * Num(1.44269504088896338700e00) + Num(TOINT)) - Num(TOINT)),
        assign(hi, yy - k * Num(LN2_HI)),
        assign(lo, k * Num(LN2_LO)),
        assign(r, hi - lo),
        assign(t, r * r),
        assign(c, r - t * (p[0] + t * (p[1] + t * (p[2] + t * (p[3] + t * p[4]))))),
        assign(v, Num(1.0) - ((lo - (r * c) / (Num(2.0) - c)) - hi)),
    ]
    k1 = Var("k1")
    body += [
        assign(k1, fn("max", k, Num(EXP_MIN))),
        assign(v, v * fn("pow2", k1) * fn("pow2", k - k1)),  # the second 1 unless subnormal
    ]
    tail: E = sel(cmp(y, "<", -745.0), Num(0.0), y)  # y NaN: every comparison false
    body.append(Return(sel(cmp(y, ">", 709.0), Const("HUGE"), sel(cmp(y, ">=", -745.0), v, tail))))
    doc = ("e^y for the step size, branch-free (see gyrogen.codegen.integrators.elementary).",)
    locals_ = reals("yy", "k", "k1", "hi", "lo", "r", "t", "c", "v")
    return Func("step_exp", (real("y"),), tuple(body), "double", locals_, doc, inline=True)


def functions() -> list[Func]:
    return [log_function(), exp_function()]
