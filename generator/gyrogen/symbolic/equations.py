"""The equations gyrogen generates code for: M u' = F, q' = f, and the
optional outputs, for the states a scene keeps.

Plain symbols (q1, not q1(t)), so printers and CSE see ordinary variables.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import sympy as sm
import sympy.physics.mechanics as me

from gyrogen.symbolic import model


@dataclass(frozen=True)
class Equations:
    states: tuple[sm.Symbol, ...]
    """Kept states, in x[] order."""
    params: tuple[sm.Symbol, ...]
    """Runtime parameters, in p[] order; every other parameter is folded."""
    mass_matrix: sm.Matrix
    """Constant: depends on parameters and lumped scalars only."""
    forcing: sm.Matrix
    kinematics: sm.Matrix
    """q' for the kept coordinates, in state order."""
    lumped: dict[sm.Symbol, sm.Expr]
    """Lumped inertia scalars that depend on runtime parameters, in terms of
    them (the others are numbers, already substituted)."""
    inputs: tuple[sm.Symbol, ...] = ()
    """Per-call values that are not states: the torque of a T(t) table."""
    outputs: dict[str, tuple[sm.Expr, ...]] = field(default_factory=dict)
    """Optional extra functions, by name, in states, inputs and parameters."""
    checks: dict[str, sm.Expr] = field(default_factory=dict)
    """The parameters setup checks, by name: a runtime symbol or a number."""
    coupled: sm.Matrix = field(default_factory=lambda: sm.eye(2))
    """The mass matrix's coupled block (rows and columns of u1, u3)."""
    shared: dict[sm.Symbol, sm.Expr] = field(default_factory=dict)
    """Per-call values the forcing reads by name, in states and parameters,
    each computed once at the top of the rhs: the speed controller's slip.
    Expanded into monomials, the carrier's and the rotor's equations would
    each round their own copy of a large torque; with one rounded torque the
    angular momentum they exchange cancels (drift 1e-10 -> 1e-15 at
    k/J = 1e6)."""


def plain(expr: sm.Expr | sm.Matrix) -> sm.Expr | sm.Matrix:
    """q1(t) -> q1 and so on for every state of the model."""
    s = model.symbols()
    swap = {f: sm.Symbol(f.func.__name__, real=True) for f in (*s.q, *s.u)}
    return me.msubs(expr, swap)


def plain_states() -> tuple[sm.Symbol, ...]:
    s = model.symbols()
    return tuple(sm.Symbol(f.func.__name__, real=True) for f in s.states)
