"""The model's sympy blocks as IR functions: setup (with its checks), the
rhs and its lanes twins, the outputs, the Jacobian and the linear model.

Each is lowered once into the IR (gyrogen.codegen.ir.nodes) and printed by
the same C and Fortran printers as the integrators, so every target rounds
alike. A sympy expression keeps sympy's order of terms and factors; a sum
puts its positive terms first and subtracts the others (c + a*b - d, never
-d + ...), a product divides its numerator by the product of its
denominators, and small integer powers are products (x*x beats pow(x, 2);
in Fortran x**2 is x*x, pow(x, 2) is not).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence

import sympy as sm

from gyrogen.abi import SIGNATURES, Arg
from gyrogen.codegen.checks import LOOP
from gyrogen.codegen.checks import lowered as lowered_checks
from gyrogen.codegen.context import Local, SceneContext, Table
from gyrogen.codegen.integrators.trig import VARIANTS
from gyrogen.codegen.ir.nodes import (
    At,
    Bin,
    Call,
    Const,
    Decl,
    E,
    Fn,
    For,
    Func,
    If,
    Int,
    Num,
    Ref,
    Return,
    S,
    Sel,
    Un,
    Unused,
    Var,
    assign,
    called,
    fn,
    not_,
    real,
    walk,
)
from gyrogen.errors import GyrogenError
from gyrogen.symbolic.hoist import constants
from gyrogen.symbolic.literals import LiteralError, exact_double, writable
from gyrogen.symbolic.optimize import Block

Names = Callable[[sm.Symbol], E]
"""A symbol's IR: a hoisted constant c_k as c[k], anything else by its name."""


def expression(e: sm.Expr, names: Names, lanes: bool = False) -> E:
    """e in the IR; with lanes, sin and cos as their branch-free twins
    (sin_lanes, cos_lanes: gyrogen.codegen.integrators.trig)."""

    def go(e: sm.Expr) -> E:
        if isinstance(e, sm.Symbol):
            return names(e)
        if isinstance(e, sm.Number):
            if not (exact_double(int(e)) if isinstance(e, sm.Integer) else writable(e)):
                raise LiteralError(f"internal: the number {e} reached a printer unconverted")
            if isinstance(e, sm.Rational) and not isinstance(e, sm.Integer):
                return Bin("/", Num(float(e.p)), Num(float(e.q)))
            return Num(float(e))
        if isinstance(e, sm.Add):
            return _sum(e, go)
        if isinstance(e, sm.Mul):
            return _product(e, go)
        if isinstance(e, sm.Pow):
            return _power(e.base, e.exp, go)
        if isinstance(e, (sm.sin, sm.cos)):
            return Fn(type(e).__name__ + ("_lanes" if lanes else ""), (go(e.args[0]),))
        if isinstance(e, (sm.Max, sm.Min)):
            name = "max" if isinstance(e, sm.Max) else "min"
            out = go(e.args[0])
            for a in e.args[1:]:
                out = Fn(name, (out, go(a)))
            return out
        if isinstance(e, sm.Abs):
            return Fn("abs", (go(e.args[0]),))
        if isinstance(e, sm.Heaviside):  # a torque limit's slope: 1 inside the clamp, 0 outside
            return Sel(Bin(">", go(e.args[0]), Num(0.0)), Num(1.0), Num(0.0))
        raise GyrogenError(f"internal: no IR for {type(e).__name__} in {e}")

    return go(e)


def _negative(term: sm.Expr) -> bool:
    return bool(term.as_coeff_Mul()[0].is_negative)


def _sum(e: sm.Add, go: Callable[[sm.Expr], E]) -> E:
    terms = [t for t in e.args if not _negative(t)] + [t for t in e.args if _negative(t)]
    out = go(terms[0]) if not _negative(terms[0]) else Un("-", go(-terms[0]))
    for t in terms[1:]:
        out = Bin("-", out, go(-t)) if _negative(t) else Bin("+", out, go(t))
    return out


