"""The IR's functions that one target has as an intrinsic and another
defines, described here: each printer spells such a function (Fn) by the
name of its definition (ir/c.py's and ir/fortran.py's FUNCTIONS), and a
file defines those its functions call (program.intrinsics).

C: max and min as dmax and dmin, fmax and fmin inline (NaN: the other
argument, as fmax and fmin). The library's are calls to legacy-SSE code:
after AVX-512 arithmetic (gcc -O3 -march=native) each call paid a state
transition (Rodas4 ran 4.8x slower), and in a loop over lanes a call stops
the vectorizer. A double's exponent and significand, and 2^k, from and to its
bits (bits_exponent, bits_significand, bits_pow2): x = m 2^e, 1 <= m < 2,
for a normal x > 0; k an integer in [-1022, 1023]. Exact, as Fortran's
exponent, fraction and scale, which Fortran calls instead. No conversion
between integers and doubles (each one "may trap" to gcc, whose loops over
lanes then did not vectorize): the integer is the low bits of 2^52 + it, a
double.

Fortran: floor as floor_real, floor(y) as a real (no integer overflow, for
any y).
"""

from __future__ import annotations

from typing import Literal

from gyrogen.codegen.ir.nodes import (
    Bin,
    Bits,
    Decl,
    Func,
    If,
    Int,
    Num,
    Return,
    Var,
    Word,
    assign,
    cmp,
    fn,
    or_,
    real,
    reals,
    sel,
)

TWO52 = 4503599627371519.0
"""2^52 + 1023: 2^52 + a biased exponent, minus this, is the exponent."""
HIGH = 0x4330000000000000
"""The bits of 2^52 above its significand."""
SIGNIFICAND = 0x000FFFFFFFFFFFFF
ONE = 0x3FF0000000000000
"""The bits of 1.0 above its significand."""


def word(name: str) -> Decl:
    return Decl(name, "word", (), "inout")


def extreme(name: str, op: Literal[">", "<"]) -> Func:
    a, b = Var("a"), Var("b")
    body = (Return(sel(or_(cmp(a, op, b), cmp(b, "!=", b)), a, b)),)
    which = "fmax" if op == ">" else "fmin"
    doc = (f"{which}, inline; NaN: the other argument (gyrogen.codegen.integrators.intrinsics).",)
    return Func(name, (real("a"), real("b")), body, "double", (), doc, inline=True)


def exponent() -> Func:
    u, e = Var("u"), Var("e")
    body = (
        Bits("u", "x"),
        assign(u, Bin("|", Bin(">>", u, Int(52)), Word(HIGH)), "2^52 + the biased exponent"),
        Bits("e", "u"),
        Return(e - Num(TWO52), "2^52 + 1023"),
    )
    doc = ("x = m 2^e, 1 <= m < 2: e (gyrogen.codegen.integrators.intrinsics).",)
    return Func("bits_exponent", (real("x"),), body, "double", (word("u"), *reals("e")), doc, True)


def significand() -> Func:
    u, m = Var("u"), Var("m")
    body = (
        Bits("u", "x"),
        assign(u, Bin("|", Bin("&", u, Word(SIGNIFICAND)), Word(ONE))),
        Bits("m", "u"),
        Return(m),
    )
    doc = ("x = m 2^e, 1 <= m < 2: m (gyrogen.codegen.integrators.intrinsics).",)
    locals_ = (word("u"), *reals("m"))
    return Func("bits_significand", (real("x"),), body, "double", locals_, doc, True)


def pow2() -> Func:
    k, t, u, x = Var("k"), Var("t"), Var("u"), Var("x")
    body = (
        assign(t, k + Num(TWO52), "2^52 + k + 1023, exact"),
        Bits("u", "t"),
        assign(u, Bin("<<", u, Int(52))),
        Bits("x", "u"),
        Return(x),
    )
    doc = ("2^k, k an integer in [-1022, 1023] (gyrogen.codegen.integrators.intrinsics).",)
    return Func("bits_pow2", (real("k"),), body, "double", (*reals("t", "x"), word("u")), doc, True)


def floor_real() -> Func:
    y, f = Var("y"), Var("f")
    body = (
        assign(f, fn("trunc", y)),
        If(cmp(y, "<", f), (assign(f, f - 1.0),)),
        Return(f),
    )
    doc = ("floor(y) as a real (no integer overflow, for any y)",)
    return Func("floor_real", (real("y"),), body, "double", reals("f"), doc)


def functions() -> list[Func]:
    """Every definition, in the order a file defines them."""
    return [
        extreme("dmax", ">"),
        extreme("dmin", "<"),
        exponent(),
        significand(),
        pow2(),
        floor_real(),
    ]
