"""C99: the two files of a scene (header, source) and, with integrators,
the two of its ODE solvers, laid out by the templates around the IR's
functions (gyrogen.codegen.statements, gyrogen.codegen.integrators)."""

from __future__ import annotations

from gyrogen import abi
from gyrogen import methods as methods_registry
from gyrogen.codegen import statements
from gyrogen.codegen.context import SceneContext
from gyrogen.codegen.integrators.program import (
    c_text,
    intrinsics_of,
    tables_text,
    trig_text,
)
from gyrogen.codegen.integrators.trig import VARIANTS
from gyrogen.codegen.ir.c import CPrinter
from gyrogen.codegen.ir.nodes import Func
from gyrogen.codegen.render import render


def files(unit: SceneContext) -> dict[str, str]:
    printer = CPrinter(unit.prefix, unit.macro, {})
    rhs = statements.rhs(unit)
    source: list[Func | None] = [
        statements.setup(unit),
        rhs,
        statements.rhs_lanes(unit),
        *statements.outputs(unit),
        statements.events(unit),
        statements.linear(unit),
    ]
    model = [f for f in source if f is not None]
    jac = statements.jacobian(unit)
    stepped = [m for m in unit.laned if not m.taylor]  # on the rhs over lanes
    lanes_ode = statements.rhs_lanes_ode(unit) if stepped else None
    jac_lanes = statements.jacobian_lanes(unit) if any(m.implicit for m in stepped) else None
    # the Taylor jet calls the rhs's sin and cos, scalar and over lanes
    rhs_trig = statements.trig_used([rhs])
    expanded = [*rhs_trig, *(v + "_lanes" for v in rhs_trig)] if unit.jet is not None else []
    ode_trig = statements.trig_used([jac, lanes_ode, jac_lanes]) + expanded
    gimbal_checks = ["cos", "cos_lanes"] if unit.laned else ["cos"]
    if not unit.quaternion:  # the gimbal-lock checks
        ode_trig += gimbal_checks
    ode_model = [f for f in (jac, lanes_ode, jac_lanes) if f is not None]
    ctx = {
        "unit": unit,
        "tables": tables_text("c", unit.prefix, unit.macro, unit.torque_tables),
        "source_trig": trig_text("c", unit.prefix, unit.macro, statements.trig_used(model)),
        "source_intrinsics": "\n".join(printer.function(f) for f in intrinsics_of(model, printer)),
        "source": "\n".join(printer.function(f) for f in model),
        "jac": None if jac is None else printer.function(jac),
        "rhs_lanes": None if lanes_ode is None else printer.function(lanes_ode),
        "jac_lanes": None if jac_lanes is None else printer.function(jac_lanes),
        "ode_tables": tables_text(
            "c", unit.prefix, unit.macro, statements.tables_used(unit, ode_model)
        ),
        "ode_trig": trig_text("c", unit.prefix, unit.macro, [v for v in VARIANTS if v in ode_trig]),
        "methods": unit.methods,
        # struct lanes on the heap where lanes were asked for (they make it large)
        "lanes_heap": any(m.lanes_asked for m in unit.laned),
        "ir": c_text(
            unit.program,
            unit.prefix,
            unit.macro,
            ode_model,
        ),
        "abi": abi,
        "registry": methods_registry,
    }
    out = {
        f"{unit.prefix}.h": render("c/header.h.jinja", **ctx),
        f"{unit.prefix}.c": render("c/source.c.jinja", **ctx),
    }
    if unit.methods:
        out[f"{unit.prefix}_ode.h"] = render("c/ode.h.jinja", **ctx)
        out[f"{unit.prefix}_ode.c"] = render("c/ode.c.jinja", **ctx)
    return out
