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
    "mG": ("kg", "mass of gimbal frame G{k}"),
    "IGs": ("kg m^2", "inertia of gimbal frame G{k} about its mass center, along g_s"),
    "IGt": ("kg m^2", "inertia of gimbal frame G{k} about its mass center, along g_t"),
    "IGg": ("kg m^2", "inertia of gimbal frame G{k} about its mass center, along g_g"),
    "Tg": ("N m", "gimbal motor torque on G{k} about g_g (minus on A)"),
    "kg": ("N m s", "gimbal rate servo gain of G{k}: u_g = -kg (gd{k} - rate_ref)"),
    "rate_ref": ("rad/s", "gimbal rate servo of G{k}: commanded rate relative to A"),
    **{
        f"r{i}": ("m", f'position of B{{k}}* from A*, a{i} component (position = "runtime")')
        for i in (1, 2, 3)
    },
    **{
        f"g{i}": ("-", f'spin axis g{{k}} of rotor B{{k}}, a{i} component (axis = "runtime")')
        for i in (1, 2, 3)
    },
    **{
        f"gg{i}": ("-", f'gimbal axis g_g of G{{k}}, a{i} component (gimbal axis = "runtime")')
        for i in (1, 2, 3)
    },
}
"""A rotor's scalar keys; in p[] and in the code the key of rotor k is <key>_<k>."""
ON_GIMBAL: dict[str, tuple[str, str]] = {
    "T": ("N m", "motor torque on rotor B{k} about its spin axis g{k} (minus on gimbal G{k})"),
    **{
        f"g{i}": (
            "-",
            f"spin axis g_s0 of rotor B{{k}} at gimbal angle 0 (g{{k}} turns with gam{{k}}), "
            f'a{i} component (axis = "runtime")',
        )
        for i in (1, 2, 3)
    },
}
"""The rotor keys a gimbal gives another meaning: their unit and doc for a
rotor on a gimbal (ROTOR_KEYS' for the others)."""
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
"""A runtime axis normalized: named scalars of setup (gn1_k, gn2_k, gn3_k);
on a gimbal whose axes are not both folded, g_s0 made perpendicular to the
unit gimbal axis and normalized (Gram-Schmidt)."""
MAX_ROTORS = 6
"""Rotors a cluster scene may have."""
AXIS_NORM_SLACK = 1e-3
"""A rotor axis must have length within this of 1; it is then normalized
(exactly when folded, by setup when runtime; a longer miss is a typo,
refused: a folded axis by the scene, a runtime one by setup's code 8)."""


GIMBAL_KEYS = {"T": "Tg", "k": "kg", "rate_ref": "rate_ref", "m": "mG"}
"""A [rotors.gimbal] table's scalar keys by the name they take in p[] and the
code (<name>_<k>): a gimbal's T is Tg_k, beside its wheel's T_k."""
GIMBAL_INERTIA = ("IGs", "IGt", "IGg")
"""A gimbal frame's principal inertias about its mass center, in its axes
(g_s, g_t = g_g x g_s, g_g): the names of [rotors.gimbal] inertia's values."""
GIMBAL_AXIS = ("gg1", "gg2", "gg3")
"""[rotors.gimbal] axis = "runtime": g_g's A-components in p[] (gg1_k, gg2_k,
gg3_k), of length within AXIS_NORM_SLACK of 1; setup normalizes them into
UNIT_GIMBAL_AXIS."""
UNIT_GIMBAL_AXIS = ("ggn1", "ggn2", "ggn3")
"""A runtime gimbal axis normalized: named scalars of setup (ggn1_k..ggn3_k)."""
CROSS_AXIS = ("gtn1", "gtn2", "gtn3")
"""g_t0 = g_g x g_s0 of a gimbal whose axes are not both folded: named
scalars of setup (gtn1_k..gtn3_k)."""
GIMBAL_PERP_SLACK = 1e-3
"""A gimbal axis g_g and its wheel's spin axis g_s0 must be perpendicular
within this (|g_s0 . g_g| / (|g_s0| |g_g|)); g_s0 is then made perpendicular
(exactly when both are folded, by setup when one is runtime; a longer miss
is a typo, refused: folded by the scene, runtime by setup's code 10)."""


def rotor_name(key: str, k: int) -> str:
    """The name of rotor k's key in p[] and in the code: T_2, w_ref_3."""
    return f"{key}_{k}"


def axis_keys(k: int, keys: tuple[str, str, str] = AXIS) -> str:
    """Rotor k's runtime axis keys as a message names them: g1_k..g3_k (or
    a gimbal axis's, keys GIMBAL_AXIS: gg1_k..gg3_k)."""
    return f"{rotor_name(keys[0], k)}..{rotor_name(keys[-1], k)}"


def cluster_states(
    n: int, quaternion: bool, angles: bool, gimbals: tuple[int, ...] = ()
) -> tuple[str, ...]:
    """A cluster's states in x[] order: attitude, the fixed rotors' angles
    th<k> (if kept; a wheel on a gimbal keeps none), the gimbal angles
    gam<k> of the rotors on gimbals (gimbals: their k), body rates u1..u3,
    the gimbal rates gd<k> relative to A, absolute wheel rates w1..wN."""
    attitude = ("e0", "e1", "e2", "e3") if quaternion else ("q1", "q2", "q3")
    th = tuple(f"th{k}" for k in range(1, n + 1) if k not in gimbals) if angles else ()
    gam = tuple(f"gam{k}" for k in gimbals)
    gd = tuple(f"gd{k}" for k in gimbals)
    return (*attitude, *th, *gam, "u1", "u2", "u3", *gd, *(f"w{k}" for k in range(1, n + 1)))
