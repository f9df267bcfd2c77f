"""The setup checks are declared once (gyrogen.setup_checks): the generated C
and Fortran setup, their evaluation in Python (the scene validator's) and the
oracle's independent mirror (sampling.setup_code) give the same code for
valid and invalid parameter vectors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gyrogen.abi import PARAMETERS, SETUP_CODES
from gyrogen.codegen.checks import Printer
from gyrogen.oracle import sampling
from gyrogen.runtime.build import Compiled
from gyrogen.setup_checks import CHECKS, checked_parameters, cluster_checks, first_failure


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
    assert codes == {c.value for c in SETUP_CODES if c.value != 8}  # 8: a cluster's axis


def test_every_setup_code_but_ok_has_its_check() -> None:
    """The single rotor's checks in code order; a cluster's runtime axis adds 8."""
    assert [c.code for c in CHECKS] == [c.value for c in SETUP_CODES if c.value not in (0, 8)]
    axis = cluster_checks({"g1_1": "runtime"}, 1)
    made = {c.code for c in (*CHECKS, *axis)}
    assert sorted(made) == [c.value for c in SETUP_CODES if c.value]


def test_the_checks_read_the_carrier_and_rotor() -> None:
    assert checked_parameters() == ("m_a", "m_b", "I11", "I22", "I33", "I13", "I", "J")


def test_the_printers_spell_the_languages() -> None:
    carrier = next(c for c in CHECKS if c.code == 4)
    c_text = Printer("c", "X").condition(carrier.kind, carrier.exprs)
    assert c_text == "!(I11 > 0.0) || !(I22 > 0.0) || !(I33 > 0.0) || !(I11*I33 - I13*I13 > 0.0)"
    f_text = Printer("fortran", "X").condition(carrier.kind, carrier.exprs)
    assert f_text.endswith(".and. I11*I33 - I13*I13 > 0.0_c_double)") and " &\n" in f_text
    triangle = next(c for c in CHECKS if c.code == 5)
    assert Printer("fortran", "X")(triangle.locals[0][1]) == (
        "sqrt(0.25_c_double*(I11 - I33)**2 + I13*I13)"
    )


def test_python_evaluation_has_the_generated_arithmetic() -> None:
    """Overflow is an infinity and NaN compares false, as in C: a carrier of
    1.7e308 passes the carrier checks and fails the condition number."""
    v = dict(zip(PARAMETERS, (1.0, 1.0, 1.7e308, 25.0, 1.7e308, 0.5, 0.01, 0.015, 0.3, 0.1,
                              0.0, 0.0), strict=True))  # fmt: skip
    failed = first_failure(v)
    assert failed is not None and failed[0] == 7 and "nan" in failed[1]
    assert math.isnan(float(failed[1].split("number ")[1].split(" ")[0]))
