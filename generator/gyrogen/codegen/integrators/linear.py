"""The LU decompositions the implicit methods solve with, described once.

E = I/(h gamma) - J is block upper triangular in state order
(gyrogen.symbolic.blocks): the decomposition pivots within a row's block,
and the solve is unrolled over the entries of L and U that can be nonzero.
Matrices are flat and row-major, a[i*NX + j], in every target. U = D V is
stored as 1/u_kk on the diagonal and V's u_kj/u_kk above it, so that each
row of the back substitution waits on one multiply-add, not on a divide.
"""

from __future__ import annotations

from gyrogen.codegen.integrators.common import NX
from gyrogen.codegen.ir.nodes import (
    Bool,
    Comment,
    Decl,
    E,
    For,
    Func,
    If,
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

i, j, k, p = Var("i"), Var("j"), Var("k"), Var("p")


def swap_rows(names: tuple[str, ...]) -> S:
    """Rows k and p of each matrix exchanged."""
    body: list[S] = []
    for a in names:
        swap = Var("swap")
        body += [
            assign(swap, Var(a)[k * NX + j]),
            assign(Var(a)[k * NX + j], Var(a)[p * NX + j]),
            assign(Var(a)[p * NX + j], swap),
        ]
    return If(cmp(p, "!=", k), (For("j", NX, tuple(body)),))


def decompose(blocks: Blocks) -> Func:
    a = Var("a")
    end = Var("lu_end")
    ik, kk, pk = a[i * NX + k], a[k * NX + k], a[p * NX + k]
    body = (
        For("k", NX, (
            assign(p, k),
            For("i", end[k], (If(cmp(fn("abs", ik), ">", fn("abs", pk)), (assign(p, i),)),),
                start=k + 1),
            assign(Var("piv")[k], p),
            If(not_(cmp(fn("abs", pk), ">", 0.0)), (Return(Bool(True), "singular"),)),
            swap_rows(("a",)),
            assign(kk, Num(1.0) / kk),
            For("i", end[k], (
                assign(Var("m"), ik * kk),
                assign(ik, Var("m")),
                For("j", NX, (assign(a[i * NX + j], a[i * NX + j] - Var("m") * a[k * NX + j]),),
                    start=k + 1),
            ), start=k + 1),
            For("j", NX, (assign(a[k * NX + j], a[k * NX + j] * kk, "u_kj / u_kk"),), start=k + 1),
        )),
        Return(Bool(False)),
    )  # fmt: skip
    params = (Decl("a", "double", ("NX2",), "inout"), Decl("piv", "int", ("NX",), "out"))
    locals_ = (
        Decl("lu_end", "int", ("NX",), values=tuple(blocks.end)),
        Decl("p", "int"),
        Decl("m", "double"),
        Decl("swap", "double"),
    )
    doc = (
        "In-place LU decomposition with partial pivoting within the diagonal",
        f"blocks {', '.join(map(str, blocks.spans))} (row i's block ends",
        "before row lu_end[i]): L unit lower; U = D V as 1/u_kk and u_kj/u_kk;",
        "row k swapped with piv[k]. 1 when a pivot is zero: singular.",
    )
    return Func("lu_decompose", params, body, "bool", locals_, doc)


def solve(blocks: Blocks, nx: int) -> Func:
    b, piv, lu = Var("b"), Var("piv"), Var("lu")
    swap = Var("swap")
    body: list[S] = [
        For("i", NX, (
            assign(swap, b[i]),
            assign(b[i], b[piv[i]]),
            assign(b[piv[i]], swap),
        )),
    ]  # fmt: skip
    for r in range(nx):
        if blocks.lower[r]:
            value: E = b[r]
            for c in blocks.lower[r]:
                value = value - lu[r * nx + c] * b[c]
            body.append(assign(b[r], value))
    for r in range(nx - 1, -1, -1):
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
    )
    return Func("lu_solve", params, tuple(body), None, (Decl("swap", "double"),), doc)


