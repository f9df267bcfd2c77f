"""The units of abi.UNITS and abi.OUTPUT_DOC as SI base units, for formats
that define their units (an FMU's UnitDefinitions), and the unit of a
state's rate of change."""

from __future__ import annotations

DIMENSIONLESS = "-"
"""abi's unit of a number without one (the Euler parameters)."""

_SYMBOLS: dict[str, dict[str, int]] = {
    "kg": {"kg": 1},
    "m": {"m": 1},
    "s": {"s": 1},
    "rad": {"rad": 1},
    "1": {},
    "N": {"kg": 1, "m": 1, "s": -2},
    "J": {"kg": 1, "m": 2, "s": -2},
    "W": {"kg": 1, "m": 2, "s": -3},
}
"""Each symbol a unit is written with, in base units."""


class UnitError(ValueError):
    """A unit written with a symbol not in _SYMBOLS."""


def _factors(text: str, sign: int, into: dict[str, int]) -> None:
    for token in text.split():
        symbol, _, power = token.partition("^")
        if symbol not in _SYMBOLS:
            raise UnitError(f"unit symbol {symbol!r} (in {text!r}) has no base units")
        for base, exponent in _SYMBOLS[symbol].items():
            into[base] = into.get(base, 0) + sign * exponent * int(power or 1)


def base_units(unit: str) -> dict[str, int]:
    """'kg m^2/s' -> {'kg': 1, 'm': 2, 's': -1}: the exponents of the base
    units, those that cancel left out; {} for DIMENSIONLESS."""
    if unit == DIMENSIONLESS:
        return {}
    numerator, _, denominator = unit.partition("/")
    out: dict[str, int] = {}
    _factors(numerator, 1, out)
    _factors(denominator, -1, out)
    return {base: exponent for base, exponent in out.items() if exponent}


def per_second(unit: str) -> str:
    """The unit of the rate of change of a quantity in unit: rad -> rad/s,
    rad/s -> rad/s^2, - -> 1/s."""
    if unit == DIMENSIONLESS:
        return "1/s"
    numerator, _, denominator = unit.partition("/")
    if not denominator:
        return f"{unit}/s"
    if denominator == "s":
        return f"{numerator}/s^2"
    return f"{unit} s"
