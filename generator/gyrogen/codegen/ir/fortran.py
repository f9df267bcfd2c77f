"""The IR as Fortran 2008 (module procedures of <prefix>_ode_mod).

Arrays are declared from 0, as the IR indexes them; k[j][i] is k(i, j). A
function's value is `res`; a return sets it and leaves. Locals get their
first values by assignment (an initializer would make them SAVE).
"""

from __future__ import annotations

from typing import ClassVar

from gyrogen.codegen.ir.c import walk
from gyrogen.codegen.ir.nodes import (
    Assign,
    Decl,
    E,
    For,
    Func,
    Sel,
    Var,
)
from gyrogen.codegen.ir.printer import ATOM, Printer, doc_lines

CONSTS = {
    "NX": "nx",
    "NC": "nc",
    "NX2": "nx * nx",
    "EPSILON": "epsilon(1.0_c_double)",
    "TINY": "tiny(1.0_c_double)",
    "HUGE": "huge(1.0_c_double)",
    "NAN": "ieee_value(1.0_c_double, ieee_quiet_nan)",
}
FTYPE = {
    "double": "real(c_double)",
    "int": "integer(c_int)",
    "long": "integer(c_long)",
    "bool": "logical",
}
RESULT = "res"
"""A function's value: its result variable (a return sets it and leaves)."""
FUNCTIONS = {"finite": "ieee_is_finite", "floor": "floor_real", "trunc": "aint"}
"""The IR's functions under Fortran names (floor_real:
gyrogen.codegen.integrators.intrinsics)."""


class FortranPrinter(Printer):
    indent = "  "
    ops: ClassVar[dict[str, str]] = {"and": ".and.", "or": ".or.", "==": "==", "!=": "/="}
    spellings = FUNCTIONS
    unary_minus = 5
    grouped = 1
    continuation = " &"

    def number(self, value: float) -> str:
        return super().number(value) + "_c_double"

    def const(self, name: str) -> str:
        return CONSTS.get(name) or f"{self.macro}_{name}"

    def var(self, name: str) -> tuple[str, int]:
        return name.replace(".", "%"), ATOM

    def element(self, name: str, index: tuple[str, ...]) -> str:
        return f"{name}({', '.join(reversed(index))})"

    def row(self, name: str, j: str) -> str:
        return f"{name}(:, {j})"

    def ref(self, name: str) -> str:
        return name

    def boolean(self, value: bool) -> str:
        return ".true." if value else ".false."

    def negate(self, text: str) -> str:
        return ".not. " + text

    def call(self, name: str, args: list[str], nodes: tuple[E, ...]) -> str:
        if name == "real":
            return f"real({args[0]}, c_double)"
        if name in ("sin", "cos"):
            return f"{self.prefix}_{name}({args[0]})"
        if name == "pow":
            return f"{self.expr(nodes[0], ATOM)}**{self.expr(nodes[1], ATOM)}"
        if name == "exponent":  # x = fraction 2^exponent, fraction in [1/2, 1)
            return f"real(exponent({args[0]}) - 1, c_double)"
        if name == "significand":
            return f"(2.0_c_double * fraction({args[0]}))"
        if name == "pow2":
            return f"scale(1.0_c_double, int({args[0]}))"
        return f"{self.spellings.get(name, name)}({', '.join(args)})"

    def select(self, e: Sel) -> str:
        return f"merge({self.expr(e.a)}, {self.expr(e.b)}, {self.expr(e.cond)})"

    def note(self, text: str) -> str:
        return f"  ! {text}"

    syntax: ClassVar[dict[str, str]] = {
        "assign": "{target} = {value}",
        "comment": "! {text}",
        "call": "call {name}({args})",
        "return": "return",
        "return_value": RESULT + " = {value}\nreturn",
        "if": "if ({cond}) then",
        "else": "else",
        "end_if": "end if",
        "loop": "do",
        "end_loop": "end do",
        "continue": "cycle",
        "break": "exit",
        "unused": ("associate (unused_{name} => {name})  ! unused in some scenes\nend associate"),
        "for": "do {v} = {start}, {stop} - 1",
        "end_for": "end do",
        "vector": "!GCC$ unroll 1",
        "simd": "",
    }

    def declaration(self, d: Decl, param: bool) -> str:
        ftype = f"type({self.prefix}_stats)" if d.type == "stats" else FTYPE[d.type]
        if d.values:
            table = self.table(d.values)
            return f"{ftype}, parameter :: {d.name}(0:{len(d.values) - 1}) = [{table}]"
        value = ", value" if param and self.public and not d.shape and d.intent == "in" else ""
        intent = f"{value}, intent({d.intent})" if param else ""
        dims = ", ".join(
            f"0:{n - 1}" if isinstance(n, int) else f"0:{self.extent(n)} - 1"
            for n in reversed(d.shape)
        )
        return f"{ftype}{intent} :: {d.name}" + (f"({dims})" if dims else "")

    def extent(self, n: str | int) -> str:
        if isinstance(n, int) or n in self.decls:
            return str(n)
        return self.const(n)

    def function(self, func: Func) -> str:
        p = self.with_decls(func)
        p.public = func.public
        names = ", ".join(d.name for d in func.params)
        kind = "subroutine" if func.returns is None else "function"
        result = "" if func.returns is None else f" result({RESULT})"
        if func.public:
            rest = func.name.removeprefix(f"{self.prefix}_")
            result += f' bind(C, name="{self.prefix}_f_{rest}")'
        pad = self.indent
        head = p.wrap(f"{pad}{kind} {func.name}({names}){result}", pad * 5, "")
        doc = [f"{pad}! {d}" for d in doc_lines(func.doc)]
        params = sorted(func.params, key=lambda d: bool(d.shape))  # extents first
        decls = [f"{pad * 2}{p.declaration(d, True)}" for d in params]
        if func.returns is not None:
            decls.append(f"{pad * 2}{FTYPE.get(func.returns, 'integer')} :: {RESULT}")
        decls += [
            line
            for d in func.locals
            for line in p.wrap(f"{pad * 2}{p.declaration(d, False)}", pad * 4, "")
        ]
        scoped = sorted({x for s in walk(func.body) if isinstance(s, For) for x in s.locals})
        decls += [f"{pad * 2}real(c_double) :: {x}" for x in scoped]
        loops = sorted({(s.var, s.type) for s in walk(func.body) if isinstance(s, For)})
        decls += [f"{pad * 2}{FTYPE[t]} :: {v}" for v, t in loops]
        inits = [
            Assign(p_var(d), d.init) for d in func.locals if d.init is not None and not d.values
        ]
        body = p.block((*inits, *func.body), 2)
        end = f"{pad}end {kind} {func.name}"
        return "\n".join([*doc, *head, *decls, "", *body, end]) + "\n"


def p_var(d: Decl) -> Var:
    return Var(d.name)
