"""Property-based tests (hypothesis): over random physically valid parameters
and states the compiled setup accepts, the RHS is finite and agrees with the
numpy reference; over invalid vectors setup refuses with the documented code."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gyrogen.abi import PARAMETERS
from gyrogen.oracle import reference, sampling
from gyrogen.runtime.build import Compiled

P = {n: i for i, n in enumerate(PARAMETERS)}
positive = st.floats(1e-3, 1e3, allow_nan=False, allow_infinity=False)
signed = st.floats(-3.0, 3.0, allow_nan=False, allow_infinity=False)


@st.composite
def valid_parameters(draw: st.DrawFn) -> np.ndarray:
    """Principal moments (y + z, x + z, x + y) satisfy the triangle inequality
    by construction; a rotation in the a1-a3 plane gives I13."""
    x, y, z = draw(positive), draw(positive), draw(positive)
    theta = draw(st.floats(-math.pi, math.pi))
    c, s = math.cos(theta), math.sin(theta)
    p1, p2, p3 = y + z, x + z, x + y
    rotor_i = draw(positive)
    p = np.zeros(len(PARAMETERS))
    p[P["m_a"]], p[P["m_b"]] = draw(positive), draw(positive)
    p[P["I11"]] = p1 * c * c + p3 * s * s
    p[P["I22"]] = p2
    p[P["I33"]] = p1 * s * s + p3 * c * c
    p[P["I13"]] = (p1 - p3) * s * c
    p[P["I"]] = rotor_i
    p[P["J"]] = 2 * rotor_i * draw(st.floats(1e-3, 1.0))
    p[P["l1"]], p[P["l3"]], p[P["g"]], p[P["T"]] = (draw(signed) for _ in range(4))
    return p


@st.composite
def states(draw: st.DrawFn) -> np.ndarray:
    x = np.array([draw(st.floats(-3.0, 3.0)) for _ in range(14)])
    x[1] = draw(st.floats(-1.4, 1.4))  # away from gimbal lock
    x[10] = draw(st.floats(-300.0, 300.0))
    return x


# derandomize: the same examples on every run, so CI cannot fail by chance.
FAST = settings(
    max_examples=150,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)


@FAST
@given(p=valid_parameters(), x=states())
def test_valid_parameters_accepted_and_rhs_agrees(
    backends: dict[str, Compiled], p: np.ndarray, x: np.ndarray
) -> None:
    code = sampling.setup_code(p)
    cond = float(sampling.lumped_condition(p))
    for b in backends.values():
        got, c = b.setup_code(p)
        assert got == code
        if code != 0:  # only code 7: a carrier so thin the mass matrix is singular
            assert code == 7 and cond > 1e13
            continue
        out = b.rhs(x, c)
        assert np.all(np.isfinite(out))
        ref = reference.rhs(x, p)
        scale = 1.0 + np.abs(ref)
        # Two correct codes agree to about cond(M) eps (see gyrogen.oracle.compare),
        # and, over ranges this wide, to the cancellation of coefficients such
        # as I~33 - I~11 when the two are close: 1e-10 rather than verify's
        # 1e-12 on realistic parameters.
        assert np.max(np.abs(out - ref) / scale) <= max(1e-10, 1e3 * cond * 2.2e-16)


@st.composite
def invalid_parameters(draw: st.DrawFn) -> np.ndarray:
    p = draw(valid_parameters())
    name = draw(st.sampled_from(PARAMETERS))
    bad = draw(st.sampled_from([math.nan, math.inf, -math.inf, 0.0, -1.0, -1e-300, 1e300, -1e300]))
    p[P[name]] = bad
    return p


@FAST
@given(p=invalid_parameters())
def test_setup_codes_match_the_documented_checks(
    backends: dict[str, Compiled], p: np.ndarray
) -> None:
    expected = sampling.setup_code(p)
    for b in backends.values():
        assert b.setup_code(p)[0] == expected
