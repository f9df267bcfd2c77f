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
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

from gyrogen import physics
from gyrogen.abi import CONTROLLER_PARAMETERS, MAX_CONDITION, PARAMETERS, TRIANGLE_SLACK
from gyrogen.abi_rotors import (
    AXIS,
    AXIS_NORM_SLACK,
    GIMBAL_AXIS,
    GIMBAL_INERTIA,
    GIMBAL_KEYS,
    GIMBAL_PERP_SLACK,
)
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
    physical, rounding must not refuse it). 'bound': value <= limit.
    'constants': every constant setup computed is finite (made last, at run
    time only: each parameter may be valid and their products overflow)."""

    code: int
    kind: Literal["finite", "positive", "slack", "bound", "constants"]
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
    Check(9, "constants"),
)
"""In the order setup makes them: the first failure wins."""


def cluster_checks(values: Mapping[str, float | str], n: int) -> tuple[Check, ...]:
    """A cluster's setup checks, on its inertial values by name (m_a, I11..I23,
    m_k, I_k, J_k, g1_k, a gimbal's mG_k, IGs_k, IGt_k, IGg_k, and with
    either of a gimbal's axes runtime both axes' g1_k..g3_k, gg1_k..gg3_k: a
    number or "runtime"; a carrier product missing is 0): every parameter finite;
    then, where a value is runtime, masses and inertias positive, the
    carrier positive definite and meeting the triangle inequality (s 1 - T
    positive definite, s = (1/2 + slack) tr T: Sylvester's leading minors),
    J_k <= 2 I_k and a gimbal frame's triangle inequality (code 6), each runtime axis of length
    within AXIS_NORM_SLACK of 1 (code 8: a spin axis, then a gimbal axis), a
    gimbal's spin axis perpendicular to its gimbal axis within
    GIMBAL_PERP_SLACK when either is runtime (code 10); the lumped inertia's condition
    number; the constants finite (code 9). The scene validator checks the
    folded values."""

    def term(name: str) -> Expr:
        v = values.get(name, 0.0)
        return Sym(name) if v == "runtime" else Num(float(v))

    def runtime(*names: str) -> tuple[Expr, ...]:
        return tuple(Sym(m) for m in names if values.get(m) == "runtime")

    finite, bound, constants = (
        next(c for c in CHECKS if c.kind == kind) for kind in ("finite", "bound", "constants")
    )
    out = [finite]
    rotors = [tuple(f"{key}_{k}" for key in ("m", "I", "J")) for k in range(1, n + 1)]
    frames = [
        tuple(f"{key}_{k}" for key in GIMBAL_INERTIA)
        for k in range(1, n + 1)
        if f"{GIMBAL_INERTIA[0]}_{k}" in values
    ]
    gimbal_masses = [f"{GIMBAL_KEYS['m']}_{k}" for k in range(1, n + 1)]
    masses = runtime("m_a", *(m for m, _, _ in rotors), *gimbal_masses)
    if masses:
        out.append(Check(2, "positive", masses, each=True))
    inertias = runtime(*(x for _, i, j in rotors for x in (i, j)), *(x for f in frames for x in f))
    if inertias:
        out.append(Check(3, "positive", inertias, each=True))
    if runtime(*CARRIER_KEYS):  # the scene validator's messages are its own (rotors.py)
        t = {key: term(key) for key in CARRIER_KEYS}
        carrier = (t["I11"], t["I22"], t["I33"], t["I12"], t["I13"], t["I23"])
        out.append(
            Check(4, "positive", (t["I11"], Sym("pd2"), Sym("pd3")),
                  locals=_minors("pd", *carrier, 1.0),
                  comment=("Sylvester: the carrier's leading minors.",))
        )  # fmt: skip
        half = ("half_trace", Num(0.5 + TRIANGLE_SLACK) * add(*carrier[:3]))
        shifted = tuple((f"s{i}", Sym("half_trace") - t[f"I{i}"]) for i in ("11", "22", "33"))
        diagonal = (Sym("s11"), Sym("s22"), Sym("s33"))
        out.append(
            Check(5, "positive", (Sym("s11"), Sym("tri2"), Sym("tri3")),
                  locals=(half, *shifted, *_minors("tri", *diagonal, *carrier[3:], -1.0)),
                  comment=("The largest principal moment is at most half the trace (with",
                           "slack): s 1 - T positive definite, s = (1/2 + slack) tr T."))
        )  # fmt: skip
    for _, i, j in rotors:
        if values.get(i) == "runtime" or values.get(j) == "runtime":
            out.append(
                Check(6, "slack", (term(j) - Num(2.0) * term(i), Num(2.0) * term(i) + term(j)))
            )
    for frame in frames:  # the largest principal inertia at most the sum of the other two
        if runtime(*frame):
            a, b, c = (term(x) for x in frame)
            out.append(Check(6, "slack", (2.0 * maximum(maximum(a, b), c) - add(a, b, c),
                                          add(a, b, c))))  # fmt: skip
    for k in range(1, n + 1):
        if values.get(f"{AXIS[0]}_{k}") == "runtime":
            out.append(_unit_length(k, AXIS, "norm", "axis"))
        if values.get(f"{GIMBAL_AXIS[0]}_{k}") == "runtime":
            out.append(_unit_length(k, GIMBAL_AXIS, "gnorm", "gimbal axis"))
        if f"{GIMBAL_AXIS[0]}_{k}" in values:
            spin, gimbal = ([term(f"{key}_{k}") for key in keys] for keys in (AXIS, GIMBAL_AXIS))
            out.append(_perpendicular(k, spin, gimbal))
    return (*out, bound, constants)


def _unit_length(k: int, keys: tuple[str, ...], name: str, what: str) -> Check:
    """Rotor k's runtime axis (keys: g1_k, g2_k, g3_k, or a gimbal axis's
    gg1_k..gg3_k) of length within AXIS_NORM_SLACK of 1: |norm_k - 1| <=
    slack (setup then normalizes it)."""
    norm = Sym(f"{name}_{k}")
    length = sqrt(add(*(square(Sym(f"{key}_{k}")) for key in keys)))
    return Check(
        8,
        "bound",
        (maximum(norm - Num(1.0), Num(1.0) - norm), Num(AXIS_NORM_SLACK)),
        locals=((f"{name}_{k}", length),),
        comment=(f"Rotor {k}'s {what}: of unit length within the slack.",),
    )


def _perpendicular(k: int, spin: list[Expr], gimbal: list[Expr]) -> Check:
    """Gimbal k's spin axis and gimbal axis (each runtime or folded)
    perpendicular within GIMBAL_PERP_SLACK, the cosine of their angle:
    (s . g)^2 <= slack^2 |s|^2 |g|^2 (no division; setup then makes them
    orthonormal)."""
    dot = Sym(f"perp_{k}")
    return Check(
        10,
        "bound",
        (
            square(dot),
            Num(GIMBAL_PERP_SLACK**2) * add(*map(square, spin)) * add(*map(square, gimbal)),
        ),
        locals=((f"perp_{k}", add(*(a * b for a, b in zip(spin, gimbal, strict=True)))),),
        comment=(f"Gimbal {k}: its spin axis perpendicular to its axis within the slack.",),
    )


CARRIER_KEYS = ("I11", "I22", "I33", "I12", "I13", "I23")


def _minors(
    name: str, a11: Expr, a22: Expr, a33: Expr, b12: Expr, b13: Expr, b23: Expr, sign: float
) -> tuple[tuple[str, Expr], ...]:
    """Locals name2, name3: the leading 2x2 and 3x3 minors of the symmetric
    matrix of diagonal a and off-diagonal sign * b (short lines: one
    cofactor each, name_m1..3)."""
    m1, m2, m3 = (Sym(f"{name}_m{i}") for i in (1, 2, 3))
    if sign > 0:
        cofactors = (b12 * a33 - b13 * b23, b12 * b23 - a22 * b13)
        det = a11 * m1 - b12 * m2 + b13 * m3
    else:  # m3 holds the cofactor's negative: no unary minus (Fortran refuses "- -x")
        cofactors = (b12 * a33 + b13 * b23, b12 * b23 + a22 * b13)
        det = a11 * m1 - b12 * m2 - b13 * m3
    return (
        (f"{name}2", a11 * a22 - b12 * b12),
        (f"{name}_m1", a22 * a33 - b23 * b23),
        (f"{name}_m2", cofactors[0]),
        (f"{name}_m3", cofactors[1]),
        (f"{name}3", det),
    )


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


def local_names(checks: Sequence[Check] = CHECKS) -> tuple[str, ...]:
    """Every local the checks compute (the generated setup declares them)."""
    return tuple(name for c in checks for name, _ in c.locals)


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
    if check.kind == "constants":  # folded values are bounded so that theirs stay finite
        return None
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
