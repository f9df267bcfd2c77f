"""A cluster whose rotors may turn on gimbals (control-moment gyros: a
[[rotors]] table with [rotors.gimbal]).

Rotor k on a gimbal: a gimbal frame G_k turns about g_g (fixed in A) by the
angle gam_k; its wheel W_k spins about g_s = cos(gam) g_s0 + sin(gam) g_t0
(g_t0 = g_g x g_s0), and g_t = g_g x g_s. Frame and wheel have their mass
center at the rotor's position, on the gimbal axis. With the speeds w_A,
nu_k = g_g . w_G (the gimbal's absolute rate) and w_k = g_s . w_W the mass
matrix is block-diagonal,

    diag(I~(gam), IGg_k + I_k, J_k),
    I~(gam) = L + sum_k d_k g_t g_t^T,   d_k = IGt_k + I_k - IGs_k,

with L constant: the lumped inertia of the fixed rotors' clusters
(symbolic.cluster.lumped_inertia), where a gimbal adds its frame's and
wheel's masses and IGs_k (1 - g_g g_g^T). KanesMethod derives it from the
bodies (carrier, gimbal frames, wheels); the code uses the momentum form it
is proven equal to here, entry by entry:

    (IGg + I) nu' = u_g + J w at - d as at                     (= (IGg + I) nd)
    J w' = net = u_s - b (w - as)
    I~ w_A' = h x w_A - sum_k [(net - d gd at) g_s + gd (J w - d as) g_t + (IGg + I) nd g_g]
    h = I~ w_A + sum_k [(IGg + I) nu g_g + J w g_s]   (fixed rotors: J w g)

with as = g_s . w_A, at = g_t . w_A and gd = nu - g_g . w_A the state (the
gimbal rate relative to A). Per call the rhs names h, f (the right side
above), I~'s six entries, their cofactors and determinant, and solves the
carrier's 3 x 3 block by them (the adjugate over the determinant: no LU);
gd' = nd - g_g . w_A'. What reads parameters alone (L, d, 1/J, ...) is
hoisted into setup. Equations.mass_matrix is then the identity: the forcing
is the solved u'.
"""

from __future__ import annotations

import dataclasses
import functools
import operator
from typing import Any

import sympy as sm
import sympy.physics.mechanics as me
from sympy.polys.domains import QQ
from sympy.polys.orderings import lex
from sympy.polys.polyerrors import CoercionFailed
from sympy.polys.rings import PolyElement, PolyRing, ring

from gyrogen.abi_rotors import (
    AXIS,
    CROSS_AXIS,
    GIMBAL_AXIS,
    GIMBAL_INERTIA,
    GIMBAL_KEYS,
    UNIT_AXIS,
    cluster_states,
    rotor_name,
)
from gyrogen.scene import Scene
from gyrogen.scene.rotors import Rotor, gimbals, lumped_part
from gyrogen.symbolic import cluster, equations, model
from gyrogen.symbolic.equations import Equations


@dataclasses.dataclass(frozen=True)
class Unit:
    """A rotor's exact geometry and inertias: a fixed rotor (g_g None) or a
    gimbal's unit (frames at gam = 0 and the frame's principal inertias)."""

    k: int
    axis: sm.Matrix
    """g (a fixed rotor) or g_s0 (on a gimbal), exact unit."""
    J: sm.Expr
    I: sm.Expr
    g_g: sm.Matrix | None = None
    g_t0: sm.Matrix | None = None
    inertia: tuple[sm.Expr, sm.Expr, sm.Expr] = (sm.S.Zero, sm.S.Zero, sm.S.Zero)
    """IGs, IGt, IGg."""

    def frames(self, c: sm.Expr, s: sm.Expr) -> tuple[sm.Matrix, sm.Matrix]:
        """g_s and g_t at cos(gam) = c, sin(gam) = s."""
        assert self.g_t0 is not None
        return c * self.axis + s * self.g_t0, c * self.g_t0 - s * self.axis

    @property
    def d(self) -> sm.Expr:
        """IGt + I - IGs: the part of the carrier's inertia that turns with g_t."""
        return self.inertia[1] + self.I - self.inertia[0]

    @property
    def c(self) -> sm.Expr:
        """IGg + I: the gimbal's own inertia about g_g."""
        return self.inertia[2] + self.I


