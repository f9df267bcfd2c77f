"""The LU decompositions the implicit methods solve with, described once.

E = I/(h gamma) - J is block upper triangular in state order
(gyrogen.symbolic.blocks): the decomposition pivots within a row's block;
both it and the solve are unrolled over the entries of L and U that can be
nonzero. An augmented system's rows that read x (Blocks.coupled) are solved
after x, less those reads times x's solution, by their own blocks.
The decompositions, their row exchanges and the solves touch only the
entries Blocks.stored names, and lu_shift builds the iteration matrix
d I - J there alone, not by a pass over all of J (the default scene's
variational unit stores 283 entries of 3,600).
Matrices are flat and row-major, a[i*NX + j], in every target. U = D V is
stored as 1/u_kk on the diagonal and V's u_kj/u_kk above it, so that each
row of the back substitution waits on one multiply-add, not on a divide.
The solves and the complex decomposition say that their arrays never
overlap (Func.restrict): out of line (radau5_integrate and radau5_grid both
call them), gcc otherwise reloads an array after each store to another, and
radau5 took 4-7 % longer a step on stiff_wheel (make bench-methods); the
real decomposition has one array of doubles.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from gyrogen.codegen.integrators.common import NX
from gyrogen.codegen.ir.nodes import (
    Bool,
    Comment,
    Decl,
    E,
    For,
    Func,
    If,
    Int,
    Num,
    Return,
    S,
    Var,
    assign,
    cmp,
    fn,
    not_,
)
from gyrogen.symbolic.blocks import Blocks

i, j, p = Var("i"), Var("j"), Var("p")
Entry = Callable[[int | E], E]
"""An entry's flat index (k * NX + j) -> its size, for the pivot search."""


def swap_rows(names: tuple[str, ...], k: int, blocks: Blocks, nx: int) -> S:
    """Rows k and p of each matrix exchanged where the block's rows are
    stored (Blocks.stored): its columns, as a loop, and U's beyond it; the
    coupled ones stay (the solve reads them in the rows' first order)."""
    s, e = blocks.start[k], blocks.end[k]
    swap = Var("swap")

    def exchange(a: Var, kj: E, pj: E) -> tuple[S, ...]:
        return (assign(swap, a[kj]), assign(a[kj], a[pj]), assign(a[pj], swap))

    arrays = [Var(a) for a in names]
    block = tuple(st for a in arrays for st in exchange(a, k * NX + j, p * NX + j))
    beyond = [c for c in blocks.upper[k] if c >= e]
    return If(cmp(p, "!=", k), (
        For("j", Int(e), block, start=Int(s)),
        *(st for c in beyond for a in arrays for st in exchange(a, Int(k * nx + c), p * NX + c)),
    ))  # fmt: skip


@dataclass(frozen=True)
class Elimination:
    """What a decomposition does to entries, by their flat indices: the
    real one's and the complex one's, with one pivoting and one order."""

    names: tuple[str, ...]
    size: Entry
    inverse: Callable[[int], tuple[S, ...]]
    """u_kk := 1/u_kk."""
    multiplier: Callable[[E, int], tuple[S, ...]]
    """l_ik := a_ik / u_kk (a product with the inverse), held in locals too."""
    update: Callable[[E, int], tuple[S, ...]]
    """a_ij -= l_ik u_kj (row i's entry, row k's)."""
    scale: Callable[[int, int], tuple[S, ...]]
    """u_kj := u_kj / u_kk (row k's entry, the diagonal)."""


