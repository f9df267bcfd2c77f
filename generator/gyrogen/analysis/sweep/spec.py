"""Sweeps: a TOML file naming a scene, with grids over its runtime
parameters and initial states, Monte Carlo draws, the integration and the
metrics to keep; validated like scenes (one line, exit 2, nothing written).

    scene = "gyrostat"            # a built-in scene, or a path from this file
    method = "dop853"             # one of the scene's integrators
    t_end = 10.0                  # s; rtol, atol, max_steps; steps for rk4
    chunk = 10000                 # trajectories per task
    combine = "product"           # the grid axes: "product" or "zip"
    [parameters]                  # runtime values over the scene's simulate.parameters
    [initial]                     # the start state (else the scene's simulate.initial)
    [grid]                        # NAME = { list = [...] | linspace = [a, b, n]
                                  #   | logspace = [a, b, n] }
    [draws]                       # seed, count, NAME = { uniform | normal | lognormal = [a, b],
                                  #   truncate = [lo, hi] }
    [draws.misalign]              # axis_K = { angle = { distribution, degrees }, max_deg = 0.5 }:
                                  #   rotor K's runtime axis tilted within a cone;
                                  #   gimbal_K = { ... }: gimbal K's runtime axes, the pair
                                  #   turned rigidly (its gimbal axis within the cone)
    [metrics]                     # keep = [...], samples, time_to = { QUANTITY = threshold }
    [criterion]                   # spin_stability = { grows_by = 10.0, band = 0.05 }

Trajectory i is grid point i // count with draw i % count; its draws are a
function of (seed, i) alone (analysis/sweep/draws.py).
"""

from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass
from functools import cache
from importlib.resources import files
from pathlib import Path
from typing import Annotated, Literal

import pydantic
from pydantic import BaseModel, ConfigDict, Field, StrictInt, field_validator, model_validator

from gyrogen import methods
from gyrogen.abi import MIN_RTOL
from gyrogen.abi_rotors import AXIS, GIMBAL_AXIS, axis_keys, rotor_name
from gyrogen.errors import SceneError
from gyrogen.limits import (
    MAX_SWEEP_CHUNK,
    MAX_SWEEP_SAMPLES,
    MAX_SWEEP_TRAJECTORIES,
)
from gyrogen.physics import LUMPED_FROM, body_momentum, lumped_inertias
from gyrogen.scene import Number, Scene, builtin_names, load_toml, one_line, read_file
from gyrogen.scene import load as load_scene
from gyrogen.scene.events import Event
from gyrogen.scene.rotors import Rotor, check_axis, check_perpendicular
from gyrogen.scene.rules import QUATERNION, check_angles, check_quaternion
from gyrogen.setup_checks import first_failure
from gyrogen.sweep_values import Axis, Distribution, Misalignment

