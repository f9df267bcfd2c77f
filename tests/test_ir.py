"""The statement IR's printers on small functions: a temporary (a local of
intent "tmp") is a scalar of the one loop over the lanes that sets it, and a
read of one outside that loop is refused while printing, not compiled into
a read of another lane's or another loop's value; an inner loop (For.inner)
sits inside the loop over the lanes, as a do-while."""

from __future__ import annotations

import itertools
import operator
from pathlib import Path

import compiled_expressions
import pytest

from gyrogen.codegen.context import make_context
from gyrogen.codegen.integrators.taylor_jet import kept
from gyrogen.codegen.ir.c import CPrinter
from gyrogen.codegen.ir.fortran import FortranPrinter
from gyrogen.codegen.ir.lanes import LanesPrinter
from gyrogen.codegen.ir.nodes import (
    Bin,
    Break,
    Call,
    Comment,
    Decl,
    E,
    Fn,
    For,
    Func,
    If,
    Int,
    Loop,
    Num,
    Row,
    Un,
    Var,
    assign,
)
from gyrogen.scene import default

STATE = {"x": Decl("x", "double", ("NX",), "inout")}
SCRATCH = {**STATE, "y": Decl("y", "double", ("NX",), "inout"),
           "k": Decl("k", "double", (2, "NX"), "inout")}  # fmt: skip


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


def test_an_inner_loop_runs_inside_the_loop_over_lanes() -> None:
    """A sum over j: over lanes, one loop over the lanes holding a do-while
    over j, its sum a scalar of that loop (a register, once gcc vectorizes
    the outer loop); scalar C and Fortran print the same loop as any."""
    x, v, j = Var("x"), Var("v"), Var("j")
    total = For("j", Var("n"), (assign(v, v + x[j]),), start=Int(1), inner=True)
    locals_ = (Decl("v", "double", (), "tmp"), Decl("n", "int", (), "in"))
    f = Func("f", (), (assign(v, x[0]), total, assign(x[0], v)), None, locals_)
    text = LanesPrinter("p", "P", {}, STATE).function(f)
    lane_loop = text.index("for (l = 0; l < P_LANES; ++l) {")
    do = text.index("do {")
    assert lane_loop < text.index("double v;") < text.index("j = 1;") < do
    assert "v = v + L->x[j][l];" in text and "} while (j < n);" in text
    assert text.count("for (l = 0;") == 1 and "double v[P_LANES]" not in text
    assert "for (j = 1; j < n; ++j) {" in CPrinter("p", "P", {}).function(f)
    assert "do j = 1, n - 1" in FortranPrinter("p", "P", {}).function(f)


def test_the_jet_over_lanes_is_one_loop_over_the_lanes_per_order() -> None:
    """The default scene's generated taylor_jet_lanes: the convolutions'
    sums are scalars of the order's loop over the lanes, the loop over j a
    do-while inside it; struct lanes is aligned, its int rows after the
    8-byte ones (what every lane shares, the output grid's, may follow)."""
    from pathlib import Path

    text = (Path(__file__).parents[1] / "generated" / "gyrostat" / "gyrostat_ode.c").read_text()
    jet = text[text.index("static void taylor_jet_lanes") :]
    jet = jet[: jet.index("\n}\n")]
    assert "double acc" in jet and "acc14[GYROSTAT_LANES]" not in jet
    order = jet[jet.index("for (n = 2; n < order; ++n) {") :]
    assert order.index("GYROSTAT_SIMD") < order.index("do {") < order.index("} while (j < n);")
    struct = text[text.index("struct GYROSTAT_ALIGNED lanes {") :]
    fields = struct[: struct.index("};")].splitlines()[1:]
    kinds = [f.split()[0] for f in fields if "LANES]" in f]  # the rows (not the shared grid's)
    assert "int" in kinds and kinds.index("int") > max(
        i for i, k in enumerate(kinds) if k in ("double", "long", "size_t")
    )


def test_a_vector_loop_is_kept_a_loop_for_gcc_to_vectorize() -> None:
    """For.vector prints gcc's and clang's directive against unrolling the
    loop whole, right above it, in C and in Fortran; any other loop none."""
    x, i = Var("x"), Var("i")
    kept = For("i", Int(8), (assign(x[i], x[i] * 2.0),), vector=True)
    plain = For("i", Int(8), (assign(x[i], x[i] + 1.0),))
    f = Func("f", (), (kept, plain), None, ())
    c = CPrinter("p", "P", {}).function(f).splitlines()
    at = c.index("    #pragma GCC unroll 1")
    assert c[at + 1].strip() == "for (i = 0; i < 8; ++i) {"
    assert sum("#pragma" in line for line in c) == 1
    fortran = FortranPrinter("p", "P", {}).function(f).splitlines()
    at = next(n for n, line in enumerate(fortran) if line.strip() == "!GCC$ unroll 1")
    assert fortran[at + 1].strip() == "do i = 0, 8 - 1"
    assert sum("!GCC$" in line for line in fortran) == 1