def eliminate(blocks: Blocks, nx: int, how: Elimination) -> tuple[S, ...]:
    """Gaussian elimination with partial pivoting within the diagonal blocks,
    unrolled over the columns k and over the entries of U that can be
    nonzero (Blocks.upper: what the solves read); the rows of a block as a
    loop. Entries outside that pattern stay zero, as they would under the
    loop over every column (l_ik times a zero); an augmented system's
    coupled entries (Blocks.coupled) stay as they are, for the solve."""
    body: list[S] = []
    piv = Var("piv")
    for k in range(nx):
        e, kk, up = blocks.end[k], k * nx + k, blocks.upper[k]
        if e - k > 1:
            body += [
                assign(p, k),
                For("i", Int(e), (If(cmp(how.size(i * NX + k), ">", how.size(p * NX + k)),
                                     (assign(p, i),)),), start=Int(k + 1)),
                assign(piv[k], p),
                If(not_(cmp(how.size(p * NX + k), ">", 0.0)), (Return(Bool(True), "singular"),)),
                swap_rows(how.names, k, blocks, nx),
                *how.inverse(kk),
                For("i", Int(e), (
                    *how.multiplier(i * NX + k, kk),
                    *(st for c in up for st in how.update(i * NX + c, k * nx + c)),
                ), start=Int(k + 1)),
            ]  # fmt: skip
        else:
            body += [
                assign(piv[k], k),
                If(not_(cmp(how.size(kk), ">", 0.0)), (Return(Bool(True), "singular"),)),
                *how.inverse(kk),
            ]
        body += [st for c in up for st in how.scale(k * nx + c, kk)]
    return (*body, Return(Bool(False)))


def shift(blocks: Blocks, nx: int) -> Func:
    """d I - J where lu_decompose reads it (Blocks.stored), J's other
    entries being zero: the iteration matrix without a pass over all of J."""
    J, d, a = Var("J"), Var("d"), Var("a")
    body = tuple(
        assign(a[q], d - J[q] if c == r else -J[q])
        for r, cols in enumerate(blocks.stored)
        for c in cols
        for q in [r * nx + c]
    )
    params = (Decl("J", "double", ("NX2",)), Decl("d", "double"),
              Decl("a", "double", ("NX2",), "out"))  # fmt: skip
    doc = (
        "a := d I - J at the entries lu_decompose and lu_solve read; J is zero",
        "at the others, which they never touch.",
    )
    return Func("lu_shift", params, body, None, (), doc, restrict=True)


def shift_complex(blocks: Blocks, nx: int) -> Func:
    """lu_shift for (dr + i di) I - J, into ar + i ai; the coupled entries
    are real, -J, and lu_solve_complex reads ar alone there."""
    J, dr, di, ar, ai = (Var(n) for n in ("J", "dr", "di", "ar", "ai"))
    coupled = blocks.coupled or tuple(() for _ in blocks.upper)
    body = tuple(
        st
        for r, cols in enumerate(blocks.stored)
        for c in cols
        for q in [r * nx + c]
        for st in (
            (assign(ar[q], dr - J[q]), assign(ai[q], di))
            if c == r
            else (assign(ar[q], -J[q]),)
            if c in coupled[r]
            else (assign(ar[q], -J[q]), assign(ai[q], 0.0))
        )
    )
    params = (
        Decl("J", "double", ("NX2",)), Decl("dr", "double"), Decl("di", "double"),
        Decl("ar", "double", ("NX2",), "out"), Decl("ai", "double", ("NX2",), "out"),
    )  # fmt: skip
    doc = (
        "lu_shift for the complex matrix ar + i ai := (dr + i di) I - J; ai is",
        "left as it is where the matrix is real, -J, for lu_solve_complex (a row's",
        "reads of the state, in an augmented system).",
    )
    return Func("lu_shift_complex", params, body, None, (), doc, restrict=True)


