"""The IR over SIMD lanes: the scalar statements of one trajectory, printed
for every lane of a struct lanes L (see gyrogen.codegen.ir.c).

A run of statements on values becomes one loop over the lanes; a loop over
the states holds a loop over the lanes; a branch becomes a selection per
lane (if-conversion: both sides computed, each lane keeps its own); a call
of the rhs runs on every lane with each lane's time, and a branch around a
call runs it when any lane needs it (the Jacobian's too).
"""

from __future__ import annotations

from collections.abc import Callable

from gyrogen.codegen.ir.c import CTYPE, CPrinter, uses
from gyrogen.codegen.ir.nodes import (
    Assign,
    At,
    Bin,
    Break,
    Call,
    Comment,
    Decl,
    E,
    For,
    Func,
    If,
    Int,
    Loop,
    Num,
    Row,
    S,
    Sel,
    Unused,
    Var,
    and_,
    not_,
)
from gyrogen.codegen.ir.printer import ATOM

MODEL = ("rhs", "jac")
"""The model's functions of (t, x, c, out): over lanes, one call with each
lane's time (rhs_lanes, jac_lanes on rows of LANES values)."""


class LanesPrinter(CPrinter):
    """state: the per-trajectory values the struct lanes holds; every other
    name is the function's (a value local: one per lane) or the same on
    every lane (rtol, atol, t1, c...)."""

    def __init__(
        self, prefix: str, macro: str, decls: dict[str, Decl], state: dict[str, Decl] | None = None
    ) -> None:
        super().__init__(prefix, macro, decls)
        self.state = state or {}
        self.scoped: set[str] = set()

    def with_decls(self, func: Func) -> LanesPrinter:
        return LanesPrinter(self.prefix, self.macro, {d.name: d for d in func.locals}, self.state)

    def uniform(self, name: str) -> bool:
        """A local the same on every lane (declared with intent "in"): set
        outside the loops over lanes, read as it is."""
        d = self.decls.get(name)
        return d is not None and d.intent == "in"

    def temporary(self, name: str) -> bool:
        d = self.decls.get(name)
        return d is not None and d.intent == "tmp"

    def sets_uniform(self, s: S) -> bool:
        return isinstance(s, Assign) and self.uniform(
            s.target.name if isinstance(s.target, (Var, At)) else ""
        )

    @property
    def width(self) -> str:
        return f"{self.macro}_LANES"

    def field(self, name: str) -> str:
        return "L->" + name.replace(".", "_")

    def shared(self, name: str) -> bool:
        """A value of the struct the same on every lane (intent "in" or
        "out"): the output grid's times and rows, the event log."""
        d = self.state.get(name)
        return d is not None and d.intent in ("in", "out")

    def var(self, name: str) -> tuple[str, int]:
        if name in self.state:
            d = self.state[name]
            whole = d.shape or self.shared(name)
            return (self.field(name) if whole else f"{self.field(name)}[l]"), ATOM
        if (
            name in self.decls
            and name not in self.scoped
            and not self.uniform(name)
            and not self.temporary(name)
        ):
            return f"{name}[l]", ATOM
        return name, ATOM

    def element(self, name: str, index: tuple[str, ...]) -> str:
        base = self.field(name) if name in self.state else name
        lane = name in self.state and not self.shared(name)
        return base + "".join(f"[{i}]" for i in index) + ("[l]" if lane else "")

    def row(self, name: str, j: str) -> str:
        return f"{self.field(name)}[{j}]"

    def call(self, name: str, args: list[str], nodes: tuple[E, ...]) -> str:
        if name in ("sin", "cos"):
            return f"{self.prefix}_{name}_lanes({args[0]})"
        return super().call(name, args, nodes)

    def _expr(self, e: E) -> tuple[str, int]:
        """An or of a variable over lanes, as an accumulation's nonfinite =
        nonfinite || ..., is a bitwise or (the same truth for any ints): the
        short-circuit || on L->nonfinite[l] kept gcc from vectorizing its
        loop over the lanes, and the scalar loop with its branches cost 4 %
        of the Taylor batch at 1e-6. In parentheses, its operands too (clang's
        -Wbitwise-conditional-parentheses; with a variable on one side,
        -Wbitwise-instead-of-logical holds its peace). And stays &&: a
        bitwise and of ints other than 0 and 1 would not be their truth."""
        if (
            self.single
            or not isinstance(e, Bin)
            or e.op != "or"
            or not (isinstance(e.a, Var) or isinstance(e.b, Var))
        ):
            return super()._expr(e)
        return "(" + " | ".join(self.expr(a, ATOM) for a in (e.a, e.b)) + ")", ATOM

    def lane_loop(self, depth: int, body: list[str], simd: bool) -> list[str]:
        pad = self.indent * depth
        pragma = (
            [f"{pad}{self.macro}_SIMD"]
            if simd
            else [f"{pad}/* pow, log, exp: scalar calls, as the single trajectory's */"]
        )
        return [*pragma, f"{pad}for (l = 0; l < {self.width}; ++l) {{", *body, f"{pad}}}"]

    single = False
    """Printing for one lane (one_lane): statements as they are."""

    def block(self, body: tuple[S, ...], depth: int) -> list[str]:
        """Top-level statements: runs of value statements share one lane loop."""
        if self.single:
            return CPrinter.block(self, body, depth)
        lines: list[str] = []
        run: list[S] = []

        def flush() -> None:
            if run:
                temps = self.temporaries(run)
                local = [f"{self.indent * (depth + 1)}double {', '.join(temps)};"] if temps else []
                inner = super(LanesPrinter, self).block(tuple(converted(run)), depth + 1)
                lines.extend(self.lane_loop(depth, [*local, *inner], vector(tuple(run))))
                run.clear()

        for s in converted(body, top=True, own=frozenset(self.decls), keep=self.lane_by_lane):
            if self.sets_uniform(s):
                flush()
                lines += CPrinter.statement(self, s, depth)
                continue
            if isinstance(s, Assign) or (isinstance(s, For) and s.inner):
                run.append(s)
                continue
            flush()
            lines += self.outer(s, depth)
        flush()
        return lines

    def statement(self, s: S, depth: int) -> list[str]:
        """In a loop over the lanes: an inner loop as do-while (For.inner)."""
        if not (isinstance(s, For) and s.inner) or self.single:
            return super().statement(s, depth)
        pad, v = self.indent * depth, s.var
        assert not isinstance(s.n, Int) or not isinstance(s.start, Int) or s.n.value > s.start.value
        body = [*self.scoped_locals(s, depth + 1), *CPrinter.block(self, s.body, depth + 1)]
        return [
            f"{pad}{v} = {self.expr(s.start)};",
            f"{pad}do {{",
            *body,
            f"{pad}{self.indent}++{v};",
            f"{pad}}} while ({v} < {self.expr(s.n, 5)});",
        ]

    def temporaries(self, run: list[S]) -> list[str]:
        """The temporaries a run of assignments (and inner loops of them)
        sets, each before any read."""
        set_: list[str] = []
        flat = [x for s in run for x in ([s] if isinstance(s, Assign) else walk_assigns(s))]
        for s in flat:
            read = {n for n in names(s.value) if self.temporary(n)}
            assert read <= set(set_), f"{sorted(read - set(set_))} read before set in a run"
            target = s.target.name if isinstance(s.target, Var) else ""
            if self.temporary(target) and target not in set_:
                set_.append(target)
        return set_

    def outer(self, s: S, depth: int) -> list[str]:
        pad = self.indent * depth
        if isinstance(s, (Comment, Unused)):
            return super().statement(s, depth)
        if isinstance(s, For) and all(self.sets_uniform(x) for x in s.body):
            return CPrinter.statement(self, s, depth)
        if isinstance(s, For) and any(isinstance(x, (For, If, Call)) for x in s.body):
            v, start, stop = s.var, self.expr(s.start), self.expr(s.n, 4)
            assert not s.locals, "a loop of loops keeps no scoped values"
            head = f"{pad}for ({v} = {start}; {v} < {stop}; ++{v}) {{"
            return [head, *self.block(s.body, depth + 1), f"{pad}}}"]
        if isinstance(s, For):
            self.scoped |= set(s.locals)
            local = [f"{pad}{self.indent * 2}double {', '.join(s.locals)};"] if s.locals else []
            inner = super().block(tuple(converted(s.body)), depth + 2)
            loop = self.lane_loop(depth + 1, [*local, *inner], vector(s.body))
            self.scoped -= set(s.locals)
            v, start, stop = s.var, self.expr(s.start), self.expr(s.n, 4)
            return [
                f"{pad}for ({v} = {start}; {v} < {stop}; ++{v}) {{",
                *loop,
                f"{pad}}}",
            ]
        if isinstance(s, Call) and s.name not in MODEL:
            kept = [a for a in s.args if not (isinstance(a, Var) and a.name in self.state)]
            args = ", ".join(["L", *(self.expr(a) for a in kept)])
            return [f"{pad}{s.name}_lanes({args});"]
        if isinstance(s, Call):
            t, x, c, out = s.args
            times = self.lane_loop(depth, [f"{pad}{self.indent}L->ts[l] = {self.expr(t)};"], True)
            args = ", ".join(self.expr(a) for a in (x, c, out))
            return [*times, f"{pad}{s.name}_lanes(L->ts, {args});"]
        if isinstance(s, Loop):
            return self.turns(s, depth)
        assert isinstance(s, If) and not s.orelse, s
        any_lane = self.lane_loop(depth, [f"{pad}{self.indent}need |= {self.expr(s.cond)};"], True)
        if self.lane_by_lane(s):
            head = f"{pad}{self.indent}for (l = 0; l < {self.width}; ++l) {{"
            each = [head, *self.one_lane((s,), depth + 2), f"{pad}{self.indent}}}"]
            return [f"{pad}need = 0;", *any_lane, f"{pad}if (need) {{", *each, f"{pad}}}"]
        return [
            f"{pad}need = 0;",
            *any_lane,
            f"{pad}if (need) {{",
            *self.block(tuple(converted(s.then, s.cond, scratch=frozenset(s.own))), depth + 1),
            f"{pad}}}",
        ]

    def turns(self, s: Loop, depth: int) -> list[str]:
        """A loop whose turn starts go := go and ..., then breaks where not
        go (go stays false on a lane once false): its turns run while any
        lane goes on, the rest of a turn under go (every value by
        selection, a branch's own arrays as they are, a branch writing
        what every lane shares lane by lane)."""
        pad, step = self.indent * depth, self.indent
        first, guard, *rest = s.body
        assert isinstance(first, Assign) and isinstance(first.target, Var), first
        go = first.target
        assert go.name in names(first.value) and guard == If(not_(go), (Break(),)), s
        any_lane = self.lane_loop(depth + 1, [f"{pad}{step * 2}need |= {self.expr(go)};"], True)
        body = converted(rest, top=True, keep=self.lane_by_lane)
        return [
            f"{pad}for (;;) {{",
            *self.block((first,), depth + 1),
            f"{pad}{step}need = 0;",
            *any_lane,
            f"{pad}{step}if (!need) {{",
            f"{pad}{step * 2}break;",
            f"{pad}{step}}}",
            *self.block(tuple(body), depth + 1),
            f"{pad}}}",
        ]

    def lane_by_lane(self, s: If) -> bool:
        """A branch run lane by lane, as the single trajectory runs it: one
        that loops until a break, or writes what every lane shares (a row
        of the output grid: by selection, a lane would write rows that are
        not its own), or calls a scalar function on one lane's values (an
        array the same on every lane, intent "in", holds them: the events
        at a lane's step end). Else a branch around a call runs the call on
        every lane when any lane needs it, its values by selection."""
        inner = nested(s)
        return (
            any(isinstance(x, Loop) for x in inner)
            or any(
                isinstance(x, Assign) and isinstance(x.target, At) and self.shared(x.target.name)
                for x in inner
            )
            or any(
                isinstance(x, Call)
                and any(isinstance(a, Var) and self.uniform(a.name) for a in x.args)
                for x in inner
            )
        )

    def one_lane(self, body: tuple[S, ...], depth: int) -> list[str]:
        """body for lane l alone (l given): no loop over the lanes."""
        self.single = True
        try:
            return CPrinter.block(self, body, depth)
        finally:
            self.single = False

    def function(self, func: Func) -> str:
        """static void name(struct lanes *L, params): func's body on every lane."""
        p = self.with_decls(func)
        params = ", ".join(
            ["struct lanes *L", *(CPrinter.declaration(p, d, True) for d in func.params)]
        )
        locals_ = [
            f"{CPrinter.declaration(p, d, False)};"
            if d.values
            else f"{CTYPE[d.type]} {d.name}{''.join(f'[{self.extent(n)}]' for n in d.shape)};"
            if d.intent == "in"
            else f"{CTYPE[d.type]} {d.name}[{self.width}]{lane_init(d)};"
            for d in func.locals
            if d.intent != "tmp"
        ]
        loops = sorted({s.var for s in walk_for(func.body)} | {"l"})
        locals_.append(f"int {', '.join(loops)};")
        if any(isinstance(s, Loop) or (isinstance(s, If) and (
                any(isinstance(x, Call) for x in s.then) or p.lane_by_lane(s)))
               for s in func.body):  # fmt: skip
            locals_.append("int need;")
        doc = [f"/* {d} */" for d in func.doc[:1]]
        body = p.block(func.body, 1)
        head = p.wrap(f"static void {func.name}({params})", " " * (13 + len(func.name)), "")
        decls = [y for x in locals_ for y in p.wrap(self.indent + x, self.indent * 3, "")]
        lines = [*doc, *head, "{", *decls, *body, "}"]
        return "\n".join(lines) + "\n"