def decompose_complex(blocks: Blocks) -> Func:
    """lu_decompose for ar + i ai, stored the same way: the pivot is the entry
    of largest |re| + |im| (as radau5.f's DECOMC); 1/u_kk by Smith's division."""
    ar, ai = Var("ar"), Var("ai")
    end = Var("lu_end")
    ik, kk, kj, ij = i * NX + k, k * NX + k, k * NX + j, i * NX + j

    def size(q: E) -> E:
        return fn("abs", ar[q]) + fn("abs", ai[q])

    re, im, r, d = Var("re"), Var("im"), Var("r"), Var("d")
    lr, li, ur, ui = Var("lr"), Var("li"), Var("ur"), Var("ui")
    inverse: tuple[S, ...] = (
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
    body = (
        For("k", NX, (
            assign(p, k),
            For("i", end[k], (If(cmp(size(ik), ">", size(p * NX + k)), (assign(p, i),)),),
                start=k + 1),
            assign(Var("piv")[k], p),
            If(not_(cmp(size(p * NX + k), ">", 0.0)), (Return(Bool(True), "singular"),)),
            swap_rows(("ar", "ai")),
            Comment("1/u_kk by Smith's division (no overflow in re^2 + im^2)", False),
            *inverse,
            For("i", end[k], (
                assign(lr, ar[ik] * ar[kk] - ai[ik] * ai[kk]),
                assign(li, ar[ik] * ai[kk] + ai[ik] * ar[kk]),
                assign(ar[ik], lr),
                assign(ai[ik], li),
                For("j", NX, (
                    assign(ur, ar[kj]), assign(ui, ai[kj]),
                    assign(ar[ij], ar[ij] - (lr * ur - li * ui)),
                    assign(ai[ij], ai[ij] - (lr * ui + li * ur)),
                ), start=k + 1),
            ), start=k + 1),
            For("j", NX, (
                assign(ur, ar[kj]), assign(ui, ai[kj]),
                assign(ar[kj], ur * ar[kk] - ui * ai[kk], "u_kj / u_kk"),
                assign(ai[kj], ur * ai[kk] + ui * ar[kk]),
            ), start=k + 1),
        )),
        Return(Bool(False)),
    )  # fmt: skip
    params = (Decl("ar", "double", ("NX2",), "inout"), Decl("ai", "double", ("NX2",), "inout"),
              Decl("piv", "int", ("NX",), "out"))  # fmt: skip
    names = ("swap", "re", "im", "r", "d", "lr", "li", "ur", "ui")
    locals_ = (Decl("lu_end", "int", ("NX",), values=tuple(blocks.end)), Decl("p", "int"),
               *(Decl(n, "double") for n in names))  # fmt: skip
    doc = (
        "lu_decompose for the complex matrix ar + i ai, stored the same way: the",
        "pivot is the entry of largest |re| + |im| (as radau5.f's DECOMC).",
    )
    return Func("lu_decompose_complex", params, body, "bool", locals_, doc)


def solve_complex(blocks: Blocks, nx: int) -> Func:
    ar, ai, br, bi, piv, swap, re = (Var(n) for n in ("ar", "ai", "br", "bi", "piv", "swap", "re"))
    body: list[S] = [
        For("i", NX, tuple(
            s for b in (br, bi)
            for s in (assign(swap, b[i]), assign(b[i], b[piv[i]]), assign(b[piv[i]], swap))
        )),
    ]  # fmt: skip

    def minus(value: E, row: int, cols: list[int], part: str) -> E:
        for c in cols:
            q = row * nx + c
            if part == "re":
                value = value - ar[q] * br[c] + ai[q] * bi[c]
            else:
                value = value - ar[q] * bi[c] - ai[q] * br[c]
        return value

    for r in range(nx):
        if blocks.lower[r]:
            body += [assign(br[r], minus(br[r], r, blocks.lower[r], "re")),
                     assign(bi[r], minus(bi[r], r, blocks.lower[r], "im"))]  # fmt: skip
    for r in range(nx - 1, -1, -1):
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
    return Func("lu_solve_complex", params, tuple(body), None, locals_, doc)


__all__ = ["decompose", "decompose_complex", "solve", "solve_complex"]
