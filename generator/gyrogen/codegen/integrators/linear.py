"""The LU decompositions the implicit methods solve with, described once.

E = I/(h gamma) - J is block upper triangular in state order
(gyrogen.symbolic.blocks): the decomposition pivots within a row's block;
both it and the solve are unrolled over the entries of L and U that can be
nonzero. An augmented system's rows that read x (Blocks.coupled) are solved
after x, less those reads times x's solution, by their own blocks.
The decompositions, their row exchanges and the solves touch only the
entries Blocks.stored names, and lu_shift builds the iteration matrix
d I - J there alone, not by a pass over all of J (the default scene's
variational unit stores 283 entries of 3,600); over lanes, E is built whole.
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
    At,
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
    or_,
    sel,
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


Index = int | E
"""A row or column: a number, or a loop's variable."""


@dataclass(frozen=True)
class Elimination:
    """What a decomposition does to entries, by their flat indices: the
    real one's and the complex one's, with one pivoting and one order."""

    names: tuple[str, ...]
    size: Entry
    inverse: Callable[[Index], tuple[S, ...]]
    """u_kk := 1/u_kk."""
    multiplier: Callable[[E, Index], tuple[S, ...]]
    """l_ik := a_ik / u_kk (a product with the inverse), held in locals too."""
    update: Callable[[E, Index], tuple[S, ...]]
    """a_ij -= l_ik u_kj (row i's entry, row k's)."""
    scale: Callable[[Index, Index], tuple[S, ...]]
    """u_kj := u_kj / u_kk (row k's entry, the diagonal)."""
    pivots: str = "piv"
    """The pivots' array."""


def eliminate(
    blocks: Blocks, nx: int, how: Elimination, singular: Var | None = None, looped: bool = False
) -> tuple[S, ...]:
    """Gaussian elimination with partial pivoting within the diagonal blocks,
    unrolled over the columns k and over the entries of U that can be
    nonzero (Blocks.upper: what the solves read); the rows of a block as a
    loop. Entries outside that pattern stay zero, as they would under the
    loop over every column (l_ik times a zero); an augmented system's
    coupled entries (Blocks.coupled) stay as they are, for the solve. With
    singular, branch-free (pivoting): a zero pivot sets singular and the
    elimination goes on (its factors are not to be used), no return.
    looped: a block of more than two columns a loop over them but the last,
    and over the rest of the block in each row (Blocks.upper's fill-in; the
    columns past the block unrolled): each entry's arithmetic as unrolled,
    in the same order, in text that does not grow with the block's size
    squared (over lanes: the decomposition's text grew 45 KB on a 15-state
    block)."""
    body: list[S] = []
    for first, end in blocks.spans:
        past = blocks.upper[end - 1]  # the columns past the block its rows use
        columns: list[Index] = list(range(first, end))
        if looped and end - first > 2:
            k = Var("col")  # not k: over lanes, the stages' rows
            body.append(For("col", Int(end - 1),
                            tuple(column(how, k, first, end, past, nx, singular, blocks)),
                            start=Int(first)))  # fmt: skip
            columns = [end - 1]
        for c in columns:
            body += column(how, c, first, end, past, nx, singular, blocks)
    return tuple(body) if singular is not None else (*body, Return(Bool(False)))


def flat(row: Index, col: Index, nx: int) -> Index:
    """An entry's flat index: a number when both are."""
    if isinstance(row, int) and isinstance(col, int):
        return row * nx + col
    return row * NX + col


def column(
    how: Elimination,
    k: Index,
    first: int,
    end: int,
    past: tuple[int, ...],
    nx: int,
    singular: Var | None,
    blocks: Blocks,
) -> list[S]:
    """Column k of the block [first, end): its pivot, its multipliers and
    the updates of the rows below, row k of U scaled. A number k unrolls
    the rest of the block (k + 1 .. end - 1); a variable loops over it."""
    piv, kk = Var(how.pivots), flat(k, k, nx)
    if isinstance(k, int) and end - k == 1:
        return [
            assign(piv[k], k),
            zero_pivot(how.size(kk), singular),
            *how.inverse(kk),
            *(st for c in past for st in how.scale(flat(k, c, nx), kk)),
        ]
    after = Int(k + 1) if isinstance(k, int) else k + 1

    def each(f: Callable[[int | E], tuple[S, ...]]) -> list[S]:
        """f on the rest of the block's columns, then on those past it."""
        if isinstance(k, int):
            return [st for c in (*range(k + 1, end), *past) for st in f(c)]
        return [For("j", Int(end), f(j), start=after), *(st for c in past for st in f(c))]

    return [
        *pivoting(how, k, (first, end), singular, blocks, nx),
        *how.inverse(kk),
        For("i", Int(end), (
            *how.multiplier(i * NX + k, kk),
            *each(lambda c: how.update(i * NX + c, flat(k, c, nx))),
        ), start=after),
        *each(lambda c: how.scale(flat(k, c, nx), kk)),
    ]  # fmt: skip


