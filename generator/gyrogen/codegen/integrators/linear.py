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


__all__ = ["decompose", "solve"]
