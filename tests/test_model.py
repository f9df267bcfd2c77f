"""The symbolic model: both formulations, their equality, and the paper's
kinematics and lumped scalars."""

from __future__ import annotations

import sympy as sm

from gyrogen.symbolic import equations, model, specialize
from gyrogen.symbolic.proof import prove


def test_lumped_formulation_equals_separate_bodies() -> None:
    results = prove()
    assert [c.what for c in results] == [
        "mass matrix (7x7)",
        "forcing (7)",
        "kinematic equations (7)",
    ]
    assert [c.entries for c in results] == [49, 7, 7]
    assert all(c.equal for c in results), results


def test_proof_detects_a_difference(monkeypatch) -> None:
    """The comparison is not vacuous: a wrong lumped scalar is caught."""
    good = model.lumped_values()
    s = model.symbols()
    wrong = dict(good)
    wrong[s.lumped[0]] = good[s.lumped[0]] + s.p("I")  # I counted twice in I~11
    monkeypatch.setattr(model, "lumped_values", lambda: wrong)
    results = prove()
    assert not results[0].equal and "[1,1]" in results[0].nonzero
    assert not results[1].equal


def test_mass_matrix_is_constant() -> None:
    eqs = specialize.full_model()
    assert not eqs.mass_matrix.free_symbols & set(eqs.states)


def test_kinematics_as_printed_in_the_paper() -> None:
    q = equations.plain_states()
    q2, q3, u1, u2, u3, u4, u5, u6, u7 = q[1], q[2], *q[7:]
    c2, s3, c3, t2 = sm.cos(q2), sm.sin(q3), sm.cos(q3), sm.tan(q2)
    paper = [
        -s3 * u1 / c2 + c3 * u3 / c2,
        c3 * u1 + s3 * u3,
        t2 * s3 * u1 + u2 - t2 * c3 * u3,
        -u2 + u4,
        u5,
        u6,
        u7,
    ]
    kin = specialize.full_model().kinematics
    assert [sm.simplify(k - p) for k, p in zip(kin, paper, strict=True)] == [0] * 7


def test_lumped_equations_as_printed_in_the_paper() -> None:
    """The paper's four lumped equations, moved to M u' = F form."""
    eqs = specialize.full_model()
    IA11, IA22, IA33, IA13 = model.symbols().lumped
    u1, u2, u3, u4 = eqs.states[7:11]
    J, T = model.symbols().p("J"), model.symbols().p("T")
    forcing = [
        -(IA13 * u1 * u2 + (IA33 - IA22) * u2 * u3 - J * u3 * u4),
        -(T - IA13 * u1**2 + IA13 * u3**2 + (IA11 - IA33) * u1 * u3),
        -(J * u1 * u4 + (IA22 - IA11) * u1 * u2 - IA13 * u2 * u3),
        T,
    ]
    assert [sm.expand(eqs.forcing[i] - f) for i, f in enumerate(forcing)] == [0] * 4
    assert eqs.mass_matrix[:4, :4] == sm.Matrix(
        [[IA11, 0, IA13, 0], [0, IA22, 0, 0], [IA13, 0, IA33, 0], [0, 0, 0, J]]
    )


def test_translation_reduces_to_gravity() -> None:
    eqs = specialize.full_model()
    m_a, m_b, g = (model.symbols().p(n) for n in ("m_a", "m_b", "g"))
    udot = eqs.mass_matrix[4:, 4:].inv() * eqs.forcing[4:, :]
    assert list(udot) == [0, 0, g]
    assert eqs.mass_matrix[4, 4] == m_a + m_b
