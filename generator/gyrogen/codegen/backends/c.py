"""C99 backend: a printer and the two files it renders (header, source)."""

from __future__ import annotations

import sympy as sm
from sympy.printing.c import C99CodePrinter

from gyrogen import abi
from gyrogen import methods as methods_registry
from gyrogen.codegen.checks import printed
from gyrogen.codegen.context import SceneContext
from gyrogen.codegen.integrators.program import c_text, program, tables_text, trig_text
from gyrogen.codegen.integrators.trig import VARIANTS
from gyrogen.codegen.render import c_double, render
from gyrogen.codegen.statements import (
    SmallPowers,
    WritableNumbers,
    functions,
    jacobian,
    linear,
    statements,
    trig_used,
)
from gyrogen.symbolic.hoist import constants


class CPrinter(SmallPowers, WritableNumbers, C99CodePrinter):
    """C99 with the hoisted constants as c[k], doubles in their shortest
    exact form, small integer powers as products (x*x beats pow(x, 2)), and
    sin and cos as the file's own <prefix>_sin, <prefix>_cos
    (gyrogen.codegen.integrators.trig: inline), or with ``lanes`` their
    branch-free twins <prefix>_sin_lanes, <prefix>_cos_lanes, so that a loop
    over lanes vectorizes."""

    def __init__(self, nc: int, prefix: str, lanes: bool = False) -> None:
        super().__init__()
        self._names = {c.name: f"c[{k}]" for k, c in enumerate(constants(nc))}
        self._trig = prefix + "_{}" + ("_lanes" if lanes else "")

    def _print_sin(self, expr: sm.sin) -> str:
        return f"{self._trig.format('sin')}({self._print(expr.args[0])})"

    def _print_cos(self, expr: sm.cos) -> str:
        return f"{self._trig.format('cos')}({self._print(expr.args[0])})"

    def _print_Symbol(self, expr: sm.Symbol) -> str:
        return self._names.get(expr.name) or str(super()._print_Symbol(expr))

    def _print_Float(self, expr: sm.Float) -> str:
        return c_double(float(expr))

    def _print_Heaviside(self, expr: sm.Heaviside) -> str:
        """A torque limit's slope in the Jacobian: 1 inside the clamp, 0 outside."""
        return f"(({self._print(expr.args[0])}) > 0.0 ? 1.0 : 0.0)"


def files(unit: SceneContext) -> dict[str, str]:
    printer = CPrinter(unit.nc, unit.prefix)
    lanes_printer = CPrinter(unit.nc, unit.prefix, lanes=True)

    def assign(lhs: str, expr: sm.Expr) -> str:
        return f"{lhs} = {printer.doprint(expr)};"

    def assign_lanes(lhs: str, expr: sm.Expr) -> str:
        return f"{lhs} = {lanes_printer.doprint(expr)};"

    rhs, *outputs = functions(unit, lambda a, i: f"{a}[{i}]", assign)
    lanes = functions(unit, lambda a, i: f"{a}[{i} * n + l]", assign_lanes)[0]
    lanes_ode = functions(unit, lambda a, i: f"{a}[{i}][l]", assign_lanes)[0]
    jac = jacobian(unit, lambda a, i: f"{a}[{i}]", assign)
    lin = linear(unit, lambda a, i: f"{a}[{i}]", assign)
    has_lanes = any(m.lanes for m in unit.methods)
    inlined = [lanes_ode] if any(m.pair for m in unit.methods) and not lanes_ode.torque else []
    # the Taylor jet calls the rhs's sin and cos, scalar and over lanes
    expanded = [rhs, lanes_ode] if unit.jet is not None else []
    ode_trig = trig_used(unit.prefix, [jac, *inlined, *expanded])  # rhs_lanes is inlined in ode.c
    gimbal_checks = ["cos", "cos_lanes"] if has_lanes else ["cos"]
    if not unit.quaternion:  # the gimbal-lock checks
        ode_trig = [n for n in VARIANTS if n in ode_trig + gimbal_checks]
    ctx = {
        "unit": unit,
        "tables": tables_text("c", unit.prefix, unit.macro, unit.torque_tables),
        "setup": statements(unit.optimized.setup, lambda k: f"c[{k}]", assign),
        "rhs": rhs,
        "rhs_lanes": lanes,
        "rhs_lanes_ode": lanes_ode,
        "outputs": outputs,
        "jac": jac,
        "linear": lin,
        "source_trig": trig_text(
            "c", unit.prefix, unit.macro, trig_used(unit.prefix, [rhs, lanes, *outputs, lin])
        ),
        "ode_trig": trig_text("c", unit.prefix, unit.macro, ode_trig),
        "methods": unit.methods,
        "ir": c_text(
            program(
                unit.methods,
                unit.quaternion,
                unit.uses_time,
                unit.lu_blocks,
                unit.jet,
                unit.measured,
            ),
            unit.prefix,
            unit.macro,
        ),
        "abi": abi,
        "registry": methods_registry,
        "checks": printed("c", unit.macro, unit.checks),
        "code_names": {c.value: c.name for c in abi.SETUP_CODES},
    }
    out = {
        f"{unit.prefix}.h": render("c/header.h.jinja", **ctx),
        f"{unit.prefix}.c": render("c/source.c.jinja", **ctx),
    }
    if unit.methods:
        out[f"{unit.prefix}_ode.h"] = render("c/ode.h.jinja", **ctx)
        out[f"{unit.prefix}_ode.c"] = render("c/ode.c.jinja", **ctx)
    return out
