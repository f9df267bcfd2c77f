"""Hoisting and CSE: the per-call code reads states and constants only, is
small, and computes the same numbers as solving M u' = F directly."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sm

from gyrogen.codegen.generate import full_model_unit
from gyrogen.oracle import sampling
from gyrogen.runtime.compiled import Compiled
from gyrogen.symbolic import equations, hoist, model, optimize, specialize
from gyrogen.symbolic.derivative import Derivatives
from gyrogen.symbolic.opcounts import variants

RHS_GOAL = 50


def _evaluate(opt: optimize.Optimized, eqs: equations.Equations, p: np.ndarray, x: np.ndarray):
    """Run the two straight-line blocks in Python, as the C would."""
    env: dict[sm.Symbol, float] = dict(zip(eqs.params, p, strict=True))
    for a in opt.setup.temporaries:
        env[a.lhs] = float(a.rhs.evalf(subs=env))
    c = [float(e.evalf(subs=env)) for e in opt.setup.outputs]
    env2: dict[sm.Symbol, float] = dict(zip(hoist.constants(opt.nc), c, strict=True))
    env2.update(zip(eqs.states, x, strict=True))
    for a in opt.rhs.temporaries:
        env2[a.lhs] = float(a.rhs.evalf(subs=env2))
    return np.array([float(sm.sympify(e).evalf(subs=env2)) for e in opt.rhs.outputs])


def _direct(eqs: equations.Equations, p: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The unoptimized path: numbers into M and F, then a numeric solve."""
    subs = dict(zip(eqs.params, p, strict=True))
    subs.update({s: float(v.subs(subs)) for s, v in eqs.lumped.items()})
    subs.update(zip(eqs.states, x, strict=True))
    mm = np.array(eqs.mass_matrix.subs(subs).evalf(), dtype=float)
    f = np.array(eqs.forcing.subs(subs).evalf(), dtype=float).ravel()
    kin = np.array(eqs.kinematics.subs(subs).evalf(), dtype=float).ravel()
    return np.concatenate([kin, np.linalg.solve(mm, f)])


def test_optimized_equals_direct_solve() -> None:
    eqs = specialize.full_model()
    opt = optimize.optimize(eqs)
    rng = np.random.default_rng(3)
    params = sampling.random_parameters(rng, 4, max_condition=100)
    states = sampling.random_states(rng, 4)
    for p, x in zip(params, states, strict=True):
        np.testing.assert_allclose(
            _evaluate(opt, eqs, p, x), _direct(eqs, p, x), rtol=1e-11, atol=1e-11
        )


def test_rhs_reads_only_states_and_constants() -> None:
    eqs = specialize.full_model()
    opt = optimize.optimize(eqs)
    allowed = set(eqs.states) | set(hoist.constants(opt.nc))
    allowed |= {a.lhs for a in opt.rhs.temporaries}
    used = set().union(*(e.free_symbols for e in opt.rhs.outputs))
    used |= set().union(*(a.rhs.free_symbols for a in opt.rhs.temporaries))
    assert used <= allowed, used - allowed
    assert not used & set(eqs.params), "a parameter leaked into the per-call code"


def test_rhs_never_solves_a_linear_system() -> None:
    """No division by anything that depends on parameters or states except
    cos(q2) of the kinematics: the inverse of M lives in setup."""
    eqs = specialize.full_model()
    opt = optimize.optimize(eqs)
    q2 = eqs.states[1]
    for expr in [*opt.rhs.outputs, *(a.rhs for a in opt.rhs.temporaries)]:
        for pw in sm.preorder_traversal(expr):
            if isinstance(pw, sm.Pow) and pw.exp.is_negative:
                assert pw.base == sm.cos(q2), f"division by {pw.base} per call"


def test_setup_reads_only_parameters() -> None:
    eqs = specialize.full_model()
    opt = optimize.optimize(eqs)
    used = set().union(*(a.rhs.free_symbols for a in opt.setup.temporaries))
    used |= set().union(*(e.free_symbols for e in opt.setup.outputs))
    assert not used & set(eqs.states)


def test_rhs_op_count_meets_goal() -> None:
    opt = optimize.optimize(specialize.full_model())
    assert opt.rhs.ops <= RHS_GOAL


def test_variants_shrink_in_order() -> None:
    by = {v.key: v.ops for v in variants(full_model_unit().ops)}
    assert by["i"] > by["lu"] > by["ii"] > by["iii"]
    assert by["iii"] <= RHS_GOAL


def test_count_ops_counts_each_trig_once() -> None:
    a, b = sm.symbols("a b")
    assert optimize.count_ops([sm.sin(a)], [sm.cos(a) * b]) == 3


def test_block_inverse_matches_full_inverse() -> None:
    m = specialize.full_model().mass_matrix
    inv = optimize.block_inverse(m)
    assert sm.simplify(inv * m - sm.eye(7)) == sm.zeros(7, 7)


def test_kinematics_reuse_earlier_output() -> None:
    """q3' is written through q1' (u2 - sin(q2) q1'), and no tan is left."""
    opt = optimize.optimize(specialize.full_model())
    text = " ".join(str(a.rhs) for a in opt.rhs.temporaries) + " ".join(map(str, opt.rhs.outputs))
    assert "tan" not in text
    q1dot = opt.rhs.outputs[0]
    assert q1dot.is_Symbol and q1dot in opt.rhs.outputs[2].free_symbols


