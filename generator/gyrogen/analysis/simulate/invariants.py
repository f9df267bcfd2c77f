"""The invariants of NOTES.md, from the numpy reference (never from the
generated code under test), all relative:

- |H| in N is constant (and so is the vector H): (|H| - |H(0)|) / |H(0)|;
- the energy balance K(t) - K(0) - int_0^t P dt is 0, P = T (u4 - u2) + M g u7
  the power: over max |K|;
- u4(t) - u4(0) - int_0^t T dt / J is 0 (J u4' = T): over max |u4|.

`along_trajectory` takes the integrals by quadrature over a simulated trajectory (any
torque law); `series_at_samples` takes them exactly for a constant torque, at the
samples of a check case. A scale that is zero (H(0) = 0, K or u4 zero
throughout) leaves the residual absolute.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gyrogen.abi import STATES
from gyrogen.abi_rotors import rotor_name
from gyrogen.analysis.simulate.trajectory import Trajectory, running_integrals
from gyrogen.oracle import cluster_reference, gimbal_view, scene_view
from gyrogen.scene import Scene


def peak(a: np.ndarray) -> float:
    """The largest |a|, 0 for no values."""
    return float(np.max(np.abs(a))) if a.size else 0.0


def _scale(a: np.ndarray) -> float:
    """The largest |a|, or 1 when a is all zero (then the residual is absolute)."""
    return float(np.max(np.abs(a))) or 1.0


def momentum(scene: Scene, p: np.ndarray, xs: np.ndarray) -> np.ndarray:
    """(n, 3): the angular momentum about AB* in N at the states xs."""
    return scene_view.output(scene, "angular_momentum", xs, p)


def kinetic(scene: Scene, p: np.ndarray, xs: np.ndarray) -> np.ndarray:
    """(n,): the kinetic energy at the states xs."""
    return scene_view.output(scene, "kinetic_energy", xs, p)[:, 0]


def momentum_drifts(h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(|H| - |H(0)|) / |H(0)| and |H - H(0)| / |H(0)| for H (n, 3); the
    second also sees errors of the attitude, which |H| does not."""
    norm = np.linalg.norm(h, axis=1)
    h0 = norm[0] or _scale(norm)
    return (norm - norm[0]) / h0, np.linalg.norm(h - h[0], axis=1) / h0


def balance(quantity: np.ndarray, integral: np.ndarray) -> np.ndarray:
    """(q - q(0) - integral) / max |q|: a balance q(t) = q(0) + int rate dt."""
    return (quantity - quantity[0] - integral) / _scale(quantity)


