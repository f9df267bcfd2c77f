"""A reaction-wheel cluster's equations: the carrier A plus N axisymmetric
rotors B_k on axes g_k fixed in A (a scene's [[rotors]]).

KanesMethod derives them with lumped inertias: a carrier A~ at the system's
mass center C (fixed in A) with the lumped inertia I~ (gyrogen.physics.
cluster_inertia), and massless rotors B~_k at C with axial inertia J_k only.
The speeds are u1..u3 (A's rates, A-components) and w_k = g_k . omega_Bk,
each rotor's absolute spin rate, so the mass matrix is the constant
block-diagonal diag(I~, J_1..J_N). The code does not expand Kane's forcing:
it uses the momentum form Kane's forcing is proven equal to here, entry by
entry,

    I~ u' = h x w_A - sum_k net_k g_k,   J_k w_k' = net_k,
    h = I~ w_A + sum_k J_k w_k g_k,      net_k = T_k - b_k (w_k - g_k . w_A),

with h and each rotor's torque named values of the rhs (Equations.shared),
so the momentum the carrier and a wheel exchange is one rounded number.
With every inertial value folded I~^-1 is numbers in the code; an entry of
I~ that reads a runtime value is a named scalar of setup (IC11..IC23,
Equations.lumped), and setup inverts I~ (optimize.block_inverse). A runtime
axis is three named scalars of setup too, g_k normalized (gn1_k..gn3_k):
the proof then holds on the unit sphere (|g_k| = 1 reduces its squares).
"""

from __future__ import annotations

import dataclasses
from fractions import Fraction

import sympy as sm
import sympy.physics.mechanics as me

from gyrogen import physics
from gyrogen.abi_rotors import (
    AXIS,
    CLUSTER_CARRIER,
    GIMBAL_AXIS,
    GIMBAL_INERTIA,
    GIMBAL_KEYS,
    POSITION,
    UNIT_AXIS,
    UNIT_GIMBAL_AXIS,
    cluster_states,
    rotor_name,
)
from gyrogen.scene import Scene
from gyrogen.scene.rotors import Rotor, lumped_part
from gyrogen.symbolic import equations, model
from gyrogen.symbolic.equations import Equations


def _number(v: float) -> sm.Expr:
    """A folded value as the exact rational of the decimal written."""
    return sm.Rational(repr(float(v)))


def _axis(r: Rotor, k: int) -> sm.Matrix:
    """g_k normalized exactly (rotors.exact_unit): |g| = 1 in the algebra;
    a runtime axis: setup's normalized scalars gn1_k..gn3_k (_unit_axes)."""
    if r.axis == "runtime":
        return sm.Matrix(_plain(tuple(rotor_name(key, k) for key in UNIT_AXIS)))
    return _exact(r.unit_axis)


def _exact(v: tuple[Fraction, Fraction, Fraction]) -> sm.Matrix:
    return sm.Matrix([sm.Rational(x.numerator, x.denominator) for x in v])


def _unit_axes(scene: Scene) -> dict[sm.Symbol, sm.Expr]:
    """Each fixed rotor's runtime axis normalized by setup: gn_i_k = g_i_k /
    |g_k| (a gimbal's pair: symbolic.gimbals)."""
    out: dict[sm.Symbol, sm.Expr] = {}
    for k, r in enumerate(scene.rotors, 1):
        if r.axis == "runtime" and r.gimbal is None:
            g = _plain(tuple(rotor_name(key, k) for key in AXIS))
            norm = sm.sqrt(sm.Add(*(x**2 for x in g)))
            out.update(zip(_axis(r, k), (x / norm for x in g), strict=True))
    return out