class LanePrinter(LanesPrinter):
    """Functions of one lane l of a struct lanes L (a trajectory handed to a
    lane and back): the struct's per-trajectory values are L->v[l] (l a
    parameter or a loop's), every other name is as in one trajectory's C; a
    local of type stats is a struct of the statistics itself (st.h)."""

    single = True
    lead = ("struct lanes *L",)
    structs: frozenset[str] = frozenset()

    def with_decls(self, func: Func) -> LanePrinter:
        p = LanePrinter(self.prefix, self.macro, {d.name: d for d in func.params}, self.state)
        p.structs = frozenset(d.name for d in func.locals if d.type == "stats")
        return p

    def var(self, name: str) -> tuple[str, int]:
        if name in self.state:
            return super().var(name)
        if name.split(".")[0] in self.structs:
            return name, ATOM
        return CPrinter.var(self, name)

    def declaration(self, d: Decl, param: bool) -> str:
        if d.type == "stats" and not param:
            return f"{self.prefix}_stats {d.name}"
        return super().declaration(d, param)

    def function(self, func: Func) -> str:
        """ret name(struct lanes *L, params), as CPrinter prints it (single:
        the body's statements as they are)."""
        return CPrinter.function(self, func)


def lane_init(d: Decl) -> str:
    """A per-lane local's start on every lane: only 0 (an initializer that
    fills the lanes whatever their number)."""
    if d.init is None:
        return ""
    assert isinstance(d.init, Num) and d.init.value == 0, f"a lane's start is 0: {d}"
    return " = {0}"


