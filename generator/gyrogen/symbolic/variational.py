"""The variational equations: Phi' = J_x Phi, S' = J_x S + J_p.

Phi = dx(t)/dx0 (nx columns, "state" in the scene's wrt) and S = dx(t)/dp
(one column per runtime parameter p in wrt) are integrated beside x as one
augmented system, x first: y = (x, then the entries of Phi and S that can be
nonzero, column by column). An entry that no path of the Jacobian's pattern
reaches from its column's start (Phi(t0) = I, S(t0) = 0 with J_p's rows as
sources) is zero for all t: it is not integrated, and a product with a
structural zero of J_x is not written.

J_x is the derivative of the hoisted rhs (it reads the same constants), and
J_p the chain rule through them: d f / d p = sum_m d f / d c_m * d c_m / d p,
each d c_m / d p a new constant of setup (parameter-only work, once). The
augmented rhs is one block, f and the variational part under one CSE, so the
variational part reuses what f computes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import sympy as sm

from gyrogen.scene.rules import WRT_STATE
from gyrogen.symbolic.derivative import Derivatives
from gyrogen.symbolic.hoist import Hoister, constants

IMPLICIT_MAX_NY = 128
"""The largest augmented system the implicit methods integrate: they hold
ny x ny matrices (the Jacobian, E's LU: 128 KB each at 128) on the stack and
write every entry of the Jacobian per call."""


@dataclass(frozen=True)
class Variational:
    """The augmented system's layout and its derivatives (before CSE)."""

    columns: tuple[str, ...]
    """Phi's columns: the states' names ("state" in wrt, wherever it stands),
    then the parameters', in wrt's order."""
    entries: tuple[tuple[int, int], ...]
    """(row, column) of each integrated entry of Phi, column by column: y[nx + r]
    holds Phi[entries[r]]; every other entry is 0 for all t."""
    symbols: tuple[sm.Symbol, ...]
    """The entries as states of the augmented system, phi_<row>_<column>."""
    derivatives: tuple[sm.Expr, ...]
    """d/dt of each entry, in states, entries and constants."""
    error: str
    """What the step-size control measures: "all" (y) or "state" (x alone)."""
    state_columns: int
    """How many of the columns are the initial state's: nx or 0."""

    @property
    def nv(self) -> int:
        return len(self.entries)


def pattern(jac: Sequence[sm.Expr], n: int) -> list[set[int]]:
    """Per row i: the columns j with J[i][j] not structurally zero."""
    return [{j for j in range(n) if jac[i * n + j] != 0} for i in range(n)]


def reached(sources: set[int], rows: list[set[int]]) -> set[int]:
    """The rows a perturbation of sources reaches through the pattern."""
    out = set(sources)
    changed = True
    while changed:
        changed = False
        for i, cols in enumerate(rows):
            if i not in out and cols & out:
                out.add(i)
                changed = True
    return out


def total_derivative(value: sm.Expr, p: sm.Symbol, lumped: dict[sm.Symbol, sm.Expr]) -> sm.Expr:
    """d value / d p through the lumped scalars value reads (each in
    parameters and possibly other lumped scalars)."""
    out = sm.diff(value, p)
    for name in value.free_symbols & set(lumped):
        inner = total_derivative(lumped[name], p, lumped)
        if inner != 0:
            out += sm.diff(value, name) * inner
    return out


def variational(
    f: Sequence[sm.Expr],
    states: Sequence[sm.Symbol],
    params: Sequence[sm.Symbol],
    wrt: Sequence[str],
    error: str,
    hoister: Hoister,
    lumped: dict[sm.Symbol, sm.Expr],
) -> Variational:
    """The variational system of f (hoisted: in states, inputs and the
    constants of hoister), its new constants d c_m / d p added to hoister."""
    n = len(states)
    d = Derivatives()
    jac = [d.of(fi, xj) for fi in f for xj in states]
    rows = pattern(jac, n)
    by_name = {p.name: p for p in params}
    columns: list[str] = []
    sources: list[set[int]] = []
    jp: list[list[sm.Expr]] = []
    state_first = sorted(wrt, key=lambda name: name != WRT_STATE)  # stable: wrt's order
    for name in state_first:
        if name == WRT_STATE:
            columns += [s.name for s in states]
            sources += [{k} for k in range(n)]
            jp += [[sm.S.Zero] * n for _ in range(n)]
            continue
        col = _parameter_column(f, by_name[name], hoister, lumped)
        columns.append(name)
        sources.append({i for i, e in enumerate(col) if e != 0})
        jp.append(col)
    entries = [(i, k) for k, src in enumerate(sources) for i in sorted(reached(src, rows))]
    symbols = {e: sm.Symbol(f"phi_{e[0]}_{e[1]}", real=True) for e in entries}
    derivatives = []
    done: dict[tuple[int, int], sm.Expr] = {}
    chains = _chains(jac, rows, n)
    for i, k in entries:
        if i in chains:
            l, r, rest = chains[i]
            terms = [rest[j] * symbols[(j, k)] for j in sorted(rest) if (j, k) in symbols]
            base = done.get((l, k), sm.S.Zero) - jp[k][l]
            expr = sm.Add(r * base, *terms, jp[k][i])
        else:
            terms = [jac[i * n + j] * symbols[(j, k)] for j in sorted(rows[i]) if (j, k) in symbols]
            expr = sm.Add(*terms, jp[k][i])
        done[(i, k)] = expr
        derivatives.append(expr)
    n_state = n if WRT_STATE in wrt else 0
    return Variational(
        tuple(columns), tuple(entries), tuple(symbols.values()), tuple(derivatives), error, n_state
    )


def _parameter_column(
    f: Sequence[sm.Expr],
    p: sm.Symbol,
    hoister: Hoister,
    lumped: dict[sm.Symbol, sm.Expr],
) -> list[sm.Expr]:
    """J_p's column of p: sum over the constants c_m that f reads of
    d f / d c_m times a new constant d c_m / d p (numbers stay numbers)."""
    read = set().union(*(e.free_symbols for e in f))
    named = constants(len(hoister.values))
    slopes: dict[sm.Symbol, sm.Expr] = {}
    for c, value in zip(named, list(hoister.values), strict=True):
        if c not in read:
            continue
        slope = total_derivative(value, p, lumped)
        if slope != 0:
            slopes[c] = hoister.symbol_for(slope, simplify=False)
    d = Derivatives()
    return [sm.Add(*(d.of(e, c) * s for c, s in slopes.items())) for e in f]


CHAIN_OPS = 40
"""The largest entry of J (sympy's count_ops) _chains compares: their
ratios and differences are cancelled, which takes minutes on a cluster's
entries of hundreds of operations."""
Chain = tuple[int, sm.Expr, dict[int, sm.Expr]]
"""An earlier row l, a factor r and the rest: J's row i is r J's row l plus
the rest (by column)."""


def _chains(jac: list[sm.Expr], rows: list[set[int]], n: int) -> dict[int, Chain]:
    """The rows of J (n x n, its pattern rows) that are a multiple of an
    earlier one plus fewer terms than they hold (a chain rule the
    derivatives wrote out: q3' = u2 - sin(q2) q1' gives J's row of q3 as
    -sin(q2) times q1's plus two terms, where it held five): each entry
    (i, k) of Phi' is then r times (l, k)'s plus the rest, one product
    where there were several. The factor is a ratio of two entries with no
    denominator (the rewritten row divides by nothing the old one did not)
    and row l reads no state row i does not (Phi' reads the entries it read);
    each row's best (the fewest terms left), on rows not rewritten; rows
    whose entries are small (CHAIN_OPS) alone."""
    out: dict[int, Chain] = {}
    small = [i for i in range(n) if all(sm.count_ops(jac[i * n + j]) <= CHAIN_OPS for j in rows[i])]
    for i in small:
        own = sorted(rows[i])
        best: Chain | None = None
        for l in (l for l in small if l < i):
            common = [j for j in own if j in rows[l]]
            if l in out or len(common) < 2 or not rows[l] <= rows[i]:
                continue
            by_ratio: dict[sm.Expr, int] = {}
            for j in common:
                r = sm.cancel(jac[i * n + j] / jac[l * n + j])
                by_ratio[r] = by_ratio.get(r, 0) + 1
            r, count = max(by_ratio.items(), key=lambda item: item[1])
            if count < 2 or sm.fraction(r)[1] != 1:
                continue
            rest = {j: e for j in own
                    if (e := sm.cancel(jac[i * n + j] - r * jac[l * n + j])) != 0}  # fmt: skip
            if 1 + len(rest) < len(own) and (best is None or len(rest) < len(best[2])):
                best = (l, r, rest)
        if best is not None:
            out[i] = best
    return out