def _unit(r: Rotor, k: int) -> Unit:
    """Rotor k's unit: on a gimbal with a runtime axis, g_g, g_s0 and
    g_t0 = g_g x g_s0 setup's scalars (_pair_axes; the proof knows their
    relations: _relations)."""
    J = cluster._param(rotor_name("J", k), r.J)
    I = cluster._param(rotor_name("I", k), r.I)
    if r.gimbal is None:
        return Unit(k, cluster._axis(r, k), J, I)
    g_g = cluster.gimbal_axis(lumped_part(r)[2], k)
    igs, igt, igg = (
        cluster._param(rotor_name(n, k), x)
        for n, x in zip(GIMBAL_INERTIA, r.gimbal.inertia, strict=True)
    )
    frame = (igs, igt, igg)
    if r.axes_at_runtime:  # setup's g_s0 and g_t0 (_pair_axes)
        g_s0, g_t0 = (sm.Matrix(_plain(_names(keys, k))) for keys in (UNIT_AXIS, CROSS_AXIS))
        return Unit(k, g_s0, J, I, g_g, g_t0, frame)
    g_s0 = cluster._exact(r.spin_axis)  # exactly perpendicular to g_g
    return Unit(k, g_s0, J, I, g_g, g_g.cross(g_s0), frame)


def _names(keys: tuple[str, ...], k: int) -> tuple[str, ...]:
    return tuple(rotor_name(key, k) for key in keys)


def _pair_axes(scene: Scene) -> dict[sm.Symbol, sm.Expr]:
    """Each gimbal's pair with a runtime axis, as setup makes it orthonormal:
    g_g normalized (ggn_k, a runtime one), g_s0 less its part along g_g,
    normalized (gn_k: Gram-Schmidt), g_t0 = g_g x g_s0 (gtn_k)."""
    out: dict[sm.Symbol, sm.Expr] = {}
    for k, r in enumerate(scene.rotors, 1):
        if r.gimbal is None or not r.axes_at_runtime:
            continue
        g_g = cluster.gimbal_axis(lumped_part(r)[2], k)
        if r.gimbal.axis == "runtime":
            raw = sm.Matrix(_plain(_names(GIMBAL_AXIS, k)))
            out.update(zip(g_g, raw / sm.sqrt(raw.dot(raw)), strict=True))
        if r.axis == "runtime":
            spin = sm.Matrix(_plain(_names(AXIS, k)))
        else:
            spin = sm.Matrix([cluster._number(x) for x in r.axis])
        along = spin - spin.dot(g_g) * g_g
        g_s0 = sm.Matrix(_plain(_names(UNIT_AXIS, k)))
        out.update(zip(g_s0, along / sm.sqrt(along.dot(along)), strict=True))
        out.update(zip(_plain(_names(CROSS_AXIS, k)), g_g.cross(g_s0), strict=True))
    return out


def _trig(k: int) -> tuple[sm.Expr, sm.Expr]:
    gam = sm.Symbol(f"gam{k}", real=True)
    return sm.cos(gam), sm.sin(gam)


