"""C, Fortran and the numpy reference, compared at random states and
random physically valid parameters; and setup's refusals of bad ones.

Two correct double-precision codes agree only to about cond(M) * eps, where
cond(M) is the condition number of the coupled 2x2 block of the mass matrix
(both form the lumped inertias with rounding, then solve). So the issue's bar,
a scaled error of 1e-12, applies to parameter sets with cond(M) <= 100; a
second group with ill-conditioned carriers (a tiny carrier with a heavy
offset rotor is nearly a dumbbell) is held to an error of at most
1000 cond(M) eps.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

from gyrogen import reference, sampling
from gyrogen.build import Compiled

TOLERANCE = 1e-12
WELL_CONDITIONED = 100.0
ILL_CONDITIONED_ULPS = 1000.0
EPS = float(np.finfo(float).eps)

Progress = Callable[[str, Iterable[np.ndarray]], Iterable[np.ndarray]]
"""(label, parameter sets) -> the same sets, reporting progress as they go."""


def scaled_error(a: np.ndarray, b: np.ndarray) -> float:
    """max |a - b| / (1 + |b|): relative for large values, absolute near 0."""
    return float(np.max(np.abs(a - b) / (1.0 + np.abs(b))))


@dataclass(frozen=True)
class Row:
    group: str
    pair: str
    error: float
    """Largest scaled error over the group."""
    bar: float
    """The largest error allowed for this group (for the worst set's cond)."""
    worst_condition: float

    @property
    def passed(self) -> bool:
        return self.error <= self.bar


@dataclass
class Report:
    n_states: int
    n_params: dict[str, int] = field(default_factory=dict)
    rows: list[Row] = field(default_factory=list)
    refusals_checked: int = 0
    refusal_failures: list[str] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return all(r.passed for r in self.rows) and not self.refusal_failures


def _label(b: Compiled) -> str:
    return "C" if b.language == "c" else "Fortran"


def _pairs(
    backends: list[Compiled], states: np.ndarray, p: np.ndarray
) -> Iterator[tuple[str, float]]:
    ref = reference.rhs(states, p)
    out = {_label(b): b.rhs(states, b.setup(p)) for b in backends}
    for name, value in out.items():
        yield f"{name} vs reference", scaled_error(value, ref)
    if len(out) == 2:
        yield "C vs Fortran", scaled_error(out["C"], out["Fortran"])


def _group(
    name: str,
    backends: list[Compiled],
    states: np.ndarray,
    params: np.ndarray,
    bar: Callable[[float], float],
    progress: Progress,
) -> list[Row]:
    worst: dict[str, tuple[float, float, float]] = {}  # pair -> (margin, error, cond)
    for p in progress(name, params):
        cond = float(sampling.lumped_condition(p))
        for pair, err in _pairs(backends, states, p):
            margin = err / bar(cond)
            if pair not in worst or margin > worst[pair][0]:
                worst[pair] = (margin, err, cond)
    return [Row(name, pair, err, bar(cond), cond) for pair, (_, err, cond) in worst.items()]


def compare(
    backends: list[Compiled],
    n_states: int = 10_000,
    n_params: int = 100,
    n_ill: int = 20,
    seed: int = 0,
    progress: Progress = lambda label, items: items,
) -> Report:
    rng = np.random.default_rng(seed)
    states = sampling.random_states(rng, n_states)
    well = sampling.random_parameters(rng, n_params, max_condition=WELL_CONDITIONED)
    draws = sampling.random_parameters(rng, 50 * n_ill)
    ill = draws[np.argsort(sampling.lumped_condition(draws))[-n_ill:]]  # the worst of many
    report = Report(n_states, {"well": len(well), "ill": len(ill)})
    report.rows += _group(
        f"cond <= {WELL_CONDITIONED:g}", backends, states, well, lambda c: TOLERANCE, progress
    )
    report.rows += _group(
        f"cond > {WELL_CONDITIONED:g}",
        backends,
        states,
        ill,
        lambda c: ILL_CONDITIONED_ULPS * c * EPS,
        progress,
    )
    _check_refusals(backends, well[:3], report)
    return report


def _check_refusals(backends: list[Compiled], bases: np.ndarray, report: Report) -> None:
    for base in bases:
        for what, p, expected in sampling.invalid_parameters(base):
            for b in backends:
                code, _ = b.setup_code(p)
                report.refusals_checked += 1
                if code != expected:
                    report.refusal_failures.append(
                        f"{b.language} setup returned {code} for {what} (expected {expected})"
                    )
