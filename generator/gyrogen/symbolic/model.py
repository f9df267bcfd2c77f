"""Kane's equations of the gyrostat, both ways the paper derives them.

Symbolic only: this module knows nothing about files, scenes or languages.

(a) ``separate``: carrier A and rotor B as two rigid bodies, each with its own
    mass and central inertia (the paper's first formulation).
(b) ``lumped``: a carrier A~ of mass M = m_a + m_b at AB* with the lumped
    inertia scalars, plus a massless rotor B~ with axial inertia J.

Both share the kinematics: 3-1-2 Euler angles q1..q3, rotor angle q4, position
q5..q7 of AB*, and the generalized speeds of the paper's (1)-(3).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import sympy as sm
import sympy.physics.mechanics as me

from gyrogen.abi import PARAMETERS
from gyrogen.physics import lumped_inertias


@dataclass(frozen=True)
class Symbols:
    """Every symbol of the model, in the manifest's order."""

    q: tuple[sm.Symbol, ...]
    u: tuple[sm.Symbol, ...]
    qd: tuple[sm.Symbol, ...]
    params: tuple[sm.Symbol, ...]
    lumped: tuple[sm.Symbol, ...]
    """IA11, IA22, IA33, IA13: the inertia scalars of A~ (J~ = J)."""

    @property
    def states(self) -> tuple[sm.Symbol, ...]:
        return self.q + self.u

    def p(self, name: str) -> sm.Symbol:
        return self.params[PARAMETERS.index(name)]


@dataclass(frozen=True)
class KaneEquations:
    """M(p) u' = F(q, u, p) and q' = f(q, u), as KanesMethod derived them."""

    name: str
    mass_matrix: sm.Matrix
    forcing: sm.Matrix
    kinematics: sm.Matrix
    """q' for q1..q7, solved from the kinematic differential equations."""


@cache
def symbols() -> Symbols:
    q = me.dynamicsymbols("q1:8")
    u = me.dynamicsymbols("u1:8")
    qd = [qi.diff(me.dynamicsymbols._t) for qi in q]
    params = sm.symbols(PARAMETERS, real=True)
    lumped = sm.symbols("IA11 IA22 IA33 IA13", real=True)
    return Symbols(tuple(q), tuple(u), tuple(qd), tuple(params), tuple(lumped))


@dataclass(frozen=True)
class _Frames:
    N: me.ReferenceFrame
    A: me.ReferenceFrame
    B: me.ReferenceFrame
    AB: me.Point
    kd_eqs: list[sm.Expr]


def _kinematics(s: Symbols) -> _Frames:
    """Frames, the mass center AB* and the kinematic differential equations."""
    q1, q2, q3, q4, q5, q6, q7 = s.q
    u1, u2, u3, u4, u5, u6, u7 = s.u
    N = me.ReferenceFrame("N")
    A = N.orientnew("A", "Body", [q1, q2, q3], "312")
    B = A.orientnew("B", "Axis", [q4, A.y])
    w_A = A.ang_vel_in(N)  # in terms of q', before the u's replace it
    kd_eqs = [
        w_A.dot(A.x) - u1,
        w_A.dot(A.y) - u2,
        w_A.dot(A.z) - u3,
        s.qd[3] - (u4 - u2),
        s.qd[4] - u5,
        s.qd[5] - u6,
        s.qd[6] - u7,
    ]
    A.set_ang_vel(N, u1 * A.x + u2 * A.y + u3 * A.z)
    B.set_ang_vel(N, u1 * A.x + u4 * A.y + u3 * A.z)
    O = me.Point("O")
    AB = O.locatenew("AB*", q5 * N.x + q6 * N.y + q7 * N.z)
    O.set_vel(N, 0)
    AB.set_vel(N, u5 * N.x + u6 * N.y + u7 * N.z)
    return _Frames(N, A, B, AB, kd_eqs)


def _solve(s: Symbols, f: _Frames, bodies: list, loads: list, name: str) -> KaneEquations:
    kane = me.KanesMethod(f.N, q_ind=list(s.q), u_ind=list(s.u), kd_eqs=f.kd_eqs)
    kane.kanes_equations(bodies, loads)
    kin = kane.kindiffdict()
    qdot = sm.Matrix([sm.trigsimp(kin[qd]) for qd in s.qd])
    return KaneEquations(name, sm.Matrix(kane.mass_matrix), sm.Matrix(kane.forcing), qdot)


