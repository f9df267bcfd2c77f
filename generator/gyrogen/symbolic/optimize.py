"""Turn M u' = F, q' = f into two blocks of straight-line code.

``setup`` runs once per parameter set: the lumped inertias, the inverse of the
constant mass matrix and every coefficient that depends on parameters only,
stored as constants c0, c1, ...  ``rhs`` runs per call and reads states and
constants only: it never solves a linear system.

How: u' = M^-1 F is expanded as a polynomial in the states; each coefficient
that involves parameters becomes a hoisted constant (shared when two terms
have the same or the opposite coefficient); what remains is factored by
Horner's scheme and then shares its common subexpressions.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field

import sympy as sm

from gyrogen import physics
from gyrogen.symbolic.derivative import Derivatives
from gyrogen.symbolic.equations import TIME, Equations
from gyrogen.symbolic.hoist import Hoister, hoist
from gyrogen.symbolic.literals import as_double, writable_form
from gyrogen.symbolic.variational import IMPLICIT_MAX_NY, Variational, variational


@dataclass(frozen=True)
class Assignment:
    lhs: sm.Symbol
    rhs: sm.Expr


@dataclass(frozen=True)
class Block:
    """Straight-line code: temporaries first, then one value per output."""

    temporaries: tuple[Assignment, ...]
    outputs: tuple[sm.Expr, ...]

    @property
    def ops(self) -> int:
        return count_ops([a.rhs for a in self.temporaries], self.outputs)

    @property
    def free_symbols(self) -> set[sm.Basic]:
        """What the block reads (its own temporaries included)."""
        exprs = [*(a.rhs for a in self.temporaries), *self.outputs]
        return set().union(*(e.free_symbols for e in exprs))


@dataclass(frozen=True)
class Optimized:
    setup: Block
    """Outputs: the hoisted constants c0..c{nc-1}, in terms of parameters."""
    rhs: Block
    """Outputs: dx/dt in state order, in terms of states and constants."""
    lumped: tuple[Assignment, ...]
    """The lumped inertia scalars: named temporaries of setup."""
    outputs: dict[str, Block] = field(default_factory=dict)
    """Optional extra functions (energy, momentum, power), per call."""
    jacobian: Block | None = None
    """d(dx/dt)/dx, row-major, when an implicit integrator needs it."""
    linear: Block | None = None
    """A, B, C, D of the linear model (Equations.perturbed), each row-major,
    one after another."""
    events: Block | None = None
    """The scene's events g(t, x), per call (their constants after the others)."""
    variational: Variational | None = None
    """The variational system's layout (the scene's [sensitivities])."""
    augmented: Block | None = None
    """d/dt of (x, the entries of Phi and S), one CSE over f and the
    variational part (symbolic.variational)."""
    augmented_jacobian: Block | None = None
    """The augmented system's Jacobian, row-major, for the implicit methods
    (when they are wanted and the system is small enough for them:
    variational.IMPLICIT_MAX_NY)."""

    @property
    def nc(self) -> int:
        return len(self.setup.outputs)


def count_ops(*groups: Iterable[sm.Expr]) -> int:
    """The issue's measure: sympy.count_ops summed over every assignment.

    A trig call counts once wherever CSE has left it: count_ops already
    counts sin(x) as one operation.
    """
    return sum(int(sm.count_ops(e)) for group in groups for e in group)


def block_inverse(m: sm.Matrix) -> sm.Matrix:
    """Inverse of a constant matrix, one diagonal block at a time.

    The mass matrix decouples (translation, rotor, carrier); inverting the
    small blocks keeps the entries short where a full symbolic inverse
    would not.
    """
    inv = sm.zeros(*m.shape)
    for block in m.connected_components():
        idx = sorted(block)
        sub = m.extract(idx, idx)
        sub_inv = sub.inv() if sub.shape[0] > 1 else sm.Matrix([[1 / sub[0, 0]]])
        for a, i in enumerate(idx):
            for b, j in enumerate(idx):
                inv[i, j] = sm.factor(sm.cancel(sub_inv[a, b]))
    return inv


def _sincos(expr: sm.Expr) -> sm.Expr:
    """tan(a) -> sin(a)/cos(a): the compiler then pairs sin and cos of one
    angle into a single sincos call (twice as fast as tan plus cos here)."""
    return expr.replace(sm.tan, lambda a: sm.sin(a) / sm.cos(a))


