"""The Taylor series method, described once: the scene's jet (the
normalized Taylor coefficients of every node of its rhs DAG,
gyrogen.symbolic.jet) and the integrator around it.

The jet at order k: first, for j = 1 .. k-1, every convolution's terms
that read only lower orders, in one loop whose body holds every node (the
terms of different nodes are independent, so the processor overlaps them);
then, node by node in DAG order, the terms that read order k and the
linear nodes; then each state's coefficient k+1 = f[k] / (k+1). The
recurrences (Jorba & Zou 2005, Sec. 2), for T[k] the coefficient of order k:
  u = a b:    u[k] = sum_{j=0..k} a[j] b[k-j]
  u = a / b:  u[k] = (a[k] - sum_{j=1..k} b[j] u[k-j]) / b[0]
  s = sin a, c = cos a:
              s[k] =  (1/k) sum_{j=1..k} j a[j] c[k-j]
              c[k] = -(1/k) sum_{j=1..k} j a[j] s[k-j]
A constant operand (hoisted parameters, numbers) has no coefficient past
order 0: a product or quotient by it is a scaling.
"""

from __future__ import annotations

import math

from gyrogen import methods as registry
from gyrogen.codegen.integrators.common import (
    NX,
    STATS,
    TOLERANCES,
    arr,
    code,
    comp,
    dx,
    h,
    i,
    real,
    x,
    xnew,
)
from gyrogen.codegen.ir.nodes import (
    At,
    Bool,
    Break,
    Call,
    Comment,
    Decl,
    E,
    For,
    Func,
    If,
    Int,
    Loop,
    Num,
    Return,
    S,
    Unused,
    Var,
    and_,
    assign,
    cmp,
    fn,
    inc,
    not_,
    or_,
    sel,
)
from gyrogen.methods import Method
from gyrogen.symbolic.jet import Jet, Node
from gyrogen.tableaus import Series

T, c, k, j = Var("tay"), Var("c"), Var("k"), Var("j")
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
        ops = {"add": "+", "sub": "-", "mul": "*", "div": "/"}
        a, b = z
        return {"+": a + b, "-": a - b, "*": a * b, "/": a / b}[ops[node.op]]

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
        """Node n at order k >= 1, from its convolution's sum and its operands' order k."""
        acc = Var(f"acc{n}")
        if node.op in ("add", "sub", "neg"):
            return self.linear(node)
        if node.op in ("sin", "cos"):
            a = node.args[0]
            s = (acc + (fn("real", k) * self.at(a, k)) * self.at(node.index, Int(0))) * Var("rk")
            return s if node.op == "sin" else -s
        a, b = node.args
        if node.op == "mul":
            if not self.varying(a):
                return self.zero(a) * self.at(b, k)
            if not self.varying(b):
                return self.at(a, k) * self.zero(b)
            return (self.at(a, Int(0)) * self.at(b, k) + acc) + self.at(a, k) * self.at(b, Int(0))
        if not self.varying(b):
            return self.at(a, k) / self.zero(b)
        known = acc + self.at(b, k) * self.at(n, Int(0))
        top = self.at(a, k) - known if self.varying(a) else -known
        return top / self.at(b, Int(0))


def reads_constants(jet: Jet) -> bool:
    """The rhs reads c[] (a scene with every value folded does not)."""
    return any(n.op == "c" for n in jet.nodes)


