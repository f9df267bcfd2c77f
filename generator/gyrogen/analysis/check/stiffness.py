"""How stiff a problem is, and so which integrator it calls for: the
largest decay rate of the Jacobian (the generated one, or central
differences of the compiled rhs when the build has none) times the time
span. `gyrogen check` and `gyrogen simulate --method auto` decide by it."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gyrogen import methods
from gyrogen.runtime.compiled import Compiled

STIFF = 1e3
"""Stiffness index (largest decay rate x time span) above which an explicit
method spends most of its steps on stability: implicit it is."""


def jacobian(comp: Compiled, c: np.ndarray, x: np.ndarray) -> np.ndarray:
    """d(dx/dt)/dx at x: the generated Jacobian, or central differences."""
    if "jac" in comp.manifest["functions"][comp.language]:
        return comp.jacobian(x, c)
    step = 1e-6 * np.maximum(1.0, np.abs(x))
    columns = []
    for j in range(len(x)):
        e = np.zeros_like(x)
        e[j] = step[j]
        columns.append((comp.rhs(x + e, c) - comp.rhs(x - e, c)) / (2 * step[j]))
    return np.stack(columns, axis=1)


def decay_rate(comp: Compiled, c: np.ndarray, xs: np.ndarray) -> float:
    """The largest decay rate of the Jacobian over the states xs (0 when
    nothing decays; inf where the Jacobian is not finite): computed without
    a numpy warning whatever the state (u1 = 1e308 overflowed the product)."""
    worst = 0.0
    with np.errstate(all="ignore"):  # central differences of a huge state overflow
        for x in np.atleast_2d(xs):
            jac = jacobian(comp, c, x)
            if not np.all(np.isfinite(jac)):
                return math.inf
            worst = max(worst, float(-np.min(np.linalg.eigvals(jac).real)))
    return worst


def index(comp: Compiled, c: np.ndarray, xs: np.ndarray, span: float) -> float:
    """max over the states xs of (largest decay rate) x span; 0 when nothing
    decays (Python floats: a product past DBL_MAX is inf, without a warning)."""
    return decay_rate(comp, c, xs) * float(span)


@dataclass(frozen=True)
class Choice:
    stiffness: float
    stiff: bool
    method: str | None
    """The build's best integrator of the kind the problem calls for (None: it has none)."""
    why: str


def choose(comp: Compiled, c: np.ndarray, xs: np.ndarray, span: float) -> Choice:
    """The method the stiffness at xs over span calls for, among the build's."""
    rate = decay_rate(comp, c, xs)
    worst = rate * float(span)
    stiff = worst > STIFF
    method = methods.pick(comp.manifest["integrators"], stiff)
    if stiff and not math.isfinite(rate):
        why = f"implicit ({method or 'none in this build'}): the Jacobian is not finite"
    elif stiff:
        why = (
            f"implicit ({method or 'none in this build'}): decay rates up to {rate:.3g} "
            f"1/s over {span:g} s would hold an explicit method to steps of ~{3.0 / rate:.2g} s"
        )
    else:
        why = (
            f"explicit ({method or 'none in this build'}): stiffness index {worst:.3g} <= {STIFF:g}"
        )
    return Choice(worst, stiff, method, why)