def decompose(blocks: Blocks, nx: int) -> Func:
    a, m = Var("a"), Var("m")
    how = Elimination(
        names=("a",),
        size=lambda q: fn("abs", a[q]),
        inverse=lambda kk: (assign(a[kk], Num(1.0) / a[kk]),),
        multiplier=lambda ik, kk: (assign(m, a[ik] * a[kk]), assign(a[ik], m)),
        update=lambda ij, kj: (assign(a[ij], a[ij] - m * a[kj]),),
        scale=lambda kj, kk: (assign(a[kj], a[kj] * a[kk]),),
    )
    params = (Decl("a", "double", ("NX2",), "inout"), Decl("piv", "int", ("NX",), "out"))
    locals_ = (Decl("p", "int"), Decl("m", "double"), Decl("swap", "double"))
    doc = (
        "In-place LU decomposition with partial pivoting within the diagonal",
        f"blocks {', '.join(map(str, blocks.spans))}, unrolled over the entries",
        "of U that can be nonzero: L unit lower; U = D V as 1/u_kk and u_kj/u_kk;",
        "row k swapped with piv[k]. 1 when a pivot is zero: singular.",
    )
    return Func("lu_decompose", params, eliminate(blocks, nx, how), "bool", locals_, doc)


def permute(blocks: Blocks, rows: range, names: tuple[Var, ...]) -> list[S]:
    """b's rows exchanged as the decomposition exchanged them: only a row
    with a row below it in its block can have been."""
    piv, swap = Var("piv"), Var("swap")
    return [
        If(cmp(piv[r], "!=", r), tuple(
            s for b in names
            for s in (assign(swap, b[r]), assign(b[r], b[piv[r]]), assign(b[piv[r]], swap))
        ))
        for r in rows if blocks.end[r] - r > 1
    ]  # fmt: skip


def solve(blocks: Blocks, nx: int) -> Func:
    b, lu = Var("b"), Var("lu")
    body: list[S] = []
    for first, end in blocks.parts:
        for r in range(first, end):  # the part's reads of x, solved already
            if blocks.coupled and blocks.coupled[r]:
                value: E = b[r]
                for c in blocks.coupled[r]:
                    value = value - lu[r * nx + c] * b[c]
                body.append(assign(b[r], value))
        body += permute(blocks, range(first, end), (b,))
        for r in range(first, end):
            if blocks.lower[r]:
                value = b[r]
                for c in blocks.lower[r]:
                    value = value - lu[r * nx + c] * b[c]
                body.append(assign(b[r], value))
        for r in range(end - 1, first - 1, -1):
            value = b[r] * lu[r * nx + r]
            for c in reversed(blocks.upper[r]):
                value = value - lu[r * nx + c] * b[c]
            body.append(assign(b[r], value))
    params = (
        Decl("lu", "double", ("NX2",)),
        Decl("piv", "int", ("NX",)),
        Decl("b", "double", ("NX",), "inout"),
    )
    doc = (
        "b := A^-1 b from lu_decompose's factors, unrolled over the entries of L",
        "and V that can be nonzero; each row subtracts the latest b_j last.",
        *(
            (f"Rows 0 .. {blocks.coupled_from - 1} first; then the rows past them, less their",
             "coupled entries times that solution, by their own blocks.")
            if blocks.coupled_from else ()
        ),
    )  # fmt: skip
    locals_ = (Decl("swap", "double"),)
    return Func("lu_solve", params, tuple(body), None, locals_, doc, restrict=True)


