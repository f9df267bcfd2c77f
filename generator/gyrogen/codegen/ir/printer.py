"""What every target's printer shares: expressions by precedence, statements
laid out by indentation, functions from their declarations.

A printer never reorders: a right operand of equal precedence is always
parenthesized, so a - (b + c) and a + (b + c) stay as the description has
them and every target performs the same roundings.
"""

from __future__ import annotations

import textwrap
from typing import ClassVar

from gyrogen.codegen.ir.nodes import (
    Assign,
    At,
    Bin,
    Bits,
    Bool,
    Break,
    Call,
    Comment,
    Const,
    Continue,
    Decl,
    E,
    Fn,
    For,
    Func,
    If,
    Int,
    Loop,
    Num,
    Ref,
    Return,
    Row,
    S,
    Sel,
    Un,
    Unused,
    Var,
    Word,
)
from gyrogen.methods import literal

PRECEDENCE = {"or": 1, "and": 2, "==": 3, "!=": 3, "<": 4, "<=": 4, ">": 4, ">=": 4}
PRECEDENCE |= {"+": 5, "-": 5, "*": 6, "/": 6}
WORD_OPS = (">>", "<<", "&", "|")
PRECEDENCE |= dict.fromkeys(WORD_OPS, 3)
"""An operation on words: its operands are always parenthesized (no reliance on
C's ranks for them, which -Wparentheses questions), and it is parenthesized
within anything but a comparison's equal."""
ATOM = 9
WRAP = 100
"""A statement continues on a new line before it would pass this column."""


def wrap(text: str, cont: str, tail: str = "", continuation: str = "") -> list[str]:
    """A line of code continued on new lines that start with cont before it
    would pass WRAP, after a comma where one is in reach, else after a space,
    else after an opening parenthesis (a run of them: Fortran's grouping of a
    long sum); each continued line ends with the language's continuation
    (Fortran's " &")."""
    lines = []
    while len(text) > WRAP:
        start = len(cont) + 8
        cut = text.rfind(", ", start, WRAP - 2) + 1 or text.rfind(" ", start, WRAP - 2)
        rest = cut + 1  # the space at cut is dropped
        if cut < 0:
            cut = rest = text.rfind("(", start, WRAP - 2) + 1
            if cut <= 0:
                break
        lines.append(text[:cut] + continuation)
        text = cont + text[rest:]
    return [*lines, text + tail]


DOC_WIDTH = 76


def doc_lines(doc: tuple[str, ...]) -> list[str]:
    """A function's comment lines, each wrapped to DOC_WIDTH columns."""
    return [part for line in doc for part in textwrap.wrap(line, DOC_WIDTH) or [""]]


def _op(e: E, op: str) -> bool:
    return isinstance(e, Bin) and e.op == op