def _product(e: sm.Mul, go: Callable[[sm.Expr], E]) -> E:
    coeff, rest = e.as_coeff_Mul()
    if coeff.is_negative:
        return Un("-", go(-e))
    num: list[E] = []
    den: list[E] = []
    if coeff.is_Rational and coeff.q != 1:  # p/q: p over q times the rest
        num += [] if coeff.p == 1 else [go(sm.Integer(coeff.p))]
        den.append(go(sm.Integer(coeff.q)))
    elif coeff != 1:
        num.append(go(coeff))
    for f in sm.Mul.make_args(rest):
        if isinstance(f, sm.Pow) and f.exp.is_Rational and f.exp.is_negative:
            den.append(_power(f.base, -f.exp, go))
        else:
            num.append(go(f))
    top = _fold("*", num) if num else Num(1.0)
    return Bin("/", top, _fold("*", den)) if den else top


def _power(base: sm.Expr, exp: sm.Expr, go: Callable[[sm.Expr], E]) -> E:
    if isinstance(exp, sm.Float) and abs(float(exp)) == 0.5:  # a root a Float turned (evalf)
        exp = sm.Rational(float(exp))
    if exp.is_Integer and 1 <= abs(int(exp)) <= 3:
        b = go(base)
        prod = _fold("*", [b] * abs(int(exp)))
        return prod if exp > 0 else Bin("/", Num(1.0), prod)
    if exp == sm.Rational(1, 2):
        return Fn("sqrt", (go(base),))
    if exp == sm.Rational(-1, 2):
        return Bin("/", Num(1.0), Fn("sqrt", (go(base),)))
    return Fn("pow", (go(base), Num(float(exp))))


def _fold(op: str, items: list[E]) -> E:
    out = items[0]
    for x in items[1:]:
        out = Bin(op, out, x)  # type: ignore[arg-type]
    return out


def symbol_names(nc: int) -> Names:
    """c_k as c[k]; every other symbol (a state, a parameter, a temporary,
    a tabulated torque) as a local of its own name."""
    index = {c.name: k for k, c in enumerate(constants(nc))}

    def names(s: sm.Symbol) -> E:
        k = index.get(s.name)
        return At("c", (Int(k),)) if k is not None else Var(s.name)

    return names


def block(
    b: Block,
    output: Callable[[int], At],
    names: Names,
    lanes: bool = False,
    zeroed: bool = False,
) -> tuple[list[str], list[S]]:
    """b's temporaries (their names, then their assignments) and one store per
    output (zeroed: per output that is not 0, the output already zero)."""
    temps = [str(a.lhs) for a in b.temporaries]
    body: list[S] = [
        assign(Var(str(a.lhs)), expression(a.rhs, names, lanes)) for a in b.temporaries
    ]
    body += [
        assign(output(i), expression(e, names, lanes))
        for i, e in enumerate(b.outputs)
        if not (zeroed and e == 0)
    ]
    return temps, body


def sizes(unit: SceneContext, out: int = 0) -> dict[str, int]:
    """The lengths abi.Arg names, for this scene (out: an output's size)."""
    nu, ny = len(unit.inputs), unit.ny
    return {"nx": unit.nx, "np": unit.np, "nc": unit.nc, "out": out, "nu": nu, "ny": ny}


def params(signature: str, unit: SceneContext, out: int = 0) -> tuple[Decl, ...]:
    """A public function's parameters from its abi signature (one home)."""
    n = sizes(unit, out)

    def decl(a: Arg) -> Decl:
        base = a.ctype.replace("const ", "").rstrip(" *")
        if not a.length:
            return Decl(a.name, "double" if base == "double" else "int", (), "in")
        length = 1
        for factor in a.length:
            length *= n[factor]
        return Decl(a.name, "double", (length,), "in" if a.ctype.startswith("const") else "out")

    return tuple(decl(a) for a in SIGNATURES[signature].args)


