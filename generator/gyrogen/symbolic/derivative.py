"""sympy's derivatives, each distinct subexpression differentiated once.

sm.diff(e, x) walks e's whole subtree at every node it differentiates (its
free symbols, then the result, for Derivative objects to make canonical),
and its cache holds the last 1000 results: on a right-hand side whose named
values are inlined (one subexpression read by many, the 3x3 solve of a
gimbal cluster in every rate) that was most of the Jacobian's time. Here
each node's derivative is built by the rule sympy applies to its type (Add,
Mul, Pow, sin, cos), from its arguments' derivatives, each kept once per
variable; any other type goes to sm.diff. The result is the expression
sm.diff gives, the same tree (tests compare them): the generated code does
not change.
"""

from __future__ import annotations

import sympy as sm
from sympy.ntheory.multinomial import multinomial_coefficients_iterator

_RULES = (sm.Add, sm.Mul, sm.Pow, sm.sin, sm.cos)
"""The types differentiated here; their free symbols are their arguments'."""


class Derivatives:
    """d e / d x for many e and x over shared subexpressions: of(e, x)."""

    def __init__(self) -> None:
        self._free: dict[sm.Basic, frozenset[sm.Basic]] = {}
        self._done: dict[tuple[sm.Basic, sm.Basic], sm.Expr] = {}

    def free(self, e: sm.Basic) -> frozenset[sm.Basic]:
        got = self._free.get(e)
        if got is None:
            if type(e) in _RULES:
                got = frozenset().union(*(self.free(a) for a in e.args))
            else:
                got = frozenset(e.free_symbols)
            self._free[e] = got
        return got

    def of(self, e: sm.Expr, x: sm.Symbol) -> sm.Expr:
        """sm.diff(e, x)."""
        if not isinstance(x, sm.Symbol):
            return sm.diff(e, x)
        key = (e, x)
        got = self._done.get(key)
        if got is None:
            got = self._rule(e, x)
            self._done[key] = got
        return got

    def _rule(self, e: sm.Expr, x: sm.Symbol) -> sm.Expr:
        if x not in self.free(e):
            return sm.S.Zero
        if e == x:
            return sm.S.One
        kind = type(e)
        if kind is sm.Add:  # Add._eval_derivative
            return sm.Add(*(self.of(a, x) for a in e.args))
        if kind is sm.Mul:  # Mul._eval_derivative_n_times, once: the Leibniz rule
            terms = []
            for ks, c in multinomial_coefficients_iterator(len(e.args), 1):
                factors = (self.of(a, x) if k else a for k, a in zip(ks, e.args, strict=True))
                terms.append(c * sm.Mul(*factors))
            return sm.Add(*terms)
        if kind is sm.Pow:  # Pow._eval_derivative
            d_base, d_exp = self.of(e.base, x), self.of(e.exp, x)
            return e * (d_exp * sm.log(e.base) + d_base * e.exp / e.base)
        if kind in (sm.sin, sm.cos):  # Function._eval_derivative
            parts = []
            for i, a in enumerate(e.args, 1):
                d = self.of(a, x)
                if d.is_zero:
                    continue
                parts.append(e.fdiff(i) * d)
            return sm.Add(*parts)
        return sm.diff(e, x)
