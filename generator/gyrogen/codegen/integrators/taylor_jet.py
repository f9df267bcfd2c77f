"""The Taylor method's jet, described once: the normalized Taylor
coefficients of every node of the scene's rhs DAG (gyrogen.symbolic.jet).

At order k >= 2: first, for j = 1 .. k-1, every convolution's terms that
read only lower orders, in one loop whose body holds every node (the terms
of different nodes are independent, so the processor overlaps them); then,
node by node in DAG order, the terms that read order k and the linear
nodes; then each state's coefficient k+1 = f[k] / (k+1). Order 1, which
has no such terms, follows order 0 in the same statements. The recurrences
(Jorba & Zou 2005, Sec. 2), for T[k] the coefficient of order k:
  u = a b:    u[k] = sum_{j=0..k} a[j] b[k-j]
  u = a / b:  u[k] = (a[k] - sum_{j=1..k} b[j] u[k-j]) / b[0]
  s = sin a, c = cos a:
              s[k] =  (1/k) sum_{j=1..k} j a[j] c[k-j]
              c[k] = -(1/k) sum_{j=1..k} j a[j] s[k-j]
A constant operand (hoisted parameters, numbers) has no coefficient past
order 0: a product or quotient by it is a scaling.

Only what a later order reads is stored (`kept`): the states (the step's
polynomial), every operand a convolution reads at a lower order, and the
constant nodes; the other nodes (sums, differences, scalings) are values of
their order alone (locals of intent "tmp": over lanes, scoped to one loop
over the lanes), so the coefficients a step touches are fewer and stay in
the first-level cache. Over lanes, an order is one loop over the lanes
with the loop over j inside it (For.inner): the accumulators are values of
that loop, in registers.
"""

from __future__ import annotations

from gyrogen.codegen.integrators.common import (
    x,
)
from gyrogen.codegen.ir.nodes import (
    At,
    Comment,
    Decl,
    E,
    For,
    Func,
    Int,
    Num,
    S,
    Var,
    arr,
    assign,
    cmp,
    fn,
    real,
    sel,
)
from gyrogen.methods import Method
from gyrogen.symbolic.jet import FIXED_PAST, Jet, Node
from gyrogen.tableaus import Series

T, c, n_, j = Var("tay"), Var("c"), Var("n"), Var("j")
order = Var("order")


def succ(e: E) -> E:
    """e + 1, folded for a number."""
    return Int(e.value + 1) if isinstance(e, Int) else e + Int(1)


ZERO = Num(0.0)


def _add(a: E, b: E) -> E:
    return b if a == ZERO else a if b == ZERO else a + b


def _sub(a: E, b: E) -> E:
    return a if b == ZERO else -b if a == ZERO else a - b


def _mul(a: E, b: E) -> E:
    return ZERO if ZERO in (a, b) else a * b


def _neg(a: E) -> E:
    return ZERO if a == ZERO else -a


def kept(jet: Jet) -> list[int]:
    """The nodes whose coefficients are stored, states first (row i is
    state i): the states, a convolution's varying operands and the
    convolution itself where its recurrence reads its own lower orders
    (quotient, sin, cos, with the partner), and the constant nodes."""
    keep = set(range(jet.nx))
    for n in jet.convolutions():
        node = jet.nodes[n]
        if node.op == "mul":
            keep |= set(node.args)
        elif node.op == "div":
            keep |= {node.args[1], n}
        else:
            keep |= {node.args[0], n, node.index}
    keep |= {n for n, node in enumerate(jet.nodes) if node.const and node.op not in ("num", "c")}
    return sorted(keep)


def arguments(jet: Jet) -> list[int]:
    """The nodes whose sine and cosine the rhs takes."""
    return sorted(
        {jet.nodes[n].args[0] for n in jet.convolutions() if jet.nodes[n].op in ("sin", "cos")}
    )


def coefficients(series: Series, jet: Jet) -> Decl:
    """tay[k][r]: the coefficient of order k of the node stored in row r (the
    kept nodes), then k a[k] of each trigonometric argument a."""
    return Decl("tay", "double", (series.order + 1, len(kept(jet)) + len(arguments(jet))), "inout")


