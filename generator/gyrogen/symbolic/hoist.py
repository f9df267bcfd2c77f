"""Hoisting: every coefficient that depends on parameters only becomes a
constant computed once in setup; what is left per call is a polynomial in
the states with constant coefficients, shaped by Horner's scheme."""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import sympy as sm
from sympy.polys.polyerrors import PolificationFailed
from sympy.polys.polytools import poly_from_expr

from gyrogen.symbolic.literals import as_double


def constants(n: int) -> tuple[sm.Symbol, ...]:
    return tuple(sm.Symbol(f"c{k}", real=True) for k in range(n))


class Hoister:
    """Gives each parameter-only coefficient a constant, sharing equal ones
    and ones that differ only in sign."""

    def __init__(self, gather: bool = False) -> None:
        self.gather = gather
        """Shape linear sums with gathered (Equations.gather)."""
        self.values: list[sm.Expr] = []
        self._index: dict[sm.Expr, int] = {}

    def symbol_for(self, coeff: sm.Expr, simplify: bool = True) -> sm.Expr:
        """coeff's constant; simplify: factored first (a derivative's many
        long coefficients are not: setup's CSE shares their terms)."""
        coeff = sm.factor(sm.cancel(coeff)) if simplify else coeff
        if coeff.is_number:
            return as_double(coeff)
        if coeff in self._index:
            return constants(self._index[coeff] + 1)[-1]
        neg = sm.factor(-coeff) if simplify else -coeff
        if neg in self._index:
            return -constants(self._index[neg] + 1)[-1]
        self._index[coeff] = len(self.values)
        self.values.append(coeff)
        return constants(len(self.values))[-1]


_EXHAUSTIVE = 5
"""Up to this many variables every Horner order is tried (5! = 120)."""


def _orders(poly: sm.Poly) -> list[tuple[sm.Expr, ...]]:
    gens = poly.gens
    if len(gens) <= _EXHAUSTIVE:
        return list(itertools.permutations(gens))
    # Too many to try: the variables in the most terms first.
    counts = [sum(1 for m in poly.monoms() if m[i]) for i in range(len(gens))]
    ranked = sorted(range(len(gens)), key=lambda i: (-counts[i], str(gens[i])))
    return [tuple(gens[i] for i in ranked)]


def _best_horner(expr: sm.Expr, gens: Sequence[sm.Expr], gather: bool) -> sm.Expr:
    """Horner's scheme in the variable order that leaves the fewest ops."""
    if not gens:
        return expr
    poly = sm.Poly(expr, *gens)
    shape = gathered if gather else (lambda e: e)
    if poly.total_degree() <= 1:  # linear: no order leaves fewer ops
        return shape(expr)
    best, best_ops = expr, int(sm.count_ops(expr))
    done: dict[tuple[sm.Expr, tuple[sm.Expr, ...]], sm.Expr] = {}
    for order in _orders(poly):
        cand = _horner(expr, tuple(order), done)
        ops = int(sm.count_ops(cand))
        if ops < best_ops:
            best, best_ops = cand, ops
    return shape(best)


def _horner(
    f: sm.Expr, gens: tuple[sm.Expr, ...], done: dict[tuple[sm.Expr, tuple[sm.Expr, ...]], sm.Expr]
) -> sm.Expr:
    """sm.horner(f, *gens) by its steps, each (expression, variables) once
    in done: the orders that end alike share their inner forms (a
    coefficient's form in the last variables), so trying every order does
    not build them again. The same expression as sm.horner."""
    key = (f, gens)
    got = done.get(key)
    if got is None:
        try:
            poly, _ = poly_from_expr(f, *gens)
        except PolificationFailed as exc:
            got = exc.expr
        else:
            got, gen = sm.S.Zero, poly.gen
            if poly.is_univariate:
                for coeff in poly.all_coeffs():
                    got = got * gen + coeff
            else:
                for coeff in sm.Poly(poly, gen).all_coeffs():
                    got = got * gen + _horner(coeff, gens[1:], done)
        done[key] = got
    return got


def gathered(linear: sm.Expr) -> sm.Expr:
    """A linear form with the terms of one |coefficient| summed before one
    multiply: k (x - y + z) for k x - k y + k z (a cluster's symmetric
    axes give such sums)."""
    groups: dict[sm.Expr, list[sm.Expr]] = {}
    rest = []
    for term in sm.Add.make_args(linear):
        coeff, var = term.as_coeff_Mul()
        if coeff.is_number and var.free_symbols and abs(coeff) != 1:
            groups.setdefault(abs(coeff), []).append(sm.sign(coeff) * var)
        else:
            rest.append(term)
    if all(len(terms) < 2 for terms in groups.values()):
        return linear
    parts = [_times(k, terms) if len(terms) > 1 else k * terms[0] for k, terms in groups.items()]
    return sm.Add(*rest, *parts)


def _times(k: sm.Expr, terms: list[sm.Expr]) -> sm.Expr:
    """k times the sum of terms, unevaluated (sympy would distribute a number
    over a sum); -k times the negated sum when most terms are negative."""
    if 2 * sum(t.could_extract_minus_sign() for t in terms) > len(terms):
        k, terms = -k, [-t for t in terms]
    return sm.Mul(k, sm.Add(*terms), evaluate=False)


def hoist(expr: sm.Expr, per_call: Sequence[sm.Symbol], hoister: Hoister) -> sm.Expr:
    """expr with its parameter-only work replaced by constants.

    A polynomial in the per-call symbols becomes a Horner form with hoisted
    coefficients. Anything else (trig of angles times a polynomial, say) is
    taken apart and each argument hoisted in turn. Folded numbers become
    doubles on the way.
    """
    per = set(per_call)
    if not expr.free_symbols & per:
        return hoister.symbol_for(expr)
    expanded = sm.expand(expr)
    gens = [s for s in per_call if s in expanded.free_symbols]
    try:
        poly = sm.Poly(expanded, *gens)
    except sm.PolynomialError:
        poly = None
    if poly is None or any(c.free_symbols & per for c in poly.coeffs()):
        return expr.func(*(hoist(a, per_call, hoister) for a in expr.args))
    rebuilt = sm.Add(
        *(
            hoister.symbol_for(coeff) * sm.Mul(*(g**k for g, k in zip(gens, monom, strict=True)))
            for monom, coeff in poly.terms()
        )
    )
    return _best_horner(rebuilt, gens, hoister.gather)
