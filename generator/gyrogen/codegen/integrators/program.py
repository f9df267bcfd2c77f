"""A scene's integrators as IR functions, and their text in each target.

The shared functions a file defines are those its methods call (C and
Fortran refuse an unused static or private procedure under -Werror).
The templates only place these texts and the public wrappers.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass, field, replace

from gyrogen.abi_groups import StateKind
from gyrogen.codegen.integrators import (
    common,
    driver,
    elementary,
    explicit,
    handover,
    intrinsics,
    linear,
    pair,
    radau,
    radau_step,
    rosenbrock,
    taylor,
    taylor_jet,
    trig,
)
from gyrogen.codegen.integrators.tables import Table, lookup
from gyrogen.codegen.ir.c import CPrinter
from gyrogen.codegen.ir.fortran import FortranPrinter
from gyrogen.codegen.ir.lanes import LanePrinter, LanesPrinter
from gyrogen.codegen.ir.nodes import At, Decl, Func, Int, S, called, substituted, walk
from gyrogen.methods import Kind, Method
from gyrogen.symbolic.blocks import Blocks
from gyrogen.symbolic.jet import Jet


@dataclass(frozen=True)
class Given:
    """What a method's description reads of the scene."""

    quaternion: bool
    uses_time: bool
    krows: int
    """The stage rows the pairs' k holds (the most any pair needs)."""
    jet: Jet | None
    events: driver.Grid | None = None
    """The scene's events: each adaptive method's _events twin besides."""
    blocks: Blocks | None = None
    """The Jacobian's diagonal blocks (the implicit methods' LU)."""
    knots: driver.Knots = ()
    """The scene's table times, which no adaptive step crosses."""
    asked: frozenset[str] = frozenset()
    """The methods whose lanes the scene asks for (its `lanes`, Method.laned)."""


@dataclass(frozen=True)
class Parts:
    """A method's functions: one trajectory's, and over the lanes of a batch
    with what struct lanes holds for them and their start in a lane."""

    single: list[Func]
    lanes: list[Func] = field(default_factory=list)
    state: list[Decl] = field(default_factory=list)
    init: list[S] = field(default_factory=list)
    """Beyond common.start_state: a trajectory's values at t0 in its lane."""


def _fixed(m: Method, g: Given) -> Parts:
    return Parts([explicit.fixed(m, g.quaternion)])


def _pair(m: Method, g: Given) -> Parts:
    common_start = common.start_state()
    return Parts(
        [
            pair.integrate(m, g.quaternion, g.krows, knots=g.knots),
            pair.integrate(m, g.quaternion, g.krows, True, g.knots),
            *([pair.integrate(m, g.quaternion, g.krows, g.events, g.knots)] if g.events else []),
        ],
        [
            pair.lanes_step(m, g.quaternion, knots=g.knots),
            pair.lanes_step(m, g.quaternion, True, g.knots),
            *([pair.lanes_step(m, g.quaternion, g.events, g.knots)] if g.events else []),
        ],
        init=[s for s in pair.start_state() if s not in common_start],
    )


def _rosenbrock(m: Method, g: Given) -> Parts:
    assert g.blocks is not None, "an implicit method needs the Jacobian's blocks"
    return Parts(
        [
            rosenbrock.trial(m, g.uses_time),
            rosenbrock.trial(m, g.uses_time, grid=True),
            rosenbrock.integrate(m, g.quaternion, g.uses_time, knots=g.knots),
            rosenbrock.integrate(m, g.quaternion, g.uses_time, True, g.knots),
            *(
                [rosenbrock.integrate(m, g.quaternion, g.uses_time, g.events, g.knots)]
                if g.events
                else []
            ),
        ],
        [
            rosenbrock.lanes_step(m, g.quaternion, g.uses_time, knots=g.knots),
            rosenbrock.lanes_step(m, g.quaternion, g.uses_time, True, g.knots),
            *(
                [rosenbrock.lanes_step(m, g.quaternion, g.uses_time, g.events, g.knots)]
                if g.events
                else []
            ),
        ],
        rosenbrock.lane_state(m, g.uses_time),
        rosenbrock.lane_start(m),
    )


def _radau(m: Method, g: Given) -> Parts:
    assert g.blocks is not None, "an implicit method needs the Jacobian's blocks"
    single = [
        radau.factor(m),
        radau.newton(m),
        radau.error(m),
        radau_step.integrate(m, g.quaternion, knots=g.knots),
        radau_step.integrate(m, g.quaternion, True, g.knots),
        *([radau_step.integrate(m, g.quaternion, g.events, g.knots)] if g.events else []),
    ]
    if not m.laned(g.asked):  # its batches: a loop of single calls
        return Parts(single)
    return Parts(
        single,
        [
            radau_step.lanes_step(m, g.quaternion, g.blocks, knots=g.knots),
            radau_step.lanes_step(m, g.quaternion, g.blocks, True, g.knots),
            *(
                [radau_step.lanes_step(m, g.quaternion, g.blocks, g.events, g.knots)]
                if g.events
                else []
            ),
        ],
        radau_step.lane_state(m),
        radau_step.lane_start(m),
    )


