"""The rhs as a DAG of elementary operations: what a Taylor method expands.

Each node is a state, a hoisted constant c[i], a number, or one operation
(+, -, unary -, *, /, sin, cos) on earlier nodes, so the nodes are in an
order where every operand comes first. A node whose operands are all
constant is constant: its Taylor coefficients past order 0 are zero, and a
product or quotient by it is a scaling. sin and cos of one argument come as
a pair (their recurrences read each other). The normalized Taylor
coefficients of every node follow from its operands' by the recurrences of
automatic differentiation (Jorba & Zou 2005, Sec. 2; heyoka's Taylor
decomposition does the same), printed by gyrogen.codegen.integrators.taylor.

A product costs a sum over every lower order at each order, unless one
factor is a polynomial of degree 1 or less (FIXED_PAST: one term), so
decompose writes a quadratic output as products of a state and a linear
form, a fixed state's first (regroup), where that leaves fewer such sums.

Only smooth operations are expanded: a min or max (a torque clamp), a table
or any other function is refused here, and the scene validator keeps the
method away from such scenes first (gyrogen.scene.rules).
"""

from __future__ import annotations

import math
import re
from collections import Counter
from dataclasses import dataclass
from typing import Literal

import sympy as sm
from sympy.polys.polyerrors import PolificationFailed

from gyrogen.errors import GyrogenError
from gyrogen.symbolic.optimize import Block

Op = Literal["x", "c", "num", "add", "sub", "neg", "mul", "div", "sin", "cos"]
CONSTANT = re.compile(r"c(\d+)")
DEGREE_CAP = 64
"""A degree past this is taken as none (a polynomial of such degree is no
shorter than a Taylor series of the highest order)."""
FIXED_PAST = 1
"""A node of degree at most this (a polynomial in t: Jet.degrees) is 0 at
every order the Taylor method's orders loop computes (k >= 2): it is not
computed there, a read of it is 0, and a convolution with it has one term
(gyrogen.codegen.integrators.taylor_jet)."""
REGROUP_SIZE = 4000
"""An output whose expression, temporaries substituted, has more nodes than
this is not tried for regrouping (its expansion would cost more than it
could save)."""


class NotExpandable(GyrogenError):
    """The rhs holds an operation a Taylor method cannot expand."""


@dataclass(frozen=True)
class Node:
    op: Op
    args: tuple[int, ...] = ()
    index: int = 0
    """x: the state's index; c: the constant's; sin and cos: the partner node."""
    value: float = 0.0
    """num: the number."""
    const: bool = False


@dataclass(frozen=True)
class Jet:
    """The nodes (the states first, 0 .. nx-1) and each state's derivative."""

    nodes: tuple[Node, ...]
    outputs: tuple[int, ...]
    scales: tuple[tuple[str, str], ...] = ()
    """Each state's group and how it enters the group's scale in the Taylor
    step (see gyrogen.codegen.integrators.taylor.state_scales); () when
    every state is of one group and enters by its magnitude."""

    @property
    def nx(self) -> int:
        return len(self.outputs)

    def convolutions(self) -> list[int]:
        """The nodes whose order-k coefficient sums over lower orders (a
        product or quotient of two varying nodes, sin, cos)."""
        return [n for n, node in enumerate(self.nodes) if self.convolves(node)]

    def degrees(self) -> tuple[float, ...]:
        """Each node's degree as a polynomial in t along any trajectory
        (math.inf where it is none): a constant's 0, a sum's the larger, a
        product's the sum, a quotient's the dividend's by a constant, a sine's
        0 of a constant; a state's one more than its derivative's, the least
        such (a state whose derivative is constant: 1). Past DEGREE_CAP, inf."""
        states = [0.0] * self.nx
        while True:
            deg = self._degrees(states)
            grown = [d if d <= DEGREE_CAP else math.inf for d in (deg[f] + 1 for f in self.outputs)]
            if grown == states:
                return deg
            states = grown

    def _degrees(self, states: list[float]) -> tuple[float, ...]:
        deg: list[float] = []
        for node in self.nodes:
            a = [deg[i] for i in node.args]
            if node.op == "x":
                deg.append(states[node.index])
            elif node.const:
                deg.append(0.0)
            elif node.op in ("add", "sub", "neg"):
                deg.append(max(a))
            elif node.op == "mul":
                deg.append(a[0] + a[1])
            elif node.op == "div":
                deg.append(a[0] if a[1] == 0 else math.inf)
            else:  # sin, cos of a varying argument
                deg.append(math.inf)
        return tuple(deg)

    def operands(self, n: int) -> tuple[int, int]:
        """A convolution's two factors, read at orders j and k - j."""
        node = self.nodes[n]
        if node.op == "mul":
            return node.args[0], node.args[1]
        if node.op == "div":
            return node.args[1], n
        return node.args[0], node.index

    def full(self) -> int:
        """The convolutions whose sums run over every lower order: neither
        factor is fixed (degree <= FIXED_PAST), where a sum has one term."""
        deg = self.degrees()
        return sum(all(deg[f] > FIXED_PAST for f in self.operands(n)) for n in self.convolutions())

    def convolves(self, node: Node) -> bool:
        if node.const or node.op in ("x", "add", "sub", "neg"):
            return False
        if node.op in ("sin", "cos"):
            return True
        a, b = (self.nodes[i] for i in node.args)
        return not a.const and not b.const if node.op == "mul" else not b.const


