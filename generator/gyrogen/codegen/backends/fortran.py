"""Fortran 2008: the module of a scene and, with integrators, the module of
its ODE solvers, laid out by the templates around the IR's functions
(gyrogen.codegen.statements, gyrogen.codegen.integrators)."""

from __future__ import annotations

from gyrogen import abi
from gyrogen import methods as methods_registry
from gyrogen.codegen import statements
from gyrogen.codegen.checks import LOOP
from gyrogen.codegen.context import SceneContext
from gyrogen.codegen.integrators.program import fortran_text, tables_text, trig_text
from gyrogen.codegen.ir.fortran import RESULT, FortranPrinter
from gyrogen.codegen.ir.nodes import Func
from gyrogen.codegen.render import render
from gyrogen.errors import GyrogenError


def _check_names(f: Func) -> None:
    """Fortran ignores case: a function whose names differ only in case is
    refused, where the compiler would take them for one."""
    seen: dict[str, str] = {}
    for n in [*(d.name for d in (*f.params, *f.locals)), RESULT, LOOP]:
        if n.lower() in seen:
            other = seen[n.lower()]
            raise GyrogenError(f"Fortran ignores case: {other!r} and {n!r} clash in {f.name}")
        seen[n.lower()] = n


def files(unit: SceneContext) -> dict[str, str]:
    printer = FortranPrinter(unit.prefix, unit.macro, {})
    setup, rhs = statements.setup(unit), statements.rhs(unit)
    outputs = [*statements.outputs(unit), *filter(None, [statements.events(unit)])]
    jac = statements.jacobian(unit)
    for f in (setup, rhs, *outputs, *([jac] if jac else [])):
        _check_names(f)

    def used(funcs: list[Func | None], gimbal: bool = False) -> list[str]:
        found = statements.trig_used(funcs) + ["cos"] * gimbal
        return [v for v in ("sin", "cos") if v in found]  # Fortran has no _lanes twins

    gimbal = bool(unit.methods) and not unit.quaternion
    trig = used([setup, rhs, *outputs, jac], gimbal)
    ctx = {
        "unit": unit,
        "tables": tables_text("fortran", unit.prefix, unit.macro, unit.torque_tables),
        "trig": trig_text("fortran", unit.prefix, unit.macro, trig),
        "trig_names": trig,
        "ode_table_names": [tb.name for tb in statements.tables_used(unit, [jac])],
        "ode_trig_names": used([jac, *([rhs] if unit.jet is not None else [])], gimbal),
        "setup": printer.function(setup),
        "rhs": printer.function(rhs),
        "outputs": [(f.name, printer.function(f)) for f in outputs],
        "jac": None if jac is None else printer.function(jac),
        "methods": unit.methods,
        "ir": fortran_text(
            unit.program,
            unit.prefix,
            unit.macro,
            [jac] if jac else [],
        ),
        "abi": abi,
        "registry": methods_registry,
    }
    out = {
        f"{unit.prefix}.f90": render("fortran/module.f90.jinja", **ctx),
        f"{unit.prefix}_f.h": render("fortran/bindings.h.jinja", **ctx),
    }
    if unit.methods:
        out[f"{unit.prefix}_ode.f90"] = render("fortran/ode.f90.jinja", **ctx)
    return out
