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
"""

from __future__ import annotations

from gyrogen.codegen.integrators.common import arr, real, x
from gyrogen.codegen.ir.nodes import (
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

T, c, k, j = Var("tay"), Var("c"), Var("n"), Var("j")
order = Var("order")


def coefficients(series: Series, jet: Jet) -> Decl:
    """tay[k][n]: the coefficient of order k of node n."""
    return Decl("tay", "double", (series.order + 1, len(jet.nodes)), "inout")


class _Printer:
    """A jet's nodes as IR expressions."""

    def __init__(self, jet: Jet):
        self.jet = jet

    def zero(self, n: int) -> E:
        """Node n at order 0: a number or c[i] as itself, else T[0][n]."""
        node = self.jet.nodes[n]
        if node.op == "num":
            return Num(node.value)
        if node.op == "c":
            return c[node.index]
        return T[Int(0), Int(n)]

    def at(self, n: int, order_: E) -> E:
        return T[order_, Int(n)]

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

    def term(self, n: int, node: Node) -> E:
        """A convolution's term j (1 <= j < k), which reads orders below k."""
        acc = Var(f"acc{n}")
        kj = k - j
        if node.op == "mul":
            a, b = node.args
            return acc + self.at(a, j) * self.at(b, kj)
        if node.op == "div":
            return acc + self.at(node.args[1], j) * self.at(n, kj)
        return acc + Var(f"w{node.args[0]}") * self.at(node.index, kj)

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


def jet_function(series: Series, jet: Jet) -> Func:
    """taylor_jet: tay[0 .. order][*] at x; inv[k] = 1/k."""
    p = _Printer(jet)
    nx = jet.nx
    body: list[S] = [Comment("order 0: the state and every node's value", False)]
    body += [assign(T[Int(0), Int(n)], x[n]) for n in range(nx)]
    body += [
        assign(T[Int(0), Int(n)], p.value(jet.nodes[n]))
        for n in range(nx, len(jet.nodes))
        if jet.nodes[n].op not in ("num", "c")
    ]
    for n in p.divisions():
        b0 = T[Int(0), Int(jet.nodes[n].args[1])]
        body += [
            assign(Var(f"ib{n}"), Num(1.0) / b0),
            assign(Var(f"ub{n}"), T[Int(0), Int(n)] / b0),
        ]
    body += [assign(T[Int(1), Int(n)], p.zero(f)) for n, f in enumerate(jet.outputs)]
    conv = jet.convolutions()
    trig_args = sorted({jet.nodes[n].args[0] for n in conv if jet.nodes[n].op in ("sin", "cos")})
    loop: list[S] = [assign(Var(f"w{a}"), fn("real", j) * p.at(a, j)) for a in trig_args]
    loop += [assign(Var(f"acc{n}"), p.term(n, jet.nodes[n])) for n in conv]
    order_k: list[S] = [assign(Var(f"acc{n}"), 0.0) for n in conv]
    if conv:
        order_k.append(For("j", k, tuple(loop), tuple(f"w{a}" for a in trig_args), start=Int(1)))
    order_k += [
        assign(T[k, Int(n)], p.finish(n, jet.nodes[n]))
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
    locals_ = (
        *(real(f"acc{n}", "inout") for n in conv),
        *(real(f"{v}{n}", "inout") for n in p.divisions() for v in ("ib", "ub")),
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
