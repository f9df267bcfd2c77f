"""A tabulated input T(t) (a motor's torque table), described once and
printed to C and Fortran: piecewise linear through its (t, T) points,
constant outside them. The rhs, its outputs and its Jacobian read it as
<prefix>_<name>(t).
"""

from __future__ import annotations

from typing import Protocol

from gyrogen.codegen.ir.nodes import Decl, For, Func, If, Int, Return, Var, cmp, real


class Table(Protocol):
    """A tabulated input (gyrogen.codegen.context.Table)."""

    @property
    def name(self) -> str: ...

    @property
    def points(self) -> list[tuple[float, float]]: ...

    @property
    def doc(self) -> str: ...


def lookup(prefix: str, tb: Table) -> Func:
    """<prefix>_<name>(t): the first point's T up to its t, then the segment's
    line up to the next point, the last point's T from its t on."""
    points = tb.points
    n = len(points)
    ts, tq = Var("ts"), Var("tq")
    t, i = Var("t"), Var("i")
    table = (
        Decl("ts", "double", (n,), values=tuple(float(p[0]) for p in points)),
        Decl("tq", "double", (n,), values=tuple(float(p[1]) for p in points)),
    )
    line = tq[i - 1] + (tq[i] - tq[i - 1]) * (t - ts[i - 1]) / (ts[i] - ts[i - 1])
    body = (
        If(cmp(t, "<=", ts[0]), (Return(tq[0]),)),
        For("i", Int(n), (If(cmp(t, "<", ts[i]), (Return(line),)),), start=Int(1)),
        Return(tq[n - 1]),
    )
    return Func(f"{prefix}_{tb.name}", (real("t"),), body, "double", table, (tb.doc,))
