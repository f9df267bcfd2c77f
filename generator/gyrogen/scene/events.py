"""A scene's events: named functions g(t, x) whose zeros the integrators
locate, written as expressions in the scene's states, parameters and
outputs.

An expression is read by a small grammar of its own, never evaluated as
Python: numbers, names, + - * / ** and parentheses, the functions in
FUNCTIONS, and angular_momentum[i] for a component of the angular
momentum. It is held as a tree of tuples (Node) that the symbolic stage
turns into sympy and the reference evaluates with numpy, each on its own.
"""

from __future__ import annotations

import ast
import math
from collections.abc import Callable, Mapping
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictBool, field_validator

from gyrogen.limits import MAX_EVENT_TEXT

FUNCTIONS = {"sin": 1, "cos": 1, "sqrt": 1, "abs": 1, "min": 2, "max": 2}
"""The functions an expression may call, by their argument count."""
OUTPUTS = ("kinetic_energy", "angular_momentum", "power")
"""The outputs an expression may read: name for one of one value, name[i]
(from 0) for a component (angular_momentum's three; a cluster's power, one
per rotor)."""
TIME = "t"

Node = tuple[Any, ...]
"""An expression: ("num", v), ("name", n), ("output", name, i), ("neg", a),
(op, a, b), ("call", f, args)."""

_OPS = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**"}