def zero_pivot(size: E, singular: Var | None) -> S:
    """A pivot of size 0 (or NaN): singular, returned at once or remembered."""
    zero = not_(cmp(size, ">", 0.0))
    if singular is None:
        return If(zero, (Return(Bool(True), "singular"),))
    return assign(singular, or_(singular, zero))


def pivoting(
    how: Elimination, k: Index, span: tuple[int, int], singular: Var | None, blocks: Blocks, nx: int
) -> list[S]:
    """Column k's pivot p, the largest of rows k..end-1 (the first of equal
    ones), into piv[k], and rows k and p exchanged. With singular, by
    selection: the running largest size in best (the size at p, as the
    search compares), and each row below k exchanged where it is p."""
    start, end = span
    piv, after = Var(how.pivots), Int(k + 1) if isinstance(k, int) else k + 1
    if singular is None:
        assert isinstance(k, int), "a branching pivot search is unrolled"
        return [
            assign(p, k),
            For("i", Int(end), (If(cmp(how.size(i * NX + k), ">", how.size(p * NX + k)),
                                   (assign(p, i),)),), start=Int(k + 1)),
            assign(piv[k], p),
            zero_pivot(how.size(p * NX + k), None),
            swap_rows(how.names, k, blocks, nx),
        ]  # fmt: skip
    best, q, swap = Var("best"), Var("q"), Var("held")
    larger = cmp(how.size(i * NX + k), ">", best)
    exchanged: list[S] = []
    for a in how.names:
        at_k, at_q = Var(a)[k * NX + j], Var(a)[q * NX + j]
        exchanged += [
            assign(swap, at_k),
            assign(at_k, sel(cmp(p, "==", q), at_q, at_k)),
            assign(at_q, sel(cmp(p, "==", q), swap, at_q)),
        ]
    return [
        assign(p, k),
        assign(best, how.size(k * NX + k)),
        For(
            "i",
            Int(end),
            (assign(p, sel(larger, i, p)), assign(best, sel(larger, how.size(i * NX + k), best))),
            start=after,
        ),
        assign(piv[k], p),
        zero_pivot(best, singular),
        For(
            "q",
            Int(end),
            (For("j", NX, tuple(exchanged), ("held",), start=Int(start)),),
            start=after,
        ),
    ]


def real(name: str) -> Elimination:
    """The real decomposition's arithmetic on the matrix name."""
    a, m = Var(name), Var("m")
    return Elimination(
        names=(name,),
        size=lambda q: fn("abs", a[q]),
        inverse=lambda kk: (assign(a[kk], Num(1.0) / a[kk]),),
        multiplier=lambda ik, kk: (assign(m, a[ik] * a[kk]), assign(a[ik], m)),
        update=lambda ij, kj: (assign(a[ij], a[ij] - m * a[kj]),),
        scale=lambda kj, kk: (assign(a[kj], a[kj] * a[kk]),),
    )


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
    how = real("a")
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


Rows = Callable[[int | E], At | Var]
"""A right-hand side's entry by its row."""


def permute_selected(
    blocks: Blocks, rows: range, bs: tuple[Rows, ...], pivots: str = "piv"
) -> list[S]:
    """permute by selection (no index read from the pivots): each row q
    below r in its block exchanged with row r where pivots[r] is q, in each
    of bs; one loop over r and q a block (17 loops over q on a block of 15
    rows took gcc a quarter of a second)."""
    piv, q, r, swap = Var(pivots), Var("q"), Var("r"), Var("swap")
    there = cmp(piv[r], "==", q)
    exchange = tuple(st for b in bs for st in (
        assign(swap, b(r)), assign(b(r), sel(there, b(q), b(r))),
        assign(b(q), sel(there, swap, b(q)))))  # fmt: skip
    return [
        For("r", Int(end - 1), (For("q", Int(end), exchange, ("swap",), start=r + 1),),
            start=Int(first))
        for first, end in blocks.spans if end - first > 1 and first in rows
    ]  # fmt: skip


