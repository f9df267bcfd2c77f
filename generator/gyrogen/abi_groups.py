"""The groups of states an integrator measures each by its own scale (the
Taylor step's, and the global error the tests hold every method to), by a
state's unit and whether it is a rotor's (gyrogen.abi, gyrogen.abi_rotors)."""

from __future__ import annotations

import math
from typing import Literal

from gyrogen.abi import UNITS, unit_and_doc

StateKind = Literal["angle", "magnitude"]

ROTOR_STATES = ("q4", "u4")
"""The rotor's states among STATES; a cluster's are th<k> and w<k>, rotor k."""
STATE_GROUPS = ("attitude", "carrier rates", "rotor angles", "rotor rates", "translation")
"""The groups of states that differ in size by orders of magnitude (a wheel
at 1e6 rad/s beside body rates of 1e-6 rad/s): an integrator's error is
measured, and the Taylor step is controlled, within each group by its own
scale."""


def state_group(name: str) -> str:
    """A state's group (STATE_GROUPS), by its unit and whether it is a
    rotor's (ROTOR_STATES or a cluster's derived name; a gimbal's rate is
    measured with the carrier's): the carrier's Euler
    angles or Euler parameters are its attitude; translation is the mass
    center's position and velocity."""
    unit = unit_and_doc(name)[0]
    if unit in ("m", "m/s"):
        return "translation"
    # a gimbal's rate (gd<k>) is of the carrier's size, not its wheel's
    rotor = name in ROTOR_STATES or (name not in UNITS and not name.startswith("gd"))
    if unit == "rad/s":
        return "rotor rates" if rotor else "carrier rates"
    return "rotor angles" if rotor else "attitude"


ANGLE_SCALE = math.pi
"""An angle enters every integrator's error scale (atol + rtol |x|, the
Taylor step's xmax) by at most this: its magnitude past half a turn is
bookkeeping (a rotor angle grows without bound, a start angle may be given
a million turns on), and counted in full it loosened that angle's tolerance
(and the Taylor step's, every state's of its group) by as much."""


def state_kind(name: str) -> StateKind:
    """How a state enters an error scale: "angle" (a state in rad: the
    carrier's 3-1-2 angles, rotor and gimbal angles; at most ANGLE_SCALE) or
    "magnitude" (a rate, a wheel speed, an Euler parameter, a position)."""
    return "angle" if unit_and_doc(name)[0] == "rad" else "magnitude"


MAX_START_ANGLE = 2.0**14
"""The largest |angle| a scene may give as a start (simulate.initial) or an
equilibrium, rad (about 2607 turns): below it a double holds the angle to
2^-40 = 9.1e-13 rad, within verify's bar of 1e-12 (oracle.compare.TOLERANCE);
above it every sine and cosine of it errs by more. Measured on vscmg3 (its
three gimbal angles wound up, the Taylor method over 60 s at rtol 1e-12):
|H| drifted 4e-15 unwound, 5e-14 at 1e3 turns, 3e-12 at 1e4, 4.5e-11 at 1e5
and 6e-11 at 1e6 turns, the angle's own rounding (half an ulp: 4.7e-10 rad
at 6.3e6) against the tolerance. The same angle modulo 2 pi is the same
motion, held to the ulp of pi."""
