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


Matrix3 = list[list[Value]]
Rotor = tuple[Value, Value, Any, Any]
"""(m, I, g, r): mass, transverse inertia, unit axis and B* from A* (3-sequences)."""


def cluster_inertia(m_a: Value, carrier: Matrix3, rotors: list[Rotor]) -> Matrix3:
    """A rotor cluster's lumped inertia about its mass center C, A-components:
    the carrier about A* and each rotor's transverse inertia I (1 - g g^T),
    plus every mass's offset from C (A* at the origin, C = sum m r / M); the
    axial inertias J stay with the wheel rates."""
    total = m_a + sum(m for m, _, _, _ in rotors)
    c = [sum(m * r[i] for m, _, _, r in rotors) / total for i in range(3)]
    points = [(m_a, [-x for x in c])] + [
        (m, [r[i] - c[i] for i in range(3)]) for m, _, _, r in rotors
    ]
    out = [[carrier[i][j] for j in range(3)] for i in range(3)]
    for i in range(3):
        for j in range(3):
            for m, rho in points:
                out[i][j] += m * (
                    (rho[0] ** 2 + rho[1] ** 2 + rho[2] ** 2) * int(i == j) - rho[i] * rho[j]
                )
            for _, inertia, g, _ in rotors:
                out[i][j] += inertia * (int(i == j) - g[i] * g[j])
    return out


def adjugate(a: Matrix3) -> Matrix3:
    """The adjugate of a 3x3 matrix (its inverse times its determinant)."""

    def cof(i: int, j: int) -> Value:
        r = [k for k in range(3) if k != i]
        s = [k for k in range(3) if k != j]
        return a[r[0]][s[0]] * a[r[1]][s[1]] - a[r[0]][s[1]] * a[r[1]][s[0]]

    return [[(-1) ** (i + j) * cof(j, i) for j in range(3)] for i in range(3)]


def frobenius_condition(a: Matrix3, sqrt: Callable[[Value], Value] = lambda x: x**0.5) -> Value:
    """||A||_F ||A^-1||_F of a 3x3 matrix: at least its condition number and at
    most 3 times it; infinite for a singular one (floats). Floats are taken
    over their largest entry first (the ratio does not change, and squares of
    entries past 1e154 would overflow)."""
    if all(isinstance(x, int | float) for row in a for x in row):
        big = max(abs(float(x)) for row in a for x in row)
        if 0 < big < float("inf"):
            a = [[float(x) / big for x in row] for row in a]
    adj = adjugate(a)
    det = sum(a[0][j] * adj[j][0] for j in range(3))
    norm = sqrt(sum(x**2 for row in a for x in row))
    norm_adj = sqrt(sum(x**2 for row in adj for x in row))
    if det == 0:
        return float("inf")
    return norm * norm_adj / abs(det)