class _Builder:
    def __init__(self, states: tuple[sm.Symbol, ...], temporaries: dict[sm.Symbol, sm.Expr]):
        self.nodes: list[Node] = [Node("x", index=i) for i in range(len(states))]
        self.found: dict[Node, int] = {n: i for i, n in enumerate(self.nodes)}
        self.states = {s: i for i, s in enumerate(states)}
        self.temporaries = temporaries
        self.memo: dict[sm.Expr, int] = {}
        self.trig: dict[int, tuple[int, int]] = {}

    def node(self, op: Op, *args: int, index: int = 0, value: float = 0.0) -> int:
        const = op in ("c", "num") or (op != "x" and all(self.nodes[a].const for a in args))
        key = Node(op, args, index, value, const)
        if key not in self.found:
            self.found[key] = len(self.nodes)
            self.nodes.append(key)
        return self.found[key]

    def number(self, v: float) -> int:
        return self.node("num", value=float(v))

    def visit(self, e: sm.Expr) -> int:
        if e not in self.memo:
            self.memo[e] = self._visit(e)
        return self.memo[e]

    def _visit(self, e: sm.Expr) -> int:
        if e.is_Symbol:
            return self._symbol(e)
        if e.is_Number:
            return self.number(float(e))
        if e.is_Add:
            return self._add(e)
        if e.is_Mul:
            return self._mul(e)
        if e.is_Pow:
            return self._pow(e)
        if isinstance(e, (sm.sin, sm.cos)):
            s, c = self._sincos(self.visit(e.args[0]))
            return s if isinstance(e, sm.sin) else c
        what = type(e).__name__
        if isinstance(e, (sm.Min, sm.Max, sm.Abs, sm.Piecewise, sm.sign, sm.Heaviside)):
            raise NotExpandable(f"the rhs is not smooth ({what}): a Taylor series cannot cross it")
        raise NotExpandable(f"the rhs calls {what}, which the Taylor method does not expand")

    def _sincos(self, a: int) -> tuple[int, int]:
        if a not in self.trig:
            s, const = len(self.nodes), self.nodes[a].const
            self.nodes += [Node("sin", (a,), s + 1, const=const), Node("cos", (a,), s, const=const)]
            self.trig[a] = (s, s + 1)
        return self.trig[a]

    def _symbol(self, s: sm.Symbol) -> int:
        if s in self.states:
            return self.states[s]
        if s in self.temporaries:
            return self.visit(self.temporaries[s])
        m = CONSTANT.fullmatch(s.name)
        if m:
            return self.node("c", index=int(m.group(1)))
        raise NotExpandable(f"the rhs reads {s.name} (not a state or constant): time-dependent")

    def _add(self, e: sm.Expr) -> int:
        out: int | None = None
        for term in e.args:
            coeff, _ = term.as_coeff_Mul()
            negative = coeff.is_negative
            v = self.visit(-term if negative else term)
            if out is None:
                out = self.node("neg", v) if negative else v
            else:
                out = self.node("sub" if negative else "add", out, v)
        assert out is not None
        return out

    def _product(self, factors: list[sm.Expr]) -> int | None:
        out: int | None = None
        for f in factors:
            v = self.visit(f)
            out = v if out is None else self.node("mul", out, v)
        return out

    def _mul(self, e: sm.Expr) -> int:
        coeff, rest = e.as_coeff_Mul()
        num: list[sm.Expr] = []
        den: list[sm.Expr] = []
        for f in sm.Mul.make_args(rest):
            if f.is_Pow and f.exp.is_Integer and f.exp < 0:
                den.append(f.base ** (-f.exp))
            else:
                num.append(f)
        sign = -1 if coeff == -1 else 1
        if coeff not in (1, -1):
            num.insert(0, coeff)
        top = self._product(num)
        if den:
            bottom = self._product(den)
            assert bottom is not None
            top = self.node("div", self.number(1.0) if top is None else top, bottom)
        assert top is not None
        return self.node("neg", top) if sign < 0 else top

    def _pow(self, e: sm.Pow) -> int:
        base, exp = e.base, e.exp
        if not exp.is_Integer:
            raise NotExpandable(
                f"the rhs raises to the power {exp}, which the Taylor method does not expand"
            )
        n = int(exp)
        if n < 0:
            return self.node("div", self.number(1.0), self._pow(sm.Pow(base, -n, evaluate=False)))
        b = self.visit(base)
        out = b
        for _ in range(n - 1):
            out = self.node("mul", out, b)
        return out


