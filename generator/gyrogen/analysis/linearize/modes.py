"""A linear model's modes in words: each eigenvalue (a complex pair once)
stable, unstable or marginal, oscillating or not, with its time scale and
the states it moves most.

Each eigenvalue is judged against its own rounding error, not against the
largest eigenvalue: A is known to ~n eps ||A|| (its entries' rounding: on a
stability boundary H_a - I_t Omega = 0 comes out as 5e-17) and the solver
adds as much, which moves a simple eigenvalue by its condition number times
that and splits a defective one apart (a Jordan block's halves by the
square root). So a stiff mode at -1e8 leaves a slow pair at 0.4i and a zero
apart (it costs them ~1e-6), while the halves of a Jordan block stay
together (their condition numbers grow as their distance shrinks).
Eigenvalues within each other's error make one cluster; its mean
(conditioned by its spectral projector, finite for a Jordan block) decides
the verdict, and a marginal cluster grows like t when its block of the
Schur form is not its mean times I to within the cluster's own error.

Every verdict holds for any backward-stable eigensolver: its eigenvalues are
those of A + E with ||E|| a small multiple of n eps ||A||, and the
tolerances are SLACK times that, so no solver, BLAS kernel or CPU can turn
one verdict into another. Within a cluster, rounding moves the members apart
by up to the power law of its size m, (error nu^(m-1))^(1/m), nu the
block's departure from its mean times I (a Jordan block's coupling): a
member's own value tells nothing within that. A cluster stands for one
eigenvalue only if its members, each judged against that bound, would get
one verdict; otherwise it is "cannot judge". Eigenvalues that A's error
swallows whole (a wheel at 1e90 rad/s makes ||A|| 1e87 and its speed loop
at -10 and its zero lie within 1e73 of each other) are one eigenvalue to
A's precision: a solver may return them at +-1e73 in any order, so their
verdict is their mean's against that error, as for any zero.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
from scipy.linalg import lapack

MARGINAL = 1e-7
"""|Re lambda| at most this times |lambda|: marginal whatever the rounding
(an oscillation that takes 1e7 radians to grow or decay by e)."""
SLACK = 10.0
"""A's error is taken as SLACK n eps ||A||_F (the model's rounding and the
solver's backward error are small multiples of n eps ||A||); a cluster's block is a
Jordan block when it is SLACK times its error or spread away from its mean."""
CANNOT = "cannot judge"
"""The verdict of a cluster whose members, each against the bound on what
rounding may move it (_spread_bound), get different verdicts."""
SHOWN = 0.3
"""A mode is said to move the states whose eigenvector entries reach this
fraction of its largest."""


@dataclass(frozen=True)
class Mode:
    eigenvalue: complex
    """Im >= 0: a pair is one mode."""
    verdict: str
    """stable, unstable, marginal or CANNOT."""
    states: tuple[str, ...]
    """The states it moves most."""
    multiplicity: int = 1
    """How many eigenvalues (within their rounding error) it stands for."""
    secular: bool = False
    """Marginal but repeated with fewer eigenvectors than its multiplicity
    (a Jordan block): it grows like t, so unstable."""
    values: tuple[complex, ...] = ()
    """CANNOT's: its members, by real part."""
    error: float = 0.0
    """CANNOT's: their rounding error."""

    @property
    def oscillating(self) -> bool:
        return self.eigenvalue.imag > 0

    def words(self) -> str:
        lam = self.eigenvalue
        where = f" in {', '.join(self.states)}" if self.states else ""
        if self.verdict == CANNOT:
            lo, hi = self.values[0], self.values[-1]
            return (
                f"{CANNOT}: {lo.real:+.6g}{lo.imag:+.6g}i to {hi.real:+.6g}{hi.imag:+.6g}i "
                f"(x{self.multiplicity}), within their rounding error {self.error:.3g} of "
                f"each other: A's condition hides whether they grow or decay{where}"
            )
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


def verdict(real: float, tol: float) -> str:
    if real > tol:
        return "unstable"
    return "stable" if real < -tol else "marginal"


