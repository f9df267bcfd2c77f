"""The paper's formulas that gyrogen's stages share, written once for
numbers and sympy symbols alike (NOTES.md, "The lumped inertia scalars").

The symbolic model derives the lumped formulation with them, the scene
validator checks folded values with them, and the checks predict spin
stability with them. The numpy reference (gyrogen.oracle) keeps its own,
written by hand from the paper, on purpose: it checks these.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

Value = Any
"""A float, a numpy array or a sympy expression: the formulas only add,
multiply and divide (and take the square root they are given)."""


def reduced_mass(m_a: Value, m_b: Value) -> Value:
    """mu = m_a m_b / (m_a + m_b)."""
    return m_a * m_b / (m_a + m_b)


LUMPED_FROM = ("m_a", "m_b", "I11", "I22", "I33", "I13", "I", "l1", "l3")
"""The parameters lumped_inertias takes, in its order."""


def lumped_inertias(
    m_a: Value, m_b: Value, I11: Value, I22: Value, I33: Value, I13: Value, I: Value,
    l1: Value, l3: Value,
) -> tuple[Value, Value, Value, Value]:  # fmt: skip
    """I~11, I~22, I~33, I~13 of the lumped carrier A~ about AB* (J~ = J)."""
    mu = reduced_mass(m_a, m_b)
    return (
        I11 + I + mu * l3**2,
        I22 + mu * (l1**2 + l3**2),
        I33 + I + mu * l1**2,
        I13 - mu * l1 * l3,
    )


def coupled_determinant(
    m_a: Value, m_b: Value, I11: Value, I33: Value, I13: Value, I: Value, l1: Value, l3: Value
) -> Value:
    """I~11 I~33 - I~13^2 multiplied out in the parameters: the mu^2 terms
    of the lumped form cancel here exactly, not in rounding."""
    i11, i33 = I11 + I, I33 + I
    mu = reduced_mass(m_a, m_b)
    return i11 * i33 - I13**2 + mu * (l1**2 * i11 + l3**2 * i33 + 2 * I13 * l1 * l3)


def condition(
    a11: Value, a13: Value, a33: Value, det: Value, sqrt: Callable[[Value], Value]
) -> Value:
    """lambda_max / lambda_min of the symmetric positive block [[a11, a13],
    [a13, a33]] of determinant det, with lambda_min = det / lambda_max (the
    difference of lambda_min's two terms would cancel for a badly
    conditioned block)."""
    big = (a11 + a33) / 2 + sqrt((a11 - a33) ** 2 / 4 + a13**2)
    return big**2 / det


def body_momentum(
    lumped: tuple[Value, Value, Value, Value], J: Value, u1: Value, u2: Value, u3: Value, u4: Value
) -> tuple[Value, Value, Value]:
    """The angular momentum about AB* in A components, from the lumped
    inertias (I~11, I~22, I~33, I~13): I~ (u1, u2, u3) + J u4 a2. Its a2
    component is NOTES.md's H_a of the spin-stability criterion."""
    a11, a22, a33, a13 = lumped
    return a11 * u1 + a13 * u3, a22 * u2 + J * u4, a13 * u1 + a33 * u3