METRICS = (
    "final_state", "max_nutation", "max_rate", "invariant_drift", "stats", "time_to", "pointing",
)  # fmt: skip
"""What a sweep may keep of each trajectory (analysis/sweep/metrics.py)."""
SAMPLED = ("max_nutation", "max_rate", "invariant_drift", "time_to")
"""The metrics that look along the run, at metrics.samples points."""
QUANTITIES = ("nutation", "rate")
"""time_to's quantities besides the states: the nutation angle and |omega|."""
DEFAULT_SAMPLES = 100
SINGLE_ROTOR_METRICS = SAMPLED
"""The sampled metrics read the paper's single rotor (u4 on a2, its lumped
inertia): a cluster scene keeps final_state and stats."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class Draws(_Strict):
    seed: Annotated[StrictInt, Field(ge=0, lt=2**64)]
    count: Annotated[StrictInt, Field(ge=1, le=MAX_SWEEP_TRAJECTORIES)]
    variables: dict[str, Distribution] = Field(default_factory=dict)
    """Every other key of [draws]: NAME = distribution."""
    misalign: dict[str, Misalignment] = Field(default_factory=dict)
    """<kind>_K = misalignment (kinds: MISALIGNED): rotor K's runtime axis
    tilted (axis_K: g1_K..g3_K drawn), or gimbal K's pair of runtime axes
    turned rigidly (gimbal_K: gg1_K..gg3_K and g1_K..g3_K drawn); their
    base values the nominal axes."""

    @model_validator(mode="before")
    @classmethod
    def _gather(cls, data: object) -> object:
        if isinstance(data, dict) and "variables" not in data:
            own = {k: v for k, v in data.items() if k in ("seed", "count", "misalign")}
            return {**own, "variables": {k: v for k, v in data.items() if k not in own}}
        return data


class Metrics(_Strict):
    keep: list[Literal[METRICS]] = ["final_state", "stats"]  # type: ignore[valid-type]
    samples: Annotated[StrictInt, Field(ge=1, le=MAX_SWEEP_SAMPLES)] | None = None
    """Equal intervals of t_end the sampled metrics look at [default: 100, or
    1 when none is kept]."""
    time_to: dict[str, Number] = Field(default_factory=dict)
    """QUANTITY = threshold: the first sample time at which it is reached."""

    @property
    def points(self) -> int:
        if self.samples is not None:
            return self.samples
        return DEFAULT_SAMPLES if set(self.keep) & set(SAMPLED) else 1


class SpinStability(_Strict):
    grows_by: Annotated[Number, Field(gt=1)] = 10.0
    """A cell whose max nutation angle exceeds its start's this many times
    over is unstable."""
    band: Annotated[Number, Field(gt=0, lt=1)] = 0.05
    """Cells whose H_a/Omega is within this fraction of a transverse
    inertia are left out of the agreement share."""


class Criterion(_Strict):
    spin_stability: SpinStability | None = None


class Sweep(_Strict):
    scene: str
    method: str = "dop853"
    t_end: Annotated[Number, Field(gt=0)] = 10.0
    rtol: Annotated[Number, Field(lt=1)] = 1e-8
    """Above abi.MIN_RTOL, as the compiled integrators require."""
    atol: Annotated[Number, Field(gt=0)] = 1e-8
    steps: Annotated[StrictInt, Field(ge=1, le=10**9)] | None = None
    """rk4 only: equal steps over t_end."""
    max_steps: Annotated[StrictInt, Field(ge=1, le=10**9)] = 10**6
    chunk: Annotated[StrictInt, Field(ge=1, le=MAX_SWEEP_CHUNK)] = 10_000
    combine: Literal["product", "zip"] = "product"
    parameters: dict[str, Number] = Field(default_factory=dict)
    initial: dict[str, Number] | None = None
    grid: dict[str, Axis] = Field(default_factory=dict)
    draws: Draws | None = None
    metrics: Metrics = Metrics()
    criterion: Criterion = Criterion()

    @field_validator("rtol")
    @classmethod
    def _rtol(cls, v: float) -> float:
        if not v > MIN_RTOL:
            raise ValueError(f"must be above {MIN_RTOL:.4g} (10 machine epsilons)")
        return v

    @model_validator(mode="after")
    def _shape(self) -> Sweep:
        sizes = {name: axis.size for name, axis in self.grid.items()}
        if self.combine == "zip" and len(set(sizes.values())) > 1:
            shown = ", ".join(f"{k} {n}" for k, n in sizes.items())
            raise ValueError(f"combine = 'zip' needs axes of one length, not {shown}")
        both = sorted(set(self.grid) & set(self.draws.variables if self.draws else ()))
        if both:
            raise ValueError(f"{', '.join(both)}: both on the grid and drawn")
        for name in self.metrics.time_to:
            if "time_to" not in self.metrics.keep:
                raise ValueError(f"metrics.time_to.{name}: add 'time_to' to metrics.keep")
        return self

    @property
    def grid_size(self) -> int:
        sizes = [axis.size for axis in self.grid.values()]
        if self.combine == "zip":
            return sizes[0] if sizes else 1
        return math.prod(sizes)

    @property
    def count(self) -> int:
        return self.draws.count if self.draws else 1


@dataclass(frozen=True)
class Spec:
    """A validated sweep with its scene."""

    name: str
    sweep: Sweep
    scene: Scene

    @property
    def size(self) -> int:
        return self.sweep.grid_size * self.sweep.count

    @property
    def variables(self) -> tuple[str, ...]:
        """The swept names: the grid's, then the drawn ones, then the
        misaligned axes' components."""
        drawn = self.sweep.draws.variables if self.sweep.draws else {}
        return (*self.sweep.grid, *drawn, *self.tilted)

    @property
    def tilted(self) -> tuple[str, ...]:
        """The components each misalignment draws (tilted_names), in the order written."""
        misalign = self.sweep.draws.misalign if self.sweep.draws else {}
        return tuple(n for key in misalign for names in tilted_names(key) for n in names)

    def base_parameters(self) -> dict[str, float]:
        """The runtime parameters' values before the grid and the draws."""
        return {**self.scene.simulate.parameters, **self.sweep.parameters}

    def base_state(self) -> dict[str, float]:
        """The start state by name before the grid and the draws."""
        given = self.sweep.initial
        return dict(self.scene.simulate.initial if given is None else given)

    def fingerprint(self) -> str:
        """Which sweep a results directory holds: its description (less the
        chunk size: another resumes it) and scene."""
        text = self.sweep.model_dump_json(exclude={"chunk"}) + self.scene.model_dump_json()
        return hashlib.sha256(text.encode()).hexdigest()[:16]