def test_lumped_scalars_are_named_in_setup() -> None:
    opt = optimize.optimize(specialize.full_model())
    names = [a.lhs for a in opt.lumped]
    assert names == list(model.symbols().lumped)
    assert set(names) <= {a.lhs for a in opt.setup.temporaries}


@pytest.mark.parametrize(
    "tiny",
    [pytest.param(5e-6, marks=pytest.mark.slow), pytest.param(1e-9, marks=pytest.mark.slow), 1e-12],
)  # the nearest to singular in the fast loop: each optimizes the full model, exact to 40 digits
def test_setup_constants_survive_a_nearly_singular_lumped_block(
    backends: dict[str, Compiled], tiny: float
) -> None:
    """A tiny carrier and rotor far from A* (the lumped block tends to rank
    one, cond ~ 1/tiny): the constants are still within a few ulp of their
    exact values for the given doubles, in C and Fortran, because the mu^2
    terms cancel in sympy rather than in rounding."""
    from gyrogen.analysis.check.cases import _dumbbell

    values = _dumbbell(tiny)
    p = np.array([values[s.name] for s in model.symbols().params])
    opt = optimize.optimize(specialize.full_model())
    exact: dict[sm.Basic, sm.Expr] = {
        s: sm.Rational(values[s.name]) for s in model.symbols().params
    }
    for a in opt.setup.temporaries:
        exact[a.lhs] = a.rhs.xreplace(exact)
    want = np.array([float(sm.N(e.xreplace(exact), 40)) for e in opt.setup.outputs])
    assert want[-1] > 0.1 / tiny  # the condition number: the case is as bad as meant
    for b in backends.values():
        code, c = b.setup_code(p)
        assert code == 0
        np.testing.assert_allclose(c, want, rtol=4e-16 * 8, atol=0)


def test_speed_controller_torque_is_rounded_once() -> None:
    """The carrier's and the rotor's equations read one named slip
    u4 - u2 - w_ref, not each its own expansion of k (u4 - u2 - w_ref): the
    angular momentum they exchange then cancels in rounding too."""
    from gyrogen.scene import load
    from gyrogen.symbolic.specialize import SLIP, specialize

    eqs = specialize(load("speed_controlled"))
    opt = optimize.optimize(eqs, jacobian=True)
    assert opt.rhs.temporaries[0].lhs == SLIP
    names = [s.name for s in eqs.states]
    u2dot, u4dot = (opt.rhs.outputs[names.index(n)] for n in ("u2", "u4"))
    assert SLIP in u2dot.free_symbols and u4dot.free_symbols <= {SLIP, *optimize_constants(opt)}
    assert opt.jacobian is not None
    jac = [*(a.rhs for a in opt.jacobian.temporaries), *opt.jacobian.outputs]
    assert all(SLIP not in e.free_symbols for e in jac)  # differentiated through


def optimize_constants(opt: optimize.Optimized) -> set[sm.Symbol]:
    return {s for e in opt.rhs.outputs for s in e.free_symbols if s.name.startswith("c")}


def _same(a: sm.Expr, b: sm.Expr) -> bool:
    """The same tree, not merely equal values."""
    return sm.srepr(a) == sm.srepr(b)


def test_derivatives_are_sympys_own_expressions() -> None:
    """Derivatives.of builds what sm.diff builds, node by node: Add, Mul,
    Pow (numeric and symbolic exponents), sin, cos by its rules; Min, Max,
    Abs and the rest through sm.diff; shared subexpressions and floats."""
    x, y, z = sm.symbols("x y z", real=True)
    shared = sm.sin(x * y) + 0.5 * z**2
    exprs = [
        x * y * z + 2.5 * x - sm.Rational(1, 3) * y,
        (x + y) ** -1 * shared + shared**2 / (1 + z**2),
        sm.sqrt(x**2 + y**2) * sm.cos(shared) - sm.sin(x) * sm.cos(y) * shared,
        x**y + sm.Min(sm.Max(x - y, -1.0), 1.0) * z,
        sm.Abs(x - z) + 3 * (x + 2 * y) * (y - z),
        sm.Integer(7),
        z,
    ]
    d = Derivatives()
    for e in exprs:
        for v in (x, y, z):
            assert _same(d.of(e, v), sm.diff(e, v)), (e, v)


@pytest.mark.parametrize("name", ["gyrostat", "speed_controlled"])
def test_jacobian_entries_are_sympys(name: str) -> None:
    """On a scene's right-hand side, its named values inlined (the
    Jacobian's input): every entry the tree sm.diff gives."""
    from gyrogen.scene import load

    eqs = specialize.specialize(load(name))
    opt = optimize.optimize(eqs)
    inline: dict[sm.Symbol, sm.Expr] = {}
    for a in opt.rhs.temporaries:
        inline[a.lhs] = a.rhs.xreplace(inline)
    f = [e.xreplace(inline) for e in opt.rhs.outputs]
    d = Derivatives()
    for fi in f:
        for xj in eqs.states:
            assert _same(d.of(fi, xj), sm.diff(fi, xj))


def test_horner_forms_are_sympys_in_every_order() -> None:
    """hoist._horner, its inner forms shared between orders, gives the
    expression sm.horner gives for each order of the variables."""
    import itertools

    x, y, z = sm.symbols("x y z", real=True)
    c = sm.symbols("c0:6", real=True)
    poly = c[0] * x**2 * y + c[1] * x * y * z - c[2] * y**2 * z + c[3] * x + c[4] * z**3 + c[5]
    done: dict = {}
    for order in itertools.permutations((x, y, z)):
        assert _same(hoist._horner(poly, order, done), sm.horner(poly, *order))