def kane(carrier: sm.Matrix, units: list[Unit]) -> tuple[sm.Matrix, sm.Matrix, sm.Matrix]:
    """KanesMethod on the bodies: the carrier (carrier: its inertia about C
    with every mass at its position and the fixed rotors' transverse
    inertias), each gimbal frame and wheel (massless at C: their masses are
    in carrier), each fixed rotor's axial inertia. Net torques net<k> on the
    wheels, ug<k> on the gimbals. Speeds u1..u3, nu<k> (gimbals), w1..wN:
    (mass matrix, forcing, q1'..q3') in plain symbols."""
    gim = [x for x in units if x.g_g is not None]
    q = me.dynamicsymbols("q1:4")
    gam = [me.dynamicsymbols(f"gam{x.k}") for x in gim]
    u = me.dynamicsymbols("u1:4")
    nu = [me.dynamicsymbols(f"nu{x.k}") for x in gim]
    w = [me.dynamicsymbols(f"w{x.k}") for x in units]
    t = me.dynamicsymbols._t
    N = me.ReferenceFrame("N")
    A = N.orientnew("A", "Body", q, "312")
    w_A = A.ang_vel_in(N)
    omega = u[0] * A.x + u[1] * A.y + u[2] * A.z

    def vec(m: sm.Matrix) -> me.Vector:
        return m[0] * A.x + m[1] * A.y + m[2] * A.z

    kd = [w_A.dot(A.x) - u[0], w_A.dot(A.y) - u[1], w_A.dot(A.z) - u[2]]
    kd += [gam[i].diff(t) - (nu[i] - vec(x.g_g).dot(omega)) for i, x in enumerate(gim)]
    A.set_ang_vel(N, omega)
    C = me.Point("C")
    C.set_vel(N, 0)
    (i11, i12, i13), (_, i22, i23), (_, _, i33) = carrier.tolist()
    bodies = [me.RigidBody("A~", C, A, 1, (me.inertia(A, i11, i22, i33, i12, i23, i13), C))]
    loads: list[tuple[me.ReferenceFrame, me.Vector]] = []
    on_a = sm.S.Zero * A.x
    for j, x in enumerate(units):
        net = sm.Symbol(f"net{x.k}", real=True)
        if x.g_g is None:
            g = vec(x.axis)
            B = me.ReferenceFrame(f"B{x.k}")
            B.set_ang_vel(N, omega + (w[j] - g.dot(omega)) * g)
            bodies.append(me.RigidBody(f"B{x.k}", C, B, 0, (x.J * (g | g), C)))
            loads.append((B, net * g))
            on_a -= net * g
            continue
        i = gim.index(x)
        axes = x.frames(sm.cos(gam[i]), sm.sin(gam[i]))
        g_s, g_t, g_g = vec(axes[0]), vec(axes[1]), vec(x.g_g)
        ug = sm.Symbol(f"ug{x.k}", real=True)
        folded = x.axis[0].is_number and x.g_g[0].is_number
        if folded:
            # G oriented from A, its axes (g_s, g_t, g_g): each inertia is
            # constant in them (no time derivative of its components in A's)
            G = A.orientnew(f"G{x.k}", "DCM", sm.Matrix.hstack(*axes, x.g_g))
            G.set_ang_vel(A, gam[i].diff(t) * g_g)
            e_s, e_t, e_g = G.x, G.y, G.z
        else:  # runtime axes, orthonormal modulo the proof's relations: in A's
            G = me.ReferenceFrame(f"G{x.k}")
            e_s, e_t, e_g = g_s, g_t, g_g
        w_G = omega + (nu[i] - g_g.dot(omega)) * g_g
        G.set_ang_vel(N, w_G)
        W = me.ReferenceFrame(f"W{x.k}")
        W.set_ang_vel(N, w_G + (w[j] - g_s.dot(w_G)) * g_s)
        if folded:
            W.set_ang_vel(G, (w[j] - g_s.dot(w_G)) * e_s)
        igs, igt, igg = x.inertia
        frame = igs * (e_s | e_s) + igt * (e_t | e_t) + igg * (e_g | e_g)
        wheel = x.I * ((e_t | e_t) + (e_g | e_g)) + x.J * (e_s | e_s)
        bodies += [me.RigidBody(f"G{x.k}", C, G, 0, (frame, C)),
                   me.RigidBody(f"W{x.k}", C, W, 0, (wheel, C))]  # fmt: skip
        loads += [(W, net * g_s), (G, ug * g_g - net * g_s)]
        on_a -= ug * g_g
    loads.append((A, on_a))
    km = me.KanesMethod(N, q_ind=[*q, *gam], u_ind=[*u, *nu, *w], kd_eqs=kd)
    km.kanes_equations(bodies, loads)
    plain = {f: sm.Symbol(f.func.__name__, real=True) for f in (*q, *gam, *u, *nu, *w)}
    kin = km.kindiffdict()
    qdot = sm.Matrix([sm.trigsimp(me.msubs(kin[x.diff(t)], plain)) for x in q])
    return me.msubs(km.mass_matrix, plain), me.msubs(km.forcing, plain), qdot


SIN_A, SIN_T = "as", "at"
"""Named values of the rhs: g_s . w_A and g_t . w_A of gimbal k (as<k>, at<k>)."""
RATE = "nd"
"""nd<k>: gimbal k's absolute acceleration nu' (a named value)."""
GIMBAL_TORQUE = "ug"
"""ug<k>: gimbal k's motor torque, when its law reads the state."""
CARRIER = ("Mt11", "Mt22", "Mt33", "Mt12", "Mt13", "Mt23")
"""I~(gam)'s entries, named values of the rhs."""
COFACTORS = ("adj11", "adj22", "adj33", "adj12", "adj13", "adj23")
"""Their cofactors (I~ symmetric: the adjugate is too)."""
DET, SOLVED = "detM", ("ud1", "ud2", "ud3")
"""I~'s determinant, and w_A' = adj(I~) f / det (named: gd' reads it)."""


def _pairs() -> list[tuple[int, int]]:
    return [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]