def _on_sphere(e: sm.Expr, axes: list[sm.Matrix]) -> sm.Expr:
    """e expanded with every runtime axis's g3^2 written 1 - g1^2 - g2^2:
    its normal form on the unit spheres (0 when e vanishes there)."""
    e = sm.expand(e)
    for g1, g2, g3 in (list(g) for g in axes if not g[0].is_number):
        square = 1 - g1**2 - g2**2
        e = sm.expand(
            e.replace(
                lambda x, g3=g3: x.is_Pow and x.base == g3 and x.exp >= 2,
                lambda x, g3=g3, square=square: square ** (x.exp // 2) * g3 ** (x.exp % 2),
            )
        )
    return e


def _carrier(scene: Scene) -> list[list[sm.Expr]]:
    v = {n: _param(n, x) for n, x in scene.parameters.items()}
    z = sm.S.Zero
    i12, i13, i23 = v.get("I12", z), v.get("I13", z), v.get("I23", z)
    return [[v["I11"], i12, i13], [i12, v["I22"], i23], [i13, i23, v["I33"]]]


def lumped_inertia(scene: Scene) -> sm.Matrix:
    """I~ about the mass center C, exact: numbers, or expressions in the
    runtime parameters (carrier tensor, masses, transverse inertias); a
    rotor on a gimbal adds its frame's mass and its constant part IGs (1 -
    g_g g_g^T) (scene.rotors.lumped_part; symbolic.gimbals adds the rest)."""
    rotors = [
        (
            _param(rotor_name("m", k), r.m) + mass,
            inertia,
            axis,
            [sm.Symbol(rotor_name(key, k), real=True) for key in POSITION]
            if r.position == "runtime"
            else [_number(x) for x in r.position],
        )
        for k, r in enumerate(scene.rotors, 1)
        for mass, inertia, axis in [_transverse(r, k)]
    ]
    m_a = _param("m_a", scene.parameters["m_a"])
    return sm.Matrix(physics.cluster_inertia(m_a, _carrier(scene), rotors))


def _transverse(r: Rotor, k: int) -> tuple[sm.Expr, sm.Expr, list[sm.Expr]]:
    """What rotor k adds to I~ beside its mass: a gimbal frame's mass, and
    the transverse inertia with the axis it is transverse to (a fixed
    rotor's I about g; a gimbal's IGs about g_g: scene.rotors.lumped_part)."""
    if r.gimbal is None:
        return sm.S.Zero, _param(rotor_name("I", k), r.I), list(_axis(r, k))
    mass, inertia, axis = lumped_part(r)
    frame = _param(rotor_name(GIMBAL_KEYS["m"], k), mass)
    return frame, _param(rotor_name(GIMBAL_INERTIA[0], k), inertia), list(gimbal_axis(axis, k))


def gimbal_axis(axis: tuple[Fraction, Fraction, Fraction] | str, k: int) -> sm.Matrix:
    """Rotor k's unit gimbal axis g_g: exact (rotors.exact_unit), or a
    runtime one as setup's normalized scalars ggn1_k..ggn3_k."""
    if axis == "runtime":
        return sm.Matrix(_plain(tuple(rotor_name(key, k) for key in UNIT_GIMBAL_AXIS)))
    return _exact(axis)  # type: ignore[arg-type]


LUMPED = ((0, 0, "IC11"), (1, 1, "IC22"), (2, 2, "IC33"), (0, 1, "IC12"), (0, 2, "IC13"),
          (1, 2, "IC23"))  # fmt: skip
"""I~'s entries as setup names them when they depend on runtime parameters."""


def _named(exact: sm.Matrix) -> tuple[sm.Matrix, dict[sm.Symbol, sm.Expr]]:
    """I~ with each entry that reads a runtime parameter as a named scalar
    of setup (Equations.lumped), and those scalars' values."""
    out = sm.Matrix(exact)
    lumped: dict[sm.Symbol, sm.Expr] = {}
    for i, j, name in LUMPED:
        if exact[i, j].free_symbols:
            s = sm.Symbol(name, real=True)
            lumped[s] = exact[i, j]  # as summed: one fraction would need huge integers
            out[i, j] = out[j, i] = s
    return out, lumped


def _plain(names: tuple[str, ...]) -> tuple[sm.Symbol, ...]:
    return tuple(sm.Symbol(n, real=True) for n in names)


def kane(inertia: sm.Matrix, axes: list[sm.Matrix], axial: list[sm.Expr]) -> tuple:
    """KanesMethod on the lumped cluster with net torques net1..netN:
    (mass matrix, forcing, q' in u and w), in plain symbols."""
    n = len(axes)
    q = me.dynamicsymbols(f"q1:4 th1:{n + 1}")
    u = me.dynamicsymbols(f"u1:4 w1:{n + 1}")
    t = me.dynamicsymbols._t
    net = sm.symbols(f"net1:{n + 1}", real=True)
    N = me.ReferenceFrame("N")
    A = N.orientnew("A", "Body", q[:3], "312")
    w_A = A.ang_vel_in(N)
    g = [ax[0] * A.x + ax[1] * A.y + ax[2] * A.z for ax in axes]
    kd = [w_A.dot(A.x) - u[0], w_A.dot(A.y) - u[1], w_A.dot(A.z) - u[2]]
    omega = u[0] * A.x + u[1] * A.y + u[2] * A.z
    kd += [q[3 + k].diff(t) - (u[3 + k] - g[k].dot(omega)) for k in range(n)]
    A.set_ang_vel(N, omega)
    C = me.Point("C")
    C.set_vel(N, 0)
    (i11, i12, i13), (_, i22, i23), (_, _, i33) = inertia.tolist()
    bodies = [me.RigidBody("A~", C, A, 1, (me.inertia(A, i11, i22, i33, i12, i23, i13), C))]
    loads = [(A, -sum((net[k] * g[k] for k in range(n)), sm.S.Zero * A.x))]
    for k in range(n):
        B = A.orientnew(f"B{k + 1}", "Axis", [q[3 + k], g[k]])
        B.set_ang_vel(N, omega + (u[3 + k] - g[k].dot(omega)) * g[k])
        dyadic = axial[k] * (g[k] | g[k])
        bodies.append(me.RigidBody(f"B~{k + 1}", C, B, 0, (dyadic, C)))
        loads.append((B, net[k] * g[k]))
    km = me.KanesMethod(N, q_ind=q, u_ind=u, kd_eqs=kd)
    km.kanes_equations(bodies, loads)
    kin = km.kindiffdict()
    plain = {f: sm.Symbol(f.func.__name__, real=True) for f in (*q, *u)}
    at_zero = {f: 0 for f in q[3:]}  # the rotor angles are ignorable
    mm = me.msubs(km.mass_matrix.subs(at_zero), plain)
    forcing = me.msubs(km.forcing.subs(at_zero), plain)
    qdot = sm.Matrix([sm.trigsimp(me.msubs(kin[x.diff(t)], plain)) for x in q])
    return mm, forcing, qdot, net


SLIP, NET, MOMENTUM, FORCING, TABLE = "rel", "net", "h", "f", "torque"
"""Named values of the rhs: each wheel's relative rate and net torque, the
momentum h, and f = h x w_A - sum_k net_k g_k (= I~ u'): I~^-1 then
multiplies three numbers, where multiplying out h x w_A costs ~20 ops more.
torque_k is rotor k's T(t) from its table: a per-call input (Equations.inputs)."""


def _by_axis_component(nets: list[sm.Expr], axes: list[sm.Matrix]) -> sm.Matrix:
    """sum_k net_k g_k with the nets of equal |g_k,i| summed before one
    multiply (a pyramid's s (net1 - net3) rather than s net1 - s net3)."""
    out = []
    for i in range(3):
        groups: dict[sm.Expr, list[sm.Expr]] = {}
        for net, g in zip(nets, axes, strict=True):
            if not g[i].is_number:  # a runtime axis: its own group
                groups.setdefault(g[i], []).append(net)
            elif g[i] != 0:
                groups.setdefault(abs(g[i]), []).append(sm.sign(g[i]) * net)
        out.append(sm.Add(*(size * sm.Add(*terms) for size, terms in groups.items())))
    return sm.Matrix(out)


def inputs(scene: Scene) -> tuple[str, ...]:
    """The linear model's inputs: each rotor's w_ref_k (a speed controller)
    or its motor torque T_k."""
    return tuple(
        rotor_name("w_ref" if r.torque == "speed_controller" else "T", k)
        for k, r in enumerate(scene.rotors, 1)
    )


def _torques(
    scene: Scene, states: dict[str, sm.Symbol], along: list[sm.Expr], perturbed: bool = False
) -> dict:
    """Each rotor's net torque, and the named values it reads: rel_k (the
    rate relative to A: w_k - along_k, along_k = g_k . w_A) when friction or
    a speed controller needs it. With perturbed, each rotor's input plus its
    delta (Equations.perturbed)."""
    shared: dict[sm.Symbol, sm.Expr] = {}
    nets: list[sm.Expr] = []
    motors: list[sm.Expr] = []
    inputs: list[sm.Symbol] = []
    for k, (r, g_w) in enumerate(zip(scene.rotors, along, strict=True), 1):
        law = {key: _param(rotor_name(key, k), v) for key, v in r.law().items()}
        if perturbed:
            key = "w_ref" if r.torque == "speed_controller" else "T"
            law[key] = law.get(key, sm.S.Zero) + equations.delta(rotor_name(key, k))
        rel = sm.Symbol(f"{SLIP}{k}", real=True)
        if r.b or r.torque == "speed_controller":
            shared[rel] = states[f"w{k}"] - g_w
        motor = law.get("T", sm.S.Zero)  # constant; a perturbed none or table
        if r.torque == "table":
            table = sm.Symbol(f"{TABLE}_{k}", real=True)
            inputs.append(table)
            motor += table
        elif r.torque == "speed_controller":
            motor = -law["k"] * (rel - law["w_ref"])
        if r.tau_max is not None:
            limit = _number(r.tau_max)
            motor = sm.Min(sm.Max(motor, -limit), limit)
        motors.append(motor)
        net = motor - _number(r.b) * rel
        if net.free_symbols & set(shared):
            name = sm.Symbol(f"{NET}{k}", real=True)
            shared[name] = net
            net = name
        nets.append(net)
    return {"shared": shared, "nets": nets, "motors": motors, "inputs": tuple(inputs)}


def _param(name: str, value: float | str) -> sm.Expr:
    return sm.Symbol(name, real=True) if value == "runtime" else _number(float(value))


def _derive(scene: Scene) -> Equations:
    inertia, lumped = _named(lumped_inertia(scene))
    lumped = {**_unit_axes(scene), **lumped}
    axes = [_axis(r, k) for k, r in enumerate(scene.rotors, 1)]
    axial = [_param(rotor_name("J", k), r.J) for k, r in enumerate(scene.rotors, 1)]
    n = len(axes)
    mm, forcing, qdot, net = kane(inertia, axes, axial)
    names = cluster_states(n, False, True)
    st = dict(zip(names, _plain(names), strict=True))
    w_a = sm.Matrix([st["u1"], st["u2"], st["u3"]])
    wheels = [st[f"w{k}"] for k in range(1, n + 1)]
    h_value = inertia * w_a + sum(
        (axial[k] * wheels[k] * axes[k] for k in range(n)), sm.zeros(3, 1)
    )
    # Kane's forcing, proven equal to the momentum form, entry by entry
    tau_a = sum((net[k] * axes[k] for k in range(n)), sm.zeros(3, 1))
    momentum = [*(h_value.cross(w_a) - tau_a), *net]
    expected = sm.diag(inertia, *axial)
    if any(_on_sphere(e, axes) != 0 for e in mm - expected) or any(
        _on_sphere(a - b, axes) != 0 for a, b in zip(forcing, momentum, strict=True)
    ):
        raise AssertionError("internal: Kane's cluster equations differ from the momentum form")
    along = [g.dot(w_a) for g in axes]
    torques = _torques(scene, st, along)
    h = sm.Matrix(_plain(("h1", "h2", "h3")))
    f = sm.Matrix(_plain(tuple(f"{FORCING}{i}" for i in (1, 2, 3))))
    f_value = h.cross(w_a) - _by_axis_component(torques["nets"], axes)
    coded = sm.Matrix([*f, *torques["nets"]])
    shared = {
        **dict(zip(h, h_value, strict=True)),
        **torques["shared"],
        **dict(zip(f, f_value, strict=True)),
    }
    eqs = _equations(scene, st, expected, coded, qdot, shared, torques["motors"], axes)
    eqs = dataclasses.replace(eqs, inputs=torques["inputs"], lumped=lumped)
    if not scene.outputs.linear_model:
        return eqs
    torques = _torques(scene, st, along, perturbed=True)
    f_value = h.cross(w_a) - _by_axis_component(torques["nets"], axes)
    shared = {
        **dict(zip(h, h_value, strict=True)),
        **torques["shared"],
        **dict(zip(f, f_value, strict=True)),
    }
    names = inputs(scene)
    perturbed = equations.Perturbed(
        controls=tuple(equations.delta(n) for n in names),
        names=names,
        forcing=sm.Matrix([*f, *torques["nets"]]),
        shared=shared,
        outputs=_outputs(scene, st, expected, shared, torques["motors"], axes),
    )
    return dataclasses.replace(eqs, perturbed=perturbed)


def _equations(
    scene: Scene,
    st: dict[str, sm.Symbol],
    mass: sm.Matrix,
    forcing: sm.Matrix,
    qdot: sm.Matrix,
    shared: dict[sm.Symbol, sm.Expr],
    motors: list[sm.Expr],
    axes: list[sm.Matrix],
) -> Equations:
    """The Equations of the states the scene keeps."""
    n = len(axes)
    kin = dict(
        zip(
            [*(f"q{i}" for i in (1, 2, 3)), *(f"th{k}" for k in range(1, n + 1))], qdot, strict=True
        )
    )
    quaternion = scene.attitude == "quaternion"
    if quaternion:
        quat = model.quaternion()
        kin.update(zip((e.name for e in quat.e), quat.kinematics, strict=True))
        st.update({e.name: e for e in quat.e})
    kept = scene.states
    n_q = len(kept) - 3 - n
    return Equations(
        states=tuple(st[s] for s in kept),
        params=tuple(sm.Symbol(name, real=True) for name in scene.runtime),
        mass_matrix=mass,
        forcing=forcing,
        kinematics=sm.Matrix([kin[s] for s in kept[:n_q]]),
        lumped={},
        outputs=_outputs(scene, st, mass, shared, motors, axes),
        shared=shared,
        checks={n: sm.Symbol(n, real=True) for n in scene.runtime if _inertial(n)},
        coupled=mass.extract([0, 1, 2], [0, 1, 2]),
        gather=True,
    )


def _outputs(
    scene: Scene,
    st: dict[str, sm.Symbol],
    mass: sm.Matrix,
    shared: dict[sm.Symbol, sm.Expr],
    motors: list[sm.Expr],
    axes: list[sm.Matrix],
) -> dict[str, tuple[sm.Expr, ...]]:
    """Energy, angular momentum about C in N, each motor's power."""
    n = len(axes)
    w_a = sm.Matrix([st["u1"], st["u2"], st["u3"]])
    wheels = [st[f"w{k}"] for k in range(1, n + 1)]
    out: dict[str, tuple[sm.Expr, ...]] = {}
    if scene.outputs.kinetic_energy:
        axial = [mass[3 + k, 3 + k] for k in range(n)]
        energy = (w_a.T * mass[:3, :3] * w_a)[0] + sum(
            j * w**2 for j, w in zip(axial, wheels, strict=True)
        )
        out["kinetic_energy"] = (energy / 2,)
    if scene.outputs.angular_momentum:
        h = [sm.expand(e) for e in list(shared.values())[:3]]
        quaternion = scene.attitude == "quaternion"
        dcm = model.quaternion().dcm if quaternion else equations.plain(model.direction_cosines())
        out["angular_momentum"] = tuple(
            sm.Add(*(dcm[i, j] * h[i] for i in range(3)), evaluate=False) for j in range(3)
        )
    if scene.outputs.power:
        full = _expanded(shared)
        out["power"] = tuple(
            motor.xreplace(full) * (wheels[k] - axes[k].dot(w_a)) for k, motor in enumerate(motors)
        )
    return out


def _inertial(name: str) -> bool:
    """A runtime parameter setup's checks read: the carrier's, a mass, an
    inertia (a gimbal frame's included)."""
    key = name.rpartition("_")[0]
    frame = (GIMBAL_KEYS["m"], *GIMBAL_INERTIA)
    axes = (*AXIS, *GIMBAL_AXIS)
    return name in CLUSTER_CARRIER or key in ("m", "I", "J", *POSITION, *axes, *frame)


def _expanded(shared: dict[sm.Symbol, sm.Expr]) -> dict[sm.Symbol, sm.Expr]:
    """Each named value in states and parameters only (later ones read earlier ones)."""
    out: dict[sm.Symbol, sm.Expr] = {}
    for name, value in shared.items():
        out[name] = value.xreplace(out)
    return out


def derive(scene: Scene) -> Equations:
    """The equations of a cluster scene (scene.rotors not empty)."""
    return _derive(scene)