class _Coefficients:
    """A jet's nodes as IR expressions."""

    def __init__(self, jet: Jet, k: E = n_):
        self.jet, self.k = jet, k
        self.row = {n: r for r, n in enumerate(kept(jet))}
        self.scaled = {a: len(self.row) + r for r, a in enumerate(arguments(jet))}
        self.deg = jet.degrees()
        self.low = k.value if isinstance(k, Int) else 2
        """The least order k stands for: the orders loop starts at 2."""

    def fixed(self, n: int) -> bool:
        """Node n is 0 at every order of the orders loop (not computed there)."""
        return self.low >= 2 and self.deg[n] <= FIXED_PAST

    def set(self, n: int, order_: E, value: E, derivative: E | None = None) -> list[S]:
        """Node n's coefficient of order_ = value; for a trigonometric
        argument also order_ times it, which the convolutions read (a
        state's: derivative, the rhs's coefficient it is 1/order_ of, with
        no multiply). Nothing for a fixed node in the orders loop (never
        read there)."""
        if not isinstance(order_, Int) and self.fixed(n):
            return []
        out: list[S] = [assign(self.target(n, order_), value)]
        if n in self.scaled and derivative is not None:
            out.append(assign(T[order_, Int(self.scaled[n])], derivative))
        elif n in self.scaled:
            times: E = self.target(n, order_)
            if order_ != Int(1):
                num = Num(float(order_.value)) if isinstance(order_, Int) else fn("real", order_)
                times = num * times
            out.append(assign(T[order_, Int(self.scaled[n])], times))
        return out

    def zero(self, n: int) -> E:
        """Node n at order 0: a number or c[i] as itself, else T[0][n]."""
        node = self.jet.nodes[n]
        if node.op == "num":
            return Num(node.value)
        if node.op == "c":
            return c[node.index]
        return self.at(n, Int(0))

    def at(self, n: int, order_: E) -> E:
        """Node n's coefficient of order_: a stored one, or the value of
        the order being computed (of order 0 or k only); 0 past its degree."""
        return ZERO if self._low(order_) > self.deg[n] else self.target(n, order_)

    def target(self, n: int, order_: E) -> At | Var:
        """Where node n's coefficient of order_ is (stored, or a value of its order)."""
        if n in self.row:
            return T[order_, Int(self.row[n])]
        assert order_ in (self.k, Int(0)), f"node {n} is not kept, yet read at order {order_}"
        return Var(f"v{n}")

    def _low(self, order_: E) -> float:
        """The least value order_ takes, where it is known (else 0)."""
        if isinstance(order_, Int):
            return order_.value
        if order_ == self.k:
            return self.low
        return self.low + 1 if order_ == succ(self.k) else 0

    def temporaries(self) -> list[int]:
        """The nodes computed and not stored."""
        nodes = self.jet.nodes
        return [
            n
            for n in range(self.jet.nx, len(nodes))
            if n not in self.row and nodes[n].op not in ("num", "c")
        ]

    def value(self, node: Node) -> E:
        """The node's value from its operands' (order 0)."""
        z = [self.zero(a) for a in node.args]
        if node.op in ("sin", "cos"):
            return fn(node.op, z[0])
        if node.op == "neg":
            return -z[0]
        a, b = z
        return {"add": a + b, "sub": a - b, "mul": a * b, "div": a / b}[node.op]

    def varying(self, n: int) -> bool:
        return not self.jet.nodes[n].const

    def linear(self, node: Node) -> E:
        """add, sub, neg at order k >= 1: the varying operands' order k."""
        a, k = node.args[0], self.k
        if node.op == "neg":
            return _neg(self.at(a, k))
        b = node.args[1]
        if not self.varying(a):
            return self.at(b, k) if node.op == "add" else _neg(self.at(b, k))
        if not self.varying(b):
            return self.at(a, k)
        return (_add if node.op == "add" else _sub)(self.at(a, k), self.at(b, k))

    def single(self, n: int) -> E | None:
        """A convolution's sum when one factor is fixed (1 <= j < k has one
        term: j = 1, or k - j = 1), else None."""
        first, second = (self.deg[f] <= FIXED_PAST for f in self.jet.operands(n))
        k = self.k
        if first and second:  # a product of two lines: a[1] b[1] at k = 2 only
            a, b = self.jet.operands(n)
            return sel(cmp(k, "==", Int(2)), self.target(a, Int(1)) * self.target(b, Int(1)), ZERO)
        if first:
            return self.term(n, Int(1))
        return self.term(n, k - Int(1)) if second else None

    def term(self, n: int, jj: E) -> E:
        """A convolution's term jj (1 <= jj < k), which reads orders below k."""
        node, kj = self.jet.nodes[n], self.k - jj
        if node.op == "mul":
            a, b = node.args
            return self.at(a, jj) * self.at(b, kj)
        if node.op == "div":
            return self.at(node.args[1], jj) * self.at(n, kj)
        return T[jj, Int(self.scaled[node.args[0]])] * self.at(node.index, kj)

    def finish(self, n: int, node: Node) -> E:
        """Node n at order k >= 1, from its convolution's sum (none at order
        1) and its operands' order k, each of which enters once, last (the
        chain from one order's state to the next is as short as it can be)."""
        k = self.k
        acc = None if k == Int(1) else Var(f"acc{n}")
        if node.op in ("add", "sub", "neg"):
            return self.linear(node)
        if node.op in ("sin", "cos"):
            a, partner = node.args[0], self.at(node.index, Int(0))
            head = _mul(self.at(a, k), partner)
            if node.op == "sin":  # (acc + k a[k] c[0]) / k
                return head if acc is None else _add(acc * Var("inv")[k], head)
            return _neg(head) if acc is None else _sub(-(acc * Var("inv")[k]), head)
        a, b = node.args
        if node.op == "mul":
            if not self.varying(a):
                return _mul(self.zero(a), self.at(b, k))
            if not self.varying(b):
                return _mul(self.at(a, k), self.zero(b))
            head = _mul(self.at(a, Int(0)), self.at(b, k))
            return _add(
                head if acc is None else _add(acc, head), _mul(self.at(a, k), self.at(b, Int(0)))
            )
        if not self.varying(b):
            return self.at(a, k) / self.zero(b) if self.at(a, k) != ZERO else ZERO
        # (a[k] - acc - b[k] u[0]) / b[0], with 1/b[0] and u[0]/b[0] from order 0
        head = _mul(self.at(b, k), Var(f"ub{n}"))
        known = head if acc is None else _add(acc * Var(f"ib{n}"), head)
        return _sub(_mul(self.at(a, k), Var(f"ib{n}")), known) if self.varying(a) else _neg(known)

    def order_k(self) -> list[S]:
        """Every varying node at order k, then the states' order k+1."""
        jet, k = self.jet, self.k
        out: list[S] = [
            s
            for n in range(jet.nx, len(jet.nodes))
            if not jet.nodes[n].const and not self.fixed(n)
            for s in self.set(n, k, self.finish(n, jet.nodes[n]))
        ]
        for n, f in enumerate(jet.outputs):
            value = _mul(self.at(f, k), Var("inv")[succ(k)]) if self.varying(f) else ZERO
            out += self.set(n, succ(k), value, self.at(f, k) if self.varying(f) else None)
        return out

    def divisions(self) -> list[int]:
        """The quotients by a varying node: 1/b[0] and u[0]/b[0] kept from order 0."""
        return [
            n
            for n, node in enumerate(self.jet.nodes)
            if node.op == "div" and not node.const and self.varying(node.args[1])
        ]