def substitution(
    blocks: Blocks,
    nx: int,
    b: Rows,
    permuting: Callable[[range], list[S]],
    stored: Rows | None = None,
) -> list[S]:
    """b := A^-1 b, part by part (Blocks.parts): the part's reads of x, solved
    already, subtracted; its rows permuted (permuting); then L^-1 and U^-1,
    unrolled over the entries of L and V that can be nonzero; each row
    subtracts the latest b_j last. stored: where the rows live, when b is
    a copy of a part's rows (over lanes, values in registers: loaded after
    the part's permutation, stored after its solve)."""
    lu, at = Var("lu"), stored or b
    body: list[S] = []
    for first, end in blocks.parts:
        for r in range(first, end):
            if blocks.coupled and blocks.coupled[r]:
                value: E = at(r)
                for c in blocks.coupled[r]:
                    value = value - lu[r * nx + c] * at(c)
                body.append(assign(at(r), value))
        body += permuting(range(first, end))
        body += [assign(b(r), at(r)) for r in range(first, end) if stored]
        for r in range(first, end):
            if blocks.lower[r]:
                value = b(r)
                for c in blocks.lower[r]:
                    value = value - lu[r * nx + c] * b(c)
                body.append(assign(b(r), value))
        for r in range(end - 1, first - 1, -1):
            value = b(r) * lu[r * nx + r]
            for c in reversed(blocks.upper[r]):
                value = value - lu[r * nx + c] * b(c)
            body.append(assign(b(r), value))
        body += [assign(at(r), b(r)) for r in range(first, end) if stored]
    return body


def solve(blocks: Blocks, nx: int) -> Func:
    b = Var("b")
    body = substitution(blocks, nx, lambda r: b[r], lambda rows: permute(blocks, rows, (b,)))
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


def complex_(
    re_name: str, im_name: str, pivots: str = "piv", selected: bool = False
) -> Elimination:
    """The complex decomposition's arithmetic on re_name + i im_name: the
    pivot the entry of largest |re| + |im| (as radau5.f's DECOMC); 1/u_kk by
    Smith's division, its two cases a branch or (selected, over lanes) a
    selection of each value, the same arithmetic on each lane."""
    ar, ai = Var(re_name), Var(im_name)
    re, im, r, d = Var("re"), Var("im"), Var("r"), Var("d")
    lr, li, ur, ui = Var("lr"), Var("li"), Var("ur"), Var("ui")

    def inverse(kk: Index) -> tuple[S, ...]:
        big = cmp(fn("abs", re), ">=", fn("abs", im))
        cases: tuple[S, ...] = (
            If(big, (
                assign(r, im / re), assign(d, re + im * r),
                assign(ar[kk], Num(1.0) / d), assign(ai[kk], -r / d),
            ), (
                assign(r, re / im), assign(d, im + re * r),
                assign(ar[kk], r / d), assign(ai[kk], Num(-1.0) / d),
            )),
        ) if not selected else (
            assign(r, sel(big, im / re, re / im)),
            assign(d, sel(big, re + im * r, im + re * r)),
            assign(ar[kk], sel(big, Num(1.0) / d, r / d)),
            assign(ai[kk], sel(big, -r / d, Num(-1.0) / d)),
        )  # fmt: skip
        return (
            Comment("1/u_kk by Smith's division (no overflow in re^2 + im^2)", False),
            assign(re, ar[kk]),
            assign(im, ai[kk]),
            *cases,
        )

    return Elimination(
        names=(re_name, im_name),
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
        pivots=pivots,
    )  # fmt: skip


COMPLEX_LOCALS = ("re", "im", "r", "d", "lr", "li", "ur", "ui")
"""What complex_'s arithmetic holds."""


def decompose_complex(blocks: Blocks, nx: int) -> Func:
    """lu_decompose for ar + i ai, stored the same way (complex_)."""
    params = (Decl("ar", "double", ("NX2",), "inout"), Decl("ai", "double", ("NX2",), "inout"),
              Decl("piv", "int", ("NX",), "out"))  # fmt: skip
    locals_ = (Decl("p", "int"), *(Decl(n, "double") for n in ("swap", *COMPLEX_LOCALS)))
    doc = (
        "lu_decompose for the complex matrix ar + i ai, stored the same way: the",
        "pivot is the entry of largest |re| + |im| (as radau5.f's DECOMC).",
    )
    body = eliminate(blocks, nx, complex_("ar", "ai"))
    return Func("lu_decompose_complex", params, body, "bool", locals_, doc, restrict=True)


