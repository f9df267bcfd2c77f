"""The names of a reaction-wheel cluster (a scene's [[rotors]]), derived
from the scene: rotor k = 1..N. gyrogen.abi holds the single-rotor model's
names and reads ROTOR_KEYS for a cluster's units."""

from __future__ import annotations

# Reaction-wheel clusters ([[rotors]] in a scene): names derived from the
# scene, rotor k = 1..N. The carrier's full tensor adds I12 and I23.
CLUSTER_CARRIER = ("m_a", "I11", "I22", "I33", "I12", "I13", "I23")
"""The carrier's keys in a cluster scene's [parameters] (I12, I23 default to 0)."""
ROTOR_KEYS: dict[str, tuple[str, str]] = {
    "m": ("kg", "mass of rotor B{k}"),
    "I": ("kg m^2", "transverse inertia of rotor B{k} about B{k}*"),
    "J": ("kg m^2", "axial inertia of rotor B{k} about B{k}*"),
    "b": ("N m s", "viscous friction of rotor B{k}: torque -b{k} (w{k} - g{k}.w_A)"),
    "T": ("N m", "motor torque on rotor B{k} about g{k} (minus on A)"),
    "k": ("N m s", "speed controller gain of rotor B{k}: T = -k (w{k} - g{k}.w_A - w_ref)"),
    "w_ref": ("rad/s", "speed controller of rotor B{k}: commanded rate relative to A"),
    "tau_max": ("N m", "torque limit of rotor B{k}: the motor torque is clamped to +-tau_max"),
    **{
        f"r{i}": ("m", f'position of B{{k}}* from A*, a{i} component (position = "runtime")')
        for i in (1, 2, 3)
    },
    **{
        f"g{i}": ("-", f'spin axis g{{k}} of rotor B{{k}}, a{i} component (axis = "runtime")')
        for i in (1, 2, 3)
    },
}
"""A rotor's scalar keys; in p[] and in the code the key of rotor k is <key>_<k>."""
ROTOR_RUNTIME = ("m", "I", "J", "T", "k", "w_ref")
"""The rotor keys that may be "runtime", in a rotor's p[] order (b and
tau_max are folded; position = "runtime" gives POSITION, then axis =
"runtime" AXIS, after J). With every inertial value folded the inverse of
the lumped inertia I~ is numbers in the code; with a runtime m, I, position,
axis or carrier value setup computes I~ and inverts it; a runtime J_k stays
out of I~. setup checks the runtime values (setup_checks.cluster_checks)."""
POSITION = ("r1", "r2", "r3")
"""position = "runtime": B_k*'s A-components in p[] (r1_k, r2_k, r3_k)."""
AXIS = ("g1", "g2", "g3")
"""axis = "runtime": g_k's A-components in p[] (g1_k, g2_k, g3_k), of length
within AXIS_NORM_SLACK of 1; setup normalizes them into UNIT_AXIS."""
UNIT_AXIS = ("gn1", "gn2", "gn3")
"""A runtime axis normalized: named scalars of setup (gn1_k, gn2_k, gn3_k)."""
MAX_ROTORS = 6
"""Rotors a cluster scene may have."""
AXIS_NORM_SLACK = 1e-3
"""A rotor axis must have length within this of 1; it is then normalized
(exactly when folded, by setup when runtime; a longer miss is a typo,
refused: a folded axis by the scene, a runtime one by setup's code 8)."""


def rotor_name(key: str, k: int) -> str:
    """The name of rotor k's key in p[] and in the code: T_2, w_ref_3."""
    return f"{key}_{k}"


def axis_keys(k: int) -> str:
    """Rotor k's runtime axis keys as a message names them: g1_k..g3_k."""
    return f"{rotor_name(AXIS[0], k)}..{rotor_name(AXIS[-1], k)}"


def cluster_states(n: int, quaternion: bool, angles: bool) -> tuple[str, ...]:
    """A cluster's states in x[] order: attitude, rotor angles th1..thN (if
    kept), body rates u1..u3, absolute wheel rates w1..wN."""
    attitude = ("e0", "e1", "e2", "e3") if quaternion else ("q1", "q2", "q3")
    th = tuple(f"th{k}" for k in range(1, n + 1)) if angles else ()
    return (*attitude, *th, "u1", "u2", "u3", *(f"w{k}" for k in range(1, n + 1)))