def _solve(
    lumped: sm.Matrix, units: list[Unit], f: sm.Matrix, trig: dict[int, tuple[sm.Expr, sm.Expr]]
) -> tuple[dict[sm.Symbol, sm.Expr], sm.Matrix, sm.Matrix]:
    """I~(gam)'s entries, cofactors, determinant and the solved w_A' as
    named values: (their values, I~ in the names, w_A' in the names)."""
    out: dict[sm.Symbol, sm.Expr] = {}
    entries = _plain(CARRIER)
    for s, (i, j) in zip(entries, _pairs(), strict=True):
        turning = sm.Add(
            *(
                x.d * x.frames(*trig[x.k])[1][i] * x.frames(*trig[x.k])[1][j]
                for x in units
                if x.g_g is not None
            )
        )
        out[s] = lumped[i, j] + turning
    m11, m22, m33, m12, m13, m23 = entries
    m = sm.Matrix([[m11, m12, m13], [m12, m22, m23], [m13, m23, m33]])
    a11, a22, a33, a12, a13, a23 = _plain(COFACTORS)
    out.update({a11: m22 * m33 - m23**2, a22: m11 * m33 - m13**2, a33: m11 * m22 - m12**2,
                a12: m13 * m23 - m12 * m33, a13: m12 * m23 - m13 * m22,
                a23: m12 * m13 - m11 * m23})  # fmt: skip
    det = sm.Symbol(DET, real=True)
    out[det] = m11 * a11 + m12 * a12 + m13 * a13
    adj = sm.Matrix([[a11, a12, a13], [a12, a22, a23], [a13, a23, a33]])
    solved = sm.Matrix(_plain(SOLVED))
    out.update(zip(solved, adj * f / det, strict=True))
    return out, m, solved


def _plain(names: tuple[str, ...]) -> tuple[sm.Symbol, ...]:
    return tuple(sm.Symbol(n, real=True) for n in names)


def _gimbal_torque(r: Rotor, k: int, gd: sm.Symbol, perturbed: bool) -> sm.Expr:
    """u_g: none, constant Tg, a table's torqueg_k(t) (an input), or the rate
    servo -kg (gd - rate_ref), clamped to tau_max."""
    assert r.gimbal is not None
    law = {
        key: cluster._param(rotor_name(GIMBAL_KEYS[key], k), v) for key, v in r.gimbal.law().items()
    }
    if perturbed:
        key = "rate_ref" if r.gimbal.torque == "rate_servo" else "T"
        law[key] = law.get(key, sm.S.Zero) + equations.delta(rotor_name(GIMBAL_KEYS[key], k))
    torque = law.get("T", sm.S.Zero)
    if r.gimbal.torque == "table":
        torque += sm.Symbol(f"{cluster.TABLE}g_{k}", real=True)
    elif r.gimbal.torque == "rate_servo":
        torque = -law["k"] * (gd - law["rate_ref"])
    if r.gimbal.tau_max is not None:
        limit = cluster._number(r.gimbal.tau_max)
        torque = sm.Min(sm.Max(torque, -limit), limit)
    return torque


def inputs(scene: Scene) -> tuple[str, ...]:
    """The linear model's inputs: each rotor's (cluster.inputs), then each
    gimbal's rate_ref_k (a rate servo) or its torque Tg_k."""
    return cluster.inputs(scene) + tuple(
        rotor_name("rate_ref" if r.gimbal.torque == "rate_servo" else "Tg", k)
        for k, r in enumerate(scene.rotors, 1)
        if r.gimbal is not None
    )


def _nd(x: Unit, ug: sm.Expr, w: sm.Expr, sa: sm.Expr, ta: sm.Expr) -> sm.Expr:
    """nu' of gimbal x: (u_g + (J w - d as) at) / (IGg + I)."""
    return (ug + (x.J * w - x.d * sa) * ta) / x.c


def _momentum(units: list[Unit], lumped: sm.Matrix, v: dict) -> sm.Matrix:
    """h about C in A: L w_A + sum_k [d at g_t + (IGg + I) nu g_g + J w g_s]
    (a fixed rotor's J w g). v: w_a, and per k w, gd, as, at, trig."""
    w_a = v["w_a"]
    h = lumped * w_a
    for x in units:
        if x.g_g is None:
            h += x.J * v["w"][x.k] * x.axis
            continue
        g_s, g_t = x.frames(*v["trig"][x.k])
        nu = x.g_g.dot(w_a) + v["gd"][x.k]
        h += x.d * v["at"][x.k] * g_t + x.c * nu * x.g_g + x.J * v["w"][x.k] * g_s
    return h


