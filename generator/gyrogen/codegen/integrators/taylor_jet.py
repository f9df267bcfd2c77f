"""The Taylor method's jet, described once: the normalized Taylor
coefficients of every node of the scene's rhs DAG (gyrogen.symbolic.jet).

At order k: first, for j = 1 .. k-1, every convolution's terms that read
only lower orders, in one loop whose body holds every node (the terms of
different nodes are independent, so the processor overlaps them); then,
node by node in DAG order, the terms that read order k and the linear
nodes; then each state's coefficient k+1 = f[k] / (k+1). The recurrences
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
the first-level cache. A convolution's lower-order terms are summed UNROLL
at a time, pairwise, then added to its accumulator.
"""

from __future__ import annotations

from gyrogen.codegen.integrators.common import arr, real, x
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
    assign,
    fn,
)
from gyrogen.methods import Method
from gyrogen.symbolic.jet import Jet, Node
from gyrogen.tableaus import Series

T, c, k, j, blk = Var("tay"), Var("c"), Var("n"), Var("j"), Var("b")
order = Var("order")
UNROLL = 2
"""Terms of a convolution per turn of its loop: their sum is added to the
accumulator once (over lanes, one load and store of it per UNROLL terms).
On the default scene 2 beat 1, 4 and 8, in the batch and the single call."""


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


def coefficients(series: Series, jet: Jet) -> Decl:
    """tay[k][r]: the coefficient of order k of the node stored in row r."""
    return Decl("tay", "double", (series.order + 1, len(kept(jet))), "inout")


class _Printer:
    """A jet's nodes as IR expressions."""

    def __init__(self, jet: Jet):
        self.jet = jet
        self.row = {n: r for r, n in enumerate(kept(jet))}

    def zero(self, n: int) -> E:
        """Node n at order 0: a number or c[i] as itself, else T[0][n]."""
        node = self.jet.nodes[n]
        if node.op == "num":
            return Num(node.value)
        if node.op == "c":
            return c[node.index]
        return self.at(n, Int(0))

    def at(self, n: int, order_: E) -> At | Var:
        """Node n's coefficient of order_: a stored one, or the value of
        the order being computed (of order 0 or k only)."""
        if n in self.row:
            return T[order_, Int(self.row[n])]
        assert order_ in (k, Int(0)), f"node {n} is not kept, yet read at order {order_}"
        return Var(f"v{n}")

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
        a = node.args[0]
        if node.op == "neg":
            return -self.at(a, k)
        b = node.args[1]
        if not self.varying(a):
            return self.at(b, k) if node.op == "add" else -self.at(b, k)
        if not self.varying(b):
            return self.at(a, k)
        return self.at(a, k) + self.at(b, k) if node.op == "add" else self.at(a, k) - self.at(b, k)

    def term(self, n: int, node: Node, jj: E, w: str) -> E:
        """A convolution's term jj (1 <= jj < k), which reads orders below
        k; w names the trigonometric argument's jj a[jj]."""
        kj = k - jj
        if node.op == "mul":
            a, b = node.args
            return self.at(a, jj) * self.at(b, kj)
        if node.op == "div":
            return self.at(node.args[1], jj) * self.at(n, kj)
        return Var(f"w{node.args[0]}{w}") * self.at(node.index, kj)

    def finish(self, n: int, node: Node) -> E:
        """Node n at order k >= 1, from its convolution's sum and its operands'
        order k, each of which enters once, last (the chain from one order's
        state to the next is as short as it can be)."""
        acc, inv_k = Var(f"acc{n}"), Var("inv")[k]
        if node.op in ("add", "sub", "neg"):
            return self.linear(node)
        if node.op in ("sin", "cos"):
            a, partner = node.args[0], self.at(node.index, Int(0))
            if node.op == "sin":  # (acc + k a[k] c[0]) / k
                return acc * inv_k + self.at(a, k) * partner
            return -(acc * inv_k) - self.at(a, k) * partner
        a, b = node.args
        if node.op == "mul":
            if not self.varying(a):
                return self.zero(a) * self.at(b, k)
            if not self.varying(b):
                return self.at(a, k) * self.zero(b)
            return (acc + self.at(a, Int(0)) * self.at(b, k)) + self.at(a, k) * self.at(b, Int(0))
        if not self.varying(b):
            return self.at(a, k) / self.zero(b)
        # (a[k] - acc - b[k] u[0]) / b[0], with 1/b[0] and u[0]/b[0] from order 0
        known = acc * Var(f"ib{n}") + self.at(b, k) * Var(f"ub{n}")
        return self.at(a, k) * Var(f"ib{n}") - known if self.varying(a) else -known

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


