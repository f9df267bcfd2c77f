"""Fortran 2008 backend: a printer and the module it renders."""

from __future__ import annotations

import sympy as sm
from sympy.printing.fortran import FCodePrinter

from gyrogen import abi
from gyrogen.codegen.context import Unit
from gyrogen.codegen.render import f_double, render
from gyrogen.codegen.statements import WritableNumbers, functions, jacobian, statements
from gyrogen.errors import GyrogenError
from gyrogen.methods import METHODS
from gyrogen.symbolic.hoist import constants


class FortranPrinter(WritableNumbers, FCodePrinter):
    """Fortran 2008 free form (wrapped under 132 columns) with the hoisted
    constants as c(k+1). Names are printed as they are: `_check_names`
    refuses a function whose names differ only in case, where sympy would
    mangle them silently."""

    def __init__(self, nc: int) -> None:
        super().__init__({"standard": 2008, "source_format": "free", "name_mangling": False})
        self._names = {c.name: f"c({k + 1})" for k, c in enumerate(constants(nc))}

    def _print_Symbol(self, expr: sm.Symbol) -> str:
        return self._names.get(expr.name) or str(super()._print_Symbol(expr))

    def _print_Float(self, expr: sm.Float) -> str:
        return f_double(float(expr))


def _check_names(names: list[str], where: str) -> None:
    seen: dict[str, str] = {}
    for n in names:
        other = seen.setdefault(n.lower(), n)
        if other != n:
            raise GyrogenError(f"Fortran ignores case: {other!r} and {n!r} clash in {where}")


def files(unit: Unit) -> dict[str, str]:
    printer = FortranPrinter(unit.nc)

    def assign(lhs: str, expr: sm.Expr) -> str:
        return str(printer.doprint(expr, assign_to=sm.Symbol(lhs)))

    rhs, *outputs = functions(unit, lambda a, i: f"{a}({i + 1})", assign)
    setup = statements(unit.optimized.setup, lambda k: f"c({k + 1})", assign)
    _check_names(
        ["p", "c", "status", "half_gap", "largest", *(v.name for v in unit.setup_locals)]
        + [s.name for s in setup if s.declare],
        "setup",
    )
    for fn in (rhs, *outputs):
        names = [unit.states[i].name for i in fn.states] + ["torque"] * fn.torque
        _check_names(
            ["t", "x", "c", "out", "dxdt", *names] + [s.name for s in fn.statements if s.declare],
            fn.name,
        )
    jac = jacobian(unit, lambda a, i: f"{a}({i + 1})", assign)
    if jac is not None:
        names = [unit.states[i].name for i in jac.states]
        _check_names(
            ["t", "x", "c", "J", *names] + [s.name for s in jac.statements if s.declare], "jac"
        )
    ctx = {
        "unit": unit,
        "setup": setup,
        "rhs": rhs,
        "outputs": outputs,
        "jac": jac,
        "methods": unit.methods,
        "tableaus": {name: m.tableau for name, m in METHODS.items()},
        "abi": abi,
    }
    out = {f"{unit.prefix}.f90": render("fortran/module.f90.jinja", **ctx)}
    if unit.methods:
        out[f"{unit.prefix}_ode.f90"] = render("fortran/ode.f90.jinja", **ctx)
    return out