def _taylor(m: Method, g: Given) -> Parts:
    assert g.jet is not None, "a Taylor method needs the scene's jet"
    common_start = common.start_state()
    return Parts(
        taylor.functions(m, g.jet, g.quaternion, g.events),
        [
            taylor_jet.jet_lanes(m, g.jet),
            taylor.lanes_step(m, g.jet, g.quaternion),
            taylor.lanes_step(m, g.jet, g.quaternion, grid=True),
            *([taylor.lanes_step(m, g.jet, g.quaternion, g.events)] if g.events else []),
        ],
        taylor.lane_state(m, g.jet, g.events is not None),
        [s for s in taylor.start_state() if s not in common_start],
    )


DESCRIPTIONS: dict[Kind, Callable[[Method, Given], Parts]] = {
    "fixed": _fixed,
    "pair": _pair,
    "rosenbrock": _rosenbrock,
    "radau": _radau,
    "taylor": _taylor,
}
"""Each kind of method (gyrogen.methods.Method.kind) and its description."""


@dataclass(frozen=True)
class Program:
    shared: list[Func]
    methods: list[Func]
    """One trajectory's functions of every method (<method>_...)."""
    lanes: list[Func]
    lanes_shared: list[Func]
    """What the lanes' steps call over lanes (E's LU and its solve), out of
    line as the scalar ones."""
    state: dict[str, Decl]
    """What struct lanes holds per lane (its arrays [..][LANES])."""
    init: list[S]
    """A trajectory's values at t0 in its lane (lane_start)."""
    handover: list[Func] = field(default_factory=list)
    """A trajectory into a lane and its results back (integrators.handover)."""


def program(
    methods: list[Method],
    quaternion: bool,
    uses_time: bool = False,
    blocks: Blocks | None = None,
    jet: Jet | None = None,
    events: driver.Grid | None = None,
    measured: int | None = None,
    kinds: Sequence[StateKind] = (),
    knots: driver.Knots = (),
    asked: Collection[str] = (),
) -> Program:
    """The methods' functions, the lanes' and the shared ones they call;
    measured: how many leading states the error norms measure (all: None);
    kinds: each state's (abi_groups.state_kind), the error scales' caps
    (common.angle_table, declared by each function that reads it); knots:
    the scene's table times, which no adaptive step crosses (driver.Knots);
    asked: the methods whose lanes the scene asks for (its `lanes`: radau5's
    are generated only then, Method.laned)."""
    pairs = [m for m in methods if m.pair]
    krows = explicit.rows(pairs) if pairs else 0
    given = Given(quaternion, uses_time, krows, jet, events, blocks, knots, frozenset(asked))
    parts = [DESCRIPTIONS[m.kind](m, given) for m in methods]
    single = [f for p in parts for f in p.single]
    lanes = [f for p in parts for f in p.lanes]
    state = pair.lane_state(given.krows, pairs)
    for d in (d for p in parts for d in p.state):
        state[d.name] = larger(state.get(d.name), d)
    state |= {d.name: d for d in driver.lane_grid_state()} if lanes else {}
    if events is not None and any(f.name.endswith("_events_step_lanes") for f in lanes):
        state |= {d.name: d for d in driver.lane_event_state(events)}
    init = common.start_state() if lanes else []
    for s in (s for p in parts for s in p.init):
        init += [] if s in init else [s]
    adaptive = any(not m.fixed_step for m in methods)
    candidates = [*common.shared(quaternion, adaptive, True), *elementary.functions()]
    candidates += [driver.grid_checks()] if adaptive else []
    candidates += [driver.knot_function(knots)] if knots and adaptive else []
    if blocks is not None:
        nx = len(blocks.end)
        candidates += [
            linear.shift(blocks, nx),
            linear.shift_complex(blocks, nx),
            linear.decompose(blocks, nx),
            linear.solve(blocks, nx),
            linear.decompose_complex(blocks, nx),
            linear.solve_complex(blocks, nx),
        ]
    wanted = called(single + lanes)
    for f in reversed(candidates):  # callers come after what they call
        if f.name in wanted:
            wanted |= called([f])
    shared = [f for f in candidates if f.name in wanted]
    over_lanes = called(lanes)  # a call of f over lanes prints f_lanes(L, ...)
    lanes_shared = [
        f for f in lane_candidates(blocks) if f.name.removesuffix("_lanes") in over_lanes
    ]
    size = common.NX if measured is None else Int(measured)
    single, lanes, shared = ([with_caps(substituted(f, common.NE, size), kinds) for f in fs]
                             for fs in (single, lanes, shared))  # fmt: skip
    events_held = int(state["ev_old"].shape[0]) if "ev_old" in state else 0
    handed = handover.functions(state, init, bool(pairs), events_held) if lanes else []
    return Program(shared, single, lanes, lanes_shared, state, init, handed)


def lane_candidates(blocks: Blocks | None) -> list[Func]:
    """The shared functions over lanes a step may call."""
    if blocks is None:
        return []
    nx = len(blocks.end)
    return [
        linear.decompose_lanes(blocks, nx),
        linear.solve_lanes(blocks, nx),
        linear.decompose_complex_lanes(blocks, nx),
        linear.solve_complex_lanes(blocks, nx),
    ]


