"""MkDocs hook: reference tables generated from the code at build time.

A page holds a marker such as ``<!-- gyrogen:scene-schema -->`` and this hook
replaces it with markdown rendered from the registries that the generator
itself reads, so the reference cannot drift from the code:

- ``scene-schema``: every key of a scene file, from the pydantic models in
  gyrogen.scene (type, default and the field's docstring);
- ``scenes``: the built-in scenes (gyrogen/scenes/*.toml);
- ``names``: the states' and parameters' units and meanings (gyrogen.abi.UNITS,
  abi_rotors.ROTOR_KEYS);
- ``setup-codes``, ``ode-codes``, ``stats``, ``signatures``: the C interface
  (gyrogen.abi);
- ``methods``: the compiled integrators (gyrogen.methods.METHODS);
- ``limits``: the thresholds the validator and the generated code apply;
- ``benchmarks``: the records in docs/benchmarks/*.json (tools/docs_bench.py).
"""

from __future__ import annotations

import ast
import importlib.util
import inspect
import itertools
import re
import sys
import textwrap
import types
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Any

_ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(_ROOT / "generator"))  # document this checkout's sources

from pydantic import BaseModel  # noqa: E402
from pydantic_core import PydanticUndefined  # noqa: E402

_MARKER = re.compile(r"<!-- gyrogen:([a-z-]+) -->")


def _attribute_docs(body: list[ast.stmt]) -> dict[str, str]:
    """The attribute docstrings of a class or module body: a string right after
    `name: type` or `NAME = value`."""
    docs: dict[str, str] = {}
    for stmt, after in itertools.pairwise(body):
        target = stmt.target if isinstance(stmt, ast.AnnAssign) else (
            stmt.targets[0] if isinstance(stmt, ast.Assign) else None
        )  # fmt: skip
        if (
            isinstance(target, ast.Name)
            and isinstance(after, ast.Expr)
            and isinstance(after.value, ast.Constant)
            and isinstance(after.value.value, str)
        ):
            docs[target.id] = _escape(" ".join(after.value.value.split()))
    return docs


def _docstrings(cls: type) -> dict[str, str]:
    body = ast.parse(textwrap.dedent(inspect.getsource(cls))).body[0]
    assert isinstance(body, ast.ClassDef)
    return _attribute_docs(body.body)


def _escape(text: str) -> str:
    """Code's text inside a markdown table: <prefix> shown, not read as a tag."""
    return text.replace("<", "&lt;").replace(">", "&gt;").replace("|", "\\|")


_SCALARS = {float: "number", int: "integer", str: "string", bool: "boolean", type(None): ""}


def _type(ann: Any) -> str:
    """A TOML reader's name for an annotation."""
    origin, args = typing.get_origin(ann), typing.get_args(ann)
    if origin is typing.Annotated:
        return _type(args[0])
    if origin is typing.Literal:
        return " or ".join(f'`"{a}"`' for a in args)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(t for t in (_type(a) for a in args) if t)
    if origin is list:
        return f"array of {_type(args[0])}"
    if origin is tuple:
        return "[" + ", ".join(_type(a) for a in args) + "]"
    if origin is dict:
        return f"table of {_type(args[1])}"
    if inspect.isclass(ann) and issubclass(ann, BaseModel):
        return "table"
    return _SCALARS.get(ann, getattr(ann, "__name__", str(ann)))


def _default(field: Any) -> str:
    if field.default_factory is not None:
        value = field.default_factory()
    elif field.default is PydanticUndefined:
        return "required"
    else:
        value = field.default
    if isinstance(value, BaseModel):
        return "see below"
    if value is None:
        return "none"
    if isinstance(value, bool):
        return f"`{str(value).lower()}`"
    if isinstance(value, str):
        return f'`"{value}"`'
    if isinstance(value, list | tuple):
        return "`[" + ", ".join(f'"{v}"' if isinstance(v, str) else repr(v) for v in value) + "]`"
    if isinstance(value, dict):
        return "`{}`" if not value else f"`{value}`"
    return f"`{value!r}`"