@dataclass(frozen=True)
class _Schur:
    """A's complex Schur form A = Z T Z^H (not balanced: A's error is
    relative to A's norm, whatever its scaling)."""

    t: np.ndarray
    z: np.ndarray
    error: float
    """A's error: SLACK n eps ||A||_F."""

    @property
    def values(self) -> np.ndarray:
        return np.diag(self.t)

    def cluster(self, members: list[int]) -> tuple[np.ndarray, np.ndarray, float]:
        """The members' block of the reordered Schur form, their invariant
        subspace (orthonormal), and the error of their mean."""
        n = len(self.t)
        select = np.zeros(n, dtype=np.int32)
        select[members] = 1
        ts, qs, _, m, s, _, info = lapack.ztrsen(select, self.t, self.z, job="E", lwork=n * n)
        if info != 0 or m != len(members):  # too close to the rest to part: all of it
            return self.t, self.z, np.inf
        error = self.error / s if s > 0 else np.inf
        return ts[:m, :m], qs[:, :m], error


def eigenvalues(a: np.ndarray) -> np.ndarray:
    """A's eigenvalues as the modes read them: the diagonal of its complex
    Schur form (linear.npz stores these, the words print their means: one
    source, so a printed eigenvalue is a stored one)."""
    return _schur(a).values if a.size else np.zeros(0, complex)


def _schur(a: np.ndarray) -> _Schur:
    t, z = scipy.linalg.schur(a, output="complex")
    big = float(np.max(np.abs(a)))
    norm = big * float(np.linalg.norm(a / big)) if big else 0.0  # its square may overflow
    error = SLACK * len(a) * np.finfo(float).eps * norm
    return _Schur(t, z, error)


def _radii(s: _Schur) -> np.ndarray:
    """How far rounding may have moved each eigenvalue: the error times its
    condition number, and at most SLACK times the distance to its nearest
    (exactly equal eigenvalues have an infinite condition number)."""
    values, n = s.values, len(s.t)
    gaps = np.abs(values[:, None] - values[None, :]) + np.diag(np.full(n, np.inf))
    out = np.zeros(n)
    for i in range(n):
        _, _, error = s.cluster([i])
        out[i] = min(error, SLACK * float(np.min(gaps[i]))) if s.error > 0 else 0.0
    return out


def clusters(s: _Schur) -> list[list[int]]:
    """The eigenvalues within each other's rounding error, joined
    transitively; then joined again while two clusters' members may lie
    together (their means within the sum of their spreads' bounds: the
    halves of two Jordan blocks on one eigenvalue, paired across the
    blocks by their nearest)."""
    groups = _nearest(s)
    while True:
        bounds = []
        for members in groups:
            block, _, error = s.cluster(members)
            mean = complex(np.mean(s.values[members]))
            bounds.append((mean, _spread_bound(block, mean, error)))
        pair = next(
            ((i, j) for i in range(len(groups)) for j in range(i)
             if abs(bounds[i][0] - bounds[j][0]) <= bounds[i][1] + bounds[j][1]),
            None,
        )  # fmt: skip
        if pair is None:
            return groups
        i, j = pair
        groups = [g for k, g in enumerate(groups) if k not in pair] + [
            sorted(groups[i] + groups[j])
        ]


def _nearest(s: _Schur) -> list[list[int]]:
    """The eigenvalues within each other's rounding error, joined transitively."""
    values, radii = s.values, _radii(s)
    owner = list(range(len(values)))

    def root(i: int) -> int:
        while owner[i] != i:
            i = owner[i]
        return i

    for i in range(len(values)):
        for j in range(i):
            if abs(values[i] - values[j]) <= radii[i] + radii[j]:
                owner[root(i)] = root(j)
    groups: dict[int, list[int]] = {}
    for i in range(len(values)):
        groups.setdefault(root(i), []).append(i)
    return list(groups.values())


