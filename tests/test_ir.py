"""The statement IR's printers on small functions: a temporary (a local of
intent "tmp") is a scalar of the one loop over the lanes that sets it, and a
read of one outside that loop is refused while printing, not compiled into
a read of another lane's or another loop's value."""

from __future__ import annotations

import pytest

from gyrogen.codegen.context import make_context
from gyrogen.codegen.integrators.taylor_jet import kept
from gyrogen.codegen.ir.c import CPrinter
from gyrogen.codegen.ir.fortran import FortranPrinter
from gyrogen.codegen.ir.lanes import LanesPrinter
from gyrogen.codegen.ir.nodes import Comment, Decl, Func, Var, assign
from gyrogen.scene import default

STATE = {"x": Decl("x", "double", ("NX",), "inout")}


def _func(*body) -> Func:
    locals_ = (Decl("v", "double", (), "tmp"), Decl("w", "double", (), "inout"))
    return Func("f", (), tuple(body), None, locals_)


def test_a_temporary_is_scoped_to_its_lane_loop() -> None:
    x = Var("x")
    f = _func(assign(Var("v"), x[0] * 2.0), assign(x[1], Var("v") + 1.0), assign(Var("w"), x[1]))
    text = LanesPrinter("p", "P", {}, STATE).function(f)
    assert "double v;" in text and "double v[P_LANES]" not in text
    assert "L->x[1][l] = v + 1.0;" in text
    assert "double w[P_LANES];" in text and "w[l] = L->x[1][l];" in text
    c = CPrinter("p", "P", {}).function(f)
    assert "double v;" in c and "x[1] = v + 1.0;" in c
    assert "real(c_double) :: v" in FortranPrinter("p", "P", {}).function(f)


def test_a_temporary_read_in_another_run_is_refused() -> None:
    x = Var("x")
    f = _func(assign(Var("v"), x[0]), Comment("a new run"), assign(x[1], Var("v")))
    with pytest.raises(AssertionError, match="read before set"):
        LanesPrinter("p", "P", {}, STATE).function(f)


def test_the_jet_stores_what_later_orders_read() -> None:
    """The default scene's jet: states first, fewer rows than nodes."""
    jet = make_context(default()).jet
    rows = kept(jet)
    assert rows[: jet.nx] == list(range(jet.nx))
    assert len(rows) < len(jet.nodes) / 2
    for n in jet.convolutions():
        node = jet.nodes[n]
        operands = set(node.args) if node.op == "mul" else {node.args[-1]}
        assert {a for a in operands if not jet.nodes[a].const} <= set(rows)
