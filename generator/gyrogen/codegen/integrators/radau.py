"""Radau IIA of order 5, described once: Hairer's radau5.f (RADCOR) with
its simplified Newton iterations on a real and a complex system, error
estimate (ESTRAD) and step-size strategy.

The stage increments z_k = x(t + c_k h) - x solve z = h (A (x) I) F(z).
With w = (T^-1 (x) I) z the Newton iterations split into a real system,
E1 = (gamma/h) I - J, and a complex one, E2 = ((alpha + i beta)/h) I - J,
the eigenvalues of A^-1 being gamma and alpha +- i beta. The step is x + z3.
"""

from __future__ import annotations

from gyrogen import methods as registry
from gyrogen.codegen.integrators import driver
from gyrogen.codegen.integrators.common import (
    NE,
    NX,
    STATS,
    code,
    comp,
    dx,
    h,
    i,
    x,
    xnew,
)
from gyrogen.codegen.integrators.explicit import at, linear
from gyrogen.codegen.ir.nodes import (
    Assign,
    Bool,
    Break,
    Call,
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
    S,
    Var,
    and_,
    arr,
    assign,
    cmp,
    fn,
    not_,
    sel,
)
from gyrogen.codegen.ir.nodes import real as scalar
from gyrogen.methods import Method, RadauControl
from gyrogen.tableaus import Radau

t, c, y = Var("t"), Var("c"), Var("y")
z1, z2, z3, w1, w2, w3 = (Var(n) for n in ("z1", "z2", "z3", "w1", "w2", "w3"))
e1, e2r, e2i, piv1, piv2, scal = (Var(n) for n in ("e1", "e2r", "e2i", "piv1", "piv2", "scal"))
EPS = Num(0.5) * Const("EPSILON")


def dot(row: tuple[float, ...], vs: list[E]) -> E:
    """sum_j row_j v_j (see explicit.linear)."""
    return linear(list(zip(row, vs, strict=True)))


def each(*body: S, local: tuple[str, ...] = ()) -> For:
    """A loop over the states, vectorized (For.vector)."""
    return For("i", NX, body, local, vector=True)


def matrix(name: str, intent: str = "in") -> Decl:
    return Decl(name, "double", ("NX2",), intent)  # type: ignore[arg-type]


def pivots(name: str, intent: str = "in") -> Decl:
    return Decl(name, "int", ("NX",), intent)  # type: ignore[arg-type]


# factor, newton and error are inline: radau5_integrate and radau5_grid call
# them, and gcc inlines a static function of two callers only when told (of
# one, always): out of line, radau5 took 8 % longer a step (make
# bench-methods). The complex LU they call (linear.py) stays out of line,
# with two callers; its restrict arrays make that cost nothing a step.


def factor(m: Method) -> Func:
    R = m.tableau
    assert isinstance(R, Radau)
    J = Var("J")
    body = (
        Call("lu_shift", (J, Num(R.gamma) / h, e1)),
        Call("lu_shift_complex", (J, Num(R.alpha) / h, Num(R.beta) / h, e2r, e2i)),
        If(fn("lu_decompose", e1, piv1), (Return(Bool(True)),)),
        Return(fn("lu_decompose_complex", e2r, e2i, piv2)),
    )  # fmt: skip
    params = (matrix("J"), scalar("h"), matrix("e1", "out"), pivots("piv1", "out"),
              matrix("e2r", "out"), matrix("e2i", "out"), pivots("piv2", "out"))  # fmt: skip
    doc = ("E1 and E2 for this h, factored; 1 when either is singular.",)
    return Func(f"{m.name}_factor", params, body, "bool", (), doc, inline=True)


