"""Scenes: what a user wants to simulate, read from TOML and validated.

A scene names the parameters it folds into the code (numbers) and those it
keeps as entries of p[] ("runtime"), the effects it needs (translation, rotor
angle, torque law), optional output functions, target languages and a
simulation setup. Validation is pydantic's; the physical checks of folded
values are the same as the generated setup's (abi.SETUP_CODES).
"""

from __future__ import annotations

import math
import os
import stat
import tomllib
from functools import cache
from importlib.resources import files
from typing import Annotated, Any, Literal

import pydantic
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    StrictBool,
    ValidationInfo,
    field_validator,
    model_serializer,
    model_validator,
)

from gyrogen import methods
from gyrogen.abi import CONTROLLER_PARAMETERS, MIN_RTOL, PARAMETERS, STATES, unit_and_doc
from gyrogen.abi_rotors import MAX_ROTORS, rotor_name
from gyrogen.errors import SceneError
from gyrogen.limits import MAX_EVENTS, MAX_SCENE_BYTES
from gyrogen.scene import events as scene_events
from gyrogen.scene import rotors
from gyrogen.scene.events import Event
from gyrogen.scene.rotors import Rotor
from gyrogen.scene.rules import (
    QUATERNION,
    Number,
    check_angles,
    check_description,
    check_name,
    check_output_grid,
    check_physics,
    check_quaternion,
    check_table,
    check_wrt,
    parameter_value,
)

