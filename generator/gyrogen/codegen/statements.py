"""What the two backends share: one statement list per generated function.

A printer turns one expression into text; the templates lay out the file.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import sympy as sm
from sympy.printing.precedence import PRECEDENCE

from gyrogen.codegen.context import SceneContext
from gyrogen.codegen.integrators.trig import VARIANTS
from gyrogen.symbolic.literals import LiteralError, writable
from gyrogen.symbolic.optimize import Block


class WritableNumbers:
    """A printer mixin: a number the target cannot write as it is (see
    gyrogen.symbolic.literals) is an error here, never a truncated literal. optimize
    puts every expression in writable form first, so this is the last guard."""

    def _print_Integer(self, expr: sm.Integer) -> str:
        self._check(expr)
        return str(super()._print_Integer(expr))  # type: ignore[misc]

    def _print_Rational(self, expr: sm.Rational) -> str:
        self._check(expr)
        return str(super()._print_Rational(expr))  # type: ignore[misc]

    @staticmethod
    def _check(expr: sm.Rational) -> None:
        if not writable(expr):
            raise LiteralError(f"internal: the number {expr} reached a printer unconverted")


class SmallPowers:
    """A printer mixin: small integer powers as products (x*x beats pow(x, 2)
    in C; in Fortran x**2 would round a*x**2 as a*(x*x), where C rounds
    a*x*x as (a*x)*x), so that both languages print, and round, alike."""

    def _print_Pow(self, expr: sm.Pow) -> str:
        base, exp = expr.base, expr.exp
        if exp.is_Integer and 1 <= abs(int(exp)) <= 3:
            b = self.parenthesize(  # type: ignore[attr-defined]
                base, PRECEDENCE["Mul"] + 1
            )
            n = abs(int(exp))
            one = self._print(sm.Float(1.0))  # type: ignore[attr-defined]
            if n == 1:
                return f"{one}/{b}"
            prod = "*".join([b] * n)
            return prod if exp > 0 else f"{one}/({prod})"
        return str(super()._print_Pow(expr))  # type: ignore[misc]

    def _print_Mul(self, expr: sm.Mul) -> str:
        """sympy writes a lone denominator bare (a/b**2 as "a/" + Pow), trusting
        a power to bind tighter than "/"; the products above do not, so
        a/b**2 must read a/(b*b), not a/b*b."""
        den = [f for f in expr.args if f.is_Pow and f.exp.is_Rational and f.exp.is_negative]
        if len(den) != 1 or not (den[0].exp.is_Integer and -3 <= den[0].exp <= -2):
            return str(super()._print_Mul(expr))  # type: ignore[misc]
        if expr.as_coeff_Mul()[0] < 0:
            return "-" + self._print(-expr)  # type: ignore[attr-defined]
        num = sm.Mul(*(f for f in expr.args if f is not den[0]))
        text = self.parenthesize(num, PRECEDENCE["Mul"], strict=True)  # type: ignore[attr-defined]
        return f"{text}/({self._print(1 / den[0])})"  # type: ignore[attr-defined]


@dataclass(frozen=True)
class Statement:
    name: str
    code: str
    """The whole assignment as the language writes it (possibly several lines)."""
    declare: bool
    """A new local (true) or a store into an output array (false)."""


@dataclass(frozen=True)
class Function:
    """One per-call function (rhs or an output) ready for a template."""

    name: str
    doc: str
    unit: str
    statements: list[Statement]
    states: list[int]
    """Indices of the states it reads: only those become locals."""
    tables: list[str]
    """The tabulated torques T(t) it reads (torque; a cluster's torque_k)."""

    @property
    def torque(self) -> bool:
        """Reads a tabulated torque."""
        return bool(self.tables)


Assign = Callable[[str, sm.Expr], str]


def statements(block: Block, output: Callable[[int], str], assign: Assign) -> list[Statement]:
    """Temporaries as locals, then one store per output."""
    temps = [Statement(str(a.lhs), assign(str(a.lhs), a.rhs), True) for a in block.temporaries]
    stores = []
    for i, e in enumerate(block.outputs):
        lhs = output(i)
        stores.append(Statement(lhs, assign(lhs, e), False))
    return temps + stores


def functions(
    unit: SceneContext, array: Callable[[str, int], str], assign: Assign
) -> list[Function]:
    """rhs first, then the scene's outputs; array(name, i) spells name[i]."""
    blocks = [("rhs", unit.optimized.rhs, "dxdt", "dx/dt", "")]
    blocks += [(o.name, o.block, "out", o.doc, o.unit) for o in unit.outputs]
    return [_function(unit, array, assign, *b) for b in blocks]


def jacobian(
    unit: SceneContext, array: Callable[[str, int], str], assign: Assign
) -> Function | None:
    """d(dx/dt)/dx into J, row-major (J[i*NX + j] = d f_i / d x_j)."""
    block = unit.optimized.jacobian
    if block is None:
        return None
    return _function(unit, array, assign, "jac", block, "J", "d(dx/dt)/dx, row-major", "1/s")


def linear(unit: SceneContext, array: Callable[[str, int], str], assign: Assign) -> Function | None:
    """A, B, C, D of the linear model, each row-major (A[i*NX + j] = d f_i /
    d x_j, B[i*NU + j] = d f_i / d u_j, C and D alike for the outputs y)."""
    block = unit.optimized.linear
    if block is None:
        return None
    sizes = unit.linear_sizes
    edges = [0]
    for rows, cols in sizes.values():
        edges.append(edges[-1] + rows * cols)
    names = list(sizes)

    def at(arr: str, i: int) -> str:
        k = max(j for j in range(len(names)) if edges[j] <= i)
        return array(names[k], i - edges[k])

    doc = "the linear model: A = df/dx, B = df/du, C = dy/dx, D = dy/du, row-major"
    return _function(unit, at, assign, "linear", block, "", doc, "")


def _function(
    unit: SceneContext,
    array: Callable[[str, int], str],
    assign: Assign,
    name: str,
    block: Block,
    arr: str,
    doc: str,
    units: str,
) -> Function:
    free = block.free_symbols
    return Function(
        name=name,
        doc=doc,
        unit=units,
        statements=statements(block, partial(array, arr), assign),
        states=[i for i, s in enumerate(unit.states) if s in free],
        tables=[s.name for s in unit.equations.inputs if s in free],
    )


def trig_used(prefix: str, fns: list[Function | None]) -> list[str]:
    """Which of <prefix>_sin, <prefix>_cos and their _lanes twins the
    functions call (gyrogen.codegen.integrators.trig): a file defines only
    those (clang warns of an unused static inline function)."""
    text = " ".join(s.code for f in fns if f is not None for s in f.statements)
    return [name for name in VARIANTS if f"{prefix}_{name}(" in text]