def _per_call(
    unit: SceneContext,
    name: str,
    signature: str,
    b: Block,
    output: Callable[[int], At],
    doc: tuple[str, ...],
    out: int = 0,
    zeroed: Sequence[S] = (),
) -> Func:
    """A per-call function (rhs, an output, the Jacobian, the linear model):
    the states and tabulated torques it reads as locals, then b (with zeroed,
    the statements that zero the output: then only b's outputs that are not 0)."""
    names = symbol_names(unit.nc)
    free = b.free_symbols
    states = [(i, s.name) for i, s in enumerate(unit.states) if s in free]
    tables = [s.name for s in unit.equations.inputs if s in free]
    temps, body = block(b, output, names, zeroed=bool(zeroed))
    body = [*zeroed, *body]
    reads = [assign(Var(n), At("x", (Int(i),))) for i, n in states]
    reads += [assign(Var(n), fn(f"{unit.prefix}_{n}", Var("t"))) for n in tables]
    unused: list[S] = [Unused(v) for v in ("t", "c") if not _reads([*body, *reads], v)]
    unused += [Unused("x")] if not states else []
    locals_ = tuple(real(n, "inout") for n in [*(n for _, n in states), *tables, *temps])
    return Func(
        f"{unit.prefix}_{name}",
        params(signature, unit, out),
        (*unused, *reads, *body),
        locals=locals_,
        doc=doc,
        public=True,
    )


def _reads(body: Iterable[S], name: str) -> bool:
    return any(isinstance(x, (Var, At)) and x.name == name for s in body for x in walk(s))


def rhs(unit: SceneContext) -> Func:
    doc = (f"dxdt = f(t, x) for the constants c from {unit.prefix}_setup ({unit.ops['rhs']} ops).",)
    return _per_call(unit, "rhs", "rhs", unit.optimized.rhs, _store("dxdt"), doc)


def outputs(unit: SceneContext) -> list[Func]:
    return [
        _per_call(
            unit,
            o.name,
            "output",
            o.block,
            _store("out"),
            (f"out = {o.doc} ({o.unit}): {unit.ops[o.name]} ops.",),
            o.size,
        )
        for o in unit.outputs
    ]


def events(unit: SceneContext) -> Func | None:
    """out[k] = event k's g(t, x), in the scene's order."""
    o = unit.events
    if o is None:
        return None
    doc = (f"out = {o.doc} ({unit.ops['events']} ops).",)
    return _per_call(unit, "events", "output", o.block, _store("out"), doc, o.size)


def jacobian(unit: SceneContext) -> Func | None:
    """d(dx/dt)/dx into J, row-major (J[i*NX + j] = d f_i / d x_j)."""
    b = unit.optimized.jacobian
    if b is None:
        return None
    doc = (
        f"d(dx/dt)/dx, row-major: J[i*nx + j] = d f_i / d x_j ({unit.ops['jac']} ops).",
        "A loop zeroes J, then the entries that can be nonzero are written (one",
        "store each: an augmented system's J is mostly zeros).",
    )
    zero = For(LOOP, Const("NX2"), (assign(At("J", (Var(LOOP),)), 0.0),))
    return _per_call(unit, "jac", "jac", b, _store("J"), doc, zeroed=(zero,))


def linear(unit: SceneContext) -> Func | None:
    """A, B, C, D of the linear model, each row-major (A[i*NX + j] = d f_i /
    d x_j, B[i*NU + j] = d f_i / d u_j, C and D alike for the outputs y)."""
    b = unit.optimized.linear
    if b is None:
        return None
    edges, names = [0], list(unit.linear_sizes)
    for rows, cols in unit.linear_sizes.values():
        edges.append(edges[-1] + rows * cols)

    def at(i: int) -> At:
        k = max(j for j in range(len(names)) if edges[j] <= i)
        return At(names[k], (Int(i - edges[k]),))

    doc = (
        "the linear model: A = df/dx, B = df/du, C = dy/dx, D = dy/du, row-major "
        f"({unit.ops['linear']} ops).",
    )
    f = _per_call(unit, "linear", "linear", b, at, doc)
    unused = [Unused(n) for n in ("C", "D") if not unit.ny]
    return Func(f.name, f.params, (*unused, *f.body), locals=f.locals, doc=f.doc, public=True)


def _store(name: str) -> Callable[[int], At]:
    return lambda i: At(name, (Int(i),))


