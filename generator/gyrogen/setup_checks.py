"""The checks <prefix>_setup makes on its parameters, declared once.

Each check is data: its return code (gyrogen.abi.SETUP_CODES), its
condition in a small expression language, and the message the scene
validator gives. codegen prints the conditions into C and Fortran (as the
headers document them), and the scene validator evaluates them in Python on
the values a scene folds, with the generated code's arithmetic: an overflow
is an infinity, a comparison with NaN is false. The numpy oracle keeps its
own mirror of them (oracle/sampling.setup_code), on purpose.

The language has what the checks need and no more: parameter names, numbers,
sums, differences, products, squares, a square root and a maximum.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Literal

from gyrogen import physics
from gyrogen.abi import CONTROLLER_PARAMETERS, MAX_CONDITION, PARAMETERS, TRIANGLE_SLACK
from gyrogen.physics import LUMPED_FROM


@dataclass(frozen=True)
class Expr:
    """A node; the operators build sums, differences and products."""

    def __add__(self, other: Expr) -> Expr:
        return Op("+", (self, other))

    def __sub__(self, other: Expr) -> Expr:
        return Op("-", (self, other))

    def __mul__(self, other: Expr) -> Expr:
        return Op("*", (self, other))

    def __rmul__(self, other: float) -> Expr:
        return Op("*", (Num(other), self))


@dataclass(frozen=True)
class Sym(Expr):
    """A parameter, a local of the check, or 'cond' (setup's condition number)."""

    name: str


@dataclass(frozen=True)
class Num(Expr):
    value: float


@dataclass(frozen=True)
class Op(Expr):
    """+ and * of any arity (flattened as written), - of two."""

    op: Literal["+", "-", "*"]
    args: tuple[Expr, ...]


@dataclass(frozen=True)
class Call(Expr):
    """square, sqrt or max."""

    fn: Literal["square", "sqrt", "max"]
    args: tuple[Expr, ...]


def add(*terms: Expr) -> Expr:
    return Op("+", terms)


def square(x: Expr) -> Expr:
    return Call("square", (x,))


def sqrt(x: Expr) -> Expr:
    return Call("sqrt", (x,))


def maximum(a: Expr, b: Expr) -> Expr:
    return Call("max", (a, b))


Values = Mapping[str, float]
Message = Callable[[Values], str]


@dataclass(frozen=True)
class Check:
    """One check. kind 'finite': every parameter finite. 'positive': each
    expression > 0. 'slack': excess <= TRIANGLE_SLACK * scale (equality is
    physical, rounding must not refuse it). 'bound': value <= limit."""

    code: int
    kind: Literal["finite", "positive", "slack", "bound"]
    exprs: tuple[Expr, ...] = ()
    """positive: the expressions; slack: (excess, scale); bound: (value, limit)."""
    locals: tuple[tuple[str, Expr], ...] = ()
    """Named values computed before the condition, in order."""
    comment: tuple[str, ...] = ()
    """What the locals are, a comment above them in the generated code."""
    message: Message = lambda v: ""
    """The scene validator's message when the check fails (values by name)."""
    each: bool = False
    """positive: the validator names the one expression (a parameter) that failed."""


I11, I22, I33, I13 = Sym("I11"), Sym("I22"), Sym("I33"), Sym("I13")
I, J, HALF_GAP, LARGEST = Sym("I"), Sym("J"), Sym("half_gap"), Sym("largest")
CARRIER = "parameters.I11, I22, I33, I13"


def _moments(v: Values) -> str:
    mean = 0.5 * (v["I11"] + v["I33"])
    moments = sorted([v["I22"], mean + v["half_gap"], mean - v["half_gap"]])
    return ", ".join(f"{m:.6g}" for m in moments)


CHECKS: tuple[Check, ...] = (
    Check(1, "finite"),
    Check(2, "positive", (Sym("m_a"), Sym("m_b")), each=True),
    Check(3, "positive", (I, J), each=True),
    Check(
        4,
        "positive",
        (I11, I22, I33, I11 * I33 - I13 * I13),
        message=lambda v: f"{CARRIER}: carrier inertia is not positive definite",
    ),
    Check(
        5,
        "slack",
        (2.0 * LARGEST - add(I11, I22, I33), add(I11, I22, I33)),
        locals=(
            ("half_gap", sqrt(0.25 * square(I11 - I33) + I13 * I13)),
            ("largest", maximum(I22, 0.5 * add(I11, I33) + HALF_GAP)),
        ),
        comment=(
            "Principal moments: I22 and the eigenvalues of [[I11, I13], [I13, I33]].",
            "The largest may not exceed the sum of the other two.",
        ),
        message=lambda v: (
            f"{CARRIER}: principal moments ({_moments(v)}) violate the triangle inequality"
        ),
    ),
    Check(
        6,
        "slack",
        (J - 2.0 * I, 2.0 * I + J),
        message=lambda v: f"parameters.J: rotor needs J <= 2 I (I = {v['I']}, J = {v['J']})",
    ),
    Check(
        7,
        "bound",
        (Sym("cond"), Num(MAX_CONDITION)),
        message=lambda v: (
            f"parameters: the mass matrix's coupled block has condition number "
            f"{v['cond']:.3g} > {MAX_CONDITION:g}: numerically singular"
        ),
    ),
)
"""In the order setup makes them: the first failure wins."""


def cluster_checks(axial: list[tuple[str, float]]) -> tuple[Check, ...]:
    """A cluster's setup checks: every parameter finite, each runtime axial
    inertia (its name, its rotor's folded I) positive and at most 2 I as
    check 6 has it, the lumped inertia's condition number (the scene
    validator checks every folded value)."""
    finite, bound = (next(c for c in CHECKS if c.kind == kind) for kind in ("finite", "bound"))
    if not axial:
        return (finite, bound)
    positive = Check(3, "positive", tuple(Sym(n) for n, _ in axial), each=True)
    slack = tuple(
        Check(6, "slack", (Sym(n) - Num(2.0 * i), Num(2.0 * i) + Sym(n))) for n, i in axial
    )
    return (finite, positive, *slack, bound)


def symbols(e: Expr) -> set[str]:
    if isinstance(e, Sym):
        return {e.name}
    if isinstance(e, Op | Call):
        return set().union(*(symbols(a) for a in e.args))
    return set()


def checked_parameters() -> tuple[str, ...]:
    """The parameters the checks read, in p[] order: setup loads them first."""
    read = set().union(*(symbols(e) for c in CHECKS for e in (*c.exprs, *dict(c.locals).values())))
    return tuple(n for n in (*PARAMETERS, *CONTROLLER_PARAMETERS) if n in read)


def local_names() -> tuple[str, ...]:
    """Every local the checks compute (the generated setup declares them)."""
    return tuple(name for c in CHECKS for name, _ in c.locals)


def evaluate(e: Expr, v: Values) -> float:
    """e with floats, as the generated code computes it (IEEE: overflow is
    inf, NaN compares false)."""
    if isinstance(e, Num):
        return e.value
    if isinstance(e, Sym):
        return v[e.name]
    assert isinstance(e, Op | Call)
    args = [evaluate(a, v) for a in e.args]
    if isinstance(e, Op):
        if e.op == "-":
            return args[0] - args[1]
        return _fold(e.op, args)
    assert isinstance(e, Call)
    if e.fn == "square":
        return args[0] * args[0]
    if e.fn == "sqrt":
        return math.sqrt(args[0]) if args[0] >= 0 or math.isnan(args[0]) else math.nan
    a, b = args  # C's fmax: a NaN argument is ignored
    return b if math.isnan(a) else a if math.isnan(b) else max(a, b)


def _fold(op: str, args: list[float]) -> float:
    out = args[0]
    for a in args[1:]:
        out = out + a if op == "+" else out * a
    return out


def failure(check: Check, v: Values) -> str | None:
    """The validator's message if check fails on the values v, else None.
    v may lack parameters (the runtime ones): a part of a check that reads
    one of those is not made (setup makes it at run time)."""
    if check.kind == "finite":
        bad = [n for n in PARAMETERS + CONTROLLER_PARAMETERS if not math.isfinite(v.get(n, 0.0))]
        return f"parameters.{bad[0]}: not a finite number" if bad else None
    values = dict(v)
    for name, e in check.locals:
        if not symbols(e) <= values.keys():
            return None
        values[name] = evaluate(e, values)
    exprs = [e for e in check.exprs if symbols(e) <= values.keys()]
    if check.kind == "positive":
        for e in exprs:
            if not evaluate(e, values) > 0.0:
                if check.each and isinstance(e, Sym):
                    return f"parameters.{e.name}: must be positive (got {values[e.name]})"
                return check.message(values)
        return None
    if len(exprs) < 2:
        return None
    a, b = (evaluate(e, values) for e in exprs)
    if check.kind == "slack":
        return check.message(values) if a > TRIANGLE_SLACK * b else None
    return None if a <= b else check.message(values)


COUPLED = ("m_a", "m_b", "I11", "I33", "I13", "I", "l1", "l3")
"""What setup's condition number reads (physics.coupled_determinant's arguments)."""


def first_failure(v: Values) -> tuple[int, str] | None:
    """The code and message of the first check the known values v fail (the
    condition number computed as setup computes it, when v has what it
    reads), or None."""
    values = dict(v)
    for check in CHECKS:
        reads_cond = any("cond" in symbols(e) for e in check.exprs)
        if reads_cond and all(n in values for n in COUPLED):
            values["cond"] = _condition(values)  # the checks before it passed: masses positive
        if (why := failure(check, values)) is not None:
            return check.code, why
    return None


def _condition(values: Values) -> float:
    """The coupled block's condition number as setup computes it."""
    a11, _, a33, a13 = physics.lumped_inertias(*(values.get(n, 0.0) for n in LUMPED_FROM))
    det = physics.coupled_determinant(*(values[n] for n in COUPLED))
    return float(physics.condition(a11, a13, a33, det, math.sqrt)) if det > 0 else math.inf
