"""Reaction-wheel clusters: a scene's [[rotors]] tables and their rules.

A cluster scene has a carrier A (mass m_a, a full symmetric inertia tensor
about A*) and N rotors, each with its own mass, inertias, spin axis g_k
(fixed in A, normalized exactly), position of B_k* from A*, viscous friction,
torque law and optional torque limit. The torque laws' T, k and w_ref, the
carrier's mass and tensor and each rotor's m, I and J may be "runtime"
(checked by setup; the values simulate.parameters gives, here), and so may
a position (p's r1_k, r2_k, r3_k) and an axis (g1_k, g2_k, g3_k: setup
checks its length and normalizes it), a gimbal axis (gg1_k, gg2_k, gg3_k:
setup checks its length and that the spin axis is perpendicular to it, and
makes them orthonormal) and a gimbal frame's mass and principal inertias
(mG_k, IGs_k, IGt_k, IGg_k); friction and limits are folded.
With every inertial value folded, setup holds the inverse of the constant
inertia as numbers. No translation:
the system's mass center is fixed in A and free in N (a free-floating
spacecraft). Each rule raises ValueError with the line pydantic shows.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from fractions import Fraction
from functools import cached_property
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    field_validator,
    model_serializer,
    model_validator,
)

from gyrogen import physics
from gyrogen.abi import MAX_CONDITION, TRIANGLE_SLACK
from gyrogen.abi_rotors import (
    AXIS,
    AXIS_NORM_SLACK,
    CLUSTER_CARRIER,
    GIMBAL_AXIS,
    GIMBAL_INERTIA,
    GIMBAL_KEYS,
    GIMBAL_PERP_SLACK,
    POSITION,
    ROTOR_RUNTIME,
    axis_keys,
    cluster_states,
    rotor_name,
)
from gyrogen.scene.rules import (
    Number,
    check_table,
    folded_size,
    number,
    parameter_value,
    shown,
)


def _folded(v: object) -> object:
    if v == "runtime":
        raise ValueError(
            "a rotor's friction and limit are folded: only "
            f'{", ".join(ROTOR_RUNTIME)} may be "runtime"'
        )
    return parameter_value(v)


def _vector(v: object) -> object:
    """An axis or a position: "runtime", or [x, y, z], three finite numbers
    (A-components). Refused here in one line: pydantic's own refusal of a
    wrong length or a nan named the members of its union."""
    if v == "runtime":
        return v
    if not isinstance(v, list | tuple):
        raise ValueError(f'expected [x, y, z] or "runtime", not {shown(v)}')
    if len(v) != 3:
        raise ValueError(f"{len(v)} components, not 3: give [x, y, z] (A-components)")
    for name, x in zip("xyz", v, strict=True):
        if isinstance(x, bool) or not isinstance(x, int | float):
            raise ValueError(f"{name} = {shown(x)} is not a number")
        number(x)  # an integer past a double's range
        if not math.isfinite(x):
            raise ValueError(f"{name} = {x!r} is not a finite number")
        if why := folded_size(float(x)):
            raise ValueError(f'{name} = {x!r}: {why}; make it "runtime"')
    return tuple(float(x) for x in v)


Folded = Annotated[float, BeforeValidator(_folded)]
Value = Annotated[float | Literal["runtime"], BeforeValidator(parameter_value)]
Vector = Annotated[tuple[float, float, float] | Literal["runtime"], BeforeValidator(_vector)]
"""[x, y, z] or "runtime" (_vector)."""

LAW_KEYS = {"none": (), "constant": ("T",), "speed_controller": ("k", "w_ref"), "table": ()}
"""The keys each torque law needs (and allows); a table's points are its torque_table."""
GIMBAL_LAW_KEYS = {"none": (), "constant": ("T",), "rate_servo": ("k", "rate_ref"), "table": ()}
"""A gimbal's torque laws and the keys each needs; rate_servo: u_g = -k (gd - rate_ref)."""