def _linear(expr: sm.Expr, speeds: Sequence[sm.Symbol]) -> dict[sm.Expr, sm.Expr] | None:
    """{u: coefficient, 1: constant} if expr is linear in the speeds."""
    try:
        poly = sm.Poly(sm.expand(expr), *speeds)
    except sm.PolynomialError:
        return None
    if poly.total_degree() > 1:
        return None
    out: dict[sm.Expr, sm.Expr] = {}
    for monom, coeff in poly.terms():
        key = sm.Mul(*(u**k for u, k in zip(speeds, monom, strict=True)))
        out[key] = coeff
    return out


def _reuse_earlier(exprs: Sequence[sm.Expr], speeds: Sequence[sm.Symbol]) -> list[sm.Expr]:
    """Write an output as rest + k * (an earlier output) when that earlier
    output's speed terms all appear in it with one common factor k.

    The kinematic equations of 3-1-2 angles have this shape: q3' equals
    u2 - sin(q2) q1'. CSE then computes q1' once instead of twice over.
    """
    forms = [_linear(e, speeds) for e in exprs]
    out = list(exprs)
    for j, fj in enumerate(forms):
        if fj is None:
            continue
        for i, fi in enumerate(forms[:j]):
            if fi is None:
                continue
            terms = [u for u in fi if u != 1]
            if len(terms) < 2 or not all(u in fj for u in terms):
                continue
            k = sm.trigsimp(sm.cancel(fj[terms[0]] / fi[terms[0]]))
            if any(sm.trigsimp(fj[u] - k * fi[u]) != 0 for u in terms):
                continue
            rest = sm.Add(*(c * u for u, c in fj.items() if u not in terms))
            cand = rest + k * (exprs[i] - fi.get(1, 0))
            if sm.count_ops(cand) < sm.count_ops(out[j]):
                out[j] = cand
    return out


def _cse(exprs: Sequence[sm.Expr], names: Iterator[sm.Symbol]) -> Block:
    """Common subexpressions of exprs, with every number in a form the code
    can write (literals.writable_form: before CSE, so it shares those)."""
    temps, reduced = sm.cse([writable_form(e) for e in exprs], symbols=names)
    return Block(tuple(Assignment(s, e) for s, e in temps), tuple(reduced))


def _temporaries() -> Iterator[sm.Symbol]:
    return sm.numbered_symbols("tmp", real=True)


def optimize(
    eqs: Equations,
    jacobian: bool = False,
    wrt: Sequence[str] = (),
    error: str = "all",
) -> Optimized:
    """Lumped + hoisted + CSE: the variant gyrogen generates; with jacobian,
    also d(dx/dt)/dx for the implicit integrators; with wrt (the scene's
    [sensitivities]), also the variational system (its constants after all
    the others but setup's condition number)."""
    inverse = block_inverse(eqs.mass_matrix)
    udot = inverse * eqs.forcing
    hoister = Hoister(eqs.gather)
    per_call = [*eqs.states, *eqs.inputs, *eqs.shared]
    dyn = [hoist(e, per_call, hoister) for e in udot]
    shared = {s: hoist(e, per_call, hoister) for s, e in eqs.shared.items()}
    n_q = len(eqs.kinematics)
    kin = _reuse_earlier([_sincos(e) for e in eqs.kinematics], eqs.states[n_q:])
    # a rotor angle's rate on a runtime axis reads setup's values: hoisted too
    kin = [hoist(e, per_call, hoister) if e.free_symbols - set(eqs.states) else e for e in kin]
    rhs = _rhs_block(shared, [*kin, *dyn], eqs.gather)
    outputs = {
        name: _cse([hoist(_sincos(e), per_call, hoister) for e in exprs], _temporaries())
        for name, exprs in eqs.outputs.items()
    }
    inline = _inlined(shared)
    jac = _jacobian([e.xreplace(inline) for e in (*kin, *dyn)], eqs.states) if jacobian else None
    linear = _linear_model(eqs, inverse, kin, hoister) if eqs.perturbed else None
    # the events' constants after every other's: a scene without events is as it was
    events = (
        _cse([hoist(_sincos(e), [*per_call, TIME], hoister) for e in eqs.events], _temporaries())
        if eqs.events
        else None
    )
    var, augmented, augmented_jac = None, None, None
    if wrt:
        f = [e.xreplace(inline) for e in (*kin, *dyn)]
        var = variational(f, eqs.states, eqs.params, wrt, error, hoister, eqs.lumped)
        augmented = _rhs_block(shared, [*kin, *dyn, *var.derivatives], eqs.gather)
        ny = len(eqs.states) + var.nv
        if jacobian and ny <= IMPLICIT_MAX_NY:
            y = (*eqs.states, *var.symbols)
            augmented_jac = _sparse_jacobian([*f, *var.derivatives], y)
    cluster = eqs.coupled.shape[0] == 3  # no reduced mass to multiply out
    values = [v if cluster else _multiplied_out(v, eqs.lumped) for v in hoister.values]
    det = sm.S.Zero if cluster else _multiplied_out(sm.Matrix(eqs.coupled).det(), eqs.lumped)
    setup, lumped = _setup(eqs, [*values, condition(eqs.coupled, det)])
    return Optimized(
        setup=setup,
        rhs=rhs,
        lumped=lumped,
        outputs=outputs,
        jacobian=jac,
        linear=linear,
        events=events,
        variational=var,
        augmented=augmented,
        augmented_jacobian=augmented_jac,
    )