def jet_function(series: Series, jet: Jet) -> Func:
    """taylor_jet: T[0 .. order][*] at x."""
    p = _Printer(jet)
    nx = jet.nx
    body: list[S] = [Comment("order 0: the state and every node's value", False)]
    body += [assign(T[Int(0), Int(n)], x[n]) for n in range(nx)]
    body += [
        assign(T[Int(0), Int(n)], p.value(jet.nodes[n]))
        for n in range(nx, len(jet.nodes))
        if jet.nodes[n].op not in ("num", "c")
    ]
    body += [assign(T[Int(1), Int(n)], p.zero(f)) for n, f in enumerate(jet.outputs)]
    conv = jet.convolutions()
    trig_args = sorted({jet.nodes[n].args[0] for n in conv if jet.nodes[n].op in ("sin", "cos")})
    loop: list[S] = [assign(Var(f"w{a}"), fn("real", j) * p.at(a, j)) for a in trig_args]
    loop += [assign(Var(f"acc{n}"), p.term(n, jet.nodes[n])) for n in conv]
    order_k: list[S] = [assign(Var("rk"), Num(1.0) / fn("real", k))] * bool(trig_args)
    order_k += [assign(Var(f"acc{n}"), 0.0) for n in conv]
    if conv:
        order_k.append(For("j", k, tuple(loop), tuple(f"w{a}" for a in trig_args), start=Int(1)))
    order_k += [
        assign(T[k, Int(n)], p.finish(n, jet.nodes[n]))
        for n in range(nx, len(jet.nodes))
        if not jet.nodes[n].const
    ]
    order_k.append(assign(Var("rk1"), Num(1.0) / fn("real", k + 1)))
    for n, f in enumerate(jet.outputs):
        value = p.at(f, k) * Var("rk1") if p.varying(f) else Num(0.0)
        order_k.append(assign(T[k + 1, Int(n)], value))
    body += [
        Comment("orders 1 .. order-1 of the nodes, so orders 2 .. order of the state"),
        For("k", order, tuple(order_k), start=Int(1)),
    ]
    params = (
        Decl("order", "int"),
        arr("x"),
        *([Decl("c", "double", ("NC",))] if reads_constants(jet) else []),
        coefficients(series, jet),
    )
    locals_ = (
        *(real(f"acc{n}", "inout") for n in conv),
        *([real("rk", "inout")] if trig_args else []),
        real("rk1", "inout"),
    )
    doc = (
        f"The normalized Taylor coefficients of x and of the rhs's {len(jet.nodes) - nx}",
        f"nodes to the given order ({len(conv)} of them convolutions).",
    )
    return Func("taylor_jet", params, tuple(body), None, locals_, doc, inline=True)


