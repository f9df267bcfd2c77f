"""Numbers as the generated code may write them.

Folded values are exact rationals during the derivation (so zeros and equal
values cancel exactly), and the algebra that clears denominators (factor,
cancel, expand) can turn them into integers of 30 to 300 digits. Written as
they are, those literals mean something else to a compiler: gcc truncates an
integer literal past 64 bits with a warning, clang and gfortran refuse it,
and Fortran's default integers stop at 2**31 - 1. So before any code is
printed:

- every Add's integer content is pulled out into the coefficient of the
  product it stands in (``A t / (B x + B y)`` becomes ``(A/B) t / (x + y)``),
  so the numbers left are the ratios the math means, not their scaled-up
  numerators and denominators;
- a number that still cannot be written exactly (an integer beyond
  ``INT_LITERAL_MAX``, a fraction whose numerator or denominator is not a
  double) becomes the nearest double: one rounding, as the code's own
  arithmetic would do;
- a number outside double range is refused (``LiteralError``), never printed
  as ``inf`` or ``0``.

An expression with no such number is returned as it is, object for object.
"""

from __future__ import annotations

import math

import sympy as sm

from gyrogen.errors import GyrogenError

INT_LITERAL_MAX = 2**31 - 1
"""The largest integer both targets take as written: C's int and Fortran's
default integer kind (a larger one is printed as a double)."""


class LiteralError(GyrogenError):
    """A constant of the generated code is outside double range."""


def exact_double(n: int) -> bool:
    """n as a double literal (n.0) reads back as n."""
    try:
        return int(float(n)) == n
    except OverflowError:
        return False


def _writable(atom: sm.Basic) -> bool:
    if isinstance(atom, sm.Integer):
        return abs(int(atom)) <= INT_LITERAL_MAX
    if isinstance(atom, sm.Rational):
        return exact_double(int(atom.p)) and exact_double(int(atom.q))
    if isinstance(atom, sm.Float):
        return math.isfinite(float(atom))
    return True


def _numbers(expr: sm.Basic) -> list[sm.Basic]:
    """The numbers of expr that are printed: exponents are not."""
    if isinstance(expr, sm.Number):
        return [expr]
    if isinstance(expr, sm.Pow):
        return _numbers(expr.base)
    return [n for a in expr.args for n in _numbers(a)]


def writable(expr: sm.Basic) -> bool:
    """Every number expr prints can be written exactly as it is."""
    return all(_writable(n) for n in _numbers(expr))


def as_double(value: sm.Expr, integers: bool = True) -> sm.Expr:
    """A number as the code should write it: small integers as they are
    (unless not integers), anything else as the nearest double.
    LiteralError outside double range."""
    if integers and isinstance(value, sm.Integer) and abs(int(value)) <= INT_LITERAL_MAX:
        return value
    try:
        x = float(value)
    except OverflowError:
        x = math.inf
    if not math.isfinite(x) or (x == 0.0 and value != 0) or (x != 0.0 and abs(x) < 2.0**-1022):
        raise LiteralError(
            f"a constant of the generated code, {_magnitude(value)}, is outside double "
            "range: keep the extreme parameter values at run time"
        )
    return sm.Float(x)


def _magnitude(value: sm.Expr) -> str:
    """value to 3 digits with its exponent, however far outside double range
    (a rational's digits cut short read as another number)."""
    return sm.sstr(sm.N(value, 3))


def writable_form(expr: sm.Expr) -> sm.Expr:
    """expr with every number writable (see the module's docstring)."""
    if writable(expr):
        return expr
    return _rewrite(expr)


def _rewrite(e: sm.Expr) -> sm.Expr:
    if isinstance(e, sm.Number):
        return e if _writable(e) else as_double(e)
    if e.is_Atom:
        return e
    if isinstance(e, sm.Pow):
        return sm.Pow(_rewrite(e.base), e.exp)
    if isinstance(e, sm.Mul):
        return _product(e)
    return e.func(*(_rewrite(a) for a in e.args))


def _normal(value: sm.Expr) -> bool:
    """value is a double within range (as_double would take it)."""
    try:
        x = float(value)
    except OverflowError:
        return False
    return math.isfinite(x) and (x == 0.0) == (value == 0) and (x == 0.0 or abs(x) >= 2.0**-1022)


def _product(e: sm.Mul) -> sm.Expr:
    """The numbers of a product (a root of a number too: an exact rational's
    sqrt(p/q) is sqrt(p q)/q, each part maybe past double range where the
    whole is not), and the integer contents of the sums in it (raised to
    their powers), gathered into one coefficient."""
    coeff: sm.Expr = sm.S.One
    rest: list[sm.Expr] = []
    for factor in e.args:
        base, exp = factor.as_base_exp()
        if isinstance(factor, sm.Number) or factor.is_number:
            coeff *= factor
        elif (
            isinstance(base, sm.Add)
            and exp.is_Integer
            and _normal((split := base.as_content_primitive())[0] ** exp)
        ):  # an exact rational's content (1/lcm of the terms' denominators) may not be
            coeff *= split[0] ** exp
            rest.append(sm.Pow(_rewrite(split[1]), exp))
        else:
            rest.append(_rewrite(factor))
    body = sm.Mul(*rest)
    number = coeff if _writable(coeff) else as_double(coeff)
    if number == 1:
        return body
    # Mul(number, a single sum) would hand the number back to every term.
    return sm.Mul(number, body, evaluate=not isinstance(body, sm.Add))
