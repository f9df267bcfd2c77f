"""The attitude check of 3-1-2 angles, described once: a step that ends at
gimbal lock (|cos q2| below abi.GIMBAL_LOCK_COS) or passes a point of it
(its ends in two intervals between the points pi/2 + k pi), as expressions
the methods' steps use and as the functions gimbal_interval, gimbal_lock_at
and gimbal_lock."""

from __future__ import annotations

import math

from gyrogen import abi
from gyrogen.codegen.integrators.common import arr, real
from gyrogen.codegen.ir.nodes import Bool, Const, E, Func, Num, Return, Var, cmp, fn, not_, or_, sel

x, xnew = Var("x"), Var("xnew")

GIMBAL_NEAR = 1e-6
"""gimbal_at computes cos q2 only where q2 lies within GIMBAL_NEAR pi of a
point of gimbal lock, or beyond GIMBAL_FAR: elsewhere |cos q2| is at least
sin(pi GIMBAL_NEAR), far above the bar, and the cosine is not needed."""
GIMBAL_FAR = 1e6
assert math.sin(math.pi * GIMBAL_NEAR) > 1e3 * abi.GIMBAL_LOCK_COS


def gimbal_at(after: Var) -> E:
    """The step ends at gimbal lock: |cos q2| below the bar.

    With m = q2/pi + 1/2 and f = m - floor(m), |cos q2| = |sin(pi f)|: it
    is at least sin(pi GIMBAL_NEAR) unless f lies within GIMBAL_NEAR of 0 or
    1. For |q2| < GIMBAL_FAR, f is within 1e-9 of its exact value (q2/pi's
    rounding), so the cosine is computed only near those points (C's ?:
    skips it; the answer is the same either way). NaN and Inf fall to the
    cosine, which refuses them as before."""
    q2 = after[1]
    m = q2 * Num(abi.GIMBAL_INTERVALS) + 0.5
    f = m - fn("gimbal_interval", q2)
    near = or_(
        cmp(f, "<", Num(GIMBAL_NEAR)),
        cmp(f, ">", Num(1.0 - GIMBAL_NEAR)),
        not_(cmp(fn("abs", q2), "<", Num(GIMBAL_FAR))),
    )
    lock = cmp(fn("abs", fn("cos", q2)), "<", Const("ODE_GIMBAL_LOCK_COS"))
    return sel(near, lock, Bool(False))  # Fortran's merge evaluates both: gfortran needs that


def gimbal_jump(before: Var, after: Var) -> E:
    """The step passed a point of gimbal lock (its ends in two intervals)."""
    jump = fn("abs", fn("gimbal_interval", before[1]) - fn("gimbal_interval", after[1]))
    return cmp(jump, ">=", 1.0)


def locked(before: Var, after: Var) -> E:
    """The step from before to after ends at gimbal lock or passes a point of it."""
    return or_(gimbal_at(after), gimbal_jump(before, after))


def functions() -> list[Func]:
    q2 = Var("q2")
    interval = Func(
        "gimbal_interval",
        (real("q2"),),
        (Return(fn("floor", q2 * Num(abi.GIMBAL_INTERVALS) + 0.5)),),
        "double",
        doc=(
            "The attitude is 3-1-2 angles, q2 = x[1]: their kinematics divide by",
            "cos(q2), which is zero at q2 = pi/2 + k pi for every integer k. Between",
            "two such points lies one interval ((j - 1/2) pi, (j + 1/2) pi), numbered",
            "j = floor(q2/pi + 1/2): the two ends of a step lie in the same interval",
            "unless the step passed a point of gimbal lock, however long the step",
            "(whole turns included). Where the rounding of q2/pi could misplace q2 by",
            "an interval, |cos q2| is below the lock's bar, for |q2| up to 1e6.",
        ),
    )
    at = Func(
        "gimbal_lock_at",
        (arr("x"),),
        (Return(gimbal_at(x)),),
        "bool",
        doc=("1 when x is at gimbal lock, |cos q2| below ODE_GIMBAL_LOCK_COS.",),
    )
    lock = Func(
        "gimbal_lock",
        (arr("x"), arr("xnew")),
        (Return(locked(x, xnew)),),
        "bool",
        doc=(
            "1 when the step from x to xnew ends at gimbal lock or passes a point of",
            "it (the path crossed q2 = pi/2 + k pi, where q1 and q3 jump).",
        ),
    )
    return [interval, at, lock]
