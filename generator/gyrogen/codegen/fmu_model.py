"""What an FMU of a scene exposes, language- and version-neutral: its
variables (states, their derivatives, the runtime parameters, the outputs)
with value references, units and start values, the units they use, and how
Co-Simulation steps (the method and its tolerances)."""

from __future__ import annotations

import hashlib
import json
import uuid
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Any

from gyrogen import abi, methods
from gyrogen.codegen.units import DIMENSIONLESS, base_units, per_second
from gyrogen.scene import Scene


@dataclass(frozen=True)
class Variable:
    name: str
    vr: int
    """Value reference: states, derivatives, parameters, outputs, in that order."""
    kind: str
    """state, derivative, parameter or output."""
    offset: int
    """Its place in x[], dxdt[], p[] or the outputs laid end to end."""
    unit: str
    description: str
    start: float | None = None

    @property
    def causality(self) -> str:
        return {"parameter": "parameter", "derivative": "local"}.get(self.kind, "output")

    @property
    def variability(self) -> str:
        return "tunable" if self.kind == "parameter" else "continuous"

    @property
    def initial(self) -> str:
        """exact for what the user sets (states, parameters), calculated
        for what the model computes."""
        return "exact" if self.start is not None else "calculated"

    @property
    def unit_name(self) -> str | None:
        return None if self.unit == DIMENSIONLESS else self.unit


@dataclass(frozen=True)
class Stepping:
    """How Co-Simulation advances: the scene's compiled integrator and
    tolerances; the default experiment's end and communication step."""

    method: str
    rtol: float
    atol: float
    t_end: float
    dt: float
    max_steps: int = abi.MAX_STEPS


@dataclass(frozen=True)
class Row:
    """A state, parameter or output function as the FMU names it (size: an
    output's values; 1 for a state or parameter)."""

    index: int
    name: str
    unit: str
    doc: str
    size: int = 1


@dataclass(frozen=True, eq=False)
class Rendered:
    """What an FMU reads of a scene's rendering: the files render_all writes
    (the manifest and the C sources; the build cache keeps them, so an FMU
    of a scene rendered before derives nothing: runtime/scene_build.py's
    scene_sources), with the scene."""

    scene: Scene
    files: Mapping[str, str]

    @cached_property
    def manifest(self) -> dict[str, Any]:
        held: dict[str, Any] = json.loads(self.files["manifest.json"])
        return held

    @property
    def prefix(self) -> str:
        return str(self.manifest["prefix"])

    @property
    def macro(self) -> str:
        return self.prefix.upper()

    @property
    def nx(self) -> int:
        return int(self.manifest["nx"])

    @property
    def np(self) -> int:
        return int(self.manifest["np"])

    @property
    def build_id(self) -> str:
        return str(self.manifest["build_id"])

    @property
    def ops(self) -> dict[str, int]:
        return dict(self.manifest["ops"])

    @property
    def versions(self) -> dict[str, str]:
        return dict(self.manifest["versions"])

    @property
    def quaternion(self) -> bool:
        """The attitude is Euler parameters, x[0..3]."""
        return self.scene.attitude == "quaternion"

    @property
    def c_sources(self) -> dict[str, str]:
        """The scene's C files (the manifest's files c_*), by name."""
        names = [name for key, name in self.manifest["files"].items() if key.startswith("c_")]
        return {name: self.files[name] for name in sorted(names)}

    def _rows(self, key: str) -> list[Row]:
        return [Row(i, n, *self.scene.unit_and_doc(n)) for i, n in enumerate(self.manifest[key])]

    @property
    def state_rows(self) -> list[Row]:
        return self._rows("states")

    @property
    def param_rows(self) -> list[Row]:
        return self._rows("parameters")

    @property
    def outputs(self) -> list[Row]:
        """The output functions in out[]'s order (abi.output_doc's)."""
        sizes = self.manifest["outputs"]
        doc = abi.output_doc(bool(self.scene.rotors))
        named = [n for n in doc if n in sizes]
        return [Row(i, n, *doc[n], sizes[n]) for i, n in enumerate(named)]


@dataclass(frozen=True)
class FmuModel:
    unit: Rendered
    """The scene's rendering, as the templates read it (model.unit)."""
    parameters: tuple[float, ...]
    """Start values of the runtime parameters, in p[] order."""
    stepping: Stepping

    @property
    def prefix(self) -> str:
        return self.unit.prefix

    @cached_property
    def variables(self) -> tuple[Variable, ...]:
        u = self.unit
        x0 = u.scene.initial_state()
        out = [Variable(r.name, r.index, "state", r.index, r.unit, r.doc, x0[r.index])
               for r in u.state_rows]  # fmt: skip
        out += [Variable(f"der({r.name})", u.nx + r.index, "derivative", r.index,
                         per_second(r.unit), f"rate of {r.name}")
                for r in u.state_rows]  # fmt: skip
        out += [Variable(r.name, 2 * u.nx + r.index, "parameter", r.index, r.unit, r.doc,
                         self.parameters[r.index]) for r in u.param_rows]  # fmt: skip
        offset = 0
        for o in u.outputs:
            for k in range(o.size):
                name = f"{o.name}[{k + 1}]" if o.size > 1 else o.name
                out.append(Variable(name, len(out), "output", offset, o.unit, o.doc))
                offset += 1
        return tuple(out)

    @property
    def event_directions(self) -> list[int]:
        """Each event's crossings as the integrators take them (1 up, -1 down, 0 any)."""
        return [e.sign for e in self.unit.scene.events]

    @property
    def event_terminal(self) -> list[int]:
        return [int(e.terminal) for e in self.unit.scene.events]

    @property
    def located(self) -> bool:
        """Co-Simulation locates the events: the scene has some and the
        stepping method is adaptive (its _events call)."""
        return bool(self.unit.scene.events) and not methods.get(self.stepping.method).fixed_step

    def of_kind(self, kind: str) -> tuple[Variable, ...]:
        return tuple(v for v in self.variables if v.kind == kind)

    @property
    def output_blocks(self) -> list[tuple[str, int]]:
        """Each output function, and where its values start among the outputs."""
        starts, offset = [], 0
        for o in self.unit.outputs:
            starts.append((o.name, offset))
            offset += o.size
        return starts

    @property
    def n_outputs(self) -> int:
        return len(self.of_kind("output"))

    @cached_property
    def units(self) -> dict[str, dict[str, int]]:
        """Every unit a variable has, in base units, by name."""
        return {v.unit_name: base_units(v.unit) for v in self.variables if v.unit_name}

    def guid(self, fmi_version: str) -> str:
        """The same for the same scene, gyrogen, method and FMI version."""
        key = f"{self.unit.build_id} {fmi_version} {self.stepping} {self.parameters}"
        return "{" + str(uuid.UUID(hashlib.sha256(key.encode()).hexdigest()[:32])) + "}"