def _model_table(model: type[BaseModel], prefix: str) -> str:
    docs = _docstrings(model)
    rows = ["| key | type | default | meaning |", "|---|---|---|---|"]
    for name, field in model.model_fields.items():
        doc = docs.get(name, "")
        rows.append(f"| `{prefix}{name}` | {_type(field.annotation)} | {_default(field)} | {doc} |")
    return "\n".join(rows)


def scene_schema() -> str:
    from gyrogen.scene import Effects, Outputs, Scene, Simulate
    from gyrogen.scene.events import Event
    from gyrogen.scene.rotors import Gimbal, Rotor

    parts = [
        ("Top level", Scene, ""),
        ("`[effects]`", Effects, ""),
        ("`[outputs]`", Outputs, ""),
        ("`[simulate]`", Simulate, ""),
        ("`[[rotors]]` (one table per wheel of a cluster)", Rotor, ""),
        ("`[rotors.gimbal]` (a rotor on a gimbal: a control-moment gyro)", Gimbal, "gimbal."),
        ("`[[events]]` (one table per event)", Event, ""),
    ]
    out = []
    for title, model, prefix in parts:
        out += [f"### {title}", "", _model_table(model, prefix), ""]
    return "\n".join(out)


def scenes() -> str:
    from gyrogen.scene import builtin_names, load

    rows = ["| scene | what | attitude | states | runtime parameters | integrators |",
            "|---|---|---|---|---|---|"]  # fmt: skip
    for name in builtin_names():
        s = load(name)
        runtime = ", ".join(s.runtime) if len(s.runtime) <= 6 else f"{len(s.runtime)} of them"
        rows.append(
            f"| `{name}` | {' '.join(s.description.split())} | {s.attitude} | {len(s.states)} "
            f"| {runtime or '-'} | {', '.join(s.integrators)} |"
        )
    return "\n".join(rows)


def names() -> str:
    from gyrogen.abi import CONTROLLER_PARAMETERS, PARAMETERS, STATES, unit_and_doc
    from gyrogen.abi_rotors import CLUSTER_CARRIER, ON_GIMBAL, ROTOR_KEYS

    def table(keys: typing.Iterable[str]) -> list[str]:
        rows = ["| name | unit | meaning |", "|---|---|---|"]
        rows += [f"| `{k}` | {unit_and_doc(k)[0]} | {_escape(unit_and_doc(k)[1])} |" for k in keys]
        return rows

    quat = ("e0", "e1", "e2", "e3")
    out = [
        "### States",
        "",
        "In `x[]` order; a quaternion scene has `e0..e3` in place of "
        "`q1..q3`, a scene without translation or rotor angle leaves those out.",
        "",
    ]
    out += [*table(STATES[:3] + quat + STATES[3:]), "", "### Parameters (single rotor)", ""]
    out += table(PARAMETERS + CONTROLLER_PARAMETERS)
    out += ["", "### Parameters (cluster)", "", "The carrier's keys:", ""]
    out += table(CLUSTER_CARRIER)
    out += [
        "",
        "Rotor *k*'s keys, named `<key>_<k>` in `p[]` and in the code:",
        "",
        "| key | unit | meaning |",
        "|---|---|---|",
    ]
    out += [f"| `{k}` | {u} | {d.format(k='k')} |" for k, (u, d) in ROTOR_KEYS.items()]
    out += [
        "",
        "On a rotor on a gimbal these keys mean:",
        "",
        "| key | unit | meaning |",
        "|---|---|---|",
    ]
    out += [f"| `{k}` | {u} | {d.format(k='k')} |" for k, (u, d) in ON_GIMBAL.items()]
    return "\n".join(out)  # fmt: skip


def _codes(codes: typing.Iterable[Any], macro: str) -> str:
    rows = ["| code | macro | meaning |", "|---|---|---|"]
    for c in codes:
        rows.append(f"| {c.value} | `{macro}_{c.name}` | {_escape(c.message)} |")
    return "\n".join(rows)


def setup_codes() -> str:
    from gyrogen.abi import SETUP_CODES

    return _codes(SETUP_CODES, "<PREFIX>")


def ode_codes() -> str:
    from gyrogen.abi import ODE_CODES

    return _codes(ODE_CODES, "<PREFIX>")


