"""log2 and exp2 for the Taylor method's step size, described once and
printed to C, lanes and Fortran: branch-free, so that a loop over lanes
vectorizes (libm's calls do not, and its vector versions would round
otherwise than the single trajectory's), the same bits in every target.

The step is rho = 2^min(log2(xmax/dp) / p, log2(xmax/dq) / (p - 1)) times a
safety factor (Jorba and Zou; heyoka's factor e^(-0.7/(p-1)) / e^2), a
heuristic: what it needs is a few correct digits, not libm's last ulp.
So each is one short polynomial, no division:
step_log2(z): z = 2^e m, m in [1, 2), read from the double's bits (Fn
"exponent" and "significand": C reads the bits, Fortran calls exponent and
fraction; both exact), m > sqrt 2 halved; log2 m = f P(f), f = m - 1, P of
degree 6 (a Chebyshev fit, by Estrin's scheme): within 5.7e-7 of log2 z, exact at powers of 2.
step_exp2(y): y = k + r, |r| <= 1/2, k rounded by 1.5 2^52; 2^r by a
polynomial of degree 5, within 1.1e-7 relative; then times 2^k (Fn "pow2",
exact: C writes the bits, Fortran calls scale), in two factors below
2^-1022. The step size is then within 1.2e-6 relative of the exact
formula's (log2's error divided by p >= 2, times ln 2, and exp2's).

Their special values are what the step needs: a positive infinite z gives
+inf and a NaN gives NaN (the step's NaN paths stay as they were); z = 0
gives -DBL_MAX, and a z below DBL_MIN is taken as DBL_MIN; exp2 of y > 1023
is DBL_MAX (a step as long as it may be) and of y < -1075 is 0 (a step too
short: underflow).
"""

from __future__ import annotations

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
    real,
    reals,
    sel,
)

NAMES = ("step_log2", "step_exp2")
"""The functions, in the order a file defines them."""
SQRT2 = 1.4142135623730951
EXP_MIN = -1021.0
"""The least k with v 2^k normal for every v >= 1/sqrt 2 (2^r's least):
below it v 2^k is v 2^EXP_MIN 2^(k - EXP_MIN), rounded once, at the last."""
LOG2 = (1.442696432286588, -0.7213640408366104, 0.4806291383826822, -0.35935059807152286,
        0.29563370133125855, -0.2695068891921427, 0.17212913448722086)  # fmt: skip
"""log2(1 + f) / f on [1/sqrt 2 - 1, sqrt 2 - 1], lowest power first."""
EXP2 = (1.000000075499127, 0.6931472067117419, 0.24022107337696277, 0.05550327211816496,
        0.00967603806503104, 0.0013400433122461265)  # fmt: skip
"""2^r on [-1/2, 1/2], lowest power first."""


def estrin(coefficients: tuple[float, ...], v: E) -> E:
    """sum c_i v^i by Estrin's scheme: pairs c_2i + c_2i+1 v, then the same
    in v^2. Its chain of dependent operations is about log2 of the degree
    long, where Horner's is the degree: the step's log2 and exp2 lie on the
    step's critical path, and over lanes nothing else runs beside them."""
    terms: list[E] = [Num(c) for c in coefficients]
    while len(terms) > 1:
        pairs = [terms[i] + v * terms[i + 1] for i in range(0, len(terms) - 1, 2)]
        terms = pairs + terms[len(pairs) * 2 :]
        v = v * v
    return terms[0]


def log_function() -> Func:
    z, m, e, f = (Var(n) for n in ("z", "m", "e", "f"))
    finite = and_(cmp(z, ">", 0.0), cmp(z, "<=", Const("HUGE")))
    body: list[S] = [
        assign(m, sel(finite, fn("max", z, Const("TINY")), Num(1.0))),
        assign(e, fn("exponent", m)),
        assign(m, fn("significand", m)),
        assign(e, sel(cmp(m, ">", SQRT2), e + 1.0, e)),
        assign(m, sel(cmp(m, ">", SQRT2), m * Num(0.5), m)),
        assign(f, m - 1.0),
        Return(sel(finite, e + f * estrin(LOG2, f), sel(cmp(z, "<=", 0.0), -Const("HUGE"), z))),
    ]
    doc = ("log2 z for the step size, branch-free (see gyrogen.codegen.integrators.elementary).",)
    return Func(
        "step_log2", (real("z"),), tuple(body), "double", reals("m", "e", "f"), doc, inline=True
    )


def exp_function() -> Func:
    y, yy, k, k1, r, v = (Var(n) for n in ("y", "yy", "k", "k1", "r", "v"))
    body: list[S] = [
        assign(yy, fn("min", fn("max", y, Num(-1075.0)), Num(1023.0))),
        assign(k, (yy + Num(TOINT)) - Num(TOINT)),
        assign(r, yy - k),
        assign(k1, fn("max", k, Num(EXP_MIN))),
        assign(
            v, estrin(EXP2, r) * fn("pow2", k1) * fn("pow2", k - k1)
        ),  # the second 1 unless subnormal
    ]
    tail: E = sel(cmp(y, "<", -1075.0), Num(0.0), y)  # y NaN: every comparison false
    body.append(
        Return(sel(cmp(y, ">", 1023.0), Const("HUGE"), sel(cmp(y, ">=", -1075.0), v, tail)))
    )
    doc = ("2^y for the step size, branch-free (see gyrogen.codegen.integrators.elementary).",)
    locals_ = reals("yy", "k", "k1", "r", "v")
    return Func("step_exp2", (real("y"),), tuple(body), "double", locals_, doc, inline=True)


def functions() -> list[Func]:
    return [log_function(), exp_function()]