def newton(m: Method) -> Func:
    R = m.tableau
    assert isinstance(R, Radau)
    g, a, b_ = Var("gamma_h"), Var("alpha_h"), Var("beta_h")
    a1, a2, a3, s1, s2, s3, total = (Var(n) for n in ("a1", "a2", "a3", "s1", "s2", "s3", "total"))
    body = (
        assign(g, Num(R.gamma) / h),
        assign(a, Num(R.alpha) / h),
        assign(b_, Num(R.beta) / h),
        each(assign(y[i], x[i] + z1[i])),
        Call("rhs", (at(R.nodes[0]), y, c, z1)),
        each(assign(y[i], x[i] + z2[i])),
        Call("rhs", (at(R.nodes[1]), y, c, z2)),
        each(assign(y[i], x[i] + z3[i])),
        Call("rhs", (t + h, y, c, z3)),
        each(
            assign(a1, z1[i]), assign(a2, z2[i]), assign(a3, z3[i]),
            assign(z1[i], dot(R.ti[0], [a1, a2, a3]) - g * w1[i]),
            assign(z2[i], dot(R.ti[1], [a1, a2, a3]) - a * w2[i] + b_ * w3[i]),
            assign(z3[i], dot(R.ti[2], [a1, a2, a3]) - a * w3[i] - b_ * w2[i]),
            local=("a1", "a2", "a3"),
        ),
        Call("lu_solve", (e1, piv1, z1)),
        Call("lu_solve_complex", (e2r, e2i, piv2, z2, z3)),
        assign(total, 0.0),
        each(
            assign(s1, z1[i] / scal[i]), assign(s2, z2[i] / scal[i]), assign(s3, z3[i] / scal[i]),
            assign(total, total + (s1 * s1 + s2 * s2 + s3 * s3)),
            local=("s1", "s2", "s3"),
        ),
        Return(fn("sqrt", total / (Int(3) * NX))),
    )  # fmt: skip
    params = (
        scalar("t"), scalar("h"), arr("x"), Decl("c", "double", ("NC",)), matrix("e1"),
        pivots("piv1"), matrix("e2r"), matrix("e2i"), pivots("piv2"), arr("scal"),
        arr("z1", "inout"), arr("z2", "inout"), arr("z3", "inout"), arr("w1"), arr("w2"),
        arr("w3"),
    )  # fmt: skip
    locals_ = (arr("y", "inout"), *(scalar(n, "inout") for n in ("gamma_h", "alpha_h", "beta_h",
                                                                  "total")))  # fmt: skip
    doc = (
        "One simplified Newton iteration from the stages z (w = T^-1 z in w1..w3):",
        "F at the three stages, then the corrections to w solved into z1..z3.",
        "Returns their RMS over scal (NaN or Inf when a stage is).",
    )
    return Func(f"{m.name}_newton", params, body, "double", locals_, doc, inline=True)


def error(m: Method) -> Func:
    R, ctl = m.tableau, m.control
    assert isinstance(R, Radau) and isinstance(ctl, RadauControl)
    g, err, total, norm, f0 = Var("g"), Var("err"), Var("total"), Var("norm"), Var("f0")

    def rms() -> list[S]:
        return [
            assign(total, 0.0),
            For(
                "i",
                NE,
                (assign(total, total + (err[i] / scal[i]) * (err[i] / scal[i])),),
                vector=True,
            ),
            assign(norm, fn("sqrt", total / NE)),
        ]

    body = (
        each(assign(g[i], dot(R.e, [z1[i], z2[i], z3[i]]) / h), assign(err[i], f0[i] + g[i])),
        Call("lu_solve", (e1, piv1, err)),
        *rms(),
        If(and_(cmp(norm, ">=", 1.0), Var("again")), (
            each(assign(y[i], x[i] + err[i])),
            Call("rhs", (t, y, c, err)),
            driver.count("rhs_calls", 1),
            each(assign(err[i], err[i] + g[i])),
            Call("lu_solve", (e1, piv1, err)),
            *rms(),
        )),
        Return(sel(cmp(norm, "<", ctl.err_min), ctl.err_min, norm)),
    )  # fmt: skip
    params = (
        scalar("t"), scalar("h"), arr("x"), Decl("c", "double", ("NC",)), arr("f0"),
        matrix("e1"), pivots("piv1"), arr("scal"), arr("z1"), arr("z2"), arr("z3"),
        Decl("again", "bool"), STATS,
    )  # fmt: skip
    locals_ = (*(arr(n, "inout") for n in ("g", "err", "y")), scalar("total", "inout"),
               scalar("norm", "inout"))  # fmt: skip
    doc = (
        "The local error estimate E1^-1 (f0 + (e1 z1 + e2 z2 + e3 z3)/h), its RMS",
        f"over scal, at least {ctl.err_min:g} (NaN or Inf when it is). On the first step",
        "or after a rejection an estimate >= 1 is taken again through f at x + err",
        "(radau5.f's ESTRAD): one more rhs call.",
    )
    return Func(f"{m.name}_error", params, body, "double", locals_, doc, inline=True)


__all__ = [
    "Assign",
    "Break",
    "Continue",
    "Loop",
    "Ref",
    "code",
    "comp",
    "dx",
    "error",
    "factor",
    "newton",
    "not_",
    "registry",
    "xnew",
]  # fmt: skip