def _build(block: Block, states: tuple[sm.Symbol, ...], outputs: list[sm.Expr]) -> Jet:
    builder = _Builder(states, {a.lhs: a.rhs for a in block.temporaries})
    visited = tuple(builder.visit(e) for e in outputs)
    return Jet(tuple(builder.nodes), visited)


def decompose(block: Block, states: tuple[sm.Symbol, ...]) -> Jet:
    """The rhs block (dx/dt in state order) as a Jet; NotExpandable when it
    holds anything but the smooth operations above.

    Each output that is a quadratic polynomial in the states is tried
    regrouped (regroup), and kept so where the jet then has fewer full
    convolutions (Jet.full): a sum of products collected by a fixed state
    first (a wheel at constant acceleration: one term a product) costs a
    product less per order."""
    outputs = list(block.outputs)
    jet = _build(block, states, outputs)
    full = jet.full()
    if full == 0:
        return jet
    deg = jet.degrees()
    fixed = {i for i in range(len(states)) if deg[i] <= FIXED_PAST}
    for i, e in enumerate(_substituted(block)):
        grouped = None if e is None else regroup(e, states, fixed)
        if grouped is None:
            continue
        trial = _build(block, states, [*outputs[:i], grouped, *outputs[i + 1 :]])
        if (fewer := trial.full()) < full:
            outputs[i], jet, full = grouped, trial, fewer
    return jet


def _substituted(block: Block) -> list[sm.Expr | None]:
    """Each output with the temporaries written out (None: too large)."""
    full: dict[sm.Basic, sm.Expr] = {}
    for a in block.temporaries:
        full[a.lhs] = a.rhs.xreplace(full)
    out: list[sm.Expr | None] = []
    for e in block.outputs:
        w = e.xreplace(full)
        out.append(w if _within(w, REGROUP_SIZE) else None)
    return out


def _within(e: sm.Expr, size: int) -> bool:
    """e's tree has at most size nodes (counted no further: temporaries
    written out can share subtrees, so the tree may be far larger than the
    DAG)."""
    return all(i < size for i, _ in enumerate(sm.preorder_traversal(e)))


def regroup(e: sm.Expr, states: tuple[sm.Symbol, ...], fixed: set[int]) -> sm.Expr | None:
    """A quadratic polynomial in the states as its constant and linear part
    plus products state * (linear form), collected greedily: a fixed state's
    monomials first, then the state in most of those left (ties: the lower
    index). None unless e is such a polynomial (its coefficients hold only
    constants)."""
    used = [s for s in states if s in e.free_symbols]
    if len(used) == 0:
        return None
    try:
        poly = sm.Poly(e, *used)
    except (sm.PolynomialError, PolificationFailed):
        return None
    if poly.total_degree() != 2:
        return None
    rest: sm.Expr = sm.Integer(0)
    quad: dict[tuple[int, int], sm.Expr] = {}
    for monom, coeff in poly.terms():
        factors = [i for i, k in enumerate(monom) for _ in range(k)]
        if len(factors) < 2:
            rest += coeff * sm.Mul(*(used[i] for i in factors))
        else:
            quad[(factors[0], factors[1])] = coeff
    index = {i: states.index(s) for i, s in enumerate(used)}
    groups: list[sm.Expr] = []
    while quad:
        count = Counter(v for pair in quad for v in set(pair))
        v = min(count, key=lambda u: (index[u] not in fixed, -count[u], index[u]))
        taken = {p: c for p, c in quad.items() if v in p}
        form = sm.Add(*(c * used[p[1] if p[0] == v else p[0]] for p, c in taken.items()))
        groups.append(sm.Mul(used[v], form))
        quad = {p: c for p, c in quad.items() if p not in taken}
    return sm.Add(rest, *groups)