def _forcing(units: list[Unit], h: sm.Matrix, v: dict) -> sm.Matrix:
    """I~ w_A' = h x w_A - sum_k [(net - d gd at) g_s + gd (J w - d as) g_t
    + (IGg + I) nd g_g] (a fixed rotor's net g). v: as _momentum, with net
    and nd per k."""
    out = h.cross(v["w_a"])
    for x in units:
        net = v["net"][x.k]
        if x.g_g is None:
            out -= net * x.axis
            continue
        g_s, g_t = x.frames(*v["trig"][x.k])
        gd, sa, ta = v["gd"][x.k], v["as"][x.k], v["at"][x.k]
        out -= (net - x.d * gd * ta) * g_s + gd * (x.J * v["w"][x.k] - x.d * sa) * g_t
        out -= x.c * v["nd"][x.k] * x.g_g
    return out


@dataclasses.dataclass(frozen=True)
class Relations:
    """What the gimbal angles and the runtime axes satisfy, in blocks of
    their own variables: each angle's s, c (s^2 + c^2 - 1); a fixed
    rotor's runtime axis (g3^2 + g1^2 + g2^2 - 1); a gimbal's pair with a
    runtime axis (g_t0 = g_g x g_s0, leading in g_t0's own symbols, then
    |g_g| = 1, |g_s0| = 1, g_s0 . g_g = 0 for those of it that are
    symbols). Each block's polynomials are a lex Groebner basis of a prime
    ideal (a circle, a sphere, a conic, or the orthonormal pairs, SO(3)
    over C: smooth complete intersections) whose real points are dense in
    its variety; the blocks share no variable, so the union of their bases
    is one (leading terms in disjoint variables are coprime: Buchberger's
    first criterion), and a polynomial vanishes at every real angle and
    axis exactly when its normal form is zero."""

    swap: dict[sm.Expr, sm.Symbol]
    """cos and sin of each gimbal angle as the plain c<k>, s<k>."""
    variables: tuple[sm.Symbol, ...]
    """The blocks' variables in order: the ring's first (lex)."""
    blocks: tuple[tuple[int, int, tuple[sm.Expr, ...]], ...]
    """Each block: its variables' slice of variables, and its basis."""


def _relations(units: list[Unit]) -> Relations:
    swap: dict[sm.Expr, sm.Symbol] = {}
    variables: list[sm.Symbol] = []
    blocks: list[tuple[int, int, tuple[sm.Expr, ...]]] = []

    def block(names: list[sm.Symbol], basis: list[sm.Expr]) -> None:
        blocks.append((len(variables), len(variables) + len(names), tuple(basis)))
        variables.extend(names)

    for x in units:
        if x.g_g is not None:
            cos, sin = _trig(x.k)
            swap[cos], swap[sin] = sm.Symbol(f"c{x.k}"), sm.Symbol(f"s{x.k}")
            block([swap[sin], swap[cos]], [swap[sin] ** 2 + swap[cos] ** 2 - 1])
    for x in units:
        if x.axis[0].is_number:
            continue
        if x.g_g is None:
            g1, g2, g3 = x.axis
            block([g3, g1, g2], [g3**2 + g1**2 + g2**2 - 1])
            continue
        assert x.g_t0 is not None
        pair = [*(() if x.g_g[0].is_number else x.g_g), *x.axis]
        equations = [x.axis.dot(x.axis) - 1, x.axis.dot(x.g_g)]
        if not x.g_g[0].is_number:
            equations.append(x.g_g.dot(x.g_g) - 1)
        order = [*pair[2::-1], *pair[3:][::-1]] if len(pair) == 6 else pair[::-1]
        basis = sm.groebner(equations, *order, order="lex").exprs
        block([*x.g_t0, *order], [*(x.g_t0 - x.g_g.cross(x.axis)), *basis])
    return Relations(swap, tuple(variables), tuple(blocks))


