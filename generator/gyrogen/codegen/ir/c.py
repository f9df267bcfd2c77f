"""The IR as C99: one trajectory (CPrinter) or SIMD lanes (LanesPrinter).

The lanes printer prints the same statements for every lane of a struct
lanes L: a per-trajectory value v is L->v[l] (an array's element x[i] is
L->x[i][l]), a branch over values becomes a selection per lane, and a call
of the rhs takes each lane's time. So a lane performs, operation for
operation, what the scalar code performs for its trajectory.
"""

from __future__ import annotations

from typing import ClassVar

from gyrogen.codegen.integrators.trig import VARIANTS
from gyrogen.codegen.ir.nodes import (
    Decl,
    E,
    Fn,
    For,
    Func,
    If,
    Loop,
    S,
    Sel,
    Var,
)
from gyrogen.codegen.ir.nodes import walk as nodes_walk
from gyrogen.codegen.ir.printer import ATOM, Printer, doc_lines

CONSTS = {"EPSILON": "DBL_EPSILON", "TINY": "DBL_MIN", "HUGE": "DBL_MAX", "NAN": "(double)NAN"}
CTYPE = {"double": "double", "int": "int", "long": "long", "bool": "int", "word": "uint64_t"}
CTYPE |= {"size": "size_t"}
FUNCTIONS = {
    "max": "dmax",
    "min": "dmin",
    "abs": "fabs",
    "exponent": "bits_exponent",
    "significand": "bits_significand",
    "pow2": "bits_pow2",
}
"""The IR's functions under C names (dmax, dmin and the bits_ ones:
gyrogen.codegen.integrators.intrinsics)."""