def _inertia(v: object) -> object:
    """A gimbal frame's principal inertias [IGs, IGt, IGg]: each a number
    (a folded value's size, checked positive below) or "runtime"."""
    if not isinstance(v, list | tuple):
        raise ValueError(f"expected [IGs, IGt, IGg], not {shown(v)}")
    if len(v) != 3:
        raise ValueError(
            f"{len(v)} values, not 3: give the principal inertias [IGs, IGt, IGg] "
            "(in the gimbal frame's axes g_s, g_t, g_g)"
        )
    return tuple(parameter_value(x) for x in v)


class Gimbal(BaseModel):
    """A [rotors.gimbal] table: the rotor's wheel turns on a gimbal frame G
    about the axis g_g (fixed in A, perpendicular to the spin axis), driven
    by its own torque law (u_g on G about g_g, minus on A)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    axis: Vector
    """g_g in A-components: length within AXIS_NORM_SLACK of 1; "runtime":
    p's gg1_k, gg2_k, gg3_k (setup checks and normalizes them)."""
    inertia: Annotated[tuple[Value, Value, Value], BeforeValidator(_inertia)]
    """The gimbal frame's principal inertias about its mass center (on the
    gimbal axis at the rotor's position), kg m^2: [IGs, IGt, IGg]; each may
    be "runtime" (p's IGs_k, IGt_k, IGg_k: setup checks them)."""
    m: Value
    """The gimbal frame's mass, kg (at the rotor's position); "runtime": p's mG_k."""
    torque: str = "none"
    """One of GIMBAL_LAW_KEYS: none, constant (T), rate_servo (k, rate_ref), table."""
    T: Value | None = None
    """torque = "constant": the gimbal motor torque, N m."""
    k: Value | None = None
    """torque = "rate_servo": the gain, N m s."""
    rate_ref: Value | None = None
    """torque = "rate_servo": the commanded gimbal rate relative to A, rad/s."""
    tau_max: Annotated[Folded, Field(ge=0)] | None = None
    """|u_g| is clamped to tau_max."""
    torque_table: list[tuple[Number, Number]] | None = None
    """torque = "table": (t, T) points of a piecewise-linear u_g(t)."""

    @field_validator("axis")
    @classmethod
    def _axis(cls, v: tuple[float, float, float] | str) -> tuple[float, float, float] | str:
        if v != "runtime":
            check_axis(v, "")  # type: ignore[arg-type]
        return v

    @field_validator("torque")
    @classmethod
    def _law(cls, v: str) -> str:
        return law_name(v, GIMBAL_LAW_KEYS)

    @model_validator(mode="after")
    def _rules(self) -> Gimbal:
        if self.m != "runtime" and not self.m > 0.0:
            raise ValueError(f"m: must be positive (got {self.m})")
        if "runtime" in self.inertia:  # the runtime ones: setup's checks
            for name, x in zip(GIMBAL_INERTIA, self.inertia, strict=True):
                if x != "runtime" and not x > 0.0:
                    raise ValueError(f"inertia: {name} must be positive (got {x})")
        else:
            check_principal(self.inertia, "inertia")  # type: ignore[arg-type]
        check_table(self.torque, self.torque_table)
        need = GIMBAL_LAW_KEYS[self.torque]
        for key in ("T", "k", "rate_ref"):
            given = getattr(self, key) is not None
            if given and key not in need:
                raise ValueError(f"{key}: not used with torque = {self.torque!r}")
            if not given and key in need:
                raise ValueError(f"torque = {self.torque!r} needs {key}")
        return self

    @property
    def unit_axis(self) -> tuple[Fraction, Fraction, Fraction]:
        """g_g normalized exactly (exact_unit); a runtime one has none here."""
        if self.axis == "runtime":
            raise ValueError('gimbal.axis: "runtime" (its values come with the parameters)')
        return exact_unit(self.axis)

    def law(self) -> dict[str, float | str]:
        """The torque law's parameters by key."""
        return {
            key: v for key in GIMBAL_LAW_KEYS[self.torque] if (v := getattr(self, key)) is not None
        }

    def inertial(self) -> dict[str, float | str]:
        """The frame's mass and principal inertias by their names in p[]
        (GIMBAL_KEYS' mG, then GIMBAL_INERTIA)."""
        return {GIMBAL_KEYS["m"]: self.m, **dict(zip(GIMBAL_INERTIA, self.inertia, strict=True))}