Value = Annotated[float | Literal["runtime"], BeforeValidator(parameter_value)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class Effects(_Strict):
    translation: StrictBool = True
    """Keep q5..q7, u5..u7 (they never couple to the rest; gravity acts only on them)."""
    rotor_angle: StrictBool = True
    """Keep q4 (ignorable: nothing depends on it)."""
    torque: Literal["none", "constant", "speed_controller", "table"] = "constant"
    """The motor's law: none; constant T; speed_controller T = -k (u4 - u2 - w_ref);
    table, T(t) from torque_table."""
    torque_table: list[tuple[Number, Number]] | None = None
    """(t, T) points of a piecewise-linear T(t), held constant outside."""

    @model_validator(mode="after")
    def _table(self) -> Effects:
        check_table(self.torque, self.torque_table)
        return self


class Outputs(_Strict):
    kinetic_energy: StrictBool = False
    """Kinetic energy of the system."""
    angular_momentum: StrictBool = False
    """Angular momentum about AB* in N components (uses the direction cosines)."""
    power: StrictBool = False
    """Power of the motor torque, T (u4 - u2)."""
    linear_model: StrictBool = False
    """The function <prefix>_linear: A, B, C, D of the linear model at any
    state (inputs: each rotor's motor torque, or its speed controller's
    w_ref; outputs: the ones above). `gyrogen linearize` sets it."""

    @property
    def functions(self) -> tuple[str, ...]:
        """The output functions switched on, each <prefix>_<name>(t, x, c,
        out) with a reference counterpart (the linear model is not one)."""
        return tuple(n for n, on in self.model_dump().items() if on and n != "linear_model")


class Simulate(_Strict):
    initial: dict[str, Number] = Field(default_factory=dict)
    """Initial state by name; states not named start at 0."""
    parameters: dict[str, Number] = Field(default_factory=dict)
    """Values of the runtime parameters for `gyrogen simulate`."""
    t_end: Annotated[Number, Field(gt=0)] = 10.0
    """End time of the simulation, s (it starts at 0)."""
    dt: Annotated[Number, Field(gt=0)] = 0.01
    """Output step of the trajectory: at most t_end, and at most MAX_OUTPUT_POINTS of them in it."""
    rtol: Annotated[Number, Field(lt=1)] = 1e-10
    """Above abi.MIN_RTOL, as the compiled integrators require."""
    atol: Annotated[Number, Field(gt=0)] = 1e-10
    """Absolute tolerance of the integrators, above 0."""

    @field_validator("rtol")
    @classmethod
    def _rtol(cls, v: float) -> float:
        if not v > MIN_RTOL:
            raise ValueError(
                f"must be above {MIN_RTOL:.4g} (10 machine epsilons): "
                "no double arithmetic meets a tighter relative tolerance"
            )
        return v

    @field_validator("dt")
    @classmethod
    def _points(cls, dt: float, info: ValidationInfo) -> float:
        if "t_end" in info.data:  # else t_end failed its own check
            check_output_grid(info.data["t_end"], dt)
        return dt


class Sensitivities(_Strict):
    wrt: list[str] = Field(min_length=1)
    """What the variational system differentiates the flow with respect to,
    in the order of Phi's columns: "state" (the initial state: nx columns)
    and runtime parameters by name (one column each)."""
    error: Literal["all", "state"] = "all"
    """What the step-size control measures: the state together with Phi
    ("all"), or the state alone ("state": Phi rides on the state's steps)."""

    @field_validator("wrt")
    @classmethod
    def _once(cls, v: list[str]) -> list[str]:
        seen = [n for i, n in enumerate(v) if n in v[:i]]
        if seen:
            raise ValueError(f"{seen[0]!r} is listed twice")
        return v


class Scene(_Strict):
    name: str
    """Also the prefix of every generated C symbol and file."""
    description: str
    """What the scene is: any text without control characters, at most 2000
    characters; it reaches the generated files only inside comments."""
    parameters: dict[str, Value]
    """Each parameter: a number folded into the code, or "runtime", an entry
    of p[] that setup checks."""
    effects: Effects = Effects()
    """Which effects the equations keep, and the motor's torque law."""
    outputs: Outputs = Outputs()
    """Optional output functions beside the rhs."""
    targets: list[Literal["c", "fortran"]] = ["c", "fortran"]
    """The languages to generate."""
    integrators: list[str] = Field(default_factory=lambda: list(methods.NAMES))
    """Compiled integrators to render beside the RHS (gyrogen.methods; an
    implicit one adds the Jacobian)."""
    lanes: list[str] = Field(default_factory=list)
    """Integrators whose C `_batch` and `_grid_batch` run over SIMD lanes
    only when listed here: radau5 (its lanes make the scene's C build
    slower and struct lanes larger). Not listed, its batches are a loop of
    its single calls. The explicit pairs, taylor and rodas4 always run over
    lanes."""
    attitude: Literal["euler312", "quaternion"] = "euler312"
    """3-1-2 Euler angles q1..q3 (singular at q2 = +-pi/2), or Euler parameters
    e0..e3 (no singularity; the integrators keep |e| = 1 by projection)."""
    simulate: Simulate = Simulate()
    """Defaults of `gyrogen simulate`, `gyrogen check SCENE` and the FMU."""
    rotors: Annotated[list[Rotor], Field(max_length=MAX_ROTORS)] = Field(default_factory=list)
    """A reaction-wheel cluster (gyrogen.scene.rotors); none: the paper's one rotor on a2."""
    equilibrium: dict[str, Number] | None = None
    """The state `gyrogen linearize` linearizes about, by name (states not
    named: 0, e0: 1); the runtime parameters are simulate.parameters."""
    events: Annotated[list[Event], Field(max_length=MAX_EVENTS)] = Field(default_factory=list)
    """Functions g(t, x) whose zero crossings the integrators locate
    (gyrogen.scene.events): in states, parameters, outputs and t."""
    sensitivities: Sensitivities | None = None
    """Generate the variational equations too (the state transition matrix
    and the sensitivities to runtime parameters): <prefix>_var_*."""

    @model_serializer(mode="wrap")
    def _dump(self, handler: Any) -> Any:
        """Without rotors, the dump of a scene before clusters existed (its build
        id); with them, only the effects a cluster has (the others are refused)."""
        data = handler(self)
        if self.equilibrium is None:
            data.pop("equilibrium", None)  # the dump before linear models
        if not self.events:
            data.pop("events", None)  # the dump before events
        if self.sensitivities is None:
            data.pop("sensitivities", None)  # the dump before sensitivities
        if not self.lanes:
            data.pop("lanes", None)  # the dump before lanes were asked for
        if isinstance(data.get("outputs"), dict) and not self.outputs.linear_model:
            data["outputs"].pop("linear_model", None)  # the dump before linear models
        if not self.rotors:
            data.pop("rotors", None)
        elif isinstance(data.get("effects"), dict):  # a cluster has only these effects
            data["effects"] = {"rotor_angle": self.effects.rotor_angle}
        return data

    @field_validator("name")
    @classmethod
    def _name(cls, v: str) -> str:
        check_name(v)
        return v

    @field_validator("description")
    @classmethod
    def _description(cls, v: str) -> str:
        return check_description(v)

    @field_validator("targets")
    @classmethod
    def _targets(cls, v: list[str]) -> list[str]:
        if not v or len(set(v)) != len(v):
            raise ValueError("list c, fortran or both, once each")
        return v

    @field_validator("integrators")
    @classmethod
    def _integrators(cls, v: list[str]) -> list[str]:
        for i, name in enumerate(v):
            if name not in methods.NAMES:
                raise ValueError(f"[{i}] {name!r}: not one of {', '.join(methods.NAMES)}")
        if len(set(v)) != len(v):
            raise ValueError("list each integrator once")
        return v

    @field_validator("lanes")
    @classmethod
    def _lanes(cls, v: list[str]) -> list[str]:
        asked = [n for n, m in methods.METHODS.items() if m.lanes_asked]
        for i, name in enumerate(v):
            if name not in methods.NAMES:
                raise ValueError(f"[{i}] {name!r}: not one of {', '.join(methods.NAMES)}")
            m = methods.get(name)
            if not m.lanes_asked:
                how = "always runs over lanes" if m.lanes else "has no lanes"
                raise ValueError(
                    f"[{i}] {name!r}: its batch {how}; only {', '.join(asked)} can be listed"
                )
        if len(set(v)) != len(v):
            raise ValueError("list each integrator once")
        return v

    @model_validator(mode="after")
    def _consistent(self) -> Scene:
        absent = [m for m in self.lanes if m not in self.integrators]
        if absent:
            raise ValueError(f"lanes: {absent[0]} is not among this scene's integrators")
        if "rotors" in self.model_fields_set and not self.rotors:
            raise ValueError(
                "rotors: empty: a cluster needs at least one [[rotors]] table "
                "(leave rotors out for the paper's single rotor on a2)"
            )
        if self.rotors:
            rotors.check_cluster(self.parameters, self.rotors, self.effects.model_fields_set)
        else:
            _check_parameter_names(self)
            check_physics(self.parameters)
        for key, point in (("simulate.initial", self.simulate.initial),
                           ("equilibrium", self.equilibrium or {})):  # fmt: skip
            bad = sorted(set(point) - set(self.states))
            if bad:
                raise ValueError(f"{key}: {', '.join(bad)} is not a state of this scene")
            check_angles(point, key)
            if self.attitude == "quaternion":
                check_quaternion(point, key)  # the start; linearize's point
        bad = sorted(set(self.simulate.parameters) - set(self.runtime))
        if bad:
            raise ValueError(
                f"simulate.parameters: {', '.join(bad)} is not a runtime parameter of this scene"
            )
        if not self.rotors:
            check_physics({**self.parameters, **self.simulate.parameters})
        elif self.runtime and (
            known := rotors.resolved(self.parameters, self.rotors, self.simulate.parameters)
        ):
            rotors.check_values(*known, "simulate.parameters")
        sizes = {"kinetic_energy": 1, "angular_momentum": 3, "power": max(len(self.rotors), 1)}
        outputs = {n: k for n, k in sizes.items() if getattr(self.outputs, n)}
        scene_events.check(self.events, self.states, set(self.parameters), outputs)
        self._series_where_smooth()
        if self.sensitivities is not None:
            check_wrt(self.sensitivities.wrt, self.runtime, self._folded_names())
        return self

    def _folded_names(self) -> set[str]:
        """Every parameter name this scene folds to a number (a cluster's
        rotor keys too)."""
        names = set(self.folded())
        for k, r in enumerate(self.rotors, 1):
            for key, v in (("m", r.m), ("I", r.I), ("J", r.J), *r.law().items(),
                           *rotors.gimbal_law(r).items()):  # fmt: skip
                if v != "runtime":
                    names.add(rotor_name(key, k))
        return names

    def _series_where_smooth(self) -> None:
        """A Taylor series is offered only where the rhs is smooth: left out
        of the default integrators elsewhere, refused when asked for."""
        why = self.not_smooth
        series = [m for m in self.integrators if methods.get(m).taylor]
        if why is None or not series:
            return
        if "integrators" in self.model_fields_set:
            raise ValueError(
                f"integrators: {series[0]} is not offered for this scene: its rhs is not "
                f"smooth ({why}), and a Taylor series would step over the kink (use dop853)"
            )
        kept = [m for m in self.integrators if m not in series]
        object.__setattr__(self, "integrators", kept)  # the default, for this scene

    @property
    def table_times(self) -> tuple[float, ...]:
        """The sorted times of every T(t) table's points (the single rotor's,
        each wheel's, each gimbal's): where a tabulated torque's slope jumps,
        and where the compiled integrators end a step (a step across one
        could pass a pulse narrower than itself)."""
        tables = [self.effects.torque_table, *(r.torque_table for r in self.rotors)]
        tables += [r.gimbal.torque_table for r in self.rotors if r.gimbal is not None]
        return tuple(sorted({float(t) for table in tables if table for t, _ in table}))

    @property
    def not_smooth(self) -> str | None:
        """Why the rhs is not smooth everywhere (a piecewise-linear torque
        table, a clamped motor torque), or None."""
        if self.effects.torque == "table":
            return "a piecewise-linear torque table"
        tabled = [k for k, r in enumerate(self.rotors, 1) if r.torque == "table"]
        if tabled:
            return f"rotor {tabled[0]}'s piecewise-linear torque table"
        clamped = [k for k, r in enumerate(self.rotors, 1) if r.tau_max is not None]
        if clamped:
            return f"rotor {clamped[0]}'s motor torque is clamped to tau_max"
        for k, r in enumerate(self.rotors, 1):
            if r.gimbal is not None and r.gimbal.torque == "table":
                return f"gimbal {k}'s piecewise-linear torque table"
            if r.gimbal is not None and r.gimbal.tau_max is not None:
                return f"gimbal {k}'s motor torque is clamped to tau_max"
        return None

    def unit_and_doc(self, name: str) -> tuple[str, str]:
        """A state's or parameter's unit and meaning in this scene
        (abi.unit_and_doc; a rotor on a gimbal's keys as ON_GIMBAL says)."""
        return unit_and_doc(name, rotors.gimbals(self.rotors))

    @property
    def states(self) -> tuple[str, ...]:
        """The kept states, in x[] order."""
        if self.rotors:
            quaternion = self.attitude == "quaternion"
            return rotors.states(self.rotors, quaternion, self.effects.rotor_angle)
        drop = set()
        if not self.effects.translation:
            drop |= {"q5", "q6", "q7", "u5", "u6", "u7"}
        if not self.effects.rotor_angle:
            drop.add("q4")
        kept = tuple(s for s in STATES if s not in drop)
        if self.attitude == "quaternion":
            kept = ("e0", "e1", "e2", "e3", *kept[3:])
        return kept

    def initial_state(self) -> tuple[float, ...]:
        """simulate.initial in state order; unnamed states start at 0, except
        e0 (the identity attitude, e = (1, 0, 0, 0)). Euler parameters are
        normalized (validation has held them within QUATERNION_NORM_SLACK)."""
        start = {"e0": 1.0, **self.simulate.initial}
        if self.attitude == "quaternion":
            norm = math.sqrt(sum(start.get(e, 0.0) ** 2 for e in QUATERNION))
            start.update({e: start.get(e, 0.0) / norm for e in QUATERNION})
        return tuple(start.get(s, 0.0) for s in self.states)

    @property
    def runtime(self) -> tuple[str, ...]:
        """Runtime parameters, in p[] order (the model's order, then k, w_ref)."""
        if self.rotors:
            return rotors.runtime_names(self.parameters, self.rotors)
        order = (*PARAMETERS, *CONTROLLER_PARAMETERS)
        return tuple(n for n in order if self.parameters.get(n) == "runtime")

    def folded(self) -> dict[str, float]:
        return {k: v for k, v in self.parameters.items() if not isinstance(v, str)}


def required_parameters(effects: Effects) -> tuple[str, ...]:
    names = ["m_a", "m_b", "I11", "I22", "I33", "I13", "I", "J", "l1", "l3"]
    if effects.translation:
        names.append("g")
    if effects.torque == "constant":
        names.append("T")
    if effects.torque == "speed_controller":
        names += list(CONTROLLER_PARAMETERS)
    return tuple(names)


def _check_parameter_names(scene: Scene) -> None:
    need = required_parameters(scene.effects)
    missing = [n for n in need if n not in scene.parameters]
    if missing:
        raise ValueError(f"parameters: missing {', '.join(missing)}")
    for n in scene.parameters:
        if n not in need:
            raise ValueError(f"parameters.{n}: {_why_not(n, scene.effects)}")


def _why_not(name: str, effects: Effects) -> str:
    if name == "g":
        return "gravity has no effect without translation (effects.translation = false)"
    if name == "T":
        return f"only used with effects.torque = 'constant' (not {effects.torque!r})"
    if name in CONTROLLER_PARAMETERS:
        return "only used with effects.torque = 'speed_controller'"
    return "unknown parameter (see `gyrogen new` for the list)"


def one_line(exc: pydantic.ValidationError) -> str:
    err = exc.errors()[0]
    # a union's member ("float", "literal['runtime']") is not a key the user wrote
    keys = [str(x) for x in err["loc"] if not str(x).startswith(("float", "literal["))]
    loc = ".".join(keys)
    msg = str(err["msg"]).removeprefix("Value error, ")
    if err["type"] == "extra_forbidden":
        msg = "unknown key"
    return f"{loc}: {msg}" if loc else msg


def load_toml(text: str, source: str) -> dict[str, Any]:  # scene and sweep files: one line
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{source}: invalid TOML: {exc}") from exc
    except ValueError as exc:  # an integer past Python's 4300-digit conversion limit
        raise SceneError(f"{source}: invalid TOML: an integer of more than 4300 digits") from exc
    except RecursionError as exc:  # tomllib recurses once per level of nesting
        raise SceneError(f"{source}: invalid TOML: arrays or tables nested too deeply") from exc


def parse(text: str, source: str) -> Scene:
    return validate(load_toml(text, source), source)


def validate(data: dict[str, Any], source: str) -> Scene:
    """A scene from its tables (as TOML reads them), or SceneError with the one line."""
    try:
        return Scene.model_validate(data)
    except pydantic.ValidationError as exc:
        raise SceneError(f"{source}: {one_line(exc)}") from exc


@cache
def builtin_names() -> tuple[str, ...]:
    root = files("gyrogen") / "scenes"
    return tuple(sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".toml")))