def _signed() -> list[tuple[E, float]]:
    """Numbers of both signs (x = 3 beside them) on each side of every
    operator, inside a difference, under a power and a negation; each with
    its value."""
    x, leaves = Var("x"), [(Num(4.0), 4.0), (Num(-4.0), -4.0), (Num(-0.5), -0.5)]
    ops = {"+": operator.add, "-": operator.sub, "*": operator.mul, "/": operator.truediv}
    out = []
    for (a, va), (b, vb) in itertools.product([*leaves, (x, 3.0)], repeat=2):
        for op, f in ops.items():
            out += [(Bin(op, a, b), f(va, vb)), (Bin("-", x, Bin(op, a, b)), 3.0 - f(va, vb))]
        out += [(Fn("pow", (a, Int(2))), va**2), (Un("-", a), -va)]
    return out


@pytest.mark.parametrize("language", ["c", "fortran"])
def test_the_printers_write_numbers_of_every_sign(language: str, tmp_path: Path) -> None:
    """The integrators' and the Taylor jet's printers give a negative number
    the precedence of the language's unary minus (Fortran refuses x - -4.0
    and reads -4.0**2 as -(4.0**2)): every place, every sign compiles
    strictly and computes what the expression means."""
    printer = (CPrinter if language == "c" else FortranPrinter)("p", "P", {})
    signed = _signed()
    got = compiled_expressions.values(language, [printer.expr(e) for e, _ in signed], tmp_path)
    assert got == [v for _, v in signed]


def test_a_run_of_parentheses_is_wrapped_after_one() -> None:
    """A long sum's grouping (Fortran keeps C's order with parentheses) left
    no comma or space within WRAP columns: the line stayed 2016 columns long,
    past Fortran's 132."""
    from gyrogen.codegen.ir.printer import WRAP, wrap

    text = "out(0) = " + "(" * 150 + " + ".join(f"a{i})" for i in range(150)) + ";"
    lines = wrap(text, "    ", continuation=" &")
    assert all(len(line) <= WRAP for line in lines), max(map(len, lines))
    joined = "".join(line.removesuffix(" &") for line in lines)
    assert joined.replace(" ", "") == text.replace(" ", "")


def test_a_branchs_own_arrays_are_set_on_every_lane() -> None:
    """Over lanes, a branch around a call runs where any lane needs it: its
    assignments keep a lane's old value by selection where its condition is
    false, but not those to the arrays the branch owns (If.own: read only
    where it holds), which are set as they are; a branch owns nothing of
    the single trajectory's (C prints it as any)."""
    x, y, go = Var("x"), Var("y"), Var("go")
    then = (assign(y[0], x[0] * 2.0), Call("rhs", (Num(0.0), y, Var("c"), Row("k", Int(1)))),
            assign(x[1], x[0] + 1.0))  # fmt: skip
    locals_ = (Decl("go", "bool", (), "inout"),)
    for own, selected in (((), True), (("y",), False)):
        f = Func("f", (), (If(go, then, own=own),), None, locals_)
        text = LanesPrinter("p", "P", {}, SCRATCH).function(f)
        assert ("L->y[0][l] = go[l] ? L->x[0][l] * 2.0 : L->y[0][l];" in text) == selected
        assert ("L->y[0][l] = L->x[0][l] * 2.0;" in text) != selected
        assert "L->x[1][l] = go[l] ? L->x[0][l] + 1.0 : L->x[1][l];" in text
        assert "y[0] = x[0] * 2.0;" in CPrinter("p", "P", {}).function(f)


def test_a_loop_over_lanes_turns_while_any_lane_goes_on() -> None:
    """go := go and ..., then a break where not go: over lanes one loop
    whose turns run while any lane goes on (no lane by lane loop of its
    own), the rest of a turn under go by selection, its own arrays set on
    every lane, and what every lane shares written lane by lane."""
    x, y, go, n = Var("x"), Var("y"), Var("go"), Var("n")
    shared = {**SCRATCH, "out": Decl("out", "double", ("NX",))}
    body = Loop((
        assign(go, Bin("and", go, Bin("<", x[0], Num(1.0)))),
        If(Un("not", go), (Break(),)),
        If(go, (assign(x[0], x[0] + 0.5), assign(y[0], x[0] * 2.0)), own=("y",)),
        If(go, (assign(Var("out")[n], y[0]),)),
    ))  # fmt: skip
    locals_ = (Decl("go", "bool", (), "inout"), Decl("n", "int", (), "in"))
    text = LanesPrinter("p", "P", {}, shared).function(Func("f", (), (body,), None, locals_))
    assert text.count("for (;;) {") == 1 and "if (!need) {" in text and "int need;" in text
    assert "go[l] = go[l] && L->x[0][l] < 1.0;" in text
    assert "L->x[0][l] = go[l] ? L->x[0][l] + 0.5 : L->x[0][l];" in text
    assert "L->y[0][l] = L->x[0][l] * 2.0;" in text
    assert "if (go[l]) {" in text and "L->out[n] = L->y[0][l];" in text