@cache
def separate() -> KaneEquations:
    """Formulation (a): two bodies, each with its own mass and inertia."""
    s = symbols()
    f = _kinematics(s)
    m_a, m_b, I11, I22, I33, I13, I, J, l1, l3, g, T = s.params
    M = m_a + m_b
    r = l1 * f.A.x + l3 * f.A.z  # r^{B*/A*}
    A_star = f.AB.locatenew("A*", -m_b / M * r)
    B_star = f.AB.locatenew("B*", m_a / M * r)
    A_star.v2pt_theory(f.AB, f.N, f.A)
    B_star.v2pt_theory(f.AB, f.N, f.A)
    carrier = me.RigidBody(
        "A", A_star, f.A, m_a, (me.inertia(f.A, I11, I22, I33, 0, 0, I13), A_star)
    )
    rotor = me.RigidBody("B", B_star, f.B, m_b, (me.inertia(f.B, I, J, I), B_star))
    loads = [
        (A_star, m_a * g * f.N.z),
        (B_star, m_b * g * f.N.z),
        (f.A, -T * f.A.y),
        (f.B, T * f.A.y),
    ]
    return _solve(s, f, [carrier, rotor], loads, "separate bodies")


@cache
def lumped() -> KaneEquations:
    """Formulation (b): lumped carrier A~ plus the massless rotor B~."""
    s = symbols()
    f = _kinematics(s)
    m_a, m_b, *_, J, _l1, _l3, g, T = s.params
    IA11, IA22, IA33, IA13 = s.lumped
    M = m_a + m_b
    carrier = me.RigidBody(
        "A~", f.AB, f.A, M, (me.inertia(f.A, IA11, IA22, IA33, 0, 0, IA13), f.AB)
    )
    rotor = me.RigidBody("B~", f.AB, f.B, sm.S.Zero, (me.inertia(f.A, 0, J, 0), f.AB))
    loads = [(f.AB, M * g * f.N.z), (f.A, -T * f.A.y), (f.B, T * f.A.y)]
    return _solve(s, f, [carrier, rotor], loads, "lumped carrier + massless rotor")


@cache
def direction_cosines() -> sm.Matrix:
    """C with a_i = sum_j C[i, j] n_j (NOTES.md, Table 1), in q1(t)..q3(t)."""
    f = _kinematics(symbols())
    return sm.Matrix(f.A.dcm(f.N))


@dataclass(frozen=True)
class Quaternion:
    """Euler parameters e0..e3 of A in N (scalar first), the alternative to
    the 3-1-2 angles: no singularity, one more state, unit norm to keep."""

    e: tuple[sm.Symbol, ...]
    kinematics: tuple[sm.Expr, ...]
    """e' in terms of e and u1..u3 (plain symbols), for |e| = 1."""
    dcm: sm.Matrix
    """C with a_i = sum_j C[i, j] n_j, in e (plain symbols)."""


@cache
def quaternion() -> Quaternion:
    """Derived like the angles: orient A by Euler parameters, ask sympy for
    omega of A in N in terms of e', and solve for e' with omega = (u1, u2,
    u3) and e.e' = 0 (the norm is constant); then set |e| = 1."""
    e_t = me.dynamicsymbols("e0:4")
    t = me.dynamicsymbols._t
    ed = [x.diff(t) for x in e_t]
    N = me.ReferenceFrame("N")
    A = N.orientnew("A", "Quaternion", e_t)
    w = A.ang_vel_in(N)
    u = sm.symbols("u1:4", real=True)
    eqs = [w.dot(A.x) - u[0], w.dot(A.y) - u[1], w.dot(A.z) - u[2]]
    eqs.append(sum(a * b for a, b in zip(e_t, ed, strict=True)))
    sol = sm.solve(eqs, ed, dict=True)[0]
    e = sm.symbols("e0:4", real=True)
    plain = dict(zip(e_t, e, strict=True))
    norm = sum(x**2 for x in e)
    kin = tuple(sm.factor(sm.cancel(sol[d].subs(plain) * norm)) for d in ed)
    dcm = sm.Matrix(A.dcm(N)).subs(plain)
    return Quaternion(tuple(e), kin, dcm)


def lumped_values() -> dict[sm.Symbol, sm.Expr]:
    """The paper's lumped inertia scalars in terms of the parameters (NOTES.md)."""
    s = symbols()
    m_a, m_b, I11, I22, I33, I13, I, _J, l1, l3, _g, _T = s.params
    return dict(
        zip(s.lumped, lumped_inertias(m_a, m_b, I11, I22, I33, I13, I, l1, l3), strict=True)
    )
