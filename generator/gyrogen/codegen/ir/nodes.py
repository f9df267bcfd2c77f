"""The integrators' statement IR: expressions, statements and functions.

An integrator is described once in these nodes (gyrogen.codegen.integrators)
and printed by one printer per target: scalar C and SIMD-lane C
(gyrogen.codegen.ir.c) and Fortran 2008 (gyrogen.codegen.ir.fortran). The
nodes keep the order of every operation as written: a printer adds
parentheses where its language needs them and never reassociates, so every
target rounds alike.

Arrays are indexed from 0 in every target (Fortran declares them 0:n-1); a
two-index array is k[j][i] in C order (Fortran prints k(i, j)). A name with
a dot, "stats.h", is a field of the statistics (stats->h, stats%h).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, fields, replace
from typing import Literal, TypeVar


@dataclass(frozen=True)
class E:
    """An expression; + - * / and unary - build operations as written."""

    def __add__(self, other: E | float) -> E:
        return Bin("+", self, lit(other))

    def __radd__(self, other: float) -> E:
        return Bin("+", lit(other), self)

    def __sub__(self, other: E | float) -> E:
        return Bin("-", self, lit(other))

    def __rsub__(self, other: float) -> E:
        return Bin("-", lit(other), self)

    def __mul__(self, other: E | float) -> E:
        return Bin("*", self, lit(other))

    def __rmul__(self, other: float) -> E:
        return Bin("*", lit(other), self)

    def __truediv__(self, other: E | float) -> E:
        return Bin("/", self, lit(other))

    def __rtruediv__(self, other: float) -> E:
        return Bin("/", lit(other), self)

    def __neg__(self) -> E:
        return Un("-", self)

    def __getitem__(self, index: E | int | tuple[E | int, ...]) -> At:
        assert isinstance(self, Var)
        idx = index if isinstance(index, tuple) else (index,)
        return At(self.name, tuple(Int(i) if isinstance(i, int) else i for i in idx))


@dataclass(frozen=True)
class Num(E):
    """A double literal."""

    value: float


@dataclass(frozen=True)
class Int(E):
    value: int


@dataclass(frozen=True)
class Bool(E):
    value: bool


@dataclass(frozen=True)
class Var(E):
    """A scalar (or a whole array, as a call's argument)."""

    name: str


@dataclass(frozen=True)
class At(E):
    """An element of an array, C order."""

    name: str
    index: tuple[E, ...]


@dataclass(frozen=True)
class Row(E):
    """Row j of a two-index array, as a call's argument (C k[j], Fortran k(:, j))."""

    name: str
    row: E


@dataclass(frozen=True)
class Ref(E):
    """A scalar passed for the callee to set (C &h, Fortran h)."""

    name: str


@dataclass(frozen=True)
class Const(E):
    """A named constant of the file: NX, a return code ("ODE_OK"), MIN_RTOL,
    GIMBAL_LOCK_COS, or the double's EPSILON, TINY, HUGE."""

    name: str


@dataclass(frozen=True)
class Word(E):
    """A 64-bit unsigned literal (C 0x...ULL): a double's bits."""

    value: int


Type = Literal["double", "int", "long", "bool", "stats", "word", "size"]
"""word: 64 unsigned bits (C uint64_t), a double's bits to shift and mask; C
only (Fortran has intrinsics for what C computes from the bits). size: C's
size_t, a trajectory's index in a batch (C only)."""
Intent = Literal["in", "out", "inout", "tmp"]
BinOp = Literal[
    "+", "-", "*", "/", "<", "<=", ">", ">=", "==", "!=", "and", "or", ">>", "<<", "&", "|"
]
"""The last four on words: shifts, bitwise and and or."""


@dataclass(frozen=True)
class Bin(E):
    op: BinOp
    a: E
    b: E


@dataclass(frozen=True)
class Un(E):
    op: Literal["-", "not"]
    a: E


@dataclass(frozen=True)
class Fn(E):
    """A function: max, min, abs, sqrt, pow, floor, finite (not NaN or Inf),
    cos (the scene's), or a function of the file by its name; C only: long
    and size, an integer converted to a long or a size_t."""

    name: str
    args: tuple[E, ...]


@dataclass(frozen=True)
class Sel(E):
    """cond ? a : b (both sides are evaluated: no side effects in them)."""

    cond: E
    a: E
    b: E


def lit(v: E | float) -> E:
    if isinstance(v, E):
        return v
    if isinstance(v, bool):
        return Bool(v)
    return Int(v) if isinstance(v, int) and not isinstance(v, bool) else Num(float(v))


def fn(name: str, *args: E | float) -> E:
    return Fn(name, tuple(lit(a) for a in args))


def cmp(a: E | float, op: BinOp, b: E | float) -> E:
    return Bin(op, lit(a), lit(b))


def and_(*terms: E) -> E:
    out = terms[0]
    for t in terms[1:]:
        out = Bin("and", out, t)
    return out


def or_(*terms: E) -> E:
    out = terms[0]
    for t in terms[1:]:
        out = Bin("or", out, t)
    return out


def not_(a: E) -> E:
    return Un("not", a)


def sel(cond: E, a: E | float, b: E | float) -> E:
    return Sel(cond, lit(a), lit(b))


# Statements


@dataclass(frozen=True)
class S:
    """A statement."""


@dataclass(frozen=True)
class Assign(S):
    target: Var | At
    value: E
    note: str = ""
    """A comment at the end of the line."""


@dataclass(frozen=True)
class For(S):
    """var = start .. n - 1; locals are scoped to the body (doubles)."""

    var: str
    n: E
    body: tuple[S, ...]
    locals: tuple[str, ...] = ()
    type: Type = "int"
    start: E = field(default_factory=lambda: Int(0))
    inner: bool = False
    """Over lanes, a loop inside the one loop over the lanes (which the
    compiler then vectorizes as the outer loop, its values in registers),
    printed as a loop that runs at least once: the describer promises a
    first turn, and bounds the same on every lane. Its body assigns values
    only. The scalar printers print it as any loop."""
    vector: bool = False
    """Kept a loop, not unrolled whole, so that the compiler vectorizes it: a
    short loop with a constant count (one over the states) is otherwise
    unrolled before the loop vectorizer runs and, the straight-line
    vectorizer being off (runtime/flags.py), left scalar. Printed with a
    directive to gcc and clang (C: #pragma GCC unroll 1, Fortran: !GCC$ unroll
    1), a comment to others; its elements are computed as before, so the
    results are the same bit for bit."""
    simd: bool = False
    """A loop whose turns are independent (one per lane of a batch): C marks
    it <MACRO>_SIMD, `omp simd` under OpenMP."""


@dataclass(frozen=True)
class If(S):
    cond: E
    then: tuple[S, ...]
    orelse: tuple[S, ...] = ()
    own: tuple[str, ...] = ()
    """Arrays then sets for itself: read only where cond holds, or set
    again before any other read. Over lanes (if-conversion) then sets them
    on every lane as they are, with no selection to keep a lane's old
    values; the scalar printers print the branch as any."""


@dataclass(frozen=True)
class Loop(S):
    """Forever, until a return."""

    body: tuple[S, ...]


@dataclass(frozen=True)
class Return(S):
    value: E | None = None
    note: str = ""


@dataclass(frozen=True)
class Continue(S):
    """On to the loop's next turn."""


@dataclass(frozen=True)
class Break(S):
    """Out of the innermost Loop (never from inside a For)."""


@dataclass(frozen=True)
class Call(S):
    """A subroutine call (the rhs: its lanes twin takes the time per lane)."""

    name: str
    args: tuple[E, ...]
    note: str = ""


@dataclass(frozen=True)
class Bits(S):
    """target takes source's bits: a double's as a word, or back (C memcpy)."""

    target: str
    source: str


@dataclass(frozen=True)
class Unused(S):
    """A parameter some scenes never read (C (void)name, a Fortran associate):
    the strict builds refuse an unused one otherwise."""

    name: str


@dataclass(frozen=True)
class Comment(S):
    text: str
    blank: bool = True
    """A blank line before it."""


def walk(node: E | S) -> Iterator[E | S]:
    """node and every expression and statement within it, in order (each
    node before what it holds, its fields in order), by a stack of what is
    left: a function's body is hundreds of thousands of nodes."""
    left: list[E | S] = [node]
    while left:
        x = left.pop()
        yield x
        inner: list[E | S] = []
        for name in _field_names(type(x)):
            value = getattr(x, name)
            if isinstance(value, tuple):
                inner += [v for v in value if isinstance(v, (E, S))]
            elif isinstance(value, (E, S)):
                inner.append(value)
        left += reversed(inner)


_FIELDS: dict[type, tuple[str, ...]] = {}


def _field_names(kind: type) -> tuple[str, ...]:
    """A node class's field names, in order (dataclasses.fields: a call each)."""
    names = _FIELDS.get(kind)
    if names is None:
        names = _FIELDS[kind] = tuple(f.name for f in fields(kind))
    return names


Node = TypeVar("Node")


def substituted(node: Node, old: E, new: E) -> Node:
    """node with every expression equal to old replaced by new (a Func, a
    statement, an expression or a declaration: frozen dataclasses all)."""
    if node == old:
        return new  # type: ignore[return-value]
    if not hasattr(node, "__dataclass_fields__"):
        return node
    changes = {}
    for f in fields(node):  # type: ignore[arg-type]
        value = getattr(node, f.name)
        if isinstance(value, tuple):
            done = tuple(substituted(v, old, new) for v in value)
        else:
            done = substituted(value, old, new)
        if done is not value and done != value:
            changes[f.name] = done
    return replace(node, **changes) if changes else node  # type: ignore[type-var]


def called(funcs: Iterable[Func]) -> set[str]:
    """The names of the functions funcs call (Fn in expressions, Call statements)."""
    roots = [r for f in funcs for r in (*f.body, *(d.init for d in f.locals)) if r is not None]
    return {x.name for r in roots for x in walk(r) if isinstance(x, (Fn, Call))}


def assign(target: Var | At, value: E | float, note: str = "") -> Assign:
    return Assign(target, lit(value), note)


def inc(target: Var | At, by: E | float) -> Assign:
    """target += by, written out (target + by)."""
    return Assign(target, Bin("+", target, lit(by)))


# Declarations and functions


@dataclass(frozen=True)
class Decl:
    """A parameter or a local: a scalar, or an array of shape (C order) whose
    extents are names (NX) or numbers."""

    name: str
    type: Type
    shape: tuple[str | int, ...] = ()
    intent: Intent = "in"
    """A local's "in": the same on every lane (set outside the loops over
    lanes); "tmp": a value used only in the run of statements that sets it
    (over lanes, a scalar of the one loop over the lanes)."""
    init: E | None = None
    """A local's value at the start (an array: every element)."""
    values: tuple[int | float, ...] = ()
    """A constant table (an array local that never changes)."""


def arr(name: str, intent: Intent = "in", *shape: str | int) -> Decl:
    """An array of doubles, NX of them unless shape says otherwise."""
    return Decl(name, "double", shape or ("NX",), intent)


def real(name: str, intent: Intent = "in") -> Decl:
    """A double."""
    return Decl(name, "double", (), intent)


def reals(*names: str) -> tuple[Decl, ...]:
    """Local doubles a function sets."""
    return tuple(real(n, "inout") for n in names)


@dataclass(frozen=True)
class Func:
    name: str
    params: tuple[Decl, ...]
    body: tuple[S, ...]
    returns: Type | None = None
    locals: tuple[Decl, ...] = field(default=())
    doc: tuple[str, ...] = ()
    inline: bool = False
    """C: static inline (small functions in a header-like role)."""
    public: bool = False
    """Part of the file's interface: C gives it external linkage; Fortran binds
    it to C under the name <prefix>_f_<rest> and takes its scalars by value."""
    restrict: bool = False
    """Its array parameters never overlap (C: <MACRO>_RESTRICT pointers, for
    the vectorizer; Fortran's dummy arguments never alias)."""