def _on_circles(e: sm.Expr, rel: Relations) -> PolyElement:
    """e with cos and sin of every gimbal angle as c, s, a polynomial over
    the rationals (or the field of its radicals) reduced modulo rel's bases
    (each runtime axis is normalized by setup, a gimbal's pair made
    orthonormal): its normal form, zero exactly when e vanishes for every
    angle and axis."""
    e = e.xreplace(rel.swap)
    radicals = [a for a in e.atoms(sm.Pow) if not a.free_symbols]
    field = QQ.algebraic_field(*radicals) if radicals else QQ
    others = sorted(e.free_symbols - set(rel.variables), key=str)
    try:  # a polynomial in every symbol
        r, *_ = ring([*rel.variables, *others], field, lex)
        p = _polynomial(e, r)
    except ValueError:  # a runtime mass in a denominator: its rational functions as coefficients
        domain = field.frac_field(*others) if others else field
        r, *_ = ring(list(rel.variables), domain, lex)
        p = _polynomial(e, r)
    for start, stop, basis in rel.blocks:
        p = _reduced(p, [r.from_expr(x) for x in basis], start, stop)
    return p


def _polynomial(e: sm.Expr, r: PolyRing) -> PolyElement:
    """r.from_expr(e) by its steps, each distinct subexpression converted
    once: Kane's forcing repeats its subexpressions many times over (its
    tree is ~20,000 operations, its polynomial ~240 terms)."""
    gens = dict(zip(r.symbols, r.gens, strict=True))
    done: dict[sm.Expr, PolyElement] = {}

    def walk(x: sm.Expr) -> PolyElement:
        got = gens.get(x, done.get(x))
        if got is None:
            if x.is_Add:
                got = functools.reduce(operator.add, [walk(a) for a in x.args])
            elif x.is_Mul:
                got = functools.reduce(operator.mul, [walk(a) for a in x.args])
            else:
                base, exp = x.as_base_exp()
                if exp.is_Integer and exp > 1:
                    got = walk(base) ** int(exp)
                else:
                    got = r.ground_new(r.domain.convert(x))
            done[x] = got
        return got

    try:
        return r.ring_new(walk(sm.sympify(e)))
    except CoercionFailed as exc:
        raise ValueError(f"not a polynomial in {r}: {e}") from exc


def _reduced(p: PolyElement, basis: list[PolyElement], start: int, stop: int) -> PolyElement:
    """p's normal form modulo basis, a Groebner basis in the ring's
    variables start..stop-1 (lex), term by term: the normal form is
    linear, and a term's is its part in those variables' (reduced once per
    such monomial) times the rest, which no leading term of the basis
    divides; a term reduced modulo another block stays so.
    (PolyElement.rem would look for the leading term of all of p at each
    step: quadratic in p's terms.)"""
    r = p.ring
    one = r.domain.one
    cache: dict[tuple[int, ...], PolyElement] = {}
    out: dict[tuple[int, ...], Any] = {}
    for expv, coeff in p.items():
        head = expv[start:stop]
        if head not in cache:
            mono = (0,) * start + head + (0,) * (r.ngens - stop)
            cache[head] = r({mono: one}).rem(basis)
        for term, c in cache[head].items():
            key = expv[:start] + term[start:stop] + expv[stop:]
            out[key] = out.get(key, r.domain.zero) + coeff * c
    return r({key: c for key, c in out.items() if c})


def _prove(units: list[Unit], lumped: sm.Matrix, carrier: sm.Matrix) -> sm.Matrix:
    """Kane's mass matrix and forcing against the momentum form, entry by
    entry, with plain net<k>, ug<k> and the speeds u, nu<k>, w<k>; q1'..q3'."""
    mm, forcing, qdot = kane(carrier, units)
    gim = [x for x in units if x.g_g is not None]
    w_a = sm.Matrix(_plain(("u1", "u2", "u3")))
    trig = {x.k: _trig(x.k) for x in gim}
    nu = {x.k: sm.Symbol(f"nu{x.k}", real=True) for x in gim}
    v: dict = {"w_a": w_a, "trig": trig, "w": {x.k: sm.Symbol(f"w{x.k}", real=True) for x in units},
               "net": {x.k: sm.Symbol(f"net{x.k}", real=True) for x in units},
               "gd": {x.k: nu[x.k] - x.g_g.dot(w_a) for x in gim},  # type: ignore[union-attr]
               "as": {x.k: x.frames(*trig[x.k])[0].dot(w_a) for x in gim},
               "at": {x.k: x.frames(*trig[x.k])[1].dot(w_a) for x in gim}}  # fmt: skip
    v["nd"] = {
        x.k: _nd(x, sm.Symbol(f"ug{x.k}", real=True), v["w"][x.k], v["as"][x.k], v["at"][x.k])
        for x in gim
    }
    turning = sm.zeros(3, 3)
    for x in gim:
        g_t = x.frames(*trig[x.k])[1]
        turning += x.d * g_t * g_t.T
    expected = sm.diag(lumped + turning, *(x.c for x in gim), *(x.J for x in units))
    f = _forcing(units, _momentum(units, lumped, v), v)
    momentum = [*f, *(x.c * v["nd"][x.k] for x in gim), *(v["net"][x.k] for x in units)]
    rel = _relations(units)
    if any(_on_circles(e, rel) != 0 for e in mm - expected) or any(
        _on_circles(a - b, rel) != 0 for a, b in zip(forcing, momentum, strict=True)
    ):
        raise AssertionError("internal: Kane's gimbal equations differ from the momentum form")
    return qdot