def _linear_model(
    eqs: Equations, inverse: sm.Matrix, kin: list[sm.Expr], hoister: Hoister
) -> Block:
    """A = df/dx, B = df/du, C = dy/dx, D = dy/du at u = 0, row-major, from
    the perturbed equations hoisted after the scene's own (their constants
    come after the rhs's: the rhs and its constants stay as they were)."""
    pert = eqs.perturbed
    assert pert is not None
    per_call = [*eqs.states, *eqs.inputs, *pert.shared, *pert.controls]
    dyn = [hoist(e, per_call, hoister) for e in inverse * pert.forcing]
    shared = _inlined({s: hoist(e, per_call, hoister) for s, e in pert.shared.items()})
    f = [e.xreplace(shared) for e in (*kin, *dyn)]
    y = [hoist(_sincos(e), per_call, hoister) for exprs in pert.outputs.values() for e in exprs]
    at_zero = dict.fromkeys(pert.controls, sm.S.Zero)
    d = Derivatives()
    entries = [
        d.of(e, v).xreplace(at_zero)
        for rows, columns in (
            (f, eqs.states),
            (f, pert.controls),
            (y, eqs.states),
            (y, pert.controls),
        )
        for e in rows
        for v in columns
    ]
    return _cse(entries, _temporaries())


def _rhs_block(shared: dict[sm.Symbol, sm.Expr], f: list[sm.Expr], gather: bool) -> Block:
    """The named values first, then dx/dt by CSE; with gather (a cluster),
    one CSE over both, so the wheels' relative rates share their common
    terms too, each assignment after those it reads."""
    named = tuple(Assignment(s, e) for s, e in shared.items())
    if not gather:
        rhs = _cse(f, _temporaries())
        return Block(named + rhs.temporaries, rhs.outputs)
    both = _cse([*shared.values(), *f], _temporaries())
    n = len(shared)
    named = tuple(Assignment(s, e) for s, e in zip(shared, both.outputs[:n], strict=True))
    return Block(_in_order(both.temporaries + named), both.outputs[n:])


def _inlined(shared: dict[sm.Symbol, sm.Expr]) -> dict[sm.Symbol, sm.Expr]:
    """Each named value in states alone: a later one may read an earlier one
    (a wheel's net torque reads its relative rate)."""
    out: dict[sm.Symbol, sm.Expr] = {}
    for name, value in shared.items():
        out[name] = value.xreplace(out)
    return out


def condition(block: sm.Matrix, det: sm.Expr) -> sm.Expr:
    """lambda_max / lambda_min of a symmetric positive 2x2 block, the last
    constant of setup. lambda_min = det / lambda_max: the difference of the
    two terms of lambda_min would cancel for a badly conditioned block
    (det: the block's determinant in a form that does not). A rotor
    cluster's 3x3 block, folded: ||M||_F ||M^-1||_F (physics.frobenius_condition)."""
    if block.shape[0] == 3:
        cond = physics.frobenius_condition(block.tolist(), sm.sqrt)
        return as_double(cond, integers=False) if cond.is_number else cond
    cond = physics.condition(block[0, 0], block[0, 1], block[1, 1], det, sm.sqrt)
    return as_double(cond, integers=False) if cond.is_number else cond


MU = sm.Symbol("mu", positive=True)
"""The reduced mass m_a m_b / (m_a + m_b), a named scalar of setup."""