def modes(a: np.ndarray, states: tuple[str, ...]) -> list[Mode]:
    """A's modes, the unstable first, then marginal, then stable (each by
    decreasing real part, the marginal by decreasing frequency: their real
    parts are rounding); a complex pair once."""
    if not a.size:
        return []
    s = _schur(a)
    found = []
    for members in clusters(s):
        block, basis, error = s.cluster(members)
        mean = complex(np.mean(s.values[members]))  # its block's trace, as stored
        found.append((mean, max(error, MARGINAL * abs(mean)), members, block, basis, error))
    out: list[Mode] = []
    for mean, tol, members, block, basis, error in sorted(found, key=lambda f: -f[0].imag):
        if mean.imag < -tol and any(abs(mean.conjugate() - m.eigenvalue) <= tol for m in out):
            continue  # the pair's other half
        lam = complex(mean.real, abs(mean.imag) if abs(mean.imag) > tol else 0.0)
        vectors = _eigenvectors(block, basis, mean, tol, s.values[members])
        size = np.sqrt(np.sum(np.abs(vectors) ** 2, axis=1))  # the same for any basis
        top = float(size.max())
        moved = tuple(n for n, v in zip(states, size, strict=True) if top and v >= SHOWN * top)
        said = verdict(lam.real, tol)
        secular = said == "marginal" and vectors.shape[1] < len(members)
        values = s.values[members]
        if not secular and len(_faces(values, _spread_bound(block, mean, error))) > 1:
            told = tuple(sorted(values, key=lambda v: (v.real, v.imag)))
            out.append(Mode(lam, CANNOT, moved, len(members), values=told, error=error))
            continue
        out.append(Mode(lam, "unstable" if secular else said, moved, len(members), secular))
    rank = {"unstable": 0, CANNOT: 1, "marginal": 2, "stable": 3}
    return sorted(out, key=lambda m: (rank[m.verdict], -_growth(m), -m.eigenvalue.imag))


def _spread_bound(block: np.ndarray, mean: complex, error: float) -> float:
    """How far rounding may move a cluster's members from its mean: the power
    law of its size m, (error nu^(m-1))^(1/m), nu its block's departure from
    mean I (at least the error): error for a semisimple cluster, the square
    root of error times the coupling for a Jordan block of two."""
    m = len(block)
    nu = max(float(np.linalg.norm(block - mean * np.eye(m), 2)), error)
    return float(error ** (1.0 / m) * nu ** (1.0 - 1.0 / m)) if error > 0 else 0.0


def _faces(values: np.ndarray, bound: float) -> set[str]:
    """The verdicts the members get on their own: each against MARGINAL of
    its |lambda|, or the bound on what rounding may have moved it (below
    it, its sign is the solver's, not A's)."""
    return {verdict(v.real, max(MARGINAL * abs(v), bound)) for v in values}


def _growth(m: Mode) -> float:
    return 0.0 if m.verdict == "marginal" else m.eigenvalue.real


def _eigenvectors(
    block: np.ndarray, basis: np.ndarray, mean: complex, tol: float, values: np.ndarray
) -> np.ndarray:
    """A basis of the cluster's eigenvectors: where its Schur block minus
    its mean times I vanishes to within SLACK times the cluster's error or
    spread (a semisimple cluster's block is mean I to within them; a Jordan
    block's coupling is not, and leaves fewer eigenvectors than eigenvalues)."""
    spread = float(np.max(np.abs(values - mean)))
    _, sv, vh = np.linalg.svd(block - mean * np.eye(len(block)))
    rank = int(np.sum(sv > SLACK * max(tol, spread)))
    return np.asarray(basis @ vh[rank:].conj().T)


def overall(found: list[Mode]) -> str:
    """unstable if any mode is; else CANNOT if one is; else marginal if one
    is; else stable."""
    verdicts = {m.verdict for m in found}
    for v in ("unstable", CANNOT, "marginal"):
        if v in verdicts:
            return v
    return "stable"


def unstable(a: np.ndarray, states: tuple[str, ...]) -> bool:
    """Whether A has a growing mode, exponentially or like t."""
    return overall(modes(a, states)) == "unstable"