def builtin_text(name: str) -> str:
    return (files("gyrogen") / "scenes" / f"{name}.toml").read_text(encoding="utf-8")


def load(arg: str) -> Scene:
    """A built-in scene by name, or a .toml file by path."""
    if arg in builtin_names():
        return parse(builtin_text(arg), f"{arg} (built-in)")
    return parse(read_file(arg), arg)


def read_file(path: str) -> str:
    """A scene file's text: a regular file (opened without blocking, so a
    FIFO is refused, not waited on) of at most MAX_SCENE_BYTES, in UTF-8
    (a byte-order mark at its start, as some editors write, is dropped)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except FileNotFoundError as exc:
        names = ", ".join(builtin_names())
        raise SceneError(
            f"{path}: no such file, and no built-in scene of that name ({names})"
        ) from exc
    except OSError as exc:
        raise SceneError(f"{path}: cannot read: {exc.strerror}") from exc
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            what = "a directory" if stat.S_ISDIR(mode) else "a device, FIFO or socket"
            raise SceneError(f"{path}: is {what}, not a scene file")
        with open(fd, "rb", closefd=False) as fh:
            data = fh.read(MAX_SCENE_BYTES + 1)
    except OSError as exc:
        raise SceneError(f"{path}: cannot read: {exc.strerror}") from exc
    finally:
        os.close(fd)
    if len(data) > MAX_SCENE_BYTES:
        raise SceneError(f"{path}: more than {MAX_SCENE_BYTES:,} bytes, the limit for a scene file")
    try:
        return data.decode("utf-8").removeprefix("\ufeff")  # a byte-order mark: not TOML
    except UnicodeDecodeError as exc:
        raise SceneError(
            f"{path}: cannot read: not UTF-8 ({exc.reason} at byte {exc.start})"
        ) from exc


@cache
def default() -> Scene:
    """The paper's full model, every parameter at run time."""
    return load("gyrostat")