def rhs_lanes(unit: SceneContext) -> Func:
    """<prefix>_rhs for n states at once, stored by state (x[i*n + l]): the
    same statements, lane by lane, over sin and cos's branch-free twins."""
    n, l_ = Var("n"), Var("l")

    def at(name: str) -> Callable[[int], At]:
        return lambda i: At(name, (Bin("+", Bin("*", Int(i), n), l_) if i else l_,))

    return _lanes(unit, f"{unit.prefix}_rhs_lanes", n, at, At("t", (l_,)), public=True)


def rhs_lanes_ode(unit: SceneContext) -> Func:
    """The pairs' rhs over the lanes of their struct lanes (ode.c): rows
    x[i] and dxdt[i] of LANES values, which the compiler sees do not overlap
    (with n unknown, it cannot). A scene with a torque table calls
    <prefix>_rhs_lanes, whose table lives in <prefix>.c."""
    lanes = Const("LANES")
    if unit.equations.inputs:
        args = (lanes, Var("t"), Ref("x[0][0]"), Var("c"), Ref("dxdt[0][0]"))
        return Func(
            "rhs_lanes",
            _lane_params(),
            (Call(f"{unit.prefix}_rhs_lanes", args, "the torque table lives in <prefix>.c"),),
            restrict=True,
        )
    l_ = Var("l")

    def at(name: str) -> Callable[[int], At]:
        return lambda i: At(name, (Int(i), l_))

    f = _lanes(unit, "rhs_lanes", lanes, at, At("t", (l_,)), public=False)
    return Func(f.name, _lane_params(), f.body, restrict=True)


JAC_LANES_MAX_OPS = 1000
"""The most operations (Block.ops) of a Jacobian printed over lanes from the
model; a larger one runs the scalar <prefix>_jac lane by lane. J is computed
once a step, the rhs six times: over lanes, gyrostat's (58 ops) took its
rodas4 batch from 17.1 to 13.3 us a state, while cmg4_pyramid's (2413)
made its file 58 KB larger, more than the rest of rodas4's lanes together
(bench_lanes.py, gcc -O2)."""


def jacobian_lanes(unit: SceneContext) -> Func:
    """<prefix>_jac on the lanes of struct lanes (ode.c, a Rosenbrock
    method's): rows J[i*NX + j] of LANES values. Up to JAC_LANES_MAX_OPS,
    the same statements lane by lane, over sin and cos's branch-free twins
    (the scalar ones' bits); past it, the scalar Jacobian on each lane in
    turn (its x gathered, its J scattered)."""
    b = unit.optimized.jacobian
    assert b is not None, "a Jacobian over lanes needs the scene's Jacobian"
    params = (*_lane_params()[:3], Decl("J", "double", ("NX2", "LANES"), "out"))
    lane, i, t, x, c, J = (Var(n) for n in ("l", "i", "t", "x", "c", "J"))
    if b.ops <= JAC_LANES_MAX_OPS:

        def at(name: str) -> Callable[[int], At]:
            return lambda i: At(name, (Int(i), lane))

        f = _lanes(unit, "jac_lanes", Const("LANES"), at, At("t", (lane,)), False, b, "J")
        return Func(f.name, params, f.body, restrict=True)
    one_x, one_j = Var("xl"), Var("Jl")
    each = (
        For("i", Const("NX"), (assign(one_x[i], x[i, lane]),)),
        Call("jac", (t[lane], one_x, c, one_j)),
        For("i", Const("NX2"), (assign(J[i, lane], one_j[i]),)),
    )
    locals_ = (Decl("xl", "double", ("NX",)), Decl("Jl", "double", ("NX2",)))
    return Func("jac_lanes", params, (For("l", Const("LANES"), each),), None, locals_,
                restrict=True)  # fmt: skip


def _lane_params() -> tuple[Decl, ...]:
    return (
        Decl("t", "double", ("LANES",)),
        Decl("x", "double", ("NX", "LANES")),
        Decl("c", "double", ("NC",)),
        Decl("dxdt", "double", ("NX", "LANES"), "out"),
    )


