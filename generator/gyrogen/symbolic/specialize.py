"""From the full lumped model to the equations one scene needs: fold the
numbers it fixes, apply its torque law, drop the states it does not keep,
and add the outputs it asks for."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import sympy as sm

from gyrogen.abi import CONTROLLER_PARAMETERS
from gyrogen.scene import Scene
from gyrogen.setup_checks import checked_parameters
from gyrogen.symbolic import cluster, equations, gimbals, model
from gyrogen.symbolic import events as symbolic_events
from gyrogen.symbolic.equations import Equations


def _symbols(scene: Scene) -> dict[str, sm.Symbol]:
    s = model.symbols()
    names = dict(zip((p.name for p in s.params), s.params, strict=True))
    names.update({n: sm.Symbol(n, real=True) for n in CONTROLLER_PARAMETERS})
    return names


def _values(scene: Scene, sym: dict[str, sm.Symbol]) -> dict[str, sm.Expr]:
    """Each parameter as the code sees it: its symbol (runtime) or its value
    (folded) as the exact rational of the decimal the scene writes (0.05 is
    1/20, not the double's 3602879701896397/2**56): zeros and equal values
    cancel exactly, and the numbers stay as short as the user wrote them."""
    return {
        n: sym[n] if v == "runtime" else sm.Rational(repr(float(v)))
        for n, v in scene.parameters.items()
    }


SLIP = sm.Symbol("slip", real=True)
"""The speed controller's u4 - u2 - w_ref (rad/s), named: see Equations.shared."""


def _shared(
    scene: Scene, v: dict[str, sm.Expr], u: dict[str, sm.Symbol]
) -> dict[sm.Symbol, sm.Expr]:
    if scene.effects.torque == "speed_controller":
        return {SLIP: u["u4"] - u["u2"] - v["w_ref"]}
    return {}


def _torque(scene: Scene, v: dict[str, sm.Expr], u: dict[str, sm.Symbol]) -> sm.Expr:
    law = scene.effects.torque
    if law == "none":
        return sm.S.Zero
    if law == "constant":
        return v["T"]
    if law == "speed_controller":
        return -v["k"] * SLIP
    return sm.Symbol("torque", real=True)  # table: a per-call input computed from t


def specialize(scene: Scene) -> Equations:
    if any(r.gimbal is not None for r in scene.rotors):
        eqs = gimbals.derive(scene)
    else:
        eqs = cluster.derive(scene) if scene.rotors else _single(scene)
    if scene.events:
        eqs = dataclasses.replace(eqs, events=symbolic_events.events(scene, eqs))
    return eqs


def _single(scene: Scene) -> Equations:
    sym = _symbols(scene)
    v = _values(scene, sym)
    full = model.lumped()
    states = equations.plain_states()
    by_name = {s.name: s for s in states}
    torque = _torque(scene, v, by_name)
    shared = _shared(scene, v, by_name)
    subs: dict[sm.Basic, sm.Expr] = {sym[n]: x for n, x in v.items() if x != sym[n]}
    subs[sym["T"]] = torque
    if "g" not in scene.parameters:  # no translation: gravity has nothing to act on
        subs[sym["g"]] = sm.S.Zero
    lumped = {s: e.subs(subs) for s, e in model.lumped_values().items()}
    numeric = {s: e for s, e in lumped.items() if e.is_number}
    subs.update(numeric)

    names = set(scene.states)
    if scene.attitude == "quaternion":  # derive as with angles, swap them for e below
        names |= {"q1", "q2", "q3"}
    keep = [i for i, s in enumerate(states) if s.name in names]
    keep_u = [i - 7 for i in keep if i >= 7]
    keep_q = [i for i in keep if i < 7]
    mm = equations.plain(full.mass_matrix).subs(subs).extract(keep_u, keep_u)
    f = equations.plain(full.forcing).subs(subs).extract(keep_u, [0])
    kin = equations.plain(full.kinematics).extract(keep_q, [0])
    kept = [states[i] for i in keep]
    if scene.attitude == "quaternion":  # e0..e3 in place of q1..q3
        quat = model.quaternion()
        kept = [*quat.e, *kept[3:]]
        kin = sm.Matrix([*quat.kinematics, *kin[3:]])
    runtime = tuple(sym[n] for n in scene.runtime)
    perturbed = None
    if scene.outputs.linear_model:
        forcing = equations.plain(full.forcing)
        perturbed = _perturbed(
            scene, v, by_name, subs, sym["T"], torque,
            lambda s: forcing.subs(s).extract(keep_u, [0]),
        )  # fmt: skip
    return Equations(
        states=tuple(kept),
        params=runtime,
        mass_matrix=mm,
        forcing=f,
        kinematics=kin,
        lumped={s: e for s, e in lumped.items() if s not in numeric},
        inputs=(torque,) if scene.effects.torque == "table" else (),
        outputs=_outputs(scene, subs, by_name, torque.xreplace(shared)),
        shared=shared,
        checks={n: v[n] for n in checked_parameters()},
        coupled=mm.extract([0, 2], [0, 2]),  # u1..u4 are always kept
        perturbed=perturbed,
    )


def _perturbed(
    scene: Scene,
    v: dict[str, sm.Expr],
    u: dict[str, sm.Symbol],
    subs: dict[sm.Basic, sm.Expr],
    T: sm.Symbol,
    torque: sm.Expr,
    forcing: Callable[[dict[sm.Basic, sm.Expr]], sm.Matrix],
) -> equations.Perturbed:
    """The rotor's input: delta on w_ref (a speed controller) or on the motor
    torque; forcing(subs) is the kept forcing under subs."""
    if scene.effects.torque == "speed_controller":
        d = equations.delta("w_ref")
        shared = {SLIP: u["u4"] - u["u2"] - (v["w_ref"] + d)}
        with_d = subs
    else:
        d = equations.delta("T")
        shared = {}
        torque = torque + d
        with_d = {**subs, T: torque}
    outputs = _outputs(scene, with_d, u, torque.xreplace(shared))
    name = "w_ref" if shared else "T"
    return equations.Perturbed((d,), (name,), forcing(with_d), shared, outputs)


def _outputs(
    scene: Scene, subs: dict[sm.Basic, sm.Expr], u: dict[str, sm.Symbol], torque: sm.Expr
) -> dict[str, tuple[sm.Expr, ...]]:
    """Energy, angular momentum in N and motor power (NOTES.md), unexpanded
    so the hoisting sees each parameter-only factor."""
    s = model.symbols()
    IA11, IA22, IA33, IA13 = (x.subs(subs) for x in s.lumped)
    J = s.p("J").subs(subs)
    u1, u2, u3, u4 = (u[f"u{i}"] for i in range(1, 5))
    out: dict[str, tuple[sm.Expr, ...]] = {}
    if scene.outputs.kinetic_energy:
        k = (IA11 * u1**2 + 2 * IA13 * u1 * u3 + IA22 * u2**2 + IA33 * u3**2 + J * u4**2) / 2
        if scene.effects.translation:
            mass = (s.p("m_a") + s.p("m_b")).subs(subs)
            k += mass * (u["u5"] ** 2 + u["u6"] ** 2 + u["u7"] ** 2) / 2
        out["kinetic_energy"] = (k,)
    if scene.outputs.angular_momentum:
        h = sm.Matrix([IA11 * u1 + IA13 * u3, IA22 * u2 + J * u4, IA13 * u1 + IA33 * u3])
        if scene.attitude == "quaternion":
            dcm = model.quaternion().dcm
        else:
            dcm = equations.plain(model.direction_cosines())
        out["angular_momentum"] = tuple(
            sm.Add(*(dcm[i, j] * h[i] for i in range(3)), evaluate=False) for j in range(3)
        )
    if scene.outputs.power:
        out["power"] = (torque * (u4 - u2),)
    return out


def full_model() -> Equations:
    """The paper's full model (the default scene)."""
    from gyrogen.scene import default

    return specialize(default())