def parse(text: str, source: str, name: str, here: Path | None) -> Spec:
    """A sweep from its TOML text; here: the directory scene paths start
    from (None for a built-in sweep, which names built-in scenes only)."""
    data = load_toml(text, source)
    try:
        sweep = Sweep.model_validate(data)
    except pydantic.ValidationError as exc:
        raise SceneError(f"{source}: {one_line(exc).replace('.variables', '')}") from exc
    scene = _scene(sweep.scene, source, here)
    try:
        check_against(sweep, scene)
    except ValueError as exc:
        raise SceneError(f"{source}: {exc}") from exc
    if sweep.metrics.time_to and not methods.get(sweep.method).fixed_step:
        events = [*scene.events, *threshold_events(sweep.metrics.time_to)]
        try:
            scene = Scene.model_validate({**scene.model_dump(), "events": events})
        except pydantic.ValidationError as exc:
            raise SceneError(f"{source}: metrics.time_to: {one_line(exc)}") from exc
    return Spec(name, sweep, scene)


THRESHOLD = "time_to_"
"""The events a sweep adds to its scene for its time_to thresholds:
time_to_<quantity> (a scene's own event of that name is refused)."""


class _Text(str):
    """An expression of the events' grammar that physics' formulas can
    build: each operation parenthesized."""

    def _op(self, op: str, other: object, right: bool = False) -> _Text:
        a, b = (other, self) if right else (self, other)
        return _Text(f"({a} {op} {b})")

    def __add__(self, other: object) -> _Text:
        return self._op("+", other)

    def __radd__(self, other: object) -> _Text:
        return self._op("+", other, True)

    def __sub__(self, other: object) -> _Text:
        return self._op("-", other)

    def __rsub__(self, other: object) -> _Text:
        return self._op("-", other, True)

    def __mul__(self, other: object) -> _Text:
        return self._op("*", other)

    def __rmul__(self, other: object) -> _Text:
        return self._op("*", other, True)

    def __truediv__(self, other: object) -> _Text:
        return self._op("/", other)

    def __pow__(self, other: object) -> _Text:
        return self._op("**", other)


