"""The Euler parameters' checks, described once: |e| (the one expression
the projection and the checks read), when it is lost (zero or not finite
in doubles: e / |e| has no direction), the start refused or normalized
(unit_start), and a step's new attitude checked (attitude_ok). Used by
every method of a quaternion scene: a start whose |e| is lost is refused
with ODE_ERR_ARGUMENT, a step whose new |e| is lost is taken as a
non-finite one (retried with h shrunk, or ODE_ERR_NONFINITE), so the
projection after an accepted step never divides by 0 or Inf."""

from __future__ import annotations

from gyrogen import abi
from gyrogen.codegen.ir.nodes import (
    Bool,
    Const,
    Decl,
    E,
    For,
    Func,
    If,
    Int,
    Num,
    Return,
    Var,
    and_,
    assign,
    cmp,
    fn,
    not_,
)

x, v, norm = Var("x"), Var("v"), Var("norm")


def norm_of(e: Var) -> E:
    """|e| of the Euler parameters e[0..3], summed in this order everywhere."""
    squares = [e[j] * e[j] for j in range(4)]
    return fn("sqrt", ((squares[0] + squares[1]) + squares[2]) + squares[3])


def kept(n: E) -> E:
    """|e| = n gives the attitude a direction: at least abi.ATTITUDE_MIN_NORM
    (its square a normal double) and finite (not NaN)."""
    return and_(cmp(n, ">=", Num(abi.ATTITUDE_MIN_NORM)), cmp(n, "<=", Const("HUGE")))


def lost(n: E) -> E:
    return not_(kept(n))


def unit_start() -> Func:
    body = (
        assign(norm, norm_of(x)),
        If(lost(norm), (Return(Bool(False)),)),
        For("i", Int(4), (assign(x[Var("i")], x[Var("i")] / norm),)),
        Return(Bool(True)),
    )
    doc = (
        "A start's Euler parameters x[0..3] normalized, as each accepted step",
        "projects them; 0 (x untouched) when |e| is lost (0 or not finite).",
    )
    params = (Decl("x", "double", ("NX",), "inout"),)
    return Func("unit_start", params, body, "bool", (Decl("norm", "double", (), "inout"),), doc)


def attitude_ok() -> Func:
    doc = ("1 when the Euler parameters v[0..3] of a new state have a direction.",)
    body = (assign(norm, norm_of(v)), Return(kept(norm)))
    params, locals_ = (Decl("v", "double", ("NX",)),), (Decl("norm", "double", (), "inout"),)
    return Func("attitude_ok", params, body, "bool", locals_, doc)


def functions() -> list[Func]:
    return [unit_start(), attitude_ok()]