def check_principal(moments: tuple[float, float, float], where: str) -> None:
    """A rigid body's principal inertias: each positive, each at most the sum
    of the other two (within TRIANGLE_SLACK): a positive-definite tensor."""
    for name, x in zip(GIMBAL_INERTIA, moments, strict=True):
        if not x > 0.0:
            raise ValueError(f"{where}: {name} must be positive (got {x})")
    total = sum(moments)
    if 2.0 * max(moments) - total > TRIANGLE_SLACK * total:
        text = ", ".join(f"{x:.6g}" for x in moments)
        raise ValueError(f"{where}: principal inertias ({text}) violate the triangle inequality")


class Rotor(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    m: Value
    """Mass, kg."""
    I: Value
    """Transverse inertia about B_k*, kg m^2."""
    J: Value
    """Mass, transverse and axial inertia: numbers, or "runtime" (setup
    checks them: positive, J <= 2 I, the lumped inertia's condition)."""
    axis: Vector
    """g_k in A-components: length within AXIS_NORM_SLACK of 1, then
    normalized; "runtime": p's g1_k, g2_k, g3_k (setup checks and normalizes)."""
    position: Vector = (0.0, 0.0, 0.0)
    """B_k* from A*, in A-components (m); "runtime": p's r1_k, r2_k, r3_k."""
    b: Annotated[Folded, Field(ge=0)] = 0.0
    """Viscous friction, N m s: torque -b (w_k - g_k.w_A) on the rotor."""
    torque: str = "none"
    """One of CLUSTER_LAWS: none, constant (T), speed_controller (k, w_ref) or
    table (torque_table); a string here, so that the refusal can say why."""
    T: Value | None = None
    """torque = "constant": the motor torque, N m."""
    k: Value | None = None
    """torque = "speed_controller": the gain, N m s."""
    w_ref: Value | None = None
    """torque = "speed_controller": the commanded rate relative to A, rad/s."""
    tau_max: Annotated[Folded, Field(ge=0)] | None = None
    """|T| is clamped to tau_max (a saturating motor); refused when negative."""
    torque_table: list[tuple[Number, Number]] | None = None
    """torque = "table": (t, T) points of a piecewise-linear T(t), held
    constant outside (as the single rotor's effects.torque_table)."""
    gimbal: Gimbal | None = None
    """[rotors.gimbal]: the wheel turns on a gimbal (a control-moment gyro);
    axis is then the spin axis g_s0 at gimbal angle 0, position the common
    mass center of gimbal frame and wheel."""

    @model_serializer(mode="wrap")
    def _dump(self, handler: Any) -> Any:
        """Without a table, the dump of a rotor before tables (its scene's build
        id); without a gimbal, the dump of a rotor before gimbals."""
        data = handler(self)
        if self.torque_table is None and isinstance(data, dict):
            data.pop("torque_table", None)
        if self.gimbal is None and isinstance(data, dict):
            data.pop("gimbal", None)
        return data

    @field_validator("axis")
    @classmethod
    def _axis(cls, v: tuple[float, float, float] | str) -> tuple[float, float, float] | str:
        if v != "runtime":
            check_axis(v, "")  # type: ignore[arg-type]
        return v

    @field_validator("torque")
    @classmethod
    def _law(cls, v: str) -> str:
        return law_name(v, LAW_KEYS)

    @model_validator(mode="after")
    def _rules(self) -> Rotor:
        for name in ("m", "I"):
            value = getattr(self, name)
            if value != "runtime" and not value > 0.0:
                raise ValueError(f"{name}: must be positive (got {value})")
        if self.J != "runtime" and self.I != "runtime":
            check_axial(self.I, self.J, "J")
        elif self.J != "runtime" and not self.J > 0.0:
            raise ValueError(f"J: must be positive (got {self.J})")
        check_table(self.torque, self.torque_table)
        if self.gimbal is not None:
            check_gimbal(self)
        need = LAW_KEYS[self.torque]
        for key in ("T", "k", "w_ref"):
            given = getattr(self, key) is not None
            if given and key not in need:
                raise ValueError(f"{key}: not used with torque = {self.torque!r}")
            if not given and key in need:
                raise ValueError(f"torque = {self.torque!r} needs {key}")
        return self

    @cached_property
    def spin_axis(self) -> tuple[Fraction, Fraction, Fraction]:
        """The spin axis exactly: unit_axis, or on a gimbal g_s0 exactly
        perpendicular to the gimbal axis (exact_perpendicular); with either
        axis runtime there is none here (setup makes the pair: gimbal_axes).
        Computed once per rotor (the reference asks for it at every call)."""
        if self.gimbal is None:
            return self.unit_axis
        if self.axes_at_runtime:
            raise ValueError('axis: "runtime" on a gimbal (its values come with the parameters)')
        return exact_perpendicular(self.axis, self.gimbal.unit_axis)  # type: ignore[arg-type]

    @property
    def axes_at_runtime(self) -> bool:
        """On a gimbal, the spin axis or the gimbal axis is "runtime": setup
        makes the pair orthonormal (gimbal_axes)."""
        return self.gimbal is not None and "runtime" in (self.axis, self.gimbal.axis)

    @property
    def unit_axis(self) -> tuple[Fraction, Fraction, Fraction]:
        """g_k normalized exactly: the rational point of the unit sphere
        nearest the axis given (within 1e-15), so that |g| = 1 holds in the
        algebra of the generator and the mass matrix stays block-diagonal.
        A runtime axis has none here (resolved gives it its values)."""
        if self.axis == "runtime":
            raise ValueError('axis: "runtime" (its values come with the parameters)')
        return exact_unit(self.axis)

    def law(self) -> dict[str, float | str]:
        """The torque law's parameters by key."""
        return {key: v for key in LAW_KEYS[self.torque] if (v := getattr(self, key)) is not None}


def check_gimbal(r: Rotor, where: str = "gimbal.axis") -> None:
    """A rotor on a gimbal: its spin axis perpendicular to the gimbal axis
    within GIMBAL_PERP_SLACK (the cosine of their angle), when both are
    known (a runtime one: setup's code 10, or check_values on given values)."""
    assert r.gimbal is not None
    if r.axes_at_runtime:
        return
    spin, g_g = ((float(x), float(y), float(z)) for x, y, z in (r.unit_axis, r.gimbal.unit_axis))
    check_perpendicular(spin, g_g, where)


def check_perpendicular(
    spin: tuple[float, float, float], g_g: tuple[float, float, float], where: str
) -> None:
    """A spin axis g_s0 and its gimbal axis g_g (directions: check_axis)
    perpendicular within GIMBAL_PERP_SLACK, the cosine of their angle."""
    dot = abs(sum(a * b for a, b in zip(spin, g_g, strict=True)))
    dot /= math.sqrt(sum(a * a for a in spin) * sum(b * b for b in g_g))
    if not dot <= GIMBAL_PERP_SLACK:
        raise ValueError(
            f"{where}: not perpendicular to the spin axis (|g_s0 . g_g| = {dot:.6g} > "
            f"{GIMBAL_PERP_SLACK:g}): a gimbal turns the wheel's axis about a perpendicular one"
        )


def law_name(v: str, laws: Mapping[str, tuple[str, ...]]) -> str:
    """v if it names one of laws (a torque law), else the ValueError listing them."""
    if v not in laws:
        raise ValueError(f"{v!r}: not one of {', '.join(map(repr, laws))}")
    return v


def check_axis(axis: tuple[float, float, float], where: str) -> None:
    """A direction: length within AXIS_NORM_SLACK of 1 (then normalized);
    where: the keys the message names (none: pydantic's location does)."""
    at = f"{where}: " if where else ""
    norm = math.sqrt(sum(x * x for x in axis))
    if norm == 0.0:
        raise ValueError(f"{at}has length 0: not a direction")
    if not abs(norm - 1.0) <= AXIS_NORM_SLACK:
        raise ValueError(
            f"{at}length {norm:.9g} is not 1 (within {AXIS_NORM_SLACK:g}): give a unit vector"
        )


def check_axial(inertia: float, axial: float, where: str) -> None:
    """0 < J <= 2 I (within TRIANGLE_SLACK): an axisymmetric rotor's inertias."""
    if not axial > 0.0:
        raise ValueError(f"{where}: must be positive (got {axial})")
    if axial > 2.0 * inertia * (1.0 + TRIANGLE_SLACK):
        raise ValueError(f"{where}: rotor needs J <= 2 I (I = {inertia}, J = {axial})")


def runtime_names(parameters: Mapping[str, float | str], rotors: list[Rotor]) -> tuple[str, ...]:
    """p[] of a cluster: the carrier's runtime keys (CLUSTER_CARRIER order),
    then each rotor's, rotor by rotor (m, I, J, a position's and an axis's,
    its torque law's, then its gimbal's: its axis's gg1..gg3, mG, IGs, IGt,
    IGg, its torque law's)."""
    carrier = tuple(n for n in CLUSTER_CARRIER if parameters.get(n) == "runtime")
    return carrier + tuple(
        rotor_name(key, k)
        for k, r in enumerate(rotors, 1)
        for key, v in (
            ("m", r.m),
            ("I", r.I),
            ("J", r.J),
            *_vectors(r),
            *r.law().items(),
            *_gimbal_vector(r),
            *({} if r.gimbal is None else r.gimbal.inertial()).items(),
            *gimbal_law(r).items(),
        )
        if v == "runtime"
    )


def gimbal_law(r: Rotor) -> dict[str, float | str]:
    """A gimbal's torque law's parameters by their names in p[] (GIMBAL_KEYS:
    Tg, kg, rate_ref); none without a gimbal."""
    return {} if r.gimbal is None else {GIMBAL_KEYS[k]: v for k, v in r.gimbal.law().items()}


def gimbals(rotors: list[Rotor]) -> tuple[int, ...]:
    """The rotors on gimbals, by k (1..N)."""
    return tuple(k for k, r in enumerate(rotors, 1) if r.gimbal is not None)


def _gimbal_vector(r: Rotor) -> tuple[tuple[str, str], ...]:
    """A runtime gimbal axis's keys."""
    runtime = r.gimbal is not None and r.gimbal.axis == "runtime"
    return tuple((key, "runtime") for key in GIMBAL_AXIS) if runtime else ()


def _vectors(r: Rotor) -> tuple[tuple[str, str], ...]:
    """A runtime position's keys, then a runtime axis's."""
    position = tuple((key, "runtime") for key in POSITION) if r.position == "runtime" else ()
    return position + (tuple((key, "runtime") for key in AXIS) if r.axis == "runtime" else ())


def resolved(
    parameters: Mapping[str, float | str], rotors: list[Rotor], given: Mapping[str, float]
) -> tuple[dict[str, float], list[Rotor]] | None:
    """The carrier's and the rotors' inertial values with the runtime ones
    from given (simulate.parameters), or None when one is not given."""
    values: dict[str, float] = {}
    for n, v in parameters.items():
        if v == "runtime" and n not in given:
            return None
        values[n] = float(given[n] if v == "runtime" else v)
    out = []
    for k, r in enumerate(rotors, 1):
        update: dict[str, object] = {}
        for key in ("m", "I", "J"):
            if getattr(r, key) == "runtime":
                if rotor_name(key, k) not in given:
                    return None
                update[key] = float(given[rotor_name(key, k)])
        for field, keys in (("position", POSITION), ("axis", AXIS)):
            if getattr(r, field) == "runtime":
                if any(rotor_name(key, k) not in given for key in keys):
                    return None
                update[field] = tuple(float(given[rotor_name(key, k)]) for key in keys)
        if r.gimbal is not None:
            frame = {}
            for name, v in r.gimbal.inertial().items():
                if v == "runtime" and rotor_name(name, k) not in given:
                    return None
                frame[name] = float(given[rotor_name(name, k)] if v == "runtime" else v)
            inertia = tuple(frame[name] for name in GIMBAL_INERTIA)
            axis: object = r.gimbal.axis
            if axis == "runtime":
                if any(rotor_name(key, k) not in given for key in GIMBAL_AXIS):
                    return None
                axis = tuple(float(given[rotor_name(key, k)]) for key in GIMBAL_AXIS)
            gimbal = r.gimbal.model_copy(
                update={"m": frame[GIMBAL_KEYS["m"]], "inertia": inertia, "axis": axis}
            )
            update["gimbal"] = gimbal
        out.append(r.model_copy(update=update))
    return values, out


def unit_axes(rotors: list[Rotor], given: Mapping[str, float]) -> np.ndarray:
    """(N, 3) each rotor's unit axis in floats: a folded one's exact unit
    vector, a runtime one's g1_k..g3_k from given, normalized as setup does;
    on a gimbal, g_s0 (gimbal_axes)."""
    out = []
    for k, r in enumerate(rotors, 1):
        if r.gimbal is not None:
            out.append(gimbal_axes(r, k, given)[1])
        elif r.axis == "runtime":
            g = _given(k, AXIS, given)
            out.append(g / np.sqrt(g @ g))
        else:
            out.append(np.array([float(x) for x in r.unit_axis]))
    return np.array(out).reshape(len(rotors), 3)


def _given(k: int, keys: tuple[str, ...], given: Mapping[str, float]) -> np.ndarray:
    return np.array([float(given[rotor_name(key, k)]) for key in keys])


def gimbal_axes(r: Rotor, k: int, given: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray]:
    """Rotor k's unit gimbal axis g_g and spin axis g_s0 in floats: folded,
    the exact pair (spin_axis); with either runtime (from given), as setup
    makes them: g_g normalized, g_s0 less its part along g_g, normalized."""
    assert r.gimbal is not None
    if not r.axes_at_runtime:
        return (np.array([float(x) for x in r.gimbal.unit_axis]),
                np.array([float(x) for x in r.spin_axis]))  # fmt: skip
    g_g = _given(k, GIMBAL_AXIS, given) if r.gimbal.axis == "runtime" else np.array(r.gimbal.axis)
    g_g = g_g / np.sqrt(g_g @ g_g)
    spin = _given(k, AXIS, given) if r.axis == "runtime" else np.array(r.axis, dtype=float)
    spin = spin - (spin @ g_g) * g_g
    return g_g, spin / np.sqrt(spin @ spin)


def states(rotors: list[Rotor], quaternion: bool, angles: bool) -> tuple[str, ...]:
    return cluster_states(len(rotors), quaternion, angles, gimbals(rotors))


def check_cluster(
    parameters: Mapping[str, float | str], rotors: list[Rotor], effects_set: set[str]
) -> None:
    """The cluster scene's rules: carrier keys, no translation, no scene-wide
    torque law, physical values, a well-conditioned inertia."""
    if "translation" in effects_set or "torque" in effects_set or "torque_table" in effects_set:
        raise ValueError(
            "effects: with [[rotors]] there is no translation and each rotor has its own "
            "torque law (rotors[k].torque); set only effects.rotor_angle"
        )
    for n in ("m_a", "I11", "I22", "I33"):
        if n not in parameters:
            raise ValueError(f"parameters: missing {n}")
    for n in parameters:
        if n not in CLUSTER_CARRIER:
            raise ValueError(
                f"parameters.{n}: not a carrier key of a cluster scene "
                f"({', '.join(CLUSTER_CARRIER)}; each rotor's keys go in its [[rotors]] table)"
            )
    known = resolved(parameters, rotors, {})
    if known is not None:
        check_values(*known, "parameters")


def check_values(parameters: Mapping[str, float], rotors: list[Rotor], where: str) -> None:
    """A cluster's inertial values, every one known (folded or given in
    where): positive masses and inertias, J <= 2 I, a positive-definite
    carrier meeting the triangle inequality, a well-conditioned lumped inertia."""
    for k, r in enumerate(rotors, 1):
        for key in ("m", "I"):
            if not getattr(r, key) > 0.0:
                raise ValueError(f"{where}.{rotor_name(key, k)}: must be positive "
                                 f"(got {getattr(r, key)})")  # fmt: skip
        check_axial(r.I, r.J, f"{where}.{rotor_name('J', k)}")  # type: ignore[arg-type]
        check_axis(r.axis, f"{where}.{axis_keys(k)}")  # type: ignore[arg-type]
        if r.gimbal is not None:
            check_axis(r.gimbal.axis, f"{where}.{axis_keys(k, GIMBAL_AXIS)}")  # type: ignore[arg-type]
            check_gimbal(r, f"{where}.{axis_keys(k, GIMBAL_AXIS)}")
            mass = rotor_name(GIMBAL_KEYS["m"], k)
            if not r.gimbal.m > 0.0:  # type: ignore[operator]
                raise ValueError(f"{where}.{mass}: must be positive (got {r.gimbal.m})")
            names = ", ".join(rotor_name(n, k) for n in GIMBAL_INERTIA)
            check_principal(r.gimbal.inertia, f"{where}.{names}")  # type: ignore[arg-type]
    carrier = carrier_tensor(parameters)
    if not parameters["m_a"] > 0:
        raise ValueError(f"{where}.m_a: must be positive (got {parameters['m_a']})")
    moments = [float(x) for x in np.linalg.eigvalsh(np.array(carrier))]
    if not min(moments) > 0:
        raise ValueError(f"{where}.I11..I23: carrier inertia is not positive definite")
    if 2.0 * max(moments) - sum(moments) > TRIANGLE_SLACK * sum(moments):
        text = ", ".join(f"{m:.6g}" for m in sorted(moments))
        raise ValueError(
            f"{where}.I11..I23: principal moments ({text}) violate the triangle inequality"
        )
    try:
        lumped = lumped_inertia(parameters, rotors)
    except OverflowError:
        lumped = [[math.inf] * 3] * 3
    if not all(math.isfinite(x) for row in lumped for x in row):
        raise ValueError(
            "rotors: the lumped inertia overflows a double: masses, inertias or positions too large"
        )
    cond = physics.frobenius_condition(lumped)
    if not cond <= MAX_CONDITION:
        raise ValueError(
            f"rotors: the lumped inertia has condition number {cond:.3g} > {MAX_CONDITION:g}: "
            "numerically singular"
        )


def carrier_tensor(parameters: Mapping[str, float | str]) -> list[list[float]]:
    v = {n: float(parameters.get(n, 0.0)) for n in CLUSTER_CARRIER}
    return [
        [v["I11"], v["I12"], v["I13"]],
        [v["I12"], v["I22"], v["I23"]],
        [v["I13"], v["I23"], v["I33"]],
    ]


def lumped_inertia(parameters: Mapping[str, float | str], rotors: list[Rotor]) -> list[list[float]]:
    """The lumped carrier's inertia about the system's mass center, in floats."""
    return physics.cluster_inertia(
        float(parameters["m_a"]),
        carrier_tensor(parameters),
        [
            (float(r.m) + float(mass), float(inertia), [float(x) for x in axis], r.position)
            for r in rotors
            for mass, inertia, axis in [lumped_part(r)]
        ],
    )


def lumped_part(
    r: Rotor,
) -> tuple[float | str, float | str, tuple[Fraction, Fraction, Fraction] | str]:
    """What a rotor adds to the lumped inertia beside its mass: (the mass of
    its gimbal frame, the transverse inertia, the axis it is transverse to).
    A fixed rotor's I about g; a gimbal's constant part, IGs about g_g (the
    rest turns with the gimbal: symbolic.gimbals), "runtime" for a runtime g_g."""
    if r.gimbal is None:
        return 0.0, r.I, r.unit_axis
    axis = "runtime" if r.gimbal.axis == "runtime" else r.gimbal.unit_axis
    return r.gimbal.m, r.gimbal.inertia[0], axis


DENOMINATOR = 10**9
"""The stereographic coordinates of an axis are rationals with at most this
denominator where one is within ROUNDED of the coordinate (the point they
map to is then within about 1e-17 of the axis); else, a coordinate below
1/DENOMINATOR (a tilt of 1e-12 has no such rational but 0), with at most
FINE_DENOMINATOR."""
FINE_DENOMINATOR = 10**17
ROUNDED = Fraction(1, 10**17)


def _rational(x: float) -> Fraction:
    """x as a short rational within ROUNDED of it (module docstring)."""
    exact = Fraction(x)
    near = exact.limit_denominator(DENOMINATOR)
    return near if abs(near - exact) <= ROUNDED else exact.limit_denominator(FINE_DENOMINATOR)


def exact_perpendicular(
    v: tuple[float, float, float], g_g: tuple[Fraction, Fraction, Fraction]
) -> tuple[Fraction, Fraction, Fraction]:
    """A rational unit vector exactly perpendicular to the rational unit
    vector g_g, along v's part perpendicular to it: exact_unit(v) itself
    when that is exactly perpendicular; else a rational orthonormal basis
    (b1, b2) of the plane (the Householder reflection taking the coordinate
    axis farthest from g_g onto it is rational and orthogonal), and the
    rational point of the unit circle nearest v's direction in that plane
    (stereographic, its coordinate rounded as exact_unit's), so that
    |g_s0| = 1 and g_s0 . g_g = 0 hold in the algebra (no square roots)."""
    unit = exact_unit(v)
    if sum(a * b for a, b in zip(unit, g_g, strict=True)) == 0:
        return unit
    k = min(range(3), key=lambda i: g_g[i])
    w = [g_g[i] - Fraction(int(i == k)) for i in range(3)]  # never 0: g_g[k] < 1
    ww = sum(x * x for x in w)

    def reflected(i: int) -> list[Fraction]:
        x = [Fraction(int(i == j)) for j in range(3)]
        c = 2 * sum((a * b for a, b in zip(w, x, strict=True)), Fraction(0)) / ww
        return [a - c * b for a, b in zip(x, w, strict=True)]

    b1, b2 = (reflected(i) for i in range(3) if i != k)
    x, y = (sum(float(a) * b for a, b in zip(basis, v, strict=True)) for basis in (b1, b2))
    if abs(x) >= abs(y):
        t = _rational(y / (math.hypot(x, y) + abs(x)))
        c, s = (1 if x > 0 else -1) * (1 - t * t) / (1 + t * t), 2 * t / (1 + t * t)
    else:
        t = _rational(x / (math.hypot(x, y) + abs(y)))
        c, s = 2 * t / (1 + t * t), (1 if y > 0 else -1) * (1 - t * t) / (1 + t * t)
    out = [c * a + s * b for a, b in zip(b1, b2, strict=True)]
    return (out[0], out[1], out[2])


def exact_unit(v: tuple[float, float, float]) -> tuple[Fraction, Fraction, Fraction]:
    """A rational unit vector along v: v normalized in floats, projected
    stereographically from the pole opposite its largest component, the two
    coordinates rounded to rationals, and mapped back (a rational point of
    the sphere: its squares sum to 1 exactly). Axes along a1, a2, a3 stay exact."""
    norm = math.sqrt(sum(x * x for x in v))
    g = [x / norm for x in v]
    big = max(range(3), key=lambda i: abs(g[i]))
    sign = 1 if g[big] > 0 else -1
    others = [i for i in range(3) if i != big]
    s, t = (_rational(g[i] / (1.0 + abs(g[big]))) for i in others)
    d = 1 + s * s + t * t
    out = [Fraction(0)] * 3
    out[others[0]], out[others[1]] = 2 * s / d, 2 * t / d
    out[big] = sign * (1 - s * s - t * t) / d
    return (out[0], out[1], out[2])
