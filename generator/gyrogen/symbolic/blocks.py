"""The diagonal blocks of the implicit method's iteration matrix.

Rodas4 solves E k = b with E = I/(h gamma) - J at every stage. In state order
the gyrostat's J is block upper triangular: the speeds' derivatives do not
depend on the attitude or the position, and among the angles only q2 and q3
feed back on each other. Partial pivoting then never needs a row from a
later block and L has no entry outside the diagonal blocks, so the generated
LU eliminates within a block only and the forward substitution stops at the
block's first column: about sum(size^2) n work instead of n^3 / 3. The
solves are unrolled over the entries that can be nonzero.

An augmented system (x, then the variational part, which reads x and
which x does not read) is block lower triangular on top: its coupling
is not factored but subtracted in the solve, x's solution first.
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
    coupled: tuple[tuple[int, ...], ...] = ()
    """Per row of an augmented system's part past coupled_from: the columns
    left of coupled_from where the matrix can be nonzero (its reads of x).
    The decomposition leaves them as they are; the solve subtracts them,
    times x's solution, from the row before it solves the part's blocks
    (block forward substitution: no fill-in, and a row exchange within a
    block of the part never meets them). Empty for a block upper
    triangular matrix."""
    coupled_from: int = 0

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
        """Per row i: the columns j < i where L can be nonzero: its block's."""
        return [list(range(s, i)) for i, s in enumerate(self.start)]

    @property
    def stored(self) -> list[list[int]]:
        """Per row: the columns the decomposition and the solves read and
        write: its coupled ones, its block's and U's beyond it (the same for
        every row of a block, so that row exchanges stay among them). Every
        entry of J that can be nonzero is one of them; the rest of the
        matrix is never touched."""
        coupled = self.coupled or tuple(() for _ in self.upper)
        return [
            [*cs, *range(s, e), *(j for j in up if j >= e)]
            for cs, s, e, up in zip(coupled, self.start, self.end, self.upper, strict=True)
        ]

    @property
    def parts(self) -> list[tuple[int, int]]:
        """The rows [start, end) solved one after the other: x, then what
        reads it (coupled_from), or every row at once."""
        n = len(self.upper)
        return [(0, self.coupled_from), (self.coupled_from, n)] if self.coupled_from else [(0, n)]


def diagonal_blocks(entries: Sequence[sm.Expr], n: int, coupled_from: int = 0) -> Blocks:
    """The finest partition of range(n) into intervals such that every
    nonzero J[i][j] below the diagonal (j < i, row-major entries) has i and j
    in one interval. A full pattern gives one block: the dense LU.

    With coupled_from (an augmented system: x, then its variational part,
    which reads x while x reads none of it), an entry with j < coupled_from
    <= i joins no blocks: it is one of the row's coupled columns
    (Blocks.coupled), which the decomposition does not eliminate."""
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
    coupled = tuple(
        tuple(j for j in range(coupled_from) if i >= coupled_from and entries[i * n + j] != 0)
        for i in range(n)
    )
    return Blocks(tuple(spans), tuple(upper), coupled, coupled_from)