def _carrier(units: list[Unit], lumped: sm.Matrix) -> sm.Matrix:
    """The carrier body's inertia about C for Kane: L without the gimbals'
    constant parts IGs (1 - g_g g_g^T), which their frames carry."""
    out = sm.Matrix(lumped)
    for x in units:
        if x.g_g is not None:
            out -= x.inertia[0] * (sm.eye(3) - x.g_g * x.g_g.T)
    return out


def _code(
    scene: Scene, st: dict[str, sm.Symbol], units: list[Unit], lumped: sm.Matrix, perturbed: bool
) -> dict:
    """The rhs's named values in order (the wheels' torques, as and at, the
    gimbals' torques and nd, h, f, I~, its cofactors and determinant, w_A')
    and the solved speeds' rates (u', gd', w')."""
    w_a = sm.Matrix([st["u1"], st["u2"], st["u3"]])
    gim = [x for x in units if x.g_g is not None]
    trig = {x.k: _trig(x.k) for x in gim}
    v: dict = {"w_a": w_a, "trig": trig, "w": {x.k: st[f"w{x.k}"] for x in units},
               "gd": {x.k: st[f"gd{x.k}"] for x in gim},
               "as": {x.k: sm.Symbol(f"{SIN_A}{x.k}", real=True) for x in gim},
               "at": {x.k: sm.Symbol(f"{SIN_T}{x.k}", real=True) for x in gim}}  # fmt: skip
    shared: dict[sm.Symbol, sm.Expr] = {}
    for x in gim:
        g_s, g_t = x.frames(*trig[x.k])
        shared[v["as"][x.k]], shared[v["at"][x.k]] = g_s.dot(w_a), g_t.dot(w_a)
    along = [x.axis.dot(w_a) if x.g_g is None else v["as"][x.k] for x in units]
    torques = cluster._torques(scene, st, along, perturbed)
    shared.update(torques["shared"])
    v["net"] = {x.k: net for x, net in zip(units, torques["nets"], strict=True)}
    v["nd"], gimbal_motors = {}, {}
    for x in gim:
        ug = _gimbal_torque(scene.rotors[x.k - 1], x.k, st[f"gd{x.k}"], perturbed)
        if ug.free_symbols & set(st.values()):
            name = sm.Symbol(f"{GIMBAL_TORQUE}{x.k}", real=True)
            shared[name], ug = ug, name
        gimbal_motors[x.k] = ug
        v["nd"][x.k] = sm.Symbol(f"{RATE}{x.k}", real=True)
        shared[v["nd"][x.k]] = _nd(x, ug, v["w"][x.k], v["as"][x.k], v["at"][x.k])
    h = sm.Matrix(_plain(("h1", "h2", "h3")))
    f = sm.Matrix(_plain(tuple(f"{cluster.FORCING}{i}" for i in (1, 2, 3))))
    shared.update(zip(h, _momentum(units, lumped, v), strict=True))
    shared.update(zip(f, _forcing(units, h, v), strict=True))
    solve, _, solved = _solve(lumped, units, f, trig)
    shared.update(solve)
    rates = [*solved, *(v["nd"][x.k] - x.g_g.dot(solved) for x in gim),  # type: ignore[union-attr]
             *(net / x.J for x, net in zip(units, torques["nets"], strict=True))]  # fmt: skip
    tabled = [x.k for x in gim if _law_of(scene, x.k) == "table"]
    tables = tuple(sm.Symbol(f"{cluster.TABLE}g_{k}", real=True) for k in tabled)
    return {
        "shared": shared,
        "rates": sm.Matrix(rates),
        "motors": torques["motors"],
        "gimbal_motors": gimbal_motors,
        "inputs": torques["inputs"] + tables,
        "v": v,
    }


def _law_of(scene: Scene, k: int) -> str:
    """Rotor k's gimbal torque law."""
    gimbal = scene.rotors[k - 1].gimbal
    assert gimbal is not None
    return gimbal.torque