def reads_constants(jet: Jet) -> bool:
    """The rhs reads c[] (a scene with every value folded does not)."""
    return any(n.op == "c" for n in jet.nodes)


def _lower_orders(p: _Coefficients) -> list[S]:
    """The convolutions' terms j = 1 .. k-1 (k >= 2: one turn at least)."""
    jet = p.jet
    conv = [n for n in jet.convolutions() if not p.fixed(n)]
    singles = {n: e for n in conv if (e := p.single(n)) is not None}
    looped = [n for n in conv if n not in singles]
    out: list[S] = [assign(Var(f"acc{n}"), e) for n, e in singles.items()]
    if looped:
        sums = tuple(assign(Var(f"acc{n}"), Var(f"acc{n}") + p.term(n, j)) for n in looped)
        out += [assign(Var(f"acc{n}"), 0.0) for n in looped]
        out.append(For("j", p.k, sums, start=Int(1), inner=True))
    return out


def jet_function(series: Series, jet: Jet) -> Func:
    """taylor_jet: tay[0 .. order][*] at x; inv[k] = 1/k."""
    p = _Coefficients(jet)
    nx = jet.nx
    body: list[S] = [Comment("orders 0 and 1 of the state and of every node", False)]
    body += [assign(T[Int(0), Int(n)], x[n]) for n in range(nx)]
    body += [
        assign(p.target(n, Int(0)), p.value(jet.nodes[n]))
        for n in range(nx, len(jet.nodes))
        if jet.nodes[n].op not in ("num", "c")
    ]
    for n in p.divisions():
        b0 = p.at(jet.nodes[n].args[1], Int(0))
        body += [
            assign(Var(f"ib{n}"), Num(1.0) / b0),
            assign(Var(f"ub{n}"), p.at(n, Int(0)) / b0),
        ]
    body += [s for n, f in enumerate(jet.outputs) for s in p.set(n, Int(1), p.zero(f))]
    body += _Coefficients(jet, Int(1)).order_k()
    body += [
        Comment("orders 2 .. order-1 of the nodes, so orders 3 .. order of the state"),
        For("n", order, (*_lower_orders(p), *p.order_k()), start=Int(2)),
    ]
    params = (
        Decl("order", "int"),
        arr("x"),
        *([Decl("c", "double", ("NC",))] if reads_constants(jet) else []),
        Decl("inv", "double", (series.order + 1,)),
        coefficients(series, jet),
    )
    conv = jet.convolutions()
    locals_ = (
        *(real(f"acc{n}", "tmp") for n in conv),
        *(real(f"{v}{n}", "inout") for n in p.divisions() for v in ("ib", "ub")),
        *(real(f"v{n}", "tmp") for n in p.temporaries()),
    )
    doc = (
        f"The normalized Taylor coefficients of x and of the rhs's {len(jet.nodes) - nx}",
        f"nodes to the given order ({len(conv)} of them convolutions).",
    )
    return Func("taylor_jet", params, tuple(body), None, locals_, doc, inline=True)


def jet_lanes(m: Method, jet: Jet) -> Func:
    """taylor_jet over lanes: x and the coefficients are the lanes' own."""
    series = m.tableau
    assert isinstance(series, Series)
    f = jet_function(series, jet)
    params = tuple(d for d in f.params if d.name not in ("x", "tay"))
    return Func("taylor_jet_lanes", params, f.body, None, f.locals, f.doc)
