"""Op counts of the ways one could code the full model, for the report.

The measure is the issue's: sympy.count_ops summed over every assignment of
a function, CSE temporaries included, each sin/cos/tan counted once.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from gyrogen.symbolic import equations, model
from gyrogen.symbolic.optimize import count_ops, cse_only


@dataclass(frozen=True)
class Variant:
    key: str
    what: str
    ops: int


def variants(lumped: Mapping[str, int]) -> list[Variant]:
    """The ways to code the full model; lumped: the ops of the one gyrogen
    generates (the default scene's unit.ops, which its caller has)."""
    sep = model.separate()
    mm, f, kin = (equations.plain(m) for m in (sep.mass_matrix, sep.forcing, sep.kinematics))
    lu = mm.LUsolve(f)
    return [
        Variant("i", "separate bodies: raw mass matrix and forcing", count_ops(mm, f)),
        Variant(
            "ii", "separate bodies: CSE alone (mass matrix and forcing)", cse_only([*mm, *f]).ops
        ),
        Variant(
            "lu",
            "separate bodies: symbolic LU solve + kinematics, then CSE",
            cse_only([*kin, *lu]).ops,
        ),
        Variant("iii", "lumped + hoisted + CSE: per-call rhs, kinematics included", lumped["rhs"]),
        Variant("setup", "lumped + hoisted + CSE: setup, once per parameter set", lumped["setup"]),
    ]