def complex_substitution(
    blocks: Blocks,
    nx: int,
    factors: tuple[Var, Var],
    b: tuple[Rows, Rows],
    permuting: Callable[[range], list[S]],
    stored: tuple[Rows, Rows] | None = None,
) -> list[S]:
    """b := A^-1 b for the complex factors (re, im) and b = (re rows, im
    rows), part by part as substitution: the part's reads of x (real: -J),
    solved already, subtracted; its rows permuted; then L^-1 and U^-1.
    stored: where the rows live, when b is a copy (over lanes, registers)."""
    ar, ai = factors
    br, bi = b
    sr, si = stored or b
    re = Var("re")
    body: list[S] = []

    def minus(value: E, row: int, cols: list[int], part: str, real: bool = False,
              at: tuple[Rows, Rows] = b) -> E:  # fmt: skip
        xr, xi = at
        for c in cols:
            q = row * nx + c
            if real:
                value = value - ar[q] * (xr(c) if part == "re" else xi(c))
            elif part == "re":
                value = value - ar[q] * xr(c) + ai[q] * xi(c)
            else:
                value = value - ar[q] * xi(c) - ai[q] * xr(c)
        return value

    for first, end in blocks.parts:
        for r in range(first, end):  # the part's reads of x (real: -J), solved already
            cols = list(blocks.coupled[r]) if blocks.coupled else []
            if cols:
                body += [assign(sr(r), minus(sr(r), r, cols, "re", True, (sr, si))),
                         assign(si(r), minus(si(r), r, cols, "im", True, (sr, si)))]  # fmt: skip
        body += permuting(range(first, end))
        body += [st for r in range(first, end) if stored
                 for st in (assign(br(r), sr(r)), assign(bi(r), si(r)))]  # fmt: skip
        for r in range(first, end):
            if blocks.lower[r]:
                body += [assign(br(r), minus(br(r), r, blocks.lower[r], "re")),
                         assign(bi(r), minus(bi(r), r, blocks.lower[r], "im"))]  # fmt: skip
        for r in range(end - 1, first - 1, -1):
            up, q = list(reversed(blocks.upper[r])), r * nx + r
            body += [
                assign(re, minus(br(r) * ar[q] - bi(r) * ai[q], r, up, "re")),
                assign(bi(r), minus(bi(r) * ar[q] + br(r) * ai[q], r, up, "im")),
                assign(br(r), re),
            ]
        body += [st for r in range(first, end) if stored
                 for st in (assign(sr(r), br(r)), assign(si(r), bi(r)))]  # fmt: skip
    return body


def solve_complex(blocks: Blocks, nx: int) -> Func:
    ar, ai, br, bi = (Var(n) for n in ("ar", "ai", "br", "bi"))
    rows: tuple[Rows, Rows] = (lambda r: br[r], lambda r: bi[r])
    body = complex_substitution(
        blocks, nx, (ar, ai), rows, lambda rs: permute(blocks, rs, (br, bi))
    )
    params = (Decl("ar", "double", ("NX2",)), Decl("ai", "double", ("NX2",)),
              Decl("piv", "int", ("NX",)), Decl("br", "double", ("NX",), "inout"),
              Decl("bi", "double", ("NX",), "inout"))  # fmt: skip
    doc = ("lu_solve for lu_decompose_complex's factors: b = br + i bi.",)
    locals_ = (Decl("swap", "double"), Decl("re", "double"))
    return Func("lu_solve_complex", params, tuple(body), None, locals_, doc, restrict=True)


# Over SIMD lanes (gyrogen.codegen.ir.lanes): the factors, the pivots and
# the right-hand sides are struct lanes' own, each lane's pivots its own.
# One function each, out of line, called by every step over lanes: unrolled
# into each, they made the file 2.4 times larger and its compile 11 times
# longer (cmg4_pyramid).

ZERO_PIVOT = Var("zero_pivot")
"""Over lanes, the lane's E has a zero pivot (its factors are not to be used)."""


