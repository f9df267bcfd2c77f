"""Numbers the generated code writes: never a literal its compiler reads as
something else (gyrogen.symbolic.literals), and folded decimals that compute the
physics they mean."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
import sympy as sm
from sources import write_sources
from wide import WIDE

from gyrogen.codegen.ir.c import CPrinter
from gyrogen.codegen.statements import expression, symbol_names
from gyrogen.oracle import scene_view
from gyrogen.oracle.compare import compare
from gyrogen.runtime import build
from gyrogen.runtime.flags import C_WARNINGS
from gyrogen.scene import parse
from gyrogen.symbolic.literals import (
    INT_LITERAL_MAX,
    LiteralError,
    as_double,
    writable,
    writable_form,
)

x, y, t = sm.symbols("x y t", real=True)
BIG = sm.Integer(2**112)
ODD = sm.Integer(12980742146337070512478121581609)


def test_writable_expressions_are_left_as_they_are() -> None:
    e = sm.Rational(3, 10) * x + 2 * y / (x + 400 * y)
    assert writable(e) and writable_form(e) is e


def test_scaled_up_fractions_become_the_ratio_they_mean() -> None:
    e = ODD * t / (BIG * x + BIG * y)
    f = writable_form(e)
    assert writable(f)
    (coeff,) = [a for a in sm.preorder_traversal(f) if isinstance(a, sm.Float)]
    assert float(coeff) == float(sm.Rational(ODD, BIG))  # one rounding of the exact ratio
    at = {x: 1, y: 2, t: 1}
    assert float(f.subs(at)) == pytest.approx(float(e.subs(at)), rel=4e-16)


def test_a_sum_of_exact_rationals_of_huge_denominators_keeps_its_terms() -> None:
    """The content of a sum of rationals whose denominators' lcm is past
    double range (a CMG's exact axes: 1/5.5e530) is not pulled out of a
    power of it: each term's coefficient is a double. It was refused as a
    constant outside double range, though every term is of order one."""
    q1, q2 = sm.Integer(3) ** 560, sm.Integer(7) ** 330
    e = 2 * (sm.Rational(q1 + 1, q1) * x + sm.Rational(q2 - 1, q2)) ** 2
    f = writable_form(e)
    assert writable(f)
    assert float(f.subs(x, 0.5)) == pytest.approx(float(e.subs(x, 0.5)), rel=1e-15)


def test_large_integers_become_doubles_and_small_ones_stay() -> None:
    assert as_double(sm.Integer(3)) == 3 and isinstance(as_double(sm.Integer(3)), sm.Integer)
    big = as_double(sm.Integer(2**40 + 1))
    assert isinstance(big, sm.Float) and float(big) == 2**40 + 1
    assert isinstance(as_double(sm.Integer(INT_LITERAL_MAX + 1)), sm.Float)


@pytest.mark.parametrize("value", [sm.Integer(10) ** 400, sm.Rational(1, 10**400)])
def test_numbers_outside_double_range_are_refused(value: sm.Expr) -> None:
    with pytest.raises(LiteralError, match="outside double range"):
        as_double(value)


def test_a_refused_rational_is_named_by_its_magnitude() -> None:
    """Its digits cut short read as another number (an integer within range)."""
    value = sm.Rational(-874123862273805255713542017029594789152, 5 * 10**400)
    with pytest.raises(LiteralError, match=r"constant of the generated code, -1\.75e-362, is"):
        as_double(value)


def test_the_lowering_refuses_an_unconverted_number() -> None:
    """Every target prints the one lowering: it is the last guard. Numbers
    are written as doubles: an integer that no double is, is refused."""
    with pytest.raises(LiteralError, match="reached a printer"):
        expression(sm.Mul(sm.Integer(2**70 + 1), x, evaluate=False), symbol_names(0))


def test_the_lowering_writes_a_large_exact_coefficient() -> None:
    """A rational coefficient whose numerator passes C's int but is a
    double (a drawn scene's 2693424863253969/2^k) is its numerator over its
    denominator, both doubles."""
    e = expression(sm.Rational(2693424863253969, 2**60) * x, symbol_names(0))
    assert CPrinter("p", "P", {}).expr(e) == "2693424863253969.0 * x / 1.152921504606847e+18"


# The scene: folded decimals next to runtime inertias and masses.
FOLDED_DECIMALS = """
name = "folded_decimals"
description = "folded decimals (I13, l1) next to runtime masses and inertias"
[parameters]
m_a = "runtime"
m_b = "runtime"
I11 = "runtime"
I22 = "runtime"
I33 = "runtime"
I13 = 0.3
I   = "runtime"
J   = "runtime"
l1  = 0.05
l3  = "runtime"
T   = "runtime"
[effects]
translation = false
[simulate]
t_end = 10.0
initial = { u1 = 0.3, u2 = -0.2, u3 = 0.5, u4 = 40.0 }
[simulate.parameters]
m_a = 120.0
m_b = 6.5
I11 = 14.0
I22 = 11.0
I33 = 17.0
I = 0.03
J = 0.05
l3 = -0.12
T = 0.0
"""


@pytest.mark.slow
@WIDE
def test_folded_decimals_compile_everywhere_and_hold_momentum(tmp_path: Path) -> None:
    scene = parse(FOLDED_DECIMALS, "folded_decimals.toml")
    write_sources(scene, tmp_path)
    for name in ("folded_decimals.c", "folded_decimals.f90"):
        text = (tmp_path / name).read_text()
        assert not re.search(r"(?<![\d.e])\d{11,}(?![\d.])", text), (
            "an integer literal of 11+ digits"
        )
    for cc in ("gcc", "clang"):
        for src in ("folded_decimals.c", "folded_decimals_ode.c"):
            subprocess.run(
                [cc, "-std=c99", "-O2", *C_WARNINGS, "-c", src,
                 "-o", f"{cc}.o"], cwd=tmp_path, check=True, capture_output=True,
            )  # fmt: skip
    backends = [build.build(tmp_path, lang) for lang in scene.targets]
    report = compare(backends, scene, n_states=300, n_params=5, n_ill=2, seed=7)
    assert report.passed, [r for r in report.rows if not r.passed] + report.refusal_failures
    # |H| over 10 s: the issue measured 88 (relative) with truncated literals
    p = np.array([scene.simulate.parameters[n] for n in scene.runtime])
    c = backends[0].setup(p)
    x0 = np.array(scene.initial_state())
    xs = [x0]
    for k in range(10):
        xk, _, code = backends[0].integrate("dop853", xs[-1], c, k, k + 1.0, rtol=1e-12, atol=1e-12)
        assert code == 0
        xs.append(xk)
    h = np.linalg.norm(scene_view.output(scene, "angular_momentum", np.array(xs), p), axis=1)
    assert np.max(np.abs(h - h[0])) / h[0] < 1e-12