def _multiplied_out(value: sm.Expr, lumped: dict[sm.Symbol, sm.Expr]) -> sm.Expr:
    """value with each sum of lumped scalars multiplied out in the parameters.

    Each coupled lumped inertia is a carrier-plus-rotor part plus the rank-one
    mu (l3, -l1)(l3, -l1)^T, so in a sum such as I~11 I~33 - I~13^2 (or
    I~11 - I~22 + I~33) the mu terms cancel; in rounding that costs as many
    digits as the block's condition number has (1e-7 of the constants at
    cond 5e9, which the integrators then turn into invariant drift).
    Multiplied out, they cancel in sympy instead. Products and quotients
    keep their shape: only the sums change.
    """
    names = set(lumped)
    if not value.free_symbols & names:
        return value
    defs = _in_reduced_mass(lumped)

    def walk(e: sm.Expr) -> sm.Expr:
        if e.is_Add and e.free_symbols & names:
            return sm.expand(e.xreplace(defs))
        return e.func(*(walk(a) for a in e.args)) if e.args else e

    return walk(value)


def _in_reduced_mass(lumped: dict[sm.Symbol, sm.Expr]) -> dict[sm.Symbol, sm.Expr]:
    """The lumped definitions with m_a m_b / (m_a + m_b) as the symbol MU."""
    free = {s.name for e in lumped.values() for s in e.free_symbols}
    if not {"m_a", "m_b"} <= free:
        return lumped  # a folded mass: the reduced mass is a number
    mu = _reduced_mass(lumped)
    return {s: e.subs(mu, MU) for s, e in lumped.items()}


def _jacobian(f: list[sm.Expr], x: Sequence[sm.Symbol]) -> Block:
    """Row-major d f_i / d x_j of the hoisted right-hand side: it reads the
    same constants, so setup covers it too."""
    d = Derivatives()
    entries = [d.of(fi, xj) for fi in f for xj in x]
    return _cse(entries, _temporaries())


def _sparse_jacobian(f: list[sm.Expr], x: Sequence[sm.Symbol]) -> Block:
    """_jacobian, each row differentiated only by the states it reads (a
    large augmented system is mostly zeros)."""
    entries, d = [], Derivatives()
    for fi in f:
        read = fi.free_symbols
        entries += [d.of(fi, xj) if xj in read else sm.S.Zero for xj in x]
    return _cse(entries, _temporaries())


def _setup(eqs: Equations, values: list[sm.Expr]) -> tuple[Block, tuple[Assignment, ...]]:
    """The constants, after the named scalars they are written in.

    Two CSE passes share one numbering: the reduced mass mu and the lumped
    scalars come first, under their own names; only those some constant uses
    are computed.
    """
    used = set().union(*(v.free_symbols for v in values)) if values else set()
    defs = _in_reduced_mass(eqs.lumped)
    while True:  # a scalar may read another (I~ a runtime axis's normalized g)
        names_used = [s for s in eqs.lumped if s in used]
        more = set().union(*(defs[s].free_symbols for s in names_used)) if names_used else set()
        if more <= used:
            break
        used |= more
    named = {MU: _reduced_mass(eqs.lumped)} if MU in used else {}
    named.update({s: defs[s] for s in names_used})
    names = _temporaries()
    first = _cse(list(named.values()), names)
    # what the first pass computed (l3**2, ...), the second reads by name
    done = {a.rhs: a.lhs for a in first.temporaries}
    second = _cse([v.xreplace(done) for v in values], names)
    scalars = tuple(Assignment(s, v) for s, v in zip(named, first.outputs, strict=True))
    setup = Block(_in_order(first.temporaries + scalars) + second.temporaries, second.outputs)
    return setup, tuple(a for a in scalars if a.lhs in eqs.lumped)


def _in_order(assignments: tuple[Assignment, ...]) -> tuple[Assignment, ...]:
    """The assignments with each after those it reads, otherwise as given: a
    temporary of the first pass may read mu (two lumped scalars sharing
    mu l1^2 when l3 is folded to 0), which the pass assigns after them."""
    defined = {a.lhs for a in assignments}
    done: set[sm.Symbol] = set()
    out: list[Assignment] = []
    waiting = list(assignments)
    while waiting:
        ready = next(a for a in waiting if not (a.rhs.free_symbols & defined) - done)
        waiting.remove(ready)
        out.append(ready)
        done.add(ready.lhs)
    return tuple(out)


def _reduced_mass(lumped: dict[sm.Symbol, sm.Expr]) -> sm.Expr:
    free = {s.name: s for e in lumped.values() for s in e.free_symbols}
    return free["m_a"] * free["m_b"] / (free["m_a"] + free["m_b"])


def cse_only(exprs: Sequence[sm.Expr]) -> Block:
    """Variant (ii): common subexpressions alone, nothing hoisted."""
    return _cse(exprs, _temporaries())
