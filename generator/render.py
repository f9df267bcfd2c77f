"""The Jinja environment: templates lay out whole files, printers fill them."""

from __future__ import annotations

from functools import cache
from importlib.resources import files
from typing import Any

import jinja2


def c_double(value: float) -> str:
    """A double as C writes it: the shortest text that reads back exactly."""
    return repr(float(value))


def f_double(value: float) -> str:
    """The same for Fortran, with the c_double kind."""
    return f"{float(value)!r}_c_double"


@cache
def environment() -> jinja2.Environment:
    root = files("gyrogen.templates")
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(root)),
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
        autoescape=False,
    )
    env.filters.update(c_double=c_double, f_double=f_double)
    return env


def render(template: str, **context: Any) -> str:
    """Render one template; the template's own name goes into its preamble."""
    return environment().get_template(template).render(template_name=template, **context)
