"""The diagonal blocks of the implicit method's iteration matrix.

Rodas4 solves E k = b with E = I/(h gamma) - J at every stage. In state order
the gyrostat's J is block upper triangular: the speeds' derivatives do not
depend on the attitude or the position, and among the angles only q2 and q3
feed back on each other. Partial pivoting then never needs a row from a
later block and L has no entry outside the diagonal blocks, so the generated
LU eliminates within a block only and the forward substitution stops at the
block's first column: about sum(size^2) n work instead of n^3 / 3. The
solves are unrolled over the entries that can be nonzero.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import sympy as sm


@dataclass(frozen=True)
class Blocks:
    """The diagonal blocks [start, end) of a matrix with J's pattern."""

    spans: tuple[tuple[int, int], ...]
    upper: tuple[tuple[int, ...], ...]
    """Per row i: the columns j > i where U can be nonzero: the rest of the
    block (fill-in), and beyond it any column some row of the block uses."""
    below: tuple[tuple[int, ...], ...] = ()
    """Per column k: the rows past k's block where L can be nonzero (an
    augmented system's coupling, diagonal_blocks' coupled_from, and its
    fill-in); empty for a block upper triangular matrix."""

    @property
    def start(self) -> list[int]:
        """Per row: the first row (and column) of its block."""
        return [s for s, e in self.spans for _ in range(s, e)]

    @property
    def end(self) -> list[int]:
        """Per row: one past the last row of its block."""
        return [e for s, e in self.spans for _ in range(s, e)]

    @property
    def lower(self) -> list[list[int]]:
        """Per row i: the columns j < i where L can be nonzero: those below
        which it is coupled (below), then its block's."""
        coupled: list[list[int]] = [[] for _ in self.start]
        for k, rows in enumerate(self.below):
            for i in rows:
                coupled[i].append(k)
        return [coupled[i] + list(range(s, i)) for i, s in enumerate(self.start)]


def diagonal_blocks(entries: Sequence[sm.Expr], n: int, coupled_from: int = 0) -> Blocks:
    """The finest partition of range(n) into intervals such that every
    nonzero J[i][j] below the diagonal (j < i, row-major entries) has i and j
    in one interval. A full pattern gives one block: the dense LU.

    With coupled_from (an augmented system: x, then its variational part,
    which reads x while x reads none of it), an entry with j < coupled_from
    <= i joins no blocks: the decomposition eliminates it as a row below
    its column's block (Blocks.below), pivoting within the blocks still."""
    if len(entries) != n * n:
        raise ValueError(f"expected {n * n} Jacobian entries, got {len(entries)}")

    def counts(i: int, j: int) -> bool:
        return entries[i * n + j] != 0 and not j < coupled_from <= i

    lowest = [max([j, *(i for i in range(j + 1, n) if counts(i, j))]) for j in range(n)]
    spans, start, end = [], 0, 0
    for k in range(n):
        end = max(end, lowest[k] + 1)
        if k + 1 == end:
            spans.append((start, end))
            start = end
    upper = []
    for s, e in spans:
        used = {j for r in range(s, e) for j in range(e, n) if entries[r * n + j] != 0}
        upper += [tuple(j for j in range(i + 1, n) if j < e or j in used) for i in range(s, e)]
    if not coupled_from:
        return Blocks(tuple(spans), tuple(upper))
    return Blocks(tuple(spans), tuple(upper), _below(entries, n, spans, upper))


def _below(
    entries: Sequence[sm.Expr],
    n: int,
    spans: list[tuple[int, int]],
    upper: list[tuple[int, ...]],
) -> tuple[tuple[int, ...], ...]:
    """Per column k, the rows past k's block that are nonzero in column k
    when the decomposition reaches it: the coupling entries, and what
    eliminating earlier columns fills in (row k's U pattern, upper[k])."""
    nonzero = {(i, j) for i in range(n) for j in range(n) if entries[i * n + j] != 0}
    end = [e for s, e in spans for _ in range(s, e)]
    out = []
    for k in range(n):
        rows = tuple(i for i in range(end[k], n) if (i, k) in nonzero)
        nonzero |= {(i, c) for i in rows for c in upper[k]}
        out.append(rows)
    return tuple(out)
