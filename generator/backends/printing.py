"""What the two backends share: one statement list per generated function.

A printer turns one expression into text; the templates lay out the file.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import sympy as sm

from gyrogen.optimize import Block


@dataclass(frozen=True)
class Statement:
    name: str
    code: str
    """The whole assignment as the language writes it (possibly several lines)."""
    declare: bool
    """A new local (true) or a store into an output array (false)."""


Assign = Callable[[str, sm.Expr], str]


def statements(block: Block, output: Callable[[int], str], assign: Assign) -> list[Statement]:
    """Temporaries as locals, then one store per output."""
    temps = [Statement(str(a.lhs), assign(str(a.lhs), a.rhs), True) for a in block.temporaries]
    stores = []
    for i, e in enumerate(block.outputs):
        lhs = output(i)
        stores.append(Statement(lhs, assign(lhs, e), False))
    return temps + stores


def used_states(block: Block, states: tuple[sm.Symbol, ...]) -> list[int]:
    """Indices of the states that appear in the block: only those become
    locals, so the compilers see no unused variable."""
    free: set[sm.Basic] = set()
    for a in block.temporaries:
        free |= a.rhs.free_symbols
    for e in block.outputs:
        free |= e.free_symbols
    return [i for i, s in enumerate(states) if s in free]