def decompose_complex(blocks: Blocks, nx: int) -> Func:
    """lu_decompose for ar + i ai, stored the same way: the pivot is the entry
    of largest |re| + |im| (as radau5.f's DECOMC); 1/u_kk by Smith's division."""
    ar, ai = Var("ar"), Var("ai")
    re, im, r, d = Var("re"), Var("im"), Var("r"), Var("d")
    lr, li, ur, ui = Var("lr"), Var("li"), Var("ur"), Var("ui")

    def inverse(kk: int) -> tuple[S, ...]:
        return (
            Comment("1/u_kk by Smith's division (no overflow in re^2 + im^2)", False),
            assign(re, ar[kk]),
            assign(im, ai[kk]),
            If(cmp(fn("abs", re), ">=", fn("abs", im)), (
                assign(r, im / re), assign(d, re + im * r),
                assign(ar[kk], Num(1.0) / d), assign(ai[kk], -r / d),
            ), (
                assign(r, re / im), assign(d, im + re * r),
                assign(ar[kk], r / d), assign(ai[kk], Num(-1.0) / d),
            )),
        )  # fmt: skip

    how = Elimination(
        names=("ar", "ai"),
        size=lambda q: fn("abs", ar[q]) + fn("abs", ai[q]),
        inverse=inverse,
        multiplier=lambda ik, kk: (
            assign(lr, ar[ik] * ar[kk] - ai[ik] * ai[kk]),
            assign(li, ar[ik] * ai[kk] + ai[ik] * ar[kk]),
            assign(ar[ik], lr),
            assign(ai[ik], li),
        ),
        update=lambda ij, kj: (
            assign(ur, ar[kj]), assign(ui, ai[kj]),
            assign(ar[ij], ar[ij] - (lr * ur - li * ui)),
            assign(ai[ij], ai[ij] - (lr * ui + li * ur)),
        ),
        scale=lambda kj, kk: (
            assign(ur, ar[kj]), assign(ui, ai[kj]),
            assign(ar[kj], ur * ar[kk] - ui * ai[kk]),
            assign(ai[kj], ur * ai[kk] + ui * ar[kk]),
        ),
    )  # fmt: skip
    params = (Decl("ar", "double", ("NX2",), "inout"), Decl("ai", "double", ("NX2",), "inout"),
              Decl("piv", "int", ("NX",), "out"))  # fmt: skip
    names = ("swap", "re", "im", "r", "d", "lr", "li", "ur", "ui")
    locals_ = (Decl("p", "int"), *(Decl(n, "double") for n in names))
    doc = (
        "lu_decompose for the complex matrix ar + i ai, stored the same way: the",
        "pivot is the entry of largest |re| + |im| (as radau5.f's DECOMC).",
    )
    body = eliminate(blocks, nx, how)
    return Func("lu_decompose_complex", params, body, "bool", locals_, doc, restrict=True)


def solve_complex(blocks: Blocks, nx: int) -> Func:
    ar, ai, br, bi, re = (Var(n) for n in ("ar", "ai", "br", "bi", "re"))
    body: list[S] = []

    def minus(value: E, row: int, cols: list[int], part: str, real: bool = False) -> E:
        for c in cols:
            q = row * nx + c
            if real:
                value = value - ar[q] * (br[c] if part == "re" else bi[c])
            elif part == "re":
                value = value - ar[q] * br[c] + ai[q] * bi[c]
            else:
                value = value - ar[q] * bi[c] - ai[q] * br[c]
        return value

    def forward(r: int, cols: list[int], real: bool = False) -> list[S]:
        if not cols:
            return []
        return [assign(br[r], minus(br[r], r, cols, "re", real)),
                assign(bi[r], minus(bi[r], r, cols, "im", real))]  # fmt: skip

    for first, end in blocks.parts:
        for r in range(first, end):  # the part's reads of x (real: -J), solved already
            body += forward(r, list(blocks.coupled[r]) if blocks.coupled else [], real=True)
        body += permute(blocks, range(first, end), (br, bi))
        for r in range(first, end):
            body += forward(r, blocks.lower[r])
        for r in range(end - 1, first - 1, -1):
            up, q = list(reversed(blocks.upper[r])), r * nx + r
            body += [
                assign(re, minus(br[r] * ar[q] - bi[r] * ai[q], r, up, "re")),
                assign(bi[r], minus(bi[r] * ar[q] + br[r] * ai[q], r, up, "im")),
                assign(br[r], re),
            ]
    params = (Decl("ar", "double", ("NX2",)), Decl("ai", "double", ("NX2",)),
              Decl("piv", "int", ("NX",)), Decl("br", "double", ("NX",), "inout"),
              Decl("bi", "double", ("NX",), "inout"))  # fmt: skip
    doc = ("lu_solve for lu_decompose_complex's factors: b = br + i bi.",)
    locals_ = (Decl("swap", "double"), Decl("re", "double"))
    return Func("lu_solve_complex", params, tuple(body), None, locals_, doc, restrict=True)


__all__ = ["decompose", "decompose_complex", "shift", "shift_complex", "solve", "solve_complex"]