def decompose_lanes(blocks: Blocks, nx: int) -> Func:
    """lu_decompose on every lane's lu, branch-free: each lane's pivots by
    selection (eliminate with singular), a zero pivot in ZERO_PIVOT."""
    body = (assign(ZERO_PIVOT, False), *eliminate(blocks, nx, real("lu"), ZERO_PIVOT, True))
    locals_ = (
        Decl("p", "int", (), "inout"),
        *(Decl(n, "double", (), "inout") for n in ("best", "m")),
    )
    doc = ("lu_decompose on every lane: its pivots by selection, a zero one in zero_pivot.",)
    return Func("lu_decompose_lanes", (), body, None, locals_, doc)


def solve_lanes(blocks: Blocks, nx: int) -> Func:
    """lu_solve's statements on every lane's row s of k (the stages), the
    rows exchanged by selection (no index read from a lane's pivots), then
    solved in registers (b0, b1, ...: one loop over the lanes of values,
    which gcc compiled in a third of the time the same loop on the rows in
    memory took)."""
    k, s = Var("k"), Var("s")

    def row(r: int | E) -> At:
        return k[s, r]

    def held(r: int | E) -> Var:
        return Var(f"b{r}")

    rows = substitution(blocks, nx, held, lambda rs: permute_selected(blocks, rs, (row,)), row)
    doc = ("lu_solve on every lane's row s of k, its rows exchanged by selection.",)
    locals_ = tuple(Decl(f"b{r}", "double", (), "tmp") for r in range(nx))
    return Func("lu_solve_lanes", (Decl("s", "int"),), tuple(rows), None, locals_, doc)


def decompose_complex_lanes(blocks: Blocks, nx: int) -> Func:
    """lu_decompose_complex on every lane's e2r + i e2i (radau5's E2),
    branch-free: each lane's pivots (piv2) by selection, Smith's division
    by selection; a zero pivot is or-ed into ZERO_PIVOT (E1's, by
    lu_decompose_lanes first: a lane's E1 or E2 singular)."""
    how = complex_("e2r", "e2i", "piv2", selected=True)
    body = eliminate(blocks, nx, how, ZERO_PIVOT, True)
    locals_ = (
        Decl("p", "int", (), "inout"),
        *(Decl(n, "double", (), "inout") for n in ("best", *COMPLEX_LOCALS)),
    )
    doc = ("lu_decompose_complex on every lane's e2r + i e2i; a zero pivot or-ed into zero_pivot.",)
    return Func("lu_decompose_complex_lanes", (), body, None, locals_, doc)


def solve_complex_lanes(blocks: Blocks, nx: int) -> Func:
    """lu_solve_complex's statements on every lane's z2 + i z3 (radau5's
    complex system), the rows exchanged by selection, then solved in
    registers, as solve_lanes."""
    z2, z3 = Var("z2"), Var("z3")
    rows: tuple[Rows, Rows] = (lambda r: z2[r], lambda r: z3[r])
    held: tuple[Rows, Rows] = (lambda r: Var(f"br{r}"), lambda r: Var(f"bi{r}"))
    factors = (Var("e2r"), Var("e2i"))
    body = complex_substitution(
        blocks, nx, factors, held, lambda rs: permute_selected(blocks, rs, rows, "piv2"), rows
    )
    doc = ("lu_solve_complex on every lane's z2 + i z3, its rows exchanged by selection.",)
    locals_ = (
        *(Decl(f"b{part}{r}", "double", (), "tmp") for r in range(nx) for part in "ri"),
        Decl("re", "double", (), "tmp"),
    )
    return Func("lu_solve_complex_lanes", (), tuple(body), None, locals_, doc)


def lanes_state_complex() -> list[Decl]:
    """What struct lanes holds for the complex decomposition and its
    right-hand side, per lane."""
    return [
        *(Decl(n, "double", ("NX2",), "inout") for n in ("e2r", "e2i")),
        Decl("piv2", "int", ("NX",), "inout"),
        *(Decl(n, "double", ("NX",), "inout") for n in ("z2", "z3")),
    ]


def lanes_state() -> list[Decl]:
    """What struct lanes holds for the decomposition, per lane."""
    return [
        Decl("lu", "double", ("NX2",), "inout"),
        Decl("piv", "int", ("NX",), "inout"),
        Decl(ZERO_PIVOT.name, "bool", (), "inout"),
    ]


__all__ = [
    "decompose",
    "decompose_complex",
    "decompose_complex_lanes",
    "decompose_lanes",
    "lanes_state",
    "real",
    "shift",
    "shift_complex",
    "solve",
    "solve_complex",
    "solve_complex_lanes",
    "solve_lanes",
]
