"""Bad input through the C interface (and the Fortran one, bound to C): setup
returns the code gyrostat.h documents, and for negative values the code of the
first check that a negative value fails. NULL pointers are not checked (the
header says so; examples/README.md repeats it), so there is nothing to test."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gyrogen import abi
from gyrogen.runtime.compiled import Compiled

# A valid, realistic parameter set (the embedding examples' dual spinner).
VALID = dict(zip(abi.PARAMETERS, (500.0, 10.0, 100.0, 80.0, 120.0, 5.0,
                                     0.05, 0.1, 0.2, -0.1, 0.0, 0.01), strict=True))  # fmt: skip

# The codes gyrostat.h documents (GYROSTAT_OK, GYROSTAT_ERR_*).
OK, NONFINITE, MASS, ROTOR_INERTIA, CARRIER_NOT_PD = 0, 1, 2, 3, 4

# What a negative value of each parameter means: masses and rotor inertias
# must be positive, a negative carrier moment breaks positive definiteness,
# and the product of inertia, offsets, gravity and torque may take any sign.
NEGATIVE = {
    "m_a": MASS,
    "m_b": MASS,
    "I11": CARRIER_NOT_PD,
    "I22": CARRIER_NOT_PD,
    "I33": CARRIER_NOT_PD,
    "I13": OK,
    "I": ROTOR_INERTIA,
    "J": ROTOR_INERTIA,
    "l1": OK,
    "l3": OK,
    "g": OK,
    "T": OK,
}

LANGUAGES = ["c", "fortran"]


def params(**changes: float) -> np.ndarray:
    return np.array([changes.get(name, VALID[name]) for name in abi.PARAMETERS])


@pytest.mark.slow
def test_the_codes_are_the_documented_ones(backends: dict[str, Compiled]) -> None:
    codes = backends["c"].manifest["setup_codes"]
    assert "accepted" in codes[str(OK)]
    assert "NaN or infinite" in codes[str(NONFINITE)]
    assert "mass" in codes[str(MASS)]
    assert "rotor inertia" in codes[str(ROTOR_INERTIA)]
    assert "positive definite" in codes[str(CARRIER_NOT_PD)]


@pytest.mark.parametrize("language", LANGUAGES)
def test_valid_parameters_are_accepted(backends: dict[str, Compiled], language: str) -> None:
    code, c = backends[language].setup_code(params())
    assert code == OK
    assert np.all(np.isfinite(c))


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf], ids=["nan", "+inf", "-inf"])
@pytest.mark.parametrize("name", abi.PARAMETERS)
@pytest.mark.parametrize("language", LANGUAGES)
def test_nonfinite(backends: dict[str, Compiled], language: str, name: str, bad: float) -> None:
    code, _ = backends[language].setup_code(params(**{name: bad}))
    assert code == NONFINITE


@pytest.mark.parametrize("name", abi.PARAMETERS)
@pytest.mark.parametrize("language", LANGUAGES)
def test_negative(backends: dict[str, Compiled], language: str, name: str) -> None:
    code, _ = backends[language].setup_code(params(**{name: -abs(VALID[name]) or -1.0}))
    assert code == NEGATIVE[name]


@pytest.mark.parametrize("name", ["m_a", "m_b", "I", "J"])
@pytest.mark.parametrize("language", LANGUAGES)
def test_zero_is_not_positive(backends: dict[str, Compiled], language: str, name: str) -> None:
    code, _ = backends[language].setup_code(params(**{name: 0.0}))
    assert code == NEGATIVE[name]


@pytest.mark.parametrize("language", LANGUAGES)
def test_first_failing_check_wins(backends: dict[str, Compiled], language: str) -> None:
    """Checked in the documented order: a NaN beats a negative mass, which
    beats a negative rotor inertia."""
    setup = backends[language].setup_code
    assert setup(params(m_a=-1.0, J=math.nan))[0] == NONFINITE
    assert setup(params(m_b=-1.0, I=-1.0))[0] == MASS
    assert setup(params(J=-1.0, I11=-1.0))[0] == ROTOR_INERTIA
