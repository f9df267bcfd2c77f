"""Op counts of the ways one could code the full model, for the report.

The measure is the issue's: sympy.count_ops summed over every assignment of
a function, CSE temporaries included, each sin/cos/tan counted once.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import sympy as sm

from gyrogen.scene import Scene
from gyrogen.scene.rotors import Rotor
from gyrogen.symbolic import equations, model
from gyrogen.symbolic.optimize import Assignment, count_ops, cse_only


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


def _mass(r: Rotor) -> float | str:
    """A rotor on a gimbal's wheel and frame mass: "runtime" if either is."""
    assert r.gimbal is not None
    if "runtime" in (r.m, r.gimbal.m):
        return "runtime"
    return float(r.m) + float(r.gimbal.m)


def gimbal_split(scene: Scene) -> list[Variant]:
    """A cluster with rotors on gimbals: its rhs's ops split into the same
    cluster with each wheel fixed at its gimbal angle 0 (gimbal frame's mass
    kept), the carrier's 3 x 3 solve (cofactors, determinant, w_A'), and the
    rest: the gimbals' kinematics (sin, cos, g_s . w_A, g_t . w_A, I~(gam))
    and their terms in h, f, nu' and gd'."""
    from gyrogen.symbolic.gimbals import COFACTORS, DET, SOLVED
    from gyrogen.symbolic.optimize import optimize
    from gyrogen.symbolic.specialize import specialize

    rhs = optimize(specialize(scene)).rhs
    fixed = [
        r if r.gimbal is None else r.model_copy(update={"gimbal": None, "m": _mass(r)})
        for r in scene.rotors
    ]
    fixed_ops = optimize(specialize(scene.model_copy(update={"rotors": fixed}))).rhs.ops
    solve = _only_for(rhs.temporaries, {*COFACTORS, DET, *SOLVED})
    return [
        Variant("fixed", "the same cluster, each wheel fixed at gimbal angle 0", fixed_ops),
        Variant("solve", "the carrier's 3x3 solve: cofactors, determinant, w_A'", solve),
        Variant(
            "gimbal", "the gimbals' kinematics and terms (the rest)", rhs.ops - fixed_ops - solve
        ),
        Variant("rhs", "the rhs with the rotors on gimbals", rhs.ops),
    ]


def _only_for(assignments: tuple[Assignment, ...], names: set[str]) -> int:
    """The ops of the assignments to names and of the CSE temporaries
    (tmp<n>) that only they read (one read elsewhere is not counted)."""
    mine = {a.lhs for a in assignments if a.lhs.name in names}
    readers: dict[sm.Symbol, set[sm.Symbol]] = {a.lhs: set() for a in assignments}
    for a in assignments:
        for s in a.rhs.free_symbols & set(readers):
            readers[s].add(a.lhs)
    for a in reversed(assignments):
        temporary = a.lhs.name.startswith("tmp")
        if temporary and a.lhs not in mine and readers[a.lhs] and readers[a.lhs] <= mine:
            mine.add(a.lhs)
    return count_ops([a.rhs for a in assignments if a.lhs in mine])