def threshold_events(time_to: dict[str, float]) -> list[Event]:
    """An event per time_to threshold, crossing zero where its quantity
    crosses the threshold (in either direction: the first crossing is the
    first time it is on the other side): a state's value, |omega|, or the
    nutation angle, as cos(threshold) |H| - H . a2 (H about AB* in A from
    the lumped inertias, physics.body_momentum: positive where the angle is
    past the threshold, no arctangent to locate)."""
    names = [_Text(n) for n in LUMPED_FROM]
    u1, u2, u3, u4 = (_Text(f"u{i}") for i in range(1, 5))
    rate = f"sqrt({u1**2 + u2**2 + u3**2})"
    h1, h2, h3 = body_momentum(lumped_inertias(*names), _Text("J"), u1, u2, u3, u4)
    out = []
    for q, value in time_to.items():
        thr = f"({float(value)!r})"
        expr = (
            f"cos({thr}) * sqrt({h1**2 + h2**2 + h3**2}) - {h2}"
            if q == "nutation"
            else f"{rate} - {thr}"
            if q == "rate"
            else f"{q} - {thr}"
        )
        out.append(Event(name=THRESHOLD + q, expr=expr))
    return out


def _scene(ref: str, source: str, here: Path | None) -> Scene:
    if ref in builtin_names() or here is None:
        if ref not in builtin_names():
            raise SceneError(f"{source}: scene: {ref!r} is not a built-in scene")
        return load_scene(ref)
    path = Path(ref) if Path(ref).is_absolute() else here / ref
    if not os.path.lexists(path):
        raise SceneError(f"{source}: scene: {path}: no such file, and no built-in scene {ref!r}")
    return load_scene(str(path))


def check_against(sweep: Sweep, scene: Scene) -> None:
    """ValueError (key: why) unless the sweep fits its scene."""
    if sweep.method not in scene.integrators:
        listed = ", ".join(scene.integrators)
        raise ValueError(
            f"method: {sweep.method!r} is not among the scene's integrators ({listed})"
        )
    if methods.get(sweep.method).fixed_step != (sweep.steps is not None):
        raise ValueError("steps: give it for rk4 (equal steps over t_end), and only for rk4")
    if sweep.steps is not None and sweep.steps < sweep.metrics.points:
        raise ValueError(f"steps: {sweep.steps} is fewer than metrics.samples")
    size = sweep.grid_size * sweep.count
    if size > MAX_SWEEP_TRAJECTORIES:
        raise ValueError(f"{size:,} trajectories: at most {MAX_SWEEP_TRAJECTORIES:,}")
    drawn = sweep.draws.variables if sweep.draws else {}
    for key, names in (("grid", list(sweep.grid)), ("draws", list(drawn))):
        for name in names:
            _check_variable(scene, f"{key}.{name}", name)
    _check_names(scene, sweep)
    _check_misalign(scene, sweep)
    _check_values(scene, sweep)
    cluster_only = sorted(set(sweep.metrics.keep) & set(SINGLE_ROTOR_METRICS))
    if scene.rotors and cluster_only:
        raise ValueError(
            f"metrics.keep: {', '.join(cluster_only)} read the paper's single rotor; a cluster "
            "scene keeps final_state and stats"
        )
    for name in sweep.metrics.time_to:
        if name not in QUANTITIES and name not in scene.states:
            choices = ", ".join((*QUANTITIES, *scene.states))
            raise ValueError(f"metrics.time_to.{name}: not one of {choices}")
    if sweep.criterion.spin_stability is not None:
        _check_spin(sweep, scene)


def _check_variable(scene: Scene, key: str, name: str) -> None:
    if name in QUATERNION and scene.attitude == "quaternion":
        raise ValueError(
            f"{key}: Euler parameters cannot be swept (they must stay a unit quaternion)"
        )
    if name in scene.states or name in scene.runtime:
        return
    value = scene.parameters.get(name)
    if value is not None:
        raise ValueError(
            f'{key}: folded into the code as {value!r}: make it "runtime" in the scene to sweep it'
        )
    raise ValueError(
        f"{key}: not a state or runtime parameter of scene {scene.name} "
        f"(states {', '.join(scene.states)}; runtime {', '.join(scene.runtime) or 'none'})"
    )


