"""A linear model's modes in words: each eigenvalue (a complex pair once)
stable, unstable or marginal, oscillating or not, with its time scale and
the states it moves most."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MARGINAL = 1e-7
"""|Re lambda| at most this times the largest |lambda| (or 1e-7 /s, if
larger): marginal. Rounding leaves ~1e-16 |A| on a zero eigenvalue, and
~1e-8 |A| on a double one (the boundary of a stability region)."""
RANK = 1e-10
"""Singular values of A - lambda I below this times ||A|| count as zero (the
eigenvectors a marginal eigenvalue has)."""
SHOWN = 0.3
"""A mode is said to move the states whose eigenvector entries reach this
fraction of its largest."""


@dataclass(frozen=True)
class Mode:
    eigenvalue: complex
    """Im >= 0: a pair is one mode."""
    verdict: str
    """stable, unstable or marginal."""
    states: tuple[str, ...]
    """The states it moves most."""
    multiplicity: int = 1
    """How many eigenvalues (within the tolerance) it stands for."""
    secular: bool = False
    """Marginal but repeated with fewer eigenvectors than its multiplicity
    (a Jordan block): it grows like t, so unstable."""

    @property
    def oscillating(self) -> bool:
        return self.eigenvalue.imag > 0

    def words(self) -> str:
        lam = self.eigenvalue
        where = f" in {', '.join(self.states)}" if self.states else ""
        if self.oscillating:
            shape = f"oscillating at {lam.imag:.6g} rad/s (period {2 * np.pi / lam.imag:.4g} s)"
        else:
            shape = "not oscillating"
        if self.secular:
            scale = ", repeated without a full set of eigenvectors: grows like t"
        elif self.verdict == "unstable":
            scale = f", growing: doubles every {np.log(2) / lam.real:.4g} s"
        elif self.verdict == "stable":
            scale = f", decaying: halves every {np.log(2) / -lam.real:.4g} s"
        else:
            scale = ", neither growing nor decaying" if self.oscillating else ", at rest (zero)"
        times = f" (x{self.multiplicity})" if self.multiplicity > 1 else ""
        return f"{self.verdict}: {lam.real:+.6g}{lam.imag:+.6g}i{times}, {shape}{scale}{where}"


def tolerance(eigenvalues: np.ndarray) -> float:
    top = float(np.max(np.abs(eigenvalues))) if eigenvalues.size else 0.0
    return MARGINAL * max(top, 1.0)


def verdict(real: float, tol: float) -> str:
    if real > tol:
        return "unstable"
    return "stable" if real < -tol else "marginal"


def modes(a: np.ndarray, states: tuple[str, ...]) -> list[Mode]:
    """A's modes, the unstable first, then marginal, then stable (each by
    decreasing real part); a complex pair once."""
    if not a.size:
        return []
    values, vectors = np.linalg.eig(a)
    tol = tolerance(values)
    groups: list[tuple[complex, list[np.ndarray]]] = []
    for lam, vec in zip(values, vectors.T, strict=True):
        if lam.imag < 0 and abs(lam.imag) > tol:
            continue  # the pair's other half
        lam = complex(lam.real, abs(lam.imag) if abs(lam.imag) > tol else 0.0)
        near = next((g for g in groups if abs(g[0] - lam) <= tol), None)
        if near is None:
            groups.append((lam, [np.abs(vec)]))
        else:
            near[1].append(np.abs(vec))
    out = []
    for lam, sizes in groups:
        size = np.max(sizes, axis=0)
        top = float(size.max())
        moved = tuple(s for s, v in zip(states, size, strict=True) if top and v >= SHOWN * top)
        said = verdict(lam.real, tol)
        secular = said == "marginal" and _defective(a, values, lam, tol)
        out.append(Mode(lam, "unstable" if secular else said, moved, len(sizes), secular))
    rank = {"unstable": 0, "marginal": 1, "stable": 2}
    return sorted(out, key=lambda m: (rank[m.verdict], -m.eigenvalue.real, -m.eigenvalue.imag))


def _defective(a: np.ndarray, values: np.ndarray, lam: complex, tol: float) -> bool:
    """Whether lam has more eigenvalues within tol than eigenvectors."""
    algebraic = int(np.sum(np.abs(values - lam) <= tol))
    if algebraic < 2:
        return False
    sv = np.linalg.svd(a - lam * np.eye(len(a)), compute_uv=False)
    geometric = int(np.sum(sv <= RANK * max(float(sv[0]), 1e-300)))
    return algebraic > geometric


def overall(found: list[Mode]) -> str:
    """unstable if any mode is; marginal if one is and none grows; else stable."""
    verdicts = {m.verdict for m in found}
    for v in ("unstable", "marginal"):
        if v in verdicts:
            return v
    return "stable"


def unstable(a: np.ndarray, states: tuple[str, ...]) -> bool:
    """Whether A has a growing mode, exponentially or like t."""
    return overall(modes(a, states)) == "unstable"