def stats() -> str:
    from gyrogen.abi import STATS_FIELDS

    rows = ["| field | C type | meaning |", "|---|---|---|"]
    for f in STATS_FIELDS:
        rows.append(f"| `{f.name}` | `{f.ctype}` | {_escape(f.doc.format(prefix='<prefix>'))} |")
    return "\n".join(rows)


def signatures() -> str:
    from gyrogen.abi import SIGNATURES

    names = {
        "setup": "<prefix>_setup",
        "rhs": "<prefix>_rhs",
        "output": "<prefix>_<output>",
        "jac": "<prefix>_jac",
        "linear": "<prefix>_linear",
        "strerror": "<prefix>_strerror",
        "fixed_step": "<prefix>_<method>",
        "fixed_step_batch": "<prefix>_<method>_batch",
        "adaptive": "<prefix>_<method>",
        "adaptive_batch": "<prefix>_<method>_batch",
        "grid": "<prefix>_<method>_grid",
        "grid_batch": "<prefix>_<method>_grid_batch",
        "grid_events": "<prefix>_<method>_events",
        "grid_events_batch": "<prefix>_<method>_events_batch",
    }
    out = []
    for key, sig in SIGNATURES.items():
        lengths = ", ".join(f"`{a.name}`: {' x '.join(a.length)}" for a in sig.args if a.length)
        out += [f"**{key}**", "", "```c", sig.c(names[key], "<prefix>") + ";", "```", ""]
        if lengths:
            out += [f"Element counts: {lengths}.", ""]
    return "\n".join(out)


def methods_table() -> str:
    from gyrogen.methods import EXPLICIT_CHOICE, METHODS, STIFF_CHOICE

    rows = ["| method | what it is | kind | batch over SIMD lanes |", "|---|---|---|---|"]
    for m in METHODS.values():
        kind = (
            "fixed step" if m.fixed_step else "implicit, adaptive" if m.implicit else
            "explicit, adaptive"
        )  # fmt: skip
        lanes = "where the scene asks (`lanes`)" if m.lanes_asked else "yes" if m.lanes else "no"
        rows.append(f"| `{m.name}` | {_escape(m.doc)} | {kind} | {lanes} |")
    rows += ["", f"Stiff problems, best first: {', '.join(STIFF_CHOICE)}. "
             f"Other problems, best first: {', '.join(EXPLICIT_CHOICE)}."]  # fmt: skip
    return "\n".join(rows)


def limits() -> str:
    from gyrogen import abi, limits

    rows = ["| name | value | where it applies |", "|---|---|---|"]
    for mod in (abi, limits):
        docs = _attribute_docs(ast.parse(inspect.getsource(mod)).body)
        for name, value in vars(mod).items():
            number = isinstance(value, int | float) and not isinstance(value, bool)
            if name.isupper() and number and name in docs:
                rows.append(f"| `{mod.__name__}.{name}` | `{value:g}` | {docs[name]} |")
    return "\n".join(rows)


def benchmarks() -> str:
    spec = importlib.util.spec_from_file_location("docs_bench", _ROOT / "tools" / "docs_bench.py")
    assert spec is not None and spec.loader is not None
    docs_bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(docs_bench)
    return str(docs_bench.page(_ROOT / "docs" / "benchmarks"))


_RENDER: dict[str, Callable[[], str]] = {
    "scene-schema": scene_schema,
    "names": names,
    "scenes": scenes,
    "setup-codes": setup_codes,
    "ode-codes": ode_codes,
    "stats": stats,
    "signatures": signatures,
    "methods": methods_table,
    "limits": limits,
    "benchmarks": benchmarks,
}


def on_config(config: Any, **_: Any) -> Any:
    """Ship nothing fetched from elsewhere: Material's offline plugin adds a
    script from a CDN (a shim for search from file:// pages); drop it. Search
    then works where the site is served over HTTP."""
    extra = config.extra
    extra["polyfills"] = [u for u in extra.get("polyfills", []) if "://" not in u]
    return config


def on_page_markdown(markdown: str, **_: Any) -> str:
    def render(m: re.Match[str]) -> str:
        if m[1] not in _RENDER:
            raise KeyError(f"no generated section {m[1]!r} (known: {', '.join(_RENDER)})")
        return _RENDER[m[1]]()

    return _MARKER.sub(render, markdown)