def vector(body: tuple[S, ...] | list[S]) -> bool:
    """A loop over lanes the compiler may vectorize: one with no call of
    pow, log or exp (their vector versions round otherwise than the scalar
    ones the single trajectory calls)."""
    return not any(uses(tuple(body), f) for f in ("pow", "log", "exp"))


def names(e: E) -> set[str]:
    """The variables an expression reads."""
    if isinstance(e, Var):
        return {e.name}
    out = {e.name} if isinstance(e, At) else set()
    for v in vars(e).values():
        for x in v if isinstance(v, tuple) else (v,):
            if isinstance(x, E):
                out |= names(x)
    return out


def nested(s: S) -> list[S]:
    if isinstance(s, If):
        return [x for y in (*s.then, *s.orelse) for x in [y, *nested(y)]]
    if isinstance(s, (For, Loop)):
        return [x for y in s.body for x in [y, *nested(y)]]
    return []


def walk_assigns(s: S) -> list[Assign]:
    """The assignments of an inner loop, in order (it holds nothing else)."""
    assert isinstance(s, For) and s.inner
    out: list[Assign] = []
    for x in s.body:
        assert isinstance(x, (Assign, For)), f"an inner loop assigns values only: {x}"
        out += [x] if isinstance(x, Assign) else walk_assigns(x)
    return out


