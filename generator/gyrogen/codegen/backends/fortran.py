"""Fortran 2008 backend: a printer and the module it renders."""

from __future__ import annotations

import sympy as sm
from sympy.printing.fortran import FCodePrinter

from gyrogen import abi
from gyrogen import methods as methods_registry
from gyrogen.abi import SETUP_RESULT, SIGNATURES
from gyrogen.codegen.checks import FORTRAN_WRAP, printed
from gyrogen.codegen.context import SceneContext
from gyrogen.codegen.integrators.program import fortran_text, program, tables_text, trig_text
from gyrogen.codegen.render import f_double, render
from gyrogen.codegen.statements import (
    Function,
    SmallPowers,
    WritableNumbers,
    functions,
    jacobian,
    statements,
    trig_used,
)
from gyrogen.errors import GyrogenError
from gyrogen.methods import signature_of
from gyrogen.setup_checks import local_names
from gyrogen.symbolic.hoist import constants


class FortranPrinter(SmallPowers, WritableNumbers, FCodePrinter):
    """Fortran 2008 free form (wrapped under 132 columns) with the hoisted
    constants as c(k+1). Names are printed as they are: `_check_names`
    refuses a function whose names differ only in case, where sympy would
    mangle them silently."""

    def __init__(self, nc: int, prefix: str) -> None:
        super().__init__({"standard": 2008, "source_format": "free", "name_mangling": False})
        self._names = {c.name: f"c({k + 1})" for k, c in enumerate(constants(nc))}
        self._prefix = prefix

    def _print_sin(self, expr: sm.sin) -> str:
        """The module's own sin and cos (gyrogen.codegen.integrators.trig):
        the same bits as the C files'."""
        return f"{self._prefix}_sin({self._print(expr.args[0])})"

    def _print_cos(self, expr: sm.cos) -> str:
        return f"{self._prefix}_cos({self._print(expr.args[0])})"

    def _print_Symbol(self, expr: sm.Symbol) -> str:
        return self._names.get(expr.name) or str(super()._print_Symbol(expr))

    def _print_Float(self, expr: sm.Float) -> str:
        return f_double(float(expr))

    def _print_Heaviside(self, expr: sm.Heaviside) -> str:
        """A torque limit's slope in the Jacobian: 1 inside the clamp, 0 outside."""
        one, zero = f_double(1.0), f_double(0.0)
        return f"merge({one}, {zero}, {self._print(expr.args[0])} > {zero})"


def _check_names(names: list[str], where: str) -> None:
    seen: dict[str, str] = {}
    for n in names:
        other = seen.setdefault(n.lower(), n)
        if other != n:
            raise GyrogenError(f"Fortran ignores case: {other!r} and {n!r} clash in {where}")


def _declared(names: tuple[str, ...]) -> list[str]:
    """names as the lists of one declaration each, each line within
    FORTRAN_WRAP columns (many checks' locals: a cluster's runtime axes)."""
    head = len("    real(c_double) :: ")
    lines: list[list[str]] = []
    for name in names:
        if lines and head + len(", ".join([*lines[-1], name])) <= FORTRAN_WRAP:
            lines[-1].append(name)
        else:
            lines.append([name])
    return [", ".join(line) for line in lines]


def files(unit: SceneContext) -> dict[str, str]:
    printer = FortranPrinter(unit.nc, unit.prefix)

    def assign(lhs: str, expr: sm.Expr) -> str:
        return str(printer.doprint(expr, assign_to=sm.Symbol(lhs)))

    rhs, *outputs = functions(unit, lambda a, i: f"{a}({i + 1})", assign)
    setup = statements(unit.optimized.setup, lambda k: f"c({k + 1})", assign)
    check_locals = local_names(unit.checks)
    setup_names = [*SIGNATURES["setup"].names, SETUP_RESULT, *check_locals]
    _check_names(
        [*setup_names, *(v.name for v in unit.setup_locals), *(s.name for s in setup if s.declare)],
        "setup",
    )
    jac = jacobian(unit, lambda a, i: f"{a}({i + 1})", assign)
    signature = {"rhs": "rhs", "jac": "jac"}
    for fn in (rhs, *outputs, *([jac] if jac else [])):
        names = [unit.states[i].name for i in fn.states] + fn.tables
        args = SIGNATURES[signature.get(fn.name, "output")].names
        _check_names([*args, *names, *(s.name for s in fn.statements if s.declare)], fn.name)

    def used(fns: list[Function | None], gimbal: bool = False) -> list[str]:
        found = trig_used(unit.prefix, fns) + ["cos"] * gimbal
        return [v for v in ("sin", "cos") if v in found]  # Fortran has no _lanes twins

    gimbal = bool(unit.methods) and not unit.quaternion
    setup_fn = Function("setup", "", "", setup, [], [])
    trig = used([setup_fn, rhs, *outputs, jac], gimbal)
    ctx = {
        "unit": unit,
        "tables": tables_text("fortran", unit.prefix, unit.macro, unit.torque_tables),
        "trig": trig_text("fortran", unit.prefix, unit.macro, trig),
        "trig_names": trig,
        "ode_trig_names": used([jac, *([rhs] if unit.jet is not None else [])], gimbal),
        "setup": setup,
        "rhs": rhs,
        "outputs": outputs,
        "jac": jac,
        "methods": unit.methods,
        "ir": fortran_text(
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
        "checks": printed("fortran", unit.macro, unit.checks),
        "code_names": {c.value: c.name for c in abi.SETUP_CODES},
        "check_locals": _declared(check_locals),
        "signature_of": signature_of,
    }
    out = {
        f"{unit.prefix}.f90": render("fortran/module.f90.jinja", **ctx),
        f"{unit.prefix}_f.h": render("fortran/bindings.h.jinja", **ctx),
    }
    if unit.methods:
        out[f"{unit.prefix}_ode.f90"] = render("fortran/ode.f90.jinja", **ctx)
    return out