class CPrinter(Printer):
    ops: ClassVar[dict[str, str]] = {"and": "&&", "or": "||"}
    spellings = FUNCTIONS

    def const(self, name: str) -> str:
        if name == "NX":
            return f"{self.macro}_NX"
        if name == "NX2":
            return f"{self.macro}_NX * {self.macro}_NX"
        return CONSTS.get(name) or f"{self.macro}_{name}"

    def word(self, value: int) -> str:
        return f"0x{value:016x}ULL"

    def var(self, name: str) -> tuple[str, int]:
        if "." in name:
            struct, field = name.split(".")
            return f"{struct}->{field}", ATOM
        d = self.decls.get(name)
        if d is not None and d in self._pointers():
            return f"*{name}", 7
        return name, ATOM

    def _pointers(self) -> set[Decl]:
        return {
            d for d in self.decls.values() if not d.shape and d.intent != "in" and d.type != "stats"
        }

    def element(self, name: str, index: tuple[str, ...]) -> str:
        return name + "".join(f"[{i}]" for i in index)

    def row(self, name: str, j: str) -> str:
        return f"{name}[{j}]"

    def ref(self, name: str) -> str:
        d = self.decls.get(name)
        return name if d is not None and d in self._pointers() else f"&{name}"

    def boolean(self, value: bool) -> str:
        return "1" if value else "0"

    def negate(self, text: str) -> str:
        return "!" + text

    def call(self, name: str, args: list[str], nodes: tuple[E, ...]) -> str:
        if name == "finite":
            return f"(fabs({args[0]}) <= DBL_MAX)"
        if name in VARIANTS:
            return f"{self.prefix}_{name}({args[0]})"
        if name == "real":
            return f"(double){self.expr(nodes[0], ATOM)}"
        if name in ("long", "size"):
            return f"({CTYPE[name]}){self.expr(nodes[0], ATOM)}"
        return f"{self.spellings.get(name, name)}({', '.join(args)})"

    def select(self, e: Sel) -> str:
        return f"{self.expr(e.cond, 1)} ? {self.expr(e.a, 1)} : {self.expr(e.b, 0)}"

    def note(self, text: str) -> str:
        return f"  /* {text} */"

    syntax: ClassVar[dict[str, str]] = {
        "assign": "{target} = {value};",
        "comment": "/* {text} */",
        "call": "{name}({args});",
        "return": "return;",
        "return_value": "return {value};",
        "if": "if ({cond}) {{",
        "else": "}} else {{",
        "end_if": "}}",
        "loop": "for (;;) {{",
        "end_loop": "}}",
        "continue": "continue;",
        "break": "break;",
        "unused": "(void){name};  /* unused in some scenes */",
        "for": "for ({v} = {start}; {v} < {stop}; ++{v}) {{",
        "end_for": "}}",
        "vector": "#pragma GCC unroll 1",
        "simd": "{macro}_SIMD",
        "bits": "memcpy(&{target}, &{source}, sizeof {target});",
    }

    def scoped_locals(self, s: For, depth: int) -> list[str]:
        pad = self.indent * depth
        return self.wrap(f"{pad}double {', '.join(s.locals)};", pad * 2, "") if s.locals else []

    def declaration(self, d: Decl, param: bool) -> str:
        if d.type == "stats":
            return f"{'const ' if d.intent == 'in' else ''}{self.prefix}_stats *{d.name}"
        ctype = CTYPE[d.type]
        if d.values:
            table = self.table(d.values)
            return f"static const {ctype} {d.name}[{len(d.values)}] = {{{table}}}"
        if param:
            restrict = f"{self.macro}_RESTRICT " if self.restrict else ""
            if len(d.shape) == 2:
                return f"{ctype} (*{restrict}{d.name})[{self.extent(d.shape[1])}]"
            if d.shape or d.intent != "in":
                return f"{'const ' if d.intent == 'in' else ''}{ctype} *{restrict}{d.name}"
            return f"{ctype} {d.name}"
        dims = "".join(f"[{self.extent(n)}]" for n in d.shape)
        init = (
            ""
            if d.init is None
            else f" = {{{self.expr(d.init)}}}"
            if d.shape
            else (f" = {self.expr(d.init)}")
        )
        return f"{ctype} {d.name}{dims}{init}"

    def extent(self, n: str | int) -> str:
        return self.const(n) if isinstance(n, str) else str(n)

    lead: ClassVar[tuple[str, ...]] = ()
    """Parameters every function of the printer takes first."""

    def function(self, func: Func) -> str:
        p = self.with_decls(func)
        p.restrict = func.restrict
        ret = "void" if func.returns is None else CTYPE[func.returns]
        params = ", ".join([*self.lead, *(p.declaration(d, True) for d in func.params)])
        static = "static inline " if func.inline else "" if func.public else "static "
        head = p.wrap(
            f"{static}{ret} {func.name}({params})",
            " " * (len(static) + len(ret) + 2 + len(func.name)),
            "",
        )
        text = doc_lines(func.doc)
        doc = [f"/* {text[0]}", *(f"   {d}" for d in text[1:])] if text else []
        if doc:
            doc[-1] += " */"
        locals_ = [
            line
            for d in func.locals
            for line in p.wrap(f"{self.indent}{p.declaration(d, False)};", self.indent * 3, "")
        ]
        loops = sorted({(s.var, s.type) for s in walk(func.body) if isinstance(s, For)})
        locals_ += [f"{self.indent}{CTYPE[t]} {v};" for v, t in loops]
        body = p.block(func.body, 1)
        blank = [""] if locals_ else []
        return "\n".join([*doc, *head, "{", *locals_, *blank, *body, "}"]) + "\n"


def walk(body: tuple[S, ...]) -> list[S]:
    """Every statement, nested ones included."""
    out: list[S] = []
    for s in body:
        out.append(s)
        if isinstance(s, If):
            out += walk(s.then) + walk(s.orelse)
        elif isinstance(s, (For, Loop)):
            out += walk(s.body)
    return out


def uses(body: tuple[S, ...], name: str) -> bool:
    """The statements call function name."""
    return any(isinstance(x, Fn) and x.name == name for s in body for x in nodes_walk(s))


__all__ = ["CPrinter", "Fn", "Var", "uses", "walk"]
