"""The Jinja environment: templates lay out whole files, printers fill them."""

from __future__ import annotations

import re
import textwrap
from functools import cache
from importlib.resources import files
from typing import Any

import jinja2

from gyrogen.abi import Signature
from gyrogen.codegen.ir.printer import wrap
from gyrogen.methods import literal, signature_of


def c_double(value: float) -> str:
    """A double as C writes it: the shortest text that reads back exactly."""
    return repr(float(value))


def f_double(value: float) -> str:
    """The same for Fortran, with the c_double kind."""
    return f"{float(value)!r}_c_double"


COMMENT_WIDTH = 72
"""Columns of scene text in a generated comment (the description)."""


def comment_lines(text: str) -> list[str]:
    """Scene text as comment lines: tabs expanded, each paragraph wrapped
    (long words broken, so no line outgrows Fortran's 132 columns)."""
    lines: list[str] = []
    for para in text.expandtabs(4).split("\n"):
        wrapped = textwrap.wrap(para, COMMENT_WIDTH, break_on_hyphens=False)
        lines += wrapped or [""]
    while lines and not lines[-1]:
        lines.pop()
    return lines or ["(no description)"]


def sentence(text: str) -> str:
    """text ending in a full stop (one: a description that ends in ".",
    "!" or "?" gets none added; an empty one stays empty)."""
    text = text.rstrip()
    return text if not text or text.endswith((".", "!", "?")) else text + "."


def _unbroken(text: str, pattern: str, fix: str) -> str:
    while re.search(pattern, text):
        text = re.sub(pattern, fix, text)
    return text


def c_comment(text: str) -> str:
    """Text for a /* */ comment, continued with " * ": no "*/" that would end
    it, no "/*" (-Wcomment) and no "??" (a trigraph, -std=c99)."""
    out = []
    for line in comment_lines(text):
        for pattern, fix in (("\\*/", "* /"), ("/\\*", "/ *"), ("\\?\\?", "? ?")):
            line = _unbroken(line, pattern, fix)
        out.append(line)
    return "\n * ".join(out).replace(" * \n", " *\n")


def f_comment(text: str) -> str:
    """Text for Fortran ! comments (anything goes after the !)."""
    return "\n! ".join(comment_lines(text)).replace("! \n", "!\n")


def hash_comment(text: str) -> str:
    """Text for # comments (CMake, make): a line each."""
    return "\n# ".join(comment_lines(text)).replace("# \n", "#\n")


def c_string(text: str) -> str:
    """A C string literal: backslashes and quotes escaped, no "??" (a trigraph)."""
    body = text.replace("\\", "\\\\").replace('"', '\\"')
    return '"' + _unbroken(body, "\\?\\?", '?" "?') + '"'


def f_string(text: str) -> str:
    """A Fortran character literal (a quote doubled)."""
    return '"' + text.replace('"', '""') + '"'


def xml_attr(text: str) -> str:
    """A quoted XML attribute value: markup escaped, and newlines and tabs as
    character references (a parser would turn them into spaces)."""
    escaped = text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    for char, reference in (('"', "&quot;"), ("\n", "&#10;"), ("\t", "&#9;"), ("\r", "&#13;")):
        escaped = escaped.replace(char, reference)
    return f'"{escaped}"'


PROTOTYPE_WIDTH = 90
"""Columns of a generated C declaration before it wraps."""


def c_prototype(signature: Signature, name: str, prefix: str) -> str:
    """A declaration of name with the signature, wrapped after a comma with
    an indent of 8 where it outgrows PROTOTYPE_WIDTH."""
    lines = [""]
    for piece in re.split(r"(?<=,) ", signature.c(name, prefix) + ";"):
        if lines[-1] and len(lines[-1]) + 1 + len(piece) > PROTOTYPE_WIDTH:
            lines.append(" " * 7)
        lines[-1] += (" " if lines[-1] else "") + piece
    return "\n".join(lines)


def c_definition(signature: Signature, name: str, prefix: str) -> str:
    """The head of a definition of name with the signature, continued under
    its parenthesis as the printers continue a function's head."""
    head = signature.c(name, prefix)
    return "\n".join(wrap(head, " " * (head.index("(") + 1)))


def c_wrap(line: str, indent: int) -> str:
    """A line of C (its own indent included) continued on lines indented by
    indent, as the printers continue a statement."""
    return "\n".join(wrap(line, " " * indent))


def f_wrap(line: str, indent: int) -> str:
    """The same for Fortran: each continued line ends in " &"."""
    return "\n".join(wrap(line, " " * indent, continuation=" &"))


@cache
def environment() -> jinja2.Environment:
    root = files("gyrogen") / "templates"
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(root)),
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
        autoescape=False,
    )
    env.filters.update(
        c_literal=literal,
        f_literal=lambda v: f"{literal(v)}_c_double",
        c_double=c_double,
        f_double=f_double,
        c_comment=c_comment,
        f_comment=f_comment,
        sentence=sentence,
        hash_comment=hash_comment,
        c_string=c_string,
        f_string=f_string,
        xml_attr=xml_attr,
        c_wrap=c_wrap,
        f_wrap=f_wrap,
    )
    env.globals.update(
        c_prototype=c_prototype, c_definition=c_definition, signature_of=signature_of
    )
    return env


def render(template: str, **context: Any) -> str:
    """Render one template; the template's own name goes into its preamble."""
    return environment().get_template(template).render(template_name=template, **context)