MISALIGNED = {"axis": (AXIS,), "gimbal": (GIMBAL_AXIS, AXIS)}
"""[draws.misalign]'s keys <kind>_K, and the runtime vectors of rotor K
each kind turns (their keys in p[]): the first tilted within the cone, the
others turned with it by the same rotation. gimbal_K turns a gimbal's axis
g_g and its spin axis g_s0 at gimbal angle 0 as one rigid pair, so the
pair stays orthonormal (setup refuses a spin axis tilted alone past
GIMBAL_PERP_SLACK: code 10)."""


def rotor_of(key: str) -> tuple[str, int]:
    """(kind, K) of a misalignment's key <kind>_K, kind one of MISALIGNED
    (("", 0) when it is not of that form)."""
    head, _, k = key.rpartition("_")
    ok = head in MISALIGNED and k.isdigit() and k == str(int(k))
    return (head, int(k)) if ok else ("", 0)


def tilted_names(key: str) -> tuple[tuple[str, str, str], ...]:
    """The p[] names of the vectors a misalignment's key turns (MISALIGNED):
    ((g1_K, g2_K, g3_K),), or gimbal K's ((gg1_K..gg3_K), (g1_K..g3_K))."""
    kind, k = rotor_of(key)
    return tuple((rotor_name(a, k), rotor_name(b, k), rotor_name(c, k))
                 for a, b, c in MISALIGNED[kind])  # fmt: skip


def _misalignable(rotors: list[Rotor]) -> str:
    """The misalignment keys of a scene's rotors: axis_K of a fixed rotor,
    gimbal_K of one on a gimbal."""
    keys = [f"{'axis' if r.gimbal is None else 'gimbal'}_{k}" for k, r in enumerate(rotors, 1)]
    if len(keys) > 2 and len({key.rpartition("_")[0] for key in keys}) == 1:
        return f"{keys[0]}..{keys[-1]}"
    return ", ".join(keys) or "none: not a cluster"


def _check_misalign(scene: Scene, sweep: Sweep) -> None:
    """Each misalignment names a rotor of the scene by its kind (axis_K a
    fixed rotor, gimbal_K one on a gimbal), whose vectors it turns are
    runtime, not also on the grid or drawn, and nominally (the base
    parameters) directions (a gimbal's pair perpendicular)."""
    if sweep.draws is None:
        return
    swept = set(sweep.grid) | set(sweep.draws.variables)
    base = {**scene.simulate.parameters, **sweep.parameters}
    for key in sweep.draws.misalign:
        where, (kind, k) = f"draws.misalign.{key}", rotor_of(key)
        if not 1 <= k <= len(scene.rotors):
            raise ValueError(
                f"{where}: not a rotor axis of scene {scene.name} ({_misalignable(scene.rotors)})"
            )
        _check_kind(scene.rotors[k - 1], kind, k, where)
        names = [n for vector in tilted_names(key) for n in vector]
        both = [n for n in names if n in swept]
        if both:
            raise ValueError(f"{where}: {', '.join(both)} also on the grid or drawn")
        if not all(n in base for n in names):
            continue
        vectors = [tuple(base[n] for n in vector) for vector in tilted_names(key)]
        nominal = [f"{where}: nominal {axis_keys(k, keys)}" for keys in MISALIGNED[kind]]
        for v, named in zip(vectors, nominal, strict=True):
            check_axis(v, named)  # type: ignore[arg-type]
        if kind == "gimbal":
            check_perpendicular(vectors[1], vectors[0], nominal[0])  # type: ignore[arg-type]


def _check_kind(rotor: Rotor, kind: str, k: int, where: str) -> None:
    """axis_K on a fixed rotor with a runtime axis, gimbal_K on a gimbal
    with both axes runtime."""
    if kind == "axis" and rotor.gimbal is not None:
        raise ValueError(
            f"{where}: rotor {k} is on a gimbal, whose spin axis turns with its gimbal axis "
            f"(tilted alone setup refuses it: code 10): misalign the pair with gimbal_{k}"
        )
    if kind == "gimbal" and rotor.gimbal is None:
        raise ValueError(f"{where}: rotor {k} has no gimbal: misalign its axis with axis_{k}")
    if kind == "axis" and rotor.axis != "runtime":
        raise ValueError(
            f"{where}: rotor {k}'s axis is folded into the code: make it "
            '"runtime" in the scene to misalign it'
        )
    if kind == "gimbal":
        axes = {"spin axis": rotor.axis, "gimbal axis": rotor.gimbal.axis}  # type: ignore[union-attr]
        folded = [name for name, v in axes.items() if v != "runtime"]
        if folded:
            verb = "is" if len(folded) == 1 else "are"
            raise ValueError(
                f"{where}: rotor {k}'s {' and '.join(folded)} {verb} folded into the code: "
                'make axis and gimbal.axis "runtime" in the scene to misalign the pair'
            )