class Event(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    name: str
    """A letter, then letters, digits and underscores: the event's name in
    the log, the manifest and the sweeps' columns."""
    expr: Annotated[str, Field(max_length=MAX_EVENT_TEXT)]
    """g(t, x): the event happens where it crosses zero."""
    direction: Literal["up", "down", "any"] = "any"
    """Which crossings count: g rising through 0, falling, or either."""
    terminal: StrictBool = False
    """Stop the integration at the event (its own return code)."""

    @property
    def sign(self) -> int:
        """direction as the integrators take it: 1 up, -1 down, 0 any."""
        return {"up": 1, "down": -1, "any": 0}[self.direction]

    @field_validator("name")
    @classmethod
    def _name(cls, v: str) -> str:
        if not (v and v.isascii() and v[0].isalpha() and v.replace("_", "a").isalnum()):
            raise ValueError(f"{v!r}: a letter, then letters, digits and underscores")
        if len(v) > 40:
            raise ValueError(f"{v!r} is longer than 40 characters")
        return v

    @field_validator("expr")
    @classmethod
    def _expr(cls, v: str) -> str:
        parse(v)  # the grammar; the names are checked against the scene's
        return " ".join(v.split())  # one line wherever it is shown (a header, the manifest)


def _shown(text: str) -> str:
    return repr(text if len(text) <= 60 else text[:57] + "...")


def parse(text: str) -> Node:
    """text as a Node, or ValueError naming what is not allowed. Line breaks
    and indentation are spaces (a TOML multi-line string)."""
    text = " ".join(text.split())
    try:
        tree = ast.parse(text, mode="eval")
    except SyntaxError as exc:
        raise ValueError(f"{_shown(text)} is not an expression ({exc.msg})") from None
    except (ValueError, RecursionError, MemoryError) as exc:  # a NUL byte, a deep nest
        raise ValueError(f"{_shown(text)} is not an expression ({type(exc).__name__})") from None
    try:
        return _node(tree.body, text)
    except RecursionError:
        raise ValueError(f"{_shown(text)}: nested too deeply") from None


def _node(e: ast.expr, text: str) -> Node:
    if isinstance(e, ast.Constant) and isinstance(e.value, (int, float)):
        if isinstance(e.value, bool):  # True, False: not numbers here
            raise ValueError(f"{_shown(text)}: {e.value!r} is not a number")
        try:
            v = float(e.value)
        except OverflowError:  # an integer beyond any double
            raise ValueError(f"{_shown(text)}: an integer beyond any double") from None
        if not math.isfinite(v):
            raise ValueError(f"{_shown(text)}: the number {e.value!r} is not finite")
        return ("num", v)
    if isinstance(e, ast.Name):
        return ("name", e.id)
    if isinstance(e, ast.UnaryOp) and isinstance(e.op, (ast.USub, ast.UAdd)):
        a = _node(e.operand, text)
        return ("neg", a) if isinstance(e.op, ast.USub) else a
    if isinstance(e, ast.BinOp) and type(e.op) in _OPS:
        op = _OPS[type(e.op)]
        right = _node(e.right, text)
        if op == "**" and not _constant(right):
            shown = ast.get_source_segment(text, e.right) or "it"
            raise ValueError(f"{_shown(text)}: an exponent must be a number, not {shown!r}")
        return (op, _node(e.left, text), right)
    if isinstance(e, ast.Call) and isinstance(e.func, ast.Name) and not e.keywords:
        f = e.func.id
        if f not in FUNCTIONS:
            raise ValueError(f"{_shown(text)}: {f}() is not one of {', '.join(FUNCTIONS)}")
        if len(e.args) != FUNCTIONS[f]:
            raise ValueError(f"{_shown(text)}: {f}() takes {FUNCTIONS[f]} argument(s)")
        return ("call", f, tuple(_node(a, text) for a in e.args))
    if (
        isinstance(e, ast.Subscript)
        and isinstance(e.value, ast.Name)
        and e.value.id in OUTPUTS
        and isinstance(e.slice, ast.Constant)
        and type(e.slice.value) is int
        and e.slice.value >= 0
    ):
        return ("output", e.value.id, e.slice.value)
    shown = ast.get_source_segment(text, e) or type(e).__name__
    raise ValueError(
        f"{_shown(text)}: {shown!r} is not allowed (numbers, names, + - * / **, parentheses, "
        f"{', '.join(FUNCTIONS)}, an output's component as angular_momentum[i])"
    )


def _constant(node: Node) -> bool:
    """node reads no name, output or time: numbers alone."""
    if node[0] == "num":
        return True
    if node[0] in ("name", "output"):
        return False
    return all(_constant(a) for a in (node[2] if node[0] == "call" else node[1:]))


def check(
    events: list[Event], states: tuple[str, ...], parameters: set[str], outputs: dict[str, int]
) -> None:
    """Each event's names are the scene's (outputs: those it computes, by
    their number of values), and no two events share a name."""
    seen: set[str] = set()
    for k, ev in enumerate(events):
        if ev.name in seen:
            raise ValueError(f"events.{k}.name: {ev.name!r} names another event too")
        seen.add(ev.name)
        _check_names(parse(ev.expr), f"events.{k}.expr", {*states, *parameters, TIME}, outputs)


def _check_names(node: Node, where: str, known: set[str], outputs: dict[str, int]) -> None:
    kind = node[0]
    if kind == "num":
        return
    if kind in ("name", "output"):
        name = node[1]
        if kind == "name" and name in known:
            return
        if name not in outputs:
            why = (
                f"set outputs.{name} = true to use it"
                if name in OUTPUTS
                else "not a state, parameter or output of this scene, nor t"
            )
            raise ValueError(f"{where}: {name!r}: {why}")
        size = outputs[name]
        if kind == "name" and size != 1:
            raise ValueError(f"{where}: {name} has {size} values: write {name}[i], i from 0")
        if kind == "output" and node[2] >= size:
            raise ValueError(f"{where}: {name}[{node[2]}]: it has {size} values, from 0")
        return
    for a in node[2] if kind == "call" else node[1:]:
        _check_names(a, where, known, outputs)


def evaluate(
    node: Node,
    value: Callable[[Node], Any],
    fns: Mapping[str, Callable[..., Any]],
    number: Callable[[float], Any] = float,
) -> Any:
    """node with value(leaf) for each ("name", n) and ("output", n, i) leaf,
    number(v) for each number and fns for the functions (numpy's, sympy's)."""
    kind = node[0]
    if kind == "num":
        return number(node[1])
    if kind in ("name", "output"):
        return value(node)
    if kind == "neg":
        return -evaluate(node[1], value, fns, number)
    if kind == "call":
        args = [evaluate(a, value, fns, number) for a in node[2]]
        return fns[node[1]](*args)
    a = evaluate(node[1], value, fns, number)
    b = evaluate(node[2], value, fns, number)
    if kind == "+":
        return a + b
    if kind == "-":
        return a - b
    if kind == "*":
        return a * b
    if kind == "/":
        return a / b
    return a**b
