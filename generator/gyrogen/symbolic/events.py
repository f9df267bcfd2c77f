"""A scene's events (gyrogen.scene.events) as sympy: each expression in the
kept states, the runtime parameters (a folded one as the exact rational of
its decimal, as every folded value), the outputs the scene computes and the
time t."""

from __future__ import annotations

import sympy as sm

from gyrogen.errors import SceneError
from gyrogen.scene import Scene
from gyrogen.scene.events import TIME, Node, evaluate, parse
from gyrogen.symbolic.equations import TIME as T
from gyrogen.symbolic.equations import Equations

FUNCTIONS = {
    "sin": sm.sin,
    "cos": sm.cos,
    "sqrt": sm.sqrt,
    "abs": sm.Abs,
    "min": sm.Min,
    "max": sm.Max,
}


def events(scene: Scene, eqs: Equations) -> tuple[sm.Expr, ...]:
    states = {s.name: s for s in eqs.states}
    runtime = {s.name: s for s in eqs.params}
    folded = scene.folded()

    def value(leaf: Node) -> sm.Expr:
        if leaf[0] == "output":
            return eqs.outputs[leaf[1]][leaf[2]]
        name = str(leaf[1])
        if name in states:
            return states[name]
        if name in runtime:
            return runtime[name]
        if name in folded:
            return sm.Rational(repr(float(folded[name])))
        if name == TIME:
            return T
        return eqs.outputs[name][0]  # an output of one value (the scene validated the name)

    def exact(v: float) -> sm.Expr:
        return sm.Rational(repr(v))  # the decimal as written, as folded values

    out = []
    for k, ev in enumerate(scene.events):
        g = sm.sympify(evaluate(parse(ev.expr), value, FUNCTIONS, exact))
        rooted = any(p.base.is_negative and not p.exp.is_integer for p in g.atoms(sm.Pow))
        if rooted or g.has(sm.I, sm.zoo, sm.oo, -sm.oo, sm.nan):
            raise SceneError(
                f"events.{k}.expr: {ev.expr!r} is not a finite real number everywhere (it reads "
                f"as {str(g)[:80]}: a division by zero, or a root of a negative number)"
            )
        out.append(g)
    return tuple(out)
