"""The equations gyrogen generates code for: M u' = F and q' = f.

Plain symbols (q1, not q1(t)), so printers and CSE see ordinary variables.
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sm
import sympy.physics.mechanics as me

from gyrogen import model


@dataclass(frozen=True)
class Equations:
    states: tuple[sm.Symbol, ...]
    params: tuple[sm.Symbol, ...]
    mass_matrix: sm.Matrix
    """Constant: depends on parameters and lumped scalars only."""
    forcing: sm.Matrix
    kinematics: sm.Matrix
    """q' for the coordinates, in state order."""
    lumped: dict[sm.Symbol, sm.Expr]
    """Lumped inertia scalars in terms of the parameters, in paper order."""


def plain(expr: sm.Expr | sm.Matrix) -> sm.Expr | sm.Matrix:
    """q1(t) -> q1 and so on for every state of the model."""
    s = model.symbols()
    swap = {f: sm.Symbol(f.func.__name__, real=True) for f in (*s.q, *s.u)}
    return me.msubs(expr, swap)


def plain_states() -> tuple[sm.Symbol, ...]:
    s = model.symbols()
    return tuple(sm.Symbol(f.func.__name__, real=True) for f in s.states)


def full_model() -> Equations:
    """The paper's full model from the lumped formulation (b)."""
    kane = model.lumped()
    s = model.symbols()
    return Equations(
        states=plain_states(),
        params=s.params,
        mass_matrix=plain(kane.mass_matrix),
        forcing=plain(kane.forcing),
        kinematics=plain(kane.kinematics),
        lumped=model.lumped_values(),
    )