def rates(scene: Scene, p: np.ndarray, t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(m, 2): the power P = dK/dt and the torque T at times t (m,), states
    x (m, nx), from the scene's torque law as the reference applies it."""
    v = scene_view.values(scene, p)
    if gimbal_view.has_gimbals(scene):  # and each gimbal's torque times its rate
        return gimbal_view.power_and_torque(scene, x, v, t)
    if scene.rotors:  # dK/dt: every net torque times its wheel's relative rate; wheel 1's
        return cluster_reference.power_and_torque(scene, x, v, t)
    full = scene_view.full_states(scene, x)
    if scene.effects.torque == "table":  # scene_view.torque takes one t; the table needs each
        table = np.array(scene.effects.torque_table)
        torque = np.interp(t, table[:, 0], table[:, 1])
    else:
        torque = scene_view.torque(scene, v, full, 0.0)
    u2, u4, u7 = (full[:, STATES.index(s)] for s in ("u2", "u4", "u7"))
    power = torque * (u4 - u2) + (v["m_a"] + v["m_b"]) * v.get("g", 0.0) * u7
    return np.column_stack([power, torque])


@dataclass(frozen=True)
class Words:
    """The balances in words for a scene: the rate checked (the rotor's u4,
    or a cluster's wheel 1: w1), its balance, and the power P."""

    rate: str
    balance: str
    power: str


def words(scene: Scene) -> Words:
    if scene.rotors:
        return Words(
            "w1",
            "w1 - w1(0) - int net_1 dt/J_1",
            "sum_k net_k (w_k - g_k . w_A), net_k = motor_k - b_k (w_k - g_k . w_A)",
        )
    return Words("u4", "u4 - u4(0) - int T dt/J", "T (u4 - u2) + M g u7")


@dataclass(frozen=True)
class Invariants:
    h: np.ndarray
    """(n, 3) angular momentum about AB* in N."""
    kinetic: np.ndarray
    power: np.ndarray
    """T (u4 - u2) + M g u7: dK/dt."""
    h_drift: np.ndarray
    """(|H| - |H(0)|) / |H(0)|."""
    h_vector_drift: np.ndarray
    """|H - H(0)| / |H(0)|: also sees errors of the attitude, which |H| does not."""
    energy: np.ndarray
    """(K - K(0) - int P dt) / max |K|."""
    u4: np.ndarray
    """(u4 - u4(0) - int T dt / J) / max |u4| (a cluster: w1's, words(scene))."""
    unresolved: tuple[str, ...] = ()
    """What the balances' quadrature could not resolve (Integrals.unresolved)."""

    def worst(self) -> dict[str, float]:
        return {
            "H_norm_relative_drift": peak(self.h_drift),
            "H_vector_relative_drift": peak(self.h_vector_drift),
            "energy_balance_relative_residual": peak(self.energy),
            "u4_relative_residual": peak(self.u4),
        }


def along_trajectory(scene: Scene, p: np.ndarray, traj: Trajectory) -> Invariants:
    """Every invariant at each grid time of traj, its integrals of P and T
    by quadrature on traj's dense output (the tables' points as ends of
    its pieces: the torque's slope jumps there)."""
    x = traj.x
    h, k = momentum(scene, p, x), kinetic(scene, p, x)
    u4 = x[:, scene.states.index("w1" if scene.rotors else "u4")]
    scales = np.array([_scale(k), _scale(u4) * _axial(scene, p)])  # the balances' normalizers
    integrals = running_integrals(
        traj, lambda t, xs: rates(scene, p, t, xs), scales, scene_view.table_times(scene)
    )
    work = integrals.values
    h_drift, h_vector_drift = momentum_drifts(h)
    return Invariants(
        h=h,
        kinetic=k,
        power=rates(scene, p, traj.t, x)[:, 0],
        h_drift=h_drift,
        h_vector_drift=h_vector_drift,
        energy=balance(k, work[:, 0]),
        u4=balance(u4, work[:, 1] / _axial(scene, p)),
        unresolved=integrals.unresolved,
    )


def _torque_free(scene: Scene) -> bool:
    """A cluster without motor torques or friction (a gimbal's torque too)."""
    return all(
        r.torque == "none" and r.b == 0 and (r.gimbal is None or r.gimbal.torque == "none")
        for r in scene.rotors
    )


def in_closed_form(scene: Scene) -> bool:
    """Whether series_at_samples has the energy balance and the rate check
    in closed form (no torque or a constant one, a cluster without torque
    or friction); otherwise they take quadrature along the run."""
    if scene.rotors:
        return _torque_free(scene)
    return scene.effects.torque in ("none", "constant")


def series_at_samples(
    scene: Scene, p: np.ndarray, xs: np.ndarray, ts: np.ndarray
) -> dict[str, np.ndarray]:
    """The relative drift of each invariant at the samples xs at times ts:
    |H| always; with no torque or a constant one, also the energy balance
    (when the rotor angle q4 gives the motor's work) and u4 = u4(0) + T t /
    J, their integrals in closed form."""
    out = {"|H| in N": momentum_drifts(momentum(scene, p, xs))[0]}
    if scene.rotors:  # a cluster's energy is constant when no wheel has torque or friction
        if _torque_free(scene):
            out["energy balance"] = balance(kinetic(scene, p, xs), np.zeros(len(xs)))
        return out
    if scene.effects.torque not in ("none", "constant"):
        return out
    v = scene_view.values(scene, p)
    torque = v.get("T", 0.0)
    idx = {s: i for i, s in enumerate(scene.states)}
    if torque == 0 or "q4" in idx:
        out["energy balance"] = balance(kinetic(scene, p, xs), _work(scene, v, xs))
    out["u4 = u4(0) + T t / J"] = balance(xs[:, idx["u4"]], torque * (ts - ts[0]) / v["J"])
    return out


def by_quadrature(scene: Scene, p: np.ndarray, traj: Trajectory) -> dict[str, np.ndarray]:
    """series_at_samples' drifts at traj's grid times for any torque law (a
    clamp, friction): the integrals of P and of the first rotor's torque by
    quadrature along traj."""
    along = along_trajectory(scene, p, traj)
    said = words(scene)
    return {"|H| in N": along.h_drift, "energy balance": along.energy, said.balance: along.u4}


def _work(scene: Scene, v: dict[str, float], xs: np.ndarray) -> np.ndarray:
    """int_0^t P dt for a constant torque: T (q4 - q4(0)) + M g (q7 - q7(0))."""
    idx = {s: i for i, s in enumerate(scene.states)}
    torque = v.get("T", 0.0)
    work = np.zeros(len(xs))
    if torque and "q4" in idx:  # integral of T (u4 - u2) dt = T (q4 - q4(0))
        work += torque * (xs[:, idx["q4"]] - xs[0, idx["q4"]])
    if scene.effects.translation:  # integral of M g u7 dt = M g (q7 - q7(0))
        work += (v["m_a"] + v["m_b"]) * v["g"] * (xs[:, idx["q7"]] - xs[0, idx["q7"]])
    return work


def _axial(scene: Scene, p: np.ndarray) -> float:
    """J of the rotor whose rate the u4 residual follows (a cluster's wheel 1)."""
    v = scene_view.values(scene, p)
    if scene.rotors:
        return v[rotor_name("J", 1)] if scene.rotors[0].J == "runtime" else float(scene.rotors[0].J)
    return v["J"]
