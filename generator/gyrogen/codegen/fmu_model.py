"""What an FMU of a scene exposes, language- and version-neutral: its
variables (states, their derivatives, the runtime parameters, the outputs)
with value references, units and start values, the units they use, and how
Co-Simulation steps (the method and its tolerances)."""

from __future__ import annotations

import hashlib
import uuid
from dataclasses import dataclass
from functools import cached_property

from gyrogen import abi, methods
from gyrogen.codegen.context import SceneContext
from gyrogen.codegen.units import DIMENSIONLESS, base_units, per_second


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
class FmuModel:
    unit: SceneContext
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
        grid = self.unit.event_grid
        return [] if grid is None else [e.direction for e in grid.events]

    @property
    def event_terminal(self) -> list[int]:
        grid = self.unit.event_grid
        return [] if grid is None else [int(e.terminal) for e in grid.events]

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
