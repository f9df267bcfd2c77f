"""The setup checks (gyrogen.setup_checks) as IR statements of setup
(gyrogen.codegen.statements.setup): each check's locals, then a return of
its code when it fails. A failing check is one whose condition does not
hold, so that a NaN fails it."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from gyrogen.abi import TRIANGLE_SLACK
from gyrogen.codegen.ir import nodes as ir
from gyrogen.setup_checks import Call, Check, Expr, Num, Op, Sym, symbols

LOOP = "i_"
"""setup's loop index over p and c: a name no parameter takes (the inertia I is one)."""


def expression(e: Expr, cond: ir.E) -> ir.E:
    """e in the IR; the symbol cond (the condition number) as the constant cond."""
    if isinstance(e, Sym):
        return cond if e.name == "cond" else ir.Var(e.name)
    if isinstance(e, Num):
        return ir.Num(e.value)
    assert isinstance(e, (Op, Call)), e
    args = [expression(a, cond) for a in e.args]
    if isinstance(e, Op):
        out = args[0]
        for a in args[1:]:
            out = ir.Bin(e.op, out, a)
        return out
    assert isinstance(e, Call)
    if e.fn == "square":
        return ir.Bin("*", args[0], args[0])
    return ir.Fn(e.fn, tuple(args))


def failed(c: Check, cond: ir.E) -> ir.E:
    """True when c fails."""
    exprs = [expression(e, cond) for e in c.exprs]
    if c.kind == "positive":
        return ir.or_(*(ir.not_(ir.cmp(e, ">", 0.0)) for e in exprs))
    a, b = exprs
    if c.kind == "slack":
        return ir.cmp(a, ">", ir.Num(TRIANGLE_SLACK) * b)
    return ir.not_(ir.cmp(a, "<=", b))


def lowered(
    checks: Sequence[Check], nc: int, cond_index: int, code: Mapping[int, str]
) -> tuple[list[ir.S], list[ir.S]]:
    """Every check but 'finite' (setup's loop over p): those made before the
    constants, then those after (they read the condition number c[cond], or
    every constant). code: a setup code's name by its value."""
    cond = ir.At("c", (ir.Int(cond_index),))
    early: list[ir.S] = []
    late: list[ir.S] = []
    for c in checks:
        if c.kind == "finite":
            continue
        stop = (ir.Return(ir.Const(code[c.code])),)
        if c.kind == "constants":  # valid parameters whose products overflow
            bad = ir.not_(ir.fn("finite", ir.At("c", (ir.Var(LOOP),))))
            late.append(ir.For(LOOP, ir.Int(nc), (ir.If(bad, stop),)))
            continue
        out = late if any("cond" in symbols(e) for e in c.exprs) else early
        out += [ir.Comment(line, k == 0) for k, line in enumerate(c.comment)]
        out += [ir.assign(ir.Var(n), expression(e, cond)) for n, e in c.locals]
        out.append(ir.If(failed(c, cond), stop))
    return early, late
