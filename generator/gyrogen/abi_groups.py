"""The groups of states an integrator measures each by its own scale (the
Taylor step's, and the global error the tests hold every method to), by a
state's unit and whether it is a rotor's (gyrogen.abi, gyrogen.abi_rotors)."""

from __future__ import annotations

from gyrogen.abi import UNITS, unit_and_doc

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