def _check_names(scene: Scene, sweep: Sweep) -> None:
    for name in sweep.parameters:
        if name not in scene.runtime:
            raise ValueError(f"parameters.{name}: not a runtime parameter of scene {scene.name}")
    for name in sweep.initial or {}:
        if name not in scene.states:
            raise ValueError(f"initial.{name}: not a state of scene {scene.name}")
    swept = set(sweep.grid) | set(sweep.draws.variables if sweep.draws else ())
    known = {**scene.simulate.parameters, **sweep.parameters}
    missing = [n for n in scene.runtime if n not in known and n not in swept]
    if missing:
        raise ValueError(f"parameters: no value for runtime parameter {', '.join(missing)}")


def _check_values(scene: Scene, sweep: Sweep) -> None:
    """The values every trajectory shares, checked as a scene file's are: the
    start's angles and Euler parameters, and setup's checks on the parameters that are
    neither on the grid nor drawn (a grid or a draw may still reach values
    setup refuses: those rows carry its code); the angles a grid axis or a
    draw reaches within MAX_START_ANGLE too."""
    swept = set(sweep.grid) | set(sweep.draws.variables if sweep.draws else ())
    if sweep.initial is not None:
        check_angles(sweep.initial, "initial")
    check_angles({n: axis.reach for n, axis in sweep.grid.items()}, "grid", "reaches")
    if sweep.draws is not None:
        drawn = sweep.draws.variables.items()
        check_angles({n: d.reach for n, d in drawn}, "draws", "reaches")
    if scene.attitude == "quaternion" and sweep.initial is not None:
        check_quaternion(sweep.initial, "initial")
    if not scene.rotors:
        fixed = {**scene.folded(), **scene.simulate.parameters, **sweep.parameters}
        failed = first_failure({k: v for k, v in fixed.items() if k not in swept})
        if failed is not None:
            raise ValueError(failed[1])


def _check_spin(sweep: Sweep, scene: Scene) -> None:
    """NOTES.md's criterion is for a torque-free spin, watched by its nutation."""
    why = "criterion.spin_stability"
    if "max_nutation" not in sweep.metrics.keep:
        raise ValueError(f"{why}: add 'max_nutation' to metrics.keep")
    torque = scene.effects.torque
    t_value = {**scene.folded(), **scene.simulate.parameters, **sweep.parameters}.get("T", 0.0)
    swept_t = "T" in sweep.grid or (sweep.draws is not None and "T" in sweep.draws.variables)
    if torque not in ("none", "constant") or t_value != 0.0 or swept_t:
        raise ValueError(f"{why}: the criterion is for a torque-free spin (T = 0)")


@cache
def builtin_sweeps() -> tuple[str, ...]:
    root = files("gyrogen") / "sweeps"
    return tuple(sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".toml")))


def load(arg: str) -> Spec:
    """A built-in sweep by name, or a sweep file by path."""
    if arg in builtin_sweeps():
        text = (files("gyrogen") / "sweeps" / f"{arg}.toml").read_text(encoding="utf-8")
        return parse(text, f"{arg} (built-in)", arg, None)
    if not os.path.lexists(arg):
        names = ", ".join(builtin_sweeps())
        raise SceneError(f"{arg}: no such file, and no built-in sweep of that name ({names})")
    path = Path(arg)
    return parse(read_file(arg), arg, path.stem, path.parent)
