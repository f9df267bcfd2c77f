"""Everything one scene's generated files need, language-neutral."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from importlib.metadata import version

import sympy as sm

import gyrogen
from gyrogen import equations
from gyrogen.layout import (
    PARAMETER_DOC,
    SETUP_CODE_NAMES,
    SETUP_CODES,
    STATE_DOC,
    TRIANGLE_SLACK,
)
from gyrogen.optimize import Optimized, optimize
from gyrogen.scene import Scene


@dataclass(frozen=True)
class Row:
    index: int
    name: str
    unit: str
    doc: str


@dataclass(frozen=True)
class Code:
    value: int
    macro: str
    doc: str


@dataclass(frozen=True)
class Unit:
    scene: Scene
    states: tuple[sm.Symbol, ...]
    params: tuple[sm.Symbol, ...]
    optimized: Optimized

    @property
    def prefix(self) -> str:
        return self.scene.name

    @property
    def macro(self) -> str:
        return self.scene.name.upper()

    @property
    def nx(self) -> int:
        return len(self.states)

    @property
    def np(self) -> int:
        return len(self.params)

    @property
    def nc(self) -> int:
        return self.optimized.nc

    @cached_property
    def ops(self) -> dict[str, int]:
        return {"setup": self.optimized.setup.ops, "rhs": self.optimized.rhs.ops}

    @property
    def state_rows(self) -> list[Row]:
        return [Row(i, s.name, *STATE_DOC[s.name]) for i, s in enumerate(self.states)]

    @property
    def param_rows(self) -> list[Row]:
        return [Row(i, s.name, *PARAMETER_DOC[s.name]) for i, s in enumerate(self.params)]

    @property
    def codes(self) -> list[Code]:
        return [Code(v, f"{self.macro}_{SETUP_CODE_NAMES[v]}", SETUP_CODES[v]) for v in SETUP_CODES]

    @property
    def triangle_slack(self) -> str:
        return repr(TRIANGLE_SLACK)

    @property
    def versions(self) -> dict[str, str]:
        return {"gyrogen": gyrogen.__version__, "sympy": version("sympy")}

    @property
    def functions(self) -> dict[str, dict[str, str]]:
        p = self.prefix
        return {
            "c": {"setup": f"{p}_setup", "rhs": f"{p}_rhs"},
            "fortran": {"module": f"{p}_mod", "setup": f"{p}_f_setup", "rhs": f"{p}_f_rhs"},
        }


def make_unit(scene: Scene) -> Unit:
    eqs = equations.full_model()
    return Unit(scene, eqs.states, eqs.params, optimize(eqs))