def larger(old: Decl | None, new: Decl) -> Decl:
    """A value of struct lanes two methods hold: the one with more rows (k:
    a pair's stages and a Rosenbrock method's)."""
    if old is None or old == new:
        return new
    assert old.shape[1:] == new.shape[1:] and old.type == new.type, (old, new)
    return max(old, new, key=lambda d: int(d.shape[0]))


def with_caps(f: Func, kinds: Sequence[StateKind]) -> Func:
    """f with the error scales' angles (common.angle_table) among its locals
    when it reads them."""
    if not any(isinstance(n, At) and n.name == common.ANGLE.name for s in f.body for n in walk(s)):
        return f
    assert kinds, f"{f.name} reads the angles: program needs the states' kinds"
    return replace(f, locals=(*f.locals, common.angle_table(kinds)))


def by_method(funcs: list[Func], text: Callable[[Func], str]) -> dict[str, str]:
    """The functions of each method (named <method>_...), as one text."""
    out: dict[str, str] = {}
    for f in funcs:
        name = f.name.split("_")[0]
        out[name] = out.get(name, "") + ("\n" if name in out else "") + text(f)
    return out


def intrinsics_of(funcs: list[Func], printer: CPrinter | FortranPrinter) -> list[Func]:
    """The definitions of gyrogen.codegen.integrators.intrinsics that funcs call in
    printer's target."""
    spelled = {printer.spellings.get(n, n) for n in called(funcs)}
    return [f for f in intrinsics.functions() if f.name in spelled]


def methods_text(
    p: Program, printer: CPrinter | FortranPrinter, others: list[Func] | None = None
) -> dict[str, object]:
    """The intrinsics the file's functions (with others: the lanes, the
    Jacobian, those too) call and the shared functions, each as one text,
    and each method's functions (<method>_...)."""
    every = [*p.shared, *p.methods, *(others or [])]
    return {
        "intrinsics": "\n".join(printer.function(f) for f in intrinsics_of(every, printer)),
        "shared": "\n".join(printer.function(f) for f in p.shared),
        "methods": by_method(p.methods, printer.function),
    }


def c_text(
    p: Program, prefix: str, macro: str, model: list[Func] | None = None
) -> dict[str, object]:
    """The file's text (model: the functions printed from the model beside
    the integrators, the Jacobian and the pairs' rhs over lanes)."""
    c = CPrinter(prefix, macro, {})
    lanes = LanesPrinter(prefix, macro, {}, p.state)
    lane = LanePrinter(prefix, macro, {}, p.state | handover.STRUCT)
    fields = []
    # the 8-byte arrays first, each LANES doubles long, so that in a struct
    # aligned to 64 bytes every one starts on a cache line (ints, then what
    # every lane shares, last)
    for d in sorted(p.state.values(), key=lambda d: (lanes.shared(d.name), d.type != "double"
                                                     and d.type != "long")):  # fmt: skip
        name = lanes.field(d.name).removeprefix("L->")
        if lanes.shared(d.name):
            fields.append(f"{c.declaration(Decl(name, d.type, d.shape, d.intent), True)};")
            continue
        dims = "".join(f"[{c.extent(n)}]" for n in d.shape)
        fields.append(
            f"{'double' if d.type == 'double' else 'long' if d.type == 'long' else 'int'} "
            f"{name}{dims}[{macro}_LANES];"
        )
    return {
        **methods_text(p, c, [*p.lanes, *p.lanes_shared, *(model or [])]),
        "lanes": by_method(p.lanes, lanes.function),
        "lanes_shared": "\n".join(lanes.function(f) for f in p.lanes_shared),
        "lane_names": [f.name for f in p.lanes],
        "fields": fields,
        "handover": "\n".join(
            (c if f.name == "put_result" else lane).function(f) for f in p.handover
        ),
        "lane_events": int(p.state["ev_old"].shape[0]) if "ev_old" in p.state else 0,
    }


def fortran_text(
    p: Program, prefix: str, macro: str, model: list[Func] | None = None
) -> dict[str, object]:
    return methods_text(p, FortranPrinter(prefix, macro, {}), model)


def text(language: str, prefix: str, macro: str, funcs: list[Func]) -> str:
    """funcs as C or Fortran."""
    printer = CPrinter(prefix, macro, {}) if language == "c" else FortranPrinter(prefix, macro, {})
    return "\n".join(printer.function(f) for f in funcs)


def trig_text(language: str, prefix: str, macro: str, used: list[str]) -> str:
    """The sin and cos variants in used, with their reduction and kernels,
    as C or Fortran (gyrogen.codegen.integrators.trig)."""
    return text(language, prefix, macro, trig.functions(prefix, used))


def tables_text(language: str, prefix: str, macro: str, tables: Sequence[Table]) -> str:
    """The tabulated inputs' lookups, as C or Fortran (gyrogen.codegen.integrators.tables)."""
    return text(language, prefix, macro, [lookup(prefix, tb) for tb in tables])