def integrate(m: Method, jet: Jet, quaternion: bool) -> Func:
    """taylor_integrate: from t0 to t1 on one trajectory."""
    series, ctl = m.tableau, m.control
    assert isinstance(series, Series) and isinstance(ctl, registry.TaylorControl)
    t, t0, t1 = Var("t"), Var("t0"), Var("t1")
    last, nonfinite, fresh, acc = Var("last"), Var("nonfinite"), Var("fresh"), Var("acc")
    xmax, dp, dq, rho, scale = (Var(n) for n in ("xmax", "dp", "dq", "rho", "scale"))
    args = (t0, t1, Var("rtol"), Var("atol"), Var("h0"), Var("max_steps"))
    body: list[S] = [
        *([] if reads_constants(jet) else [Unused("c")]),
        Call("stats_start", (Var("stats"), t0)),
        If(fn("bad_arguments", *args), (Return(code("ERR_ARGUMENT")),)),
    ]
    if not quaternion:
        at_start = Return(code("ERR_ATTITUDE_SINGULAR"), "at the start: x as given")
        body.append(If(fn("gimbal_lock_at", x), (at_start,)))
    body += [
        If(not_(cmp(t1, ">", t0)), (Return(code("OK")),)),
        If(not_(fn("all_finite", x, NX)), (Return(code("ERR_NONFINITE")),)),
        Comment("the order: min_order plus the thresholds e^(-2 (q - 1)) above rtol"),
        assign(order, Int(series.min_order)),
        *(
            inc(order, sel(cmp(Num(v), ">", Var("rtol")), Int(1), Int(0)))
            for v in series.thresholds()
        ),
        assign(Var("rhofac"), fn("exp", Num(-ctl.safety) / fn("real", order - 1)) / Num(math.e**2)),
        assign(scale, Var("atol") / Var("rtol")),
        assign(t, t0),
        assign(nonfinite, Int(0)),
        assign(fresh, Int(1)),
    ]
    horner: list[S] = [
        assign(acc, T[order, i]),
        For("q", order - 1, (assign(acc, T[order - Var("q") - 1, i] + h * acc),)),
        assign(dx[i], h * acc - comp[i]),
        assign(xnew[i], x[i] + dx[i]),
    ]
    expand: list[S] = [
        Call("taylor_jet", (order, x, *([c] if reads_constants(jet) else []), T)),
        inc(Var("stats.rhs_calls"), 1),
        assign(xmax, 0.0),
        assign(dp, 0.0),
        assign(dq, 0.0),
        For(
            "i",
            NX,
            (
                assign(xmax, fn("max", xmax, fn("abs", x[i]))),
                assign(dp, fn("max", dp, fn("abs", T[order, i]))),
                assign(dq, fn("max", dq, fn("abs", T[order - 1, i]))),
            ),
        ),
        assign(xmax, fn("max", scale, xmax), "the absolute and relative modes in one"),
        assign(
            rho,
            fn(
                "min",
                fn("pow", xmax / dp, Num(1.0) / fn("real", order)),
                fn("pow", xmax / dq, Num(1.0) / fn("real", order - 1)),
            ),
        ),
        assign(h, fn("min", rho * Var("rhofac"), t1 - t)),
        If(
            and_(cmp(Var("stats.accepted"), "==", 0), cmp(Var("h0"), ">", 0.0)),
            (assign(h, fn("min", h, Var("h0")), "a first step no longer than h0"),),
        ),
        assign(fresh, Int(0)),
    ]
    spent = cmp(Var("stats.accepted") + Var("stats.rejected"), ">=", Var("max_steps"))
    step: list[S] = [
        If(cmp(fresh, "!=", 0), tuple(expand)),
        assign(last, cmp(t + Num(registry.LAST_STEP_SLACK) * h, ">=", t1)),
        If(last, (assign(h, t1 - t),)),
        assign(Var("stats.h"), h),
        If(
            fn("step_underflow", h, t),
            (
                Return(
                    sel(
                        cmp(nonfinite, "!=", 0),
                        code("ERR_NONFINITE"),
                        code("ERR_STEP_UNDERFLOW"),
                    )
                ),
            ),
        ),
        If(spent, (Return(code("ERR_MAX_STEPS")),)),
        Comment("x(t + h) by Horner's scheme, less what the last add lost (comp)"),
        For("i", NX, tuple(horner), ("acc",)),
        assign(nonfinite, sel(fn("all_finite", xnew, NX), Int(0), Int(1))),
        If(
            cmp(nonfinite, "!=", 0),
            (
                inc(Var("stats.rejected"), 1),
                assign(h, h * Num(ctl.nonfinite_shrink)),
                assign(last, Bool(False)),
            ),
            (
                *(
                    []
                    if quaternion
                    else [
                        If(
                            fn("gimbal_lock", x, xnew),
                            (
                                Return(
                                    code("ERR_ATTITUDE_SINGULAR"), "x: the state before this step"
                                ),
                            ),
                        )
                    ]
                ),
                Call("accept_step", (x, xnew, dx, comp)),
                inc(Var("stats.accepted"), 1),
                assign(t, sel(last, t1, t + h)),
                assign(Var("stats.t"), t),
                assign(fresh, Int(1)),
            ),
        ),
        If(and_(last, cmp(nonfinite, "==", 0)), (Break(),)),
    ]
    body += [Loop(tuple(step)), Return(code("OK"))]
    params = (
        real("t0"),
        real("t1"),
        arr("x", "inout"),
        Decl("c", "double", ("NC",)),
        *TOLERANCES,
        real("h0"),
        Decl("max_steps", "long"),
        STATS,
    )
    locals_ = (
        coefficients(series, jet),
        arr("xnew", "inout"),
        arr("dx", "inout"),
        Decl("comp", "double", ("NX",), "inout", Num(0.0)),
        Decl("order", "int", (), "inout"),
        Decl("nonfinite", "int", (), "inout"),
        Decl("fresh", "int", (), "inout"),
        Decl("last", "bool", (), "inout"),
        *(real(n, "inout") for n in ("t", "h", "rhofac", "scale", "xmax", "dp", "dq", "rho")),
    )
    return Func("taylor_integrate", params, tuple(body), "int", locals_, m.notes)


def functions(m: Method, jet: Jet, quaternion: bool) -> list[Func]:
    series = m.tableau
    assert isinstance(series, Series)
    return [jet_function(series, jet), integrate(m, jet, quaternion)]


__all__ = ["At", "functions", "not_", "or_"]
