"""A scene's integrators as IR functions, and their text in each target.

The shared functions a file defines are those its methods call (C and
Fortran refuse an unused static or private procedure under -Werror).
rodas4 and radau5 are still Jinja templates: TEMPLATE_CALLS names what
they call here.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from gyrogen.codegen.integrators import common, explicit, linear, pair, rosenbrock
from gyrogen.codegen.ir.c import CPrinter
from gyrogen.codegen.ir.fortran import FortranPrinter
from gyrogen.codegen.ir.lanes import LanesPrinter
from gyrogen.codegen.ir.nodes import Decl, Func
from gyrogen.methods import Method
from gyrogen.symbolic.blocks import Blocks

TEMPLATE_CALLS = {
    "radau": {
        "ode_start",
        "step_underflow",
        "accept_step",
        "gimbal_lock",
        "all_finite",
        "lu_decompose",
        "lu_solve",
    },
}


def calls(funcs: list[Func]) -> set[str]:
    return set(re.findall(r"(?:Fn|Call)\(name='(\w+)'", repr([f.body for f in funcs])))


@dataclass(frozen=True)
class Program:
    shared: list[Func]
    fixed: list[Func]
    pairs: list[Func]
    implicit: list[Func]
    lanes: list[Func]
    state: dict[str, Decl]
    krows: int


def program(
    methods: list[Method], quaternion: bool, uses_time: bool = False, blocks: Blocks | None = None
) -> Program:
    pairs = [m for m in methods if m.pair]
    krows = explicit.rows(pairs) if pairs else 0
    fixed = [explicit.fixed(m, quaternion) for m in methods if m.fixed_step]
    integrate = [pair.integrate(m, quaternion, krows) for m in pairs]
    lanes = [pair.lanes_step(m, quaternion) for m in pairs]
    implicit: list[Func] = []
    for m in methods:
        if m.rosenbrock:
            implicit += [
                rosenbrock.trial(m, uses_time),
                rosenbrock.integrate(m, quaternion, uses_time),
            ]
    adaptive = any(not m.fixed_step for m in methods)
    candidates = common.shared(quaternion, adaptive, True)
    if blocks is not None:
        candidates += [linear.decompose(blocks), linear.solve(blocks, len(blocks.end))]
    wanted = calls(fixed + integrate + implicit + lanes)
    for m in methods:
        wanted |= TEMPLATE_CALLS["radau"] if m.radau else set()
    for f in reversed(candidates):  # callers come after what they call
        if f.name in wanted:
            wanted |= calls([f])
    shared = [f for f in candidates if f.name in wanted]
    return Program(shared, fixed, integrate, implicit, lanes, pair.lane_state(krows), krows)


def c_text(p: Program, prefix: str, macro: str) -> dict[str, object]:
    c = CPrinter(prefix, macro, {})
    lanes = LanesPrinter(prefix, macro, {}, p.state)
    fields = []
    for d in p.state.values():
        dims = "".join(f"[{c.extent(n)}]" for n in d.shape)
        fields.append(
            f"{'double' if d.type == 'double' else 'long' if d.type == 'long' else 'int'} "
            f"{lanes.field(d.name).removeprefix('L->')}{dims}[{macro}_LANES];"
        )
    return {
        "shared": "\n".join(c.function(f) for f in p.shared),
        "fixed": {f.name.removesuffix("_steps"): c.function(f) for f in p.fixed},
        "pairs": {f.name.removesuffix("_integrate"): c.function(f) for f in p.pairs},
        "implicit": {f.name: c.function(f) for f in p.implicit},
        "lanes": {f.name.removesuffix("_step_lanes"): lanes.function(f) for f in p.lanes},
        "fields": fields,
        "krows": p.krows,
    }


def fortran_text(p: Program, prefix: str, macro: str) -> dict[str, object]:
    f = FortranPrinter(prefix, macro, {})
    return {
        "shared": "\n".join(f.function(x) for x in p.shared),
        "fixed": {x.name.removesuffix("_steps"): f.function(x) for x in p.fixed},
        "pairs": {x.name.removesuffix("_integrate"): f.function(x) for x in p.pairs},
        "implicit": {x.name: f.function(x) for x in p.implicit},
        "krows": p.krows,
    }
