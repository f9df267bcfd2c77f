"""The setup checks are declared once (gyrogen.setup_checks): the generated C
and Fortran setup, their evaluation in Python (the scene validator's) and the
oracle's independent mirror (sampling.setup_code) give the same code for
valid and invalid parameter vectors."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import compiled_expressions
import numpy as np
import pytest

from gyrogen.abi import PARAMETERS, SETUP_CODES
from gyrogen.codegen.checks import expression, failed, lowered
from gyrogen.codegen.integrators.program import intrinsics_of
from gyrogen.codegen.ir.c import CPrinter
from gyrogen.codegen.ir.fortran import FortranPrinter
from gyrogen.codegen.ir.nodes import At, Func, Int, Var, assign
from gyrogen.oracle import sampling
from gyrogen.runtime.build import Compiled
from gyrogen.setup_checks import (
    CHECKS,
    Call,
    Expr,
    Num,
    Op,
    Sym,
    checked_parameters,
    cluster_checks,
    evaluate,
    first_failure,
)


def python_code(p: np.ndarray) -> int:
    failed = first_failure(dict(zip(PARAMETERS, map(float, p), strict=True)))
    return 0 if failed is None else failed[0]


def vectors() -> list[tuple[str, np.ndarray]]:
    rng = np.random.default_rng(11)
    out = [(f"random {i}", p) for i, p in enumerate(sampling.random_parameters(rng, 40))]
    for base in sampling.random_parameters(rng, 5):
        out += [(what, p) for what, p, _ in sampling.invalid_parameters(base)]
    return out


@pytest.mark.parametrize("language", ["c", "fortran"])
def test_one_declaration_three_interpretations(
    backends: dict[str, Compiled], language: str
) -> None:
    """The validator does not make 9 (the constants' overflow): it checks
    folded values, which are bounded so that their constants stay finite."""
    codes = set()
    for what, p in vectors():
        compiled, _ = backends[language].setup_code(p)
        expected = sampling.setup_code(p)
        assert compiled == expected, what
        assert python_code(p) == (0 if expected == 9 else expected), what
        codes.add(expected)
    assert codes == {c.value for c in SETUP_CODES if c.value not in (8, 10)}  # a cluster's axes


def test_every_setup_code_but_ok_has_its_check() -> None:
    """The single rotor's checks in code order; a cluster's runtime axis adds
    8, a gimbal's runtime axis 10 (its spin axis perpendicular to it)."""
    assert [c.code for c in CHECKS] == [c.value for c in SETUP_CODES if c.value not in (0, 8, 10)]
    gimbal = {f"{key}{i}_1": "runtime" for key in ("g", "gg") for i in (1, 2, 3)}
    axis = cluster_checks(gimbal, 1)
    assert [c.code for c in axis if c.code in (8, 10)] == [8, 8, 10]
    made = {c.code for c in (*CHECKS, *axis)}
    assert sorted(made) == [c.value for c in SETUP_CODES if c.value]


def test_the_checks_read_the_carrier_and_rotor() -> None:
    assert checked_parameters() == ("m_a", "m_b", "I11", "I22", "I33", "I13", "I", "J")


COND = At("c", (Int(0),))


def _printer(language: str) -> CPrinter | FortranPrinter:
    return CPrinter("x", "X", {}) if language == "c" else FortranPrinter("x", "X", {})


def test_the_printers_spell_the_languages() -> None:
    carrier = next(c for c in CHECKS if c.code == 4)
    c_text = _printer("c").expr(failed(carrier, COND))
    assert c_text == (
        "!(I11 > 0.0) || !(I22 > 0.0) || !(I33 > 0.0) || !(I11 * I33 - I13 * I13 > 0.0)"
    )
    f_text = _printer("fortran").expr(failed(carrier, COND))
    assert f_text.startswith(".not. (I11 > 0.0_c_double) .or. .not. (I22 > 0.0_c_double)")
    triangle = next(c for c in CHECKS if c.code == 5)
    assert _printer("fortran").expr(expression(triangle.locals[0][1], COND)) == (
        "sqrt(0.25_c_double * ((I11 - I33) * (I11 - I33)) + I13 * I13)"
    )


def test_python_evaluation_has_the_generated_arithmetic() -> None:
    """Overflow is an infinity and NaN compares false, as in C: a carrier of
    1.7e308 passes the carrier checks and fails the condition number."""
    v = dict(zip(PARAMETERS, (1.0, 1.0, 1.7e308, 25.0, 1.7e308, 0.5, 0.01, 0.015, 0.3, 0.1,
                              0.0, 0.0), strict=True))  # fmt: skip
    failed = first_failure(v)
    assert failed is not None and failed[0] == 7 and "nan" in failed[1]
    assert math.isnan(float(failed[1].split("number ")[1].split(" ")[0]))


def _signed() -> list[Expr]:
    """Folded values of both signs (a runtime one beside them) in every
    place a check's expression puts an operand: each side of + - *, a
    product inside a difference, a square's base, max's arguments."""
    x = Sym("x")
    leaves = [Num(4.0), Num(-4.0), Num(-0.5), x]
    out: list[Expr] = []
    for a, b in itertools.product(leaves, leaves):
        out += [Op("+", (a, b)), Op("-", (a, b)), Op("*", (a, b)), Op("-", (x, Op("*", (a, b))))]
        out += [Op("*", (x, a, b)), Op("-", (a, Op("+", (x, b)))), Call("max", (a, b))]
        out += [Call("square", (a,)), Op("*", (b, Call("square", (Op("-", (a, b)),))))]
    return out


@pytest.mark.parametrize("language", ["c", "fortran"])
def test_the_printers_write_folded_values_of_every_sign(language: str, tmp_path: Path) -> None:
    """A folded product of inertia or position is negative as often as not:
    Fortran refuses a unary minus after a binary operator (x - -4.0) and
    reads -4.0**2 as -(4.0**2). Every place, every sign: the program
    compiles under the strict flags and computes what evaluate() does."""
    exprs = _signed()
    p = _printer(language)
    lowered_ = [expression(e, COND) for e in exprs]
    calls = Func("x", (), tuple(assign(Var("y"), e) for e in lowered_))
    prelude = "".join(p.function(f) for f in intrinsics_of([calls], p)) if language == "c" else ""
    texts = [p.expr(e) for e in lowered_]
    got = compiled_expressions.values(language, texts, tmp_path, prelude=prelude)
    assert got == [evaluate(e, {"x": 3.0}) for e in exprs]


def test_fortran_checks_of_long_folded_values_fit_the_line() -> None:
    """A cluster's carrier with I11 at run time and its other moments folded
    to 17 digits, negative products: the minors' locals (pd_m2 =
    (-0.0280...)*0.6317... - (-0.2165...)*0.0115...) passed Fortran's 132
    columns. Each line, as the template places it, fits."""
    values: dict[str, float | str] = {
        "I11": "runtime", "I22": 0.5108950164969109, "I33": 0.6317458616537961,
        "I12": -0.028083875871670966, "I13": -0.21656337392856828, "I23": 0.011582093621946399,
        "I_1": 0.015651075155771636, "J_1": "runtime",
    }  # fmt: skip
    early, late = lowered(cluster_checks(values, 1), 10, 0, {c.value: c.name for c in SETUP_CODES})
    setup = Func("x_setup", (), (*early, *late), locals=(), public=True)
    lines = FortranPrinter("x", "X", {}).function(setup).splitlines()
    assert any("(-0.028083875871670966_c_double) *" in line for line in lines)
    assert max(map(len, lines)) <= 132, [line for line in lines if len(line) > 132]
