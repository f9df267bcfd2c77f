"""The paper's claim, checked symbolically: substituting the lumped inertia
scalars into formulation (b) gives exactly the mass matrix and forcing that
KanesMethod derives for the two separate bodies (a)."""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sm

from gyrogen.symbolic import model


@dataclass(frozen=True)
class Comparison:
    what: str
    entries: int
    nonzero: tuple[str, ...]
    """Entries whose difference did not simplify to zero (empty: equal)."""

    @property
    def equal(self) -> bool:
        return not self.nonzero


def _compare(what: str, a: sm.Matrix, b: sm.Matrix) -> Comparison:
    bad = []
    for i in range(a.rows):
        for j in range(a.cols):
            if sm.simplify(b[i, j] - a[i, j]) != 0:
                bad.append(f"[{i + 1},{j + 1}]" if a.cols > 1 else f"[{i + 1}]")
    return Comparison(what, a.rows * a.cols, tuple(bad))


def prove() -> list[Comparison]:
    sep, lum = model.separate(), model.lumped()
    sub = model.lumped_values()
    return [
        _compare("mass matrix (7x7)", sep.mass_matrix, lum.mass_matrix.subs(sub)),
        _compare("forcing (7)", sep.forcing, lum.forcing.subs(sub)),
        _compare("kinematic equations (7)", sep.kinematics, lum.kinematics),
    ]