def _sum(terms: list[E]) -> E:
    """Pairwise: ((t0 + t1) + (t2 + t3))."""
    while len(terms) > 1:
        terms = [terms[i] + terms[i + 1] if i + 1 < len(terms) else terms[i]
                 for i in range(0, len(terms), 2)]  # fmt: skip
    return terms[0]


def _lower_orders(p: _Printer) -> list[S]:
    """The convolutions' terms j = 1 .. k-1: UNROLL per turn of a loop over
    blocks, then the rest one at a time."""
    jet = p.jet
    conv = jet.convolutions()
    if not conv:
        return []
    trig = sorted({jet.nodes[n].args[0] for n in conv if jet.nodes[n].op in ("sin", "cos")})

    def turn(js: list[E]) -> tuple[list[S], tuple[str, ...]]:
        """The terms js of every convolution; w names per term when several."""
        names = [f"_{u}" for u in range(len(js))] if len(js) > 1 else [""]
        ws: list[S] = [
            assign(Var(f"w{a}{w}"), fn("real", jj) * p.at(a, jj))
            for a in trig
            for jj, w in zip(js, names, strict=True)
        ]
        sums: list[S] = [
            assign(
                Var(f"acc{n}"),
                Var(f"acc{n}")
                + _sum([p.term(n, jet.nodes[n], jj, w) for jj, w in zip(js, names, strict=True)]),
            )
            for n in conv
        ]
        return ws + sums, tuple(f"w{a}{w}" for a in trig for w in names)

    blocks = (k - Int(1)) / Int(UNROLL)  # then the rest (none when UNROLL is 1)
    body, scoped = turn([Int(UNROLL) * blk + Int(1 + u) for u in range(UNROLL)])
    out: list[S] = [assign(Var(f"acc{n}"), 0.0) for n in conv]
    out.append(For("b", blocks, tuple(body), scoped))
    body, scoped = turn([j])
    out.append(For("j", k, tuple(body), scoped, start=Int(UNROLL) * blocks + Int(1)))
    return out


def jet_function(series: Series, jet: Jet) -> Func:
    """taylor_jet: tay[0 .. order][*] at x; inv[k] = 1/k."""
    p = _Printer(jet)
    nx = jet.nx
    body: list[S] = [Comment("order 0: the state and every node's value", False)]
    body += [assign(T[Int(0), Int(n)], x[n]) for n in range(nx)]
    body += [
        assign(p.at(n, Int(0)), p.value(jet.nodes[n]))
        for n in range(nx, len(jet.nodes))
        if jet.nodes[n].op not in ("num", "c")
    ]
    for n in p.divisions():
        b0 = p.at(jet.nodes[n].args[1], Int(0))
        body += [
            assign(Var(f"ib{n}"), Num(1.0) / b0),
            assign(Var(f"ub{n}"), p.at(n, Int(0)) / b0),
        ]
    body += [assign(T[Int(1), Int(n)], p.zero(f)) for n, f in enumerate(jet.outputs)]
    order_k = _lower_orders(p)
    order_k += [
        assign(p.at(n, k), p.finish(n, jet.nodes[n]))
        for n in range(nx, len(jet.nodes))
        if not jet.nodes[n].const
    ]
    for n, f in enumerate(jet.outputs):
        value = p.at(f, k) * Var("inv")[k + 1] if p.varying(f) else Num(0.0)
        order_k.append(assign(T[k + 1, Int(n)], value))
    body += [
        Comment("orders 1 .. order-1 of the nodes, so orders 2 .. order of the state"),
        For("n", order, tuple(order_k), start=Int(1)),
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
        *(real(f"acc{n}", "inout") for n in conv),
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