def walk_for(body: tuple[S, ...]) -> list[For]:
    """Every loop in body, nested ones included."""
    out: list[For] = []
    for s in body:
        if isinstance(s, For):
            out += [s, *walk_for(s.body)]
        elif isinstance(s, If):
            out += walk_for((*s.then, *s.orelse))
        elif isinstance(s, Loop):
            out += walk_for(s.body)
    return out


def converted(
    body: list[S] | tuple[S, ...],
    cond: E | None = None,
    top: bool = False,
    own: frozenset = frozenset(),
    keep: Callable[[If], bool] = lambda s: False,
    scratch: frozenset = frozenset(),
) -> list[S]:
    """if-conversion: each assignment under cond keeps its old value where
    cond is false. A branch may not assign what its condition reads. At the
    top, a branch around calls stays a branch, and one that keep keeps (run
    lane by lane). Names in own are the branch's own values (a local first
    set in it): assigned as they are; so are the elements of the arrays in
    scratch, and of those a branch owns (If.own)."""
    out: list[S] = []
    for s in body:
        if top and isinstance(s, If) and (any(isinstance(x, Call) for x in nested(s)) or keep(s)):
            out.append(s)
        elif isinstance(s, If):
            written = {repr(x.target) for x in nested(s) if isinstance(x, Assign)}
            assert not any(w in repr(s.cond) for w in written), f"branch assigns its condition: {s}"
            both = s.cond if cond is None else and_(cond, s.cond)
            other = not_(s.cond) if cond is None else and_(cond, not_(s.cond))
            mine = scratch | frozenset(s.own)
            out += converted(s.then, both, own=own, scratch=mine)
            out += converted(s.orelse, other, own=own, scratch=scratch)
        elif isinstance(s, Assign) and s.target.name in (
            own if isinstance(s.target, Var) else scratch
        ):
            out.append(s)
        elif isinstance(s, Assign) and cond is not None:
            out.append(Assign(s.target, Sel(cond, s.value, s.target), s.note))
        elif isinstance(s, For) and cond is not None:
            scoped = own | frozenset(s.locals)  # a loop's scoped values are its own
            body = tuple(converted(s.body, cond, own=scoped, scratch=scratch))
            out.append(For(s.var, s.n, body, s.locals, s.type, s.start))
        else:
            out.append(s)
    return out


__all__ = ["At", "LanePrinter", "LanesPrinter", "Row", "Var"]