def derive(scene: Scene) -> Equations:
    """The equations of a cluster scene with a rotor on a gimbal."""
    units = [_unit(r, k) for k, r in enumerate(scene.rotors, 1)]
    exact = cluster.lumped_inertia(scene)
    lumped, named = cluster._named(exact)
    qdot = _prove(units, exact, _carrier(units, exact))
    names = cluster_states(len(units), False, True, gimbals(scene.rotors))
    st = dict(zip(names, _plain(names), strict=True))
    code = _code(scene, st, units, lumped, perturbed=False)
    w_a = sm.Matrix([st["u1"], st["u2"], st["u3"]])
    kin = dict(zip(("q1", "q2", "q3"), qdot, strict=True))
    kin.update({f"th{x.k}": st[f"w{x.k}"] - x.axis.dot(w_a) for x in units if x.g_g is None})
    kin.update({f"gam{x.k}": st[f"gd{x.k}"] for x in units if x.g_g is not None})
    if scene.attitude == "quaternion":
        quat = model.quaternion()
        kin.update(zip((e.name for e in quat.e), quat.kinematics, strict=True))
        st.update({e.name: e for e in quat.e})
    kept = scene.states
    n_u = 3 + len(units) + len(gimbals(scene.rotors))
    eqs = Equations(
        states=tuple(st[s] for s in kept),
        params=tuple(sm.Symbol(name, real=True) for name in scene.runtime),
        mass_matrix=sm.eye(n_u),
        forcing=code["rates"],
        kinematics=sm.Matrix([kin[s] for s in kept[: len(kept) - n_u]]),
        lumped={**cluster._unit_axes(scene), **_pair_axes(scene), **named},
        inputs=code["inputs"],
        outputs=_outputs(scene, st, units, code),
        shared=code["shared"],
        checks={n: sm.Symbol(n, real=True) for n in scene.runtime if cluster._inertial(n)},
        coupled=lumped,
        gather=True,
    )
    if not scene.outputs.linear_model:
        return eqs
    pert = _code(scene, st, units, lumped, perturbed=True)
    names_in = inputs(scene)
    perturbed = equations.Perturbed(
        controls=tuple(equations.delta(n) for n in names_in),
        names=names_in,
        forcing=pert["rates"],
        shared=pert["shared"],
        outputs=_outputs(scene, st, units, pert),
    )
    return dataclasses.replace(eqs, perturbed=perturbed)


def _outputs(
    scene: Scene, st: dict[str, sm.Symbol], units: list[Unit], code: dict
) -> dict[str, tuple[sm.Expr, ...]]:
    """Energy, angular momentum about C in N, each rotor's motor power
    (a gimbal's: u_s Omega + u_g gd), in states and parameters."""
    full = cluster._expanded(code["shared"])
    w_a = sm.Matrix([st["u1"], st["u2"], st["u3"]])
    h = [sm.expand(sm.Symbol(f"h{i}", real=True).xreplace(full)) for i in (1, 2, 3)]
    out: dict[str, tuple[sm.Expr, ...]] = {}
    if scene.outputs.kinetic_energy:
        # 2T = w_A . h + sum_k [(IGg + I) nu gd + J w Omega]: h holds w_A's share
        energy = w_a.dot(sm.Matrix(h))
        for x in units:
            w = st[f"w{x.k}"]
            along = x.axis.dot(w_a) if x.g_g is None else code["v"]["as"][x.k].xreplace(full)
            energy += x.J * w * (w - along)
            if x.g_g is not None:
                gd = st[f"gd{x.k}"]
                energy += x.c * (x.g_g.dot(w_a) + gd) * gd
        out["kinetic_energy"] = (sm.expand(energy) / 2,)
    if scene.outputs.angular_momentum:
        quaternion = scene.attitude == "quaternion"
        dcm = model.quaternion().dcm if quaternion else equations.plain(model.direction_cosines())
        out["angular_momentum"] = tuple(
            sm.Add(*(dcm[i, j] * h[i] for i in range(3)), evaluate=False) for j in range(3)
        )
    if scene.outputs.power:
        power = []
        for x, motor in zip(units, code["motors"], strict=True):
            along = x.axis.dot(w_a) if x.g_g is None else code["v"]["as"][x.k].xreplace(full)
            p = motor.xreplace(full) * (st[f"w{x.k}"] - along)
            if x.g_g is not None:
                p += code["gimbal_motors"][x.k].xreplace(full) * st[f"gd{x.k}"]
            power.append(p)
        out["power"] = tuple(power)
    return out
