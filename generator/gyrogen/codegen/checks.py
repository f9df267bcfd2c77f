"""The setup checks (gyrogen.setup_checks) as C and Fortran text.

A printer per language turns the checks' small expressions into code: the
same precedence rules for both, the languages' own spelling of numbers,
squares and the maximum. The templates lay the checks out.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

from gyrogen.abi import TRIANGLE_SLACK
from gyrogen.codegen.render import c_double, f_double
from gyrogen.setup_checks import CHECKS, Call, Check, Expr, Num, Op, Sym, symbols

Language = Literal["c", "fortran"]
_PRECEDENCE = {"+": 1, "-": 1, "*": 2}
_ATOM = 4
_UNARY_MINUS = {"c": 3, "fortran": 1}
"""A negative number's precedence: C's unary minus binds tighter than a
product; Fortran's is that of a sum (x - -4.0 and x*-4.0 are errors, and
-4.0**2 is -(4.0**2)), so there it is parenthesized as an operand."""
FORTRAN_WRAP = 100
"""A Fortran condition continues on a new line before it would pass this column."""


@dataclass(frozen=True)
class Printed:
    """One check, as a template lays it out."""

    code: int
    kind: str
    condition: str
    """True when the check fails (C: the whole if condition; Fortran: the same)."""
    locals: tuple[tuple[str, str], ...]
    comment: tuple[str, ...]
    late: bool
    """Made after the constants: it reads their condition number, or all of them."""


class Printer:
    def __init__(self, language: Language, macro: str) -> None:
        self.language = language
        self.macro = macro
        self.number: Callable[[float], str] = c_double if language == "c" else f_double

    def __call__(self, e: Expr, parent: int = 0, right: bool = False) -> str:
        """e as an operand of an operator of precedence parent (0: none);
        right: not its first operand, so that equal precedence is grouped
        as written (a - (b - c), x + (-4.0)), never reassociated."""
        if isinstance(e, Sym):
            return self._symbol(e.name)
        if isinstance(e, Call):
            return self._call(e)
        if isinstance(e, Num):
            text = self.number(e.value)
            prec = _ATOM if e.value >= 0 else _UNARY_MINUS[self.language]
        else:
            assert isinstance(e, Op)
            prec = _PRECEDENCE[e.op]
            glue = "*" if e.op == "*" else f" {e.op} "
            text = glue.join(self(a, prec, i > 0) for i, a in enumerate(e.args))
        return f"({text})" if prec < parent or (right and prec == parent) else text

    def _symbol(self, name: str) -> str:
        if name == "cond":
            return f"c[{self.macro}_COND]" if self.language == "c" else f"c({self.macro}_COND)"
        return name

    def _call(self, e: Call) -> str:
        if e.fn == "square":
            base = self(e.args[0], 3)
            return f"{base}*{base}" if self.language == "c" else f"{base}**2"
        name = {"sqrt": "sqrt", "max": "fmax" if self.language == "c" else "max"}[e.fn]
        return f"{name}({', '.join(self(a) for a in e.args)})"

    def condition(self, kind: str, exprs: tuple[Expr, ...]) -> str:
        """The text that is true when the check fails (for 'constants' in C,
        where it is a loop over c, the template's)."""
        if kind == "constants":
            return "" if self.language == "c" else ".not. all(ieee_is_finite(c))"
        if kind == "positive":
            zero = self.number(0.0)
            if self.language == "c":
                return " || ".join(f"!({self(e)} > {zero})" for e in exprs)
            return f".not. ({self._wrapped([f'{self(e)} > {zero}' for e in exprs])})"
        a, b = exprs
        if kind == "slack":
            return f"{self(a)} > {self(Num(TRIANGLE_SLACK) * b)}"
        negate = "!" if self.language == "c" else ".not. "
        return f"{negate}({self(a)} <= {self(b)})"

    def continued(self, head: str, text: str, tail: str = "") -> str:
        """Fortran: text, placed after head and before tail on a line,
        continued with & at a space or a product's * before FORTRAN_WRAP
        (folded values print long: a cluster's minors pass 132 columns). C:
        text as it is."""
        if self.language == "c":
            return text
        pad = " " * (len(head) - len(head.lstrip()) + 4)
        lines, line = [], head + text
        while len(line + tail) > FORTRAN_WRAP:
            spaces = line.rfind(" ", len(pad) + 8, FORTRAN_WRAP - 2)
            stars = [i for i in range(len(pad) + 8, FORTRAN_WRAP - 2) if _product(line, i)]
            cut = max(spaces, stars[-1] + 1 if stars else -1)
            if cut < 0:
                break
            lines.append(line[:cut].rstrip() + " &")
            line = pad + line[cut:].lstrip()
        return "\n".join([*lines, line]).removeprefix(head)

    def _wrapped(self, parts: list[str]) -> str:
        """parts joined by .and., continued with & before FORTRAN_WRAP."""
        lines, line = [], "    if (.not. (" + parts[0]
        for part in parts[1:]:
            if len(line) + len(part) + len(" .and. )) then") > FORTRAN_WRAP:
                lines.append(line + " &")
                line = " " * 15 + ".and. " + part
            else:
                line += " .and. " + part
        lines.append(line)
        return "\n".join(lines).removeprefix("    if (.not. (")


def _product(line: str, i: int) -> bool:
    """line[i] is a product's * (not half of a power's **)."""
    return line[i] == "*" and line[i - 1] != "*" and line[i + 1] != "*"


def condition(p: Printer, c: Check) -> str:
    """c's condition as the template places it: in `if (...) then`."""
    text = p.condition(c.kind, c.exprs)
    return text if c.kind == "positive" else p.continued("    if (", text, ") then")


def printed(language: Language, macro: str, checks: Sequence[Check] = CHECKS) -> list[Printed]:
    """Every check of checks but 'finite' (the templates loop over p for
    that one); a rotor cluster's are setup_checks.cluster_checks."""
    p = Printer(language, macro)
    return [
        Printed(
            c.code,
            c.kind,
            condition(p, c),
            tuple((name, p.continued(f"    {name} = ", p(e))) for name, e in c.locals),
            c.comment,
            c.kind == "constants" or any("cond" in symbols(e) for e in c.exprs),
        )
        for c in checks
        if c.kind != "finite"
    ]