class Printer:
    """A target: subclasses spell the atoms, operators and statements."""

    indent = "    "
    ops: ClassVar[dict[str, str]] = {}
    spellings: ClassVar[dict[str, str]] = {}
    """The IR's functions (Fn) this target calls by another name: its
    intrinsics' names, or a definition of gyrogen.codegen.integrators.intrinsics."""
    unary_minus = 7
    """The precedence of -x (Fortran: that of a sum; C: above a product)."""

    def __init__(self, prefix: str, macro: str, decls: dict[str, Decl]) -> None:
        self.prefix = prefix
        self.macro = macro
        self.decls = decls

    def with_decls(self, func: Func) -> Printer:
        """A printer for func's body: its parameters (and locals) by name."""
        return type(self)(self.prefix, self.macro, {d.name: d for d in func.params})

    # expressions

    def expr(self, e: E, parent: int = 0, right: bool = False) -> str:
        text, prec = self._expr(e)
        need = prec < parent or (right and prec == parent and prec < ATOM)
        return f"({text})" if need else text

    def _expr(self, e: E) -> tuple[str, int]:
        if isinstance(e, Num):
            return self.number(e.value), ATOM if e.value >= 0 else self.unary_minus
        if isinstance(e, Int):
            return str(e.value), ATOM if e.value >= 0 else self.unary_minus
        if isinstance(e, Bool):
            return self.boolean(e.value), ATOM
        if isinstance(e, Word):
            return self.word(e.value), ATOM
        if isinstance(e, Var):
            return self.var(e.name)
        if isinstance(e, At):
            return self.element(e.name, tuple(self.expr(i) for i in e.index)), ATOM
        if isinstance(e, Row):
            return self.row(e.name, self.expr(e.row)), ATOM
        if isinstance(e, Ref):
            return self.ref(e.name), ATOM
        if isinstance(e, Const):
            return self.const(e.name), ATOM
        if isinstance(e, Bin):
            return self.binary(e), PRECEDENCE[e.op]
        if isinstance(e, Un):
            if e.op == "-":
                return "-" + self.expr(e.a, self.unary_minus + 1), self.unary_minus
            return self.negate(self.expr(e.a, ATOM)), ATOM
        if isinstance(e, Fn):
            return self.call(e.name, [self.expr(a) for a in e.args], e.args), ATOM
        assert isinstance(e, Sel), e
        return self.select(e), 0

    def binary(self, e: Bin) -> str:
        prec = PRECEDENCE[e.op]
        if e.op in ("or", "and"):  # a chain; an and inside an or in parentheses (-Wparentheses)
            left, right = (
                self.expr(a, ATOM if _op(a, "and" if e.op == "or" else "or") else prec)
                for a in (e.a, e.b)
            )
            if _op(e.b, e.op):
                right = f"({right})"
        elif e.op in WORD_OPS:
            left, right = self.expr(e.a, ATOM), self.expr(e.b, ATOM)
        else:
            left = self.expr(e.a, prec + self.grouped)
            right = self.expr(e.b, prec, right=True)
        return f"{left} {self.ops.get(e.op, e.op)} {right}"

    restrict = False
    """Pointer parameters that never overlap (Func.restrict; C says so)."""
    public = False
    """Printing a public function (Func.public)."""

    grouped = 0
    """1: a left operand of equal precedence in parentheses too, (a + b) - c.
    Fortran lets a compiler evaluate any mathematically equivalent form but
    never across parentheses: without them, x + K - K (the reduction's
    rounding to an integer) could become x."""

    def number(self, value: float) -> str:
        return literal(value)

    def table(self, values: tuple[int | float, ...]) -> str:
        """A constant table's entries (Decl.values), in the target's literals."""
        return ", ".join(self.number(v) if isinstance(v, float) else str(v) for v in values)

    def const(self, name: str) -> str:
        raise NotImplementedError

    def word(self, value: int) -> str:
        raise NotImplementedError

    def var(self, name: str) -> tuple[str, int]:
        raise NotImplementedError

    def element(self, name: str, index: tuple[str, ...]) -> str:
        raise NotImplementedError

    def row(self, name: str, j: str) -> str:
        raise NotImplementedError

    def ref(self, name: str) -> str:
        raise NotImplementedError

    def boolean(self, value: bool) -> str:
        raise NotImplementedError

    def negate(self, text: str) -> str:
        raise NotImplementedError

    def call(self, name: str, args: list[str], nodes: tuple[E, ...]) -> str:
        raise NotImplementedError

    def select(self, e: Sel) -> str:
        raise NotImplementedError

    # statements

    def block(self, body: tuple[S, ...], depth: int) -> list[str]:
        lines: list[str] = []
        for s in body:
            lines += self.statement(s, depth)
        return lines

    syntax: ClassVar[dict[str, str]] = {}
    """The language's statements: assign, comment, call, return, return_value
    (lines split by newlines), if, else, end_if, loop, end_loop, continue,
    break, for, end_for, vector, simd, bits, each with {fields} to fill."""

    def statement(self, s: S, depth: int) -> list[str]:
        pad, say = self.indent * depth, self.syntax
        if isinstance(s, Assign):
            text = say["assign"].format(target=self.expr(s.target), value=self.expr(s.value))
            return self.line(depth, text, s.note)
        if isinstance(s, Comment):
            return [""] * s.blank + [pad + say["comment"].format(text=s.text)]
        if isinstance(s, Call):
            name = f"{self.prefix}_{s.name}" if s.name in ("rhs", "jac", "events") else s.name
            return self.line(depth, say["call"].format(name=name, args=self.call_args(s)), s.note)
        if isinstance(s, Return):
            if s.value is None:
                return self.line(depth, say["return"].format(), s.note)
            first, *rest = say["return_value"].format(value=self.expr(s.value)).split("\n")
            return [*self.line(depth, first, s.note), *(pad + r for r in rest)]
        if isinstance(s, If):
            more = pad + self.indent * 2
            out = self.wrap(pad + say["if"].format(cond=self.expr(s.cond)), more, "")
            out += self.block(s.then, depth + 1)
            if s.orelse:
                out += [pad + say["else"].format(), *self.block(s.orelse, depth + 1)]
            return [*out, pad + say["end_if"].format()]
        if isinstance(s, Loop):
            return [
                pad + say["loop"].format(),
                *self.block(s.body, depth + 1),
                pad + say["end_loop"].format(),
            ]
        if isinstance(s, (Continue, Break)):
            return [pad + say["continue" if isinstance(s, Continue) else "break"].format()]
        if isinstance(s, Bits):
            return [pad + say["bits"].format(target=s.target, source=s.source)]
        if isinstance(s, Unused):
            return [pad + line for line in say["unused"].format(name=s.name).split("\n")]
        assert isinstance(s, For), s
        head = say["for"].format(v=s.var, start=self.expr(s.start), stop=self.expr(s.n, 5))
        body = [*self.scoped_locals(s, depth + 1), *self.block(s.body, depth + 1)]
        marks = [pad + say["vector"]] if s.vector else []
        marks += [pad + say["simd"].format(macro=self.macro)] if s.simd and say["simd"] else []
        return [*marks, pad + head, *body, pad + say["end_for"].format()]

    def scoped_locals(self, s: For, depth: int) -> list[str]:
        """The declarations of a loop's own locals at its top (C), or none."""
        return []

    def line(self, depth: int, text: str, note: str = "") -> list[str]:
        """One statement, continued on new lines past WRAP."""
        pad = self.indent * depth
        return self.wrap(pad + text, pad + self.indent * 2, self.note(note) if note else "")

    def wrap(self, text: str, cont: str, tail: str) -> list[str]:
        return wrap(text, cont, tail, self.continuation)

    continuation = ""

    def note(self, text: str) -> str:
        raise NotImplementedError

    def call_args(self, call: Call) -> str:
        return ", ".join(self.expr(a) for a in call.args)

    def declaration(self, d: Decl, param: bool) -> str:
        raise NotImplementedError

    def function(self, func: Func) -> str:
        raise NotImplementedError