def _lanes(
    unit: SceneContext,
    name: str,
    n: E,
    at: Callable[[str], Callable[[int], At]],
    t: At,
    public: bool,
    block_: Block | None = None,
    out: str = "dxdt",
) -> Func:
    """block_ (the rhs unless given) for n states at once, its outputs into out."""
    names = symbol_names(unit.nc)
    b = unit.optimized.rhs if block_ is None else block_
    free = b.free_symbols
    states = [(i, s.name) for i, s in enumerate(unit.states) if s in free]
    tables = [s.name for s in unit.equations.inputs if s in free]
    temps, body = block(b, at(out), names, lanes=True)
    reads = [assign(Var(v), at("x")(i)) for i, v in states]
    reads += [assign(Var(v), fn(f"{unit.prefix}_{v}", t)) for v in tables]
    loop = For(
        "l", n, (*reads, *body), tuple([*(v for _, v in states), *tables, *temps]), simd=True
    )
    unused = [Unused(v) for v in ("t", "c") if not _reads([loop], v)]
    unused += [Unused("x")] if not states else []
    p = (
        Decl("n", "int"),
        Decl("t", "double", (1,)),
        Decl("x", "double", (1,)),
        Decl("c", "double", (1,)),
        Decl("dxdt", "double", (1,), "out"),
    )
    return Func(name, p, (*unused, loop), public=public, restrict=True)


def setup(unit: SceneContext) -> Func:
    """Checks p, then computes the constants c that the rhs needs; returns
    OK or the first failing check's code (c is then not to be used)."""
    names = symbol_names(unit.nc)
    code = {c.value: c.name for c in unit.setup_codes}
    i = Var(LOOP)
    body: list[S] = [For(LOOP, Int(unit.nc), (assign(At("c", (i,)), 0.0),))]
    if unit.np:
        bad = not_(fn("finite", At("p", (i,))))
        body.append(For(LOOP, Int(unit.np), (If(bad, (Return(Const("ERR_NONFINITE")),)),)))
    else:
        body.append(Unused("p"))
    body += [assign(Var(v.name), _parameter(v)) for v in unit.setup_locals]
    early, late = lowered_checks(unit.checks, unit.nc, unit.cond_index, code)
    temps, stores = block(unit.optimized.setup, lambda k: At("c", (Int(k),)), names)
    body += [*early, *stores, *late, Return(Const("OK"))]
    locals_ = [v.name for v in unit.setup_locals]
    locals_ += [n for c in unit.checks for n, _ in c.locals] + temps
    doc = (
        f"Checks p and computes the constants c that {unit.prefix}_rhs needs "
        f"({unit.ops['setup']} ops, plus the checks). Returns {unit.macro}_OK or the first "
        "failing check's code; c is then not to be used.",
    )
    return Func(
        f"{unit.prefix}_setup",
        params("setup", unit),
        tuple(body),
        returns="int",
        locals=tuple(real(n, "inout") for n in locals_),
        doc=doc,
        public=True,
    )


def _parameter(v: Local) -> E:
    """A parameter setup reads: p[index] (runtime), or its folded value."""
    if v.index is not None:
        return At("p", (Int(v.index),))
    assert v.value is not None, v
    return Num(v.value)


def tables_used(unit: SceneContext, funcs: Iterable[Func | None]) -> list[Table]:
    """The torque tables (unit.torque_tables) funcs read: the ODE unit's
    Jacobian reads one where the rates' derivatives depend on a tabulated
    torque (a gimbal's solve multiplies the torques by functions of the
    angles), and a file defines or imports only those."""
    names = called([f for f in funcs if f is not None])
    return [tb for tb in unit.torque_tables if f"{unit.prefix}_{tb.name}" in names]


def trig_used(funcs: Iterable[Func | None]) -> list[str]:
    """Which of <prefix>_sin, <prefix>_cos and their _lanes twins funcs call
    (gyrogen.codegen.integrators.trig): a file defines only those (clang
    warns of an unused static inline function)."""
    names = called([f for f in funcs if f is not None])
    return [v for v in VARIANTS if v in names]
