"""C, Fortran and the numpy reference, compared at random states and
random physically valid parameters; and setup's refusals of bad ones.

Two correct double-precision codes agree only to rounding, and rounding
scales with the sizes of what is added, not with the result: where terms
cancel (the speed controller's slip u4 - u2 - w_ref, a power T (u4 - u2))
a relative error of 1e-12 in the result is correct code. So an element's
error is |a - b| / (1 + |b| + S), S the sizes of the terms involved: the sum
over every input v_j (state or parameter) of |d f / d v_j| |v_j|, measured
on the reference by perturbing each input in turn. (S is measured only for
the states whose plain error is above SUSPECT; elsewhere it cannot change
the verdict.) And the solve of the mass matrix's coupled block loses up to
cond(M) eps: the bar TOLERANCE applies to parameter sets with cond(M) <= 100;
a second group with ill-conditioned carriers (a tiny carrier with a heavy
offset rotor is nearly a dumbbell) is held to 1000 cond(M) eps.

The Jacobian is compared with central differences of the reference's rhs,
to JAC_TOLERANCE of its row's sizes (a wrong entry is wrong by O(1)), with
slack for the differences' own error: their change with the step, and the
rounding of f's values (ROUNDING eps |f| / h).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from gyrogen.abi import PARAMETERS
from gyrogen.errors import BuildError, GyrogenError
from gyrogen.oracle import sampling, scene_view
from gyrogen.runtime.compiled import Compiled
from gyrogen.runtime.scene_build import build_files
from gyrogen.scene import Scene

if TYPE_CHECKING:  # rendering's (sympy): verify compares sources it did not render
    from gyrogen.codegen.context import SceneContext

TOLERANCE = 1e-12
JAC_TOLERANCE = 1e-6
SUSPECT = 1e-14
"""Rows with a plain scaled error above this get their term sizes measured."""
STEP = 1e-6
"""Relative perturbation of an input, for term sizes and the Jacobian."""
WELL_CONDITIONED = 100.0
ILL_CONDITIONED_ULPS = 1000.0
EPS = float(np.finfo(float).eps)
ROUNDING = 16.0
"""The Jacobian's slack for the rounding of the central differences, in
units of eps |f| / h (a few roundings of each of f's terms)."""

Progress = Callable[[str, Iterable[np.ndarray]], Iterable[np.ndarray]]
"""(label, parameter sets) -> the same sets, reporting progress as they go."""


def scaled_error(a: np.ndarray, b: np.ndarray) -> float:
    """max |a - b| / (1 + |b|): relative for large values, absolute near 0."""
    return float(np.max(np.abs(a - b) / (1.0 + np.abs(b))))


Function = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""(states (n, nx), runtime parameters) -> values (n, m), vectorized."""


def term_sizes(
    f: Function, states: np.ndarray, p: np.ndarray, base: np.ndarray | None = None
) -> np.ndarray:
    """S for each value of f at each state: sum_j |df/dv_j| |v_j| over the
    states' entries and the runtime parameters, by forward differences
    (base: f's values at the states, if the caller has them)."""
    base = f(states, p) if base is None else base
    size = np.zeros_like(base)
    nx = states.shape[1]
    moved = np.repeat(states[None], nx, axis=0)
    moved[np.arange(nx), :, np.arange(nx)] *= 1.0 + STEP
    size += np.abs(_stacked(f, moved, p) - base).sum(0)
    for j in range(len(p)):
        q = p.copy()
        q[j] *= 1.0 + STEP
        size += np.abs(f(states, q) - base)
    return size / STEP


def _stacked(f: Function, moved: np.ndarray, p: np.ndarray) -> np.ndarray:
    """f at each of the (k, n, nx) moved copies of n states, (k, n, m): one
    call over all of them (f is vectorized row by row), in chunks of at most
    CHUNK rows."""
    k, n, nx = moved.shape
    rows = moved.reshape(k * n, nx)
    out = [f(rows[i : i + CHUNK], p) for i in range(0, k * n, CHUNK)]
    return np.concatenate(out).reshape(k, n, -1)


CHUNK = 20_000
"""Rows per call of a stacked evaluation (bounds the reference's temporaries)."""


class TermSizes:
    """S of f's values at states' rows (term_sizes), each row measured once
    however many comparisons ask for it (a function's pairs share them);
    values: f at every state, if the caller has them (then f is not asked
    again at the rows)."""

    def __init__(
        self, f: Function, states: np.ndarray, p: np.ndarray, values: np.ndarray | None = None
    ) -> None:
        self.f, self.states, self.p, self.values = f, states, p, values
        self.known = np.zeros(len(states), dtype=bool)
        self.sizes: np.ndarray | None = None

    def at(self, rows: np.ndarray) -> np.ndarray:
        new = rows[~self.known[rows]]
        if len(new):
            base = None if self.values is None else self.values[new]
            measured = term_sizes(self.f, self.states[new], self.p, base)
            if self.sizes is None:
                self.sizes = np.zeros((len(self.states), measured.shape[1]))
            self.sizes[new], self.known[new] = measured, True
        assert self.sizes is not None
        return self.sizes[rows]


def size_scaled_error(a: np.ndarray, b: np.ndarray, f: Function, states: np.ndarray,
                      p: np.ndarray, sizes: TermSizes | None = None) -> float:  # fmt: skip
    """max |a - b| / (1 + |b| + S) over every element (see the module's
    docstring); sizes: the S already measured at some of the states."""
    a, b = np.atleast_2d(a), np.atleast_2d(b)
    err = np.abs(a - b) / (1.0 + np.abs(b))
    rows = np.flatnonzero(np.max(err, axis=1) > SUSPECT)
    if len(rows):
        s = (TermSizes(f, states, p) if sizes is None else sizes).at(rows)
        err[rows] = np.abs(a[rows] - b[rows]) / (1.0 + np.abs(b[rows]) + s)
    return float(np.max(err))


def jacobian_error(
    jac: np.ndarray, f: Function, states: np.ndarray, p: np.ndarray, kinks: Function | None = None
) -> float:
    """max |J - J_fd| / (1 + row sizes + fd error), J (n, nx, nx) against
    central differences of f with steps STEP (1 + |x_j|). The differences'
    own error (truncation and rounding) is estimated by the gap to those with
    twice the step, and allowed for: the bar then measures the code, not the
    reference's differencing of a stiff or tiny-scaled system. kinks(states,
    p): values whose signs change where f is not smooth (a torque clamp); a
    column whose differences would straddle one is not compared there (a
    difference across a kink is no derivative of either side)."""
    return ReferenceJacobian.of(f, states, p, kinks).error(jac)


@dataclass(frozen=True)
class ReferenceJacobian:
    """What jacobian_error measures a Jacobian against, taken once for any
    number of them: the fine differences, the bar's denominator, and where
    the differences are smooth (None: everywhere)."""

    fine: np.ndarray
    scale: np.ndarray
    smooth: np.ndarray | None

    @classmethod
    def of(
        cls, f: Function, states: np.ndarray, p: np.ndarray, kinks: Function | None = None
    ) -> ReferenceJacobian:
        (fine, noise), (coarse, _) = (
            _differences(f, states, p, 1.0),
            _differences(f, states, p, 2.0),
        )
        rows = 1.0 + np.sum(
            np.abs(fine) * (1.0 + np.abs(states[:, None, :])), axis=2, keepdims=True
        )
        slack = (np.abs(fine - coarse) + ROUNDING * noise) / JAC_TOLERANCE
        smooth = None if kinks is None else _smooth(kinks, states, p)[:, None, :]
        return cls(fine, rows + slack, smooth)

    def error(self, jac: np.ndarray) -> float:
        err = np.abs(jac - self.fine) / self.scale
        if self.smooth is not None:
            err = np.where(self.smooth, err, 0.0)
        return float(np.max(err))


def _shifts(states: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(up, down, h): the states with x_j + h_j and x_j - h_j, h_j =
    scale STEP (1 + |x_j|), in each entry j in turn, (nx, n, nx); h (nx, n)."""
    nx = states.shape[1]
    h = scale * STEP * (1.0 + np.abs(states.T))
    up, down = np.repeat(states[None], nx, axis=0), np.repeat(states[None], nx, axis=0)
    up[np.arange(nx), :, np.arange(nx)] += h
    down[np.arange(nx), :, np.arange(nx)] -= h
    return up, down, h


def _smooth(kinks: Function, states: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(n, nx): whether every kink keeps its side over x_j +- 2 STEP (1 + |x_j|),
    the widest differences jacobian_error takes."""
    side = np.sign(kinks(states, p))
    up, down, h = _shifts(states, 2.0)
    moved = np.sign(_stacked(kinks, np.concatenate([up, down]), p))
    same = np.all(moved == side, axis=2)  # (2 nx, n)
    return (same[: len(h)] & same[len(h) :]).T


def _differences(
    f: Function, states: np.ndarray, p: np.ndarray, scale: float
) -> tuple[np.ndarray, np.ndarray]:
    """Central differences (n, m, nx), and what rounding alone may make of
    each: eps (|f(x + h)| + |f(x - h)|) / 2h. Where f's terms are far larger
    than a step changes them (a wheel at 1e9 rad/s), the difference of two
    rounded values is that noise, not the derivative."""
    up, down, h = _shifts(states, scale)
    nx = len(h)
    both = _stacked(f, np.concatenate([up, down]), p)  # (2 nx, n, m)
    fd = (both[:nx] - both[nx:]) / (2.0 * h[:, :, None])  # (nx, n, m)
    noise = EPS * (np.abs(both[:nx]) + np.abs(both[nx:])) / (2.0 * h[:, :, None])
    return fd.transpose(1, 2, 0), noise.transpose(1, 2, 0)


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
    backends: list[Compiled], scene: Scene, states: np.ndarray, p: np.ndarray, t: float
) -> Iterator[tuple[str, float]]:
    """Every backend against the reference, and the backends against each
    other: the rhs, each output function, and the Jacobian."""
    names = ["rhs", *scene.outputs.functions]
    names += ["events"] if scene.events else []
    constants = {_label(b): b.setup(p) for b in backends}
    for name in names:
        tag = "" if name == "rhs" else f" {name}"
        f = _reference(scene, name, t)
        ref = values = f(states, p)
        if name == "rhs":
            out = {_label(b): b.rhs(states, constants[_label(b)], t) for b in backends}
        elif name == "events":  # NaN where the reference's is NaN too is agreement
            out = {_label(b): b.events(states, constants[_label(b)], t) for b in backends}
            both = {k: np.isnan(v) & np.isnan(ref) for k, v in out.items()}
            out = {k: np.where(both[k], 0.0, v) for k, v in out.items()}
            ref = np.where(np.any(list(both.values()), axis=0), 0.0, ref)
        else:
            out = {_label(b): b.output(name, states, constants[_label(b)], t) for b in backends}
        sizes = TermSizes(f, states, p, values)  # one measure of a row's S for every pair
        for label, value in out.items():
            err = size_scaled_error(value, ref, f, states, p, sizes)
            yield f"{label} vs reference{tag}", err
        if len(out) == 2:
            c_vs_f = size_scaled_error(out["C"], out["Fortran"], f, states, p, sizes)
            yield f"C vs Fortran{tag}", c_vs_f
    few, reference = states[:JAC_STATES], None
    for b in backends:
        if "jac" in b.manifest["functions"][b.language]:
            if reference is None:
                kinks = lambda xs, q: scene_view.kinks(scene, xs, q, t)  # noqa: E731
                reference = ReferenceJacobian.of(_reference(scene, "rhs", t), few, p, kinks)
            jac = b.jacobians(few, constants[_label(b)], t)
            yield f"{_label(b)} vs reference jac", reference.error(jac)


JAC_STATES = 200
"""States at which the Jacobian is compared (one compiled call for them all)."""


def _reference(scene: Scene, name: str, t: float) -> Function:
    if name == "rhs":
        return lambda xs, p: scene_view.rhs(scene, xs, p, t)
    if name == "events":
        return lambda xs, p: scene_view.events(scene, xs, p, t)
    return lambda xs, p: scene_view.output(scene, name, xs, p, t)


def _group(
    name: str,
    backends: list[Compiled],
    scene: Scene,
    states: np.ndarray,
    params: np.ndarray,
    bar: Callable[[float], float],
    progress: Progress,
    rng: np.random.Generator,
) -> list[Row]:
    worst: dict[str, tuple[float, float, float]] = {}  # pair -> (margin, error, cond)
    for p in progress(name, params):
        cond = _condition(scene, p)
        t = float(rng.uniform(*_time_span(scene)))
        for pair, err in _pairs(backends, scene, states, p, t):
            margin = err / _bar(pair, cond, bar)
            if pair not in worst or margin > worst[pair][0]:
                worst[pair] = (margin, err, cond)
    return [
        Row(name, pair, err, _bar(pair, cond, bar), cond) for pair, (_, err, cond) in worst.items()
    ]


def _bar(pair: str, cond: float, bar: Callable[[float], float]) -> float:
    """The group's bar; for the Jacobian JAC_TOLERANCE, or the rounding of
    the reference's differences (cond eps / STEP) when that is larger."""
    if pair.endswith(" jac"):
        return max(JAC_TOLERANCE, 10.0 * cond * EPS / STEP)
    return bar(cond)


def _time_span(scene: Scene) -> tuple[float, float]:
    """Times to evaluate at: across a T(t) table and beyond both its ends."""
    times = scene_view.table_times(scene)
    if not times.size:
        return (0.0, 1.0)
    t0, t1 = float(times[0]), float(times[-1])
    return (t0 - 0.1 * (t1 - t0) - 1.0, t1 + 0.1 * (t1 - t0) + 1.0)


def compare(
    backends: list[Compiled],
    scene: Scene,
    n_states: int = 10_000,
    n_params: int = 100,
    n_ill: int = 20,
    seed: int = 0,
    progress: Progress = lambda label, items: items,
    given: np.ndarray | None = None,
) -> Report:
    """Compare at n_states random states and random runtime parameters (and
    the sets given, e.g. the scene's own): well-conditioned ones at the
    issue's bar, the n_ill worst-conditioned of many draws at cond(M) eps."""
    rng = np.random.default_rng(seed)
    if given is not None and len(given):
        # sets setup refuses (9: their constants overflow) are not compared
        given = given[[backends[0].setup_code(p)[0] == 0 for p in given]]
    states = scene_view.random_states(scene, rng, n_states)
    well = scene_view.random_runtime(scene, rng, n_params, max_condition=WELL_CONDITIONED)
    draws = scene_view.random_runtime(scene, rng, 50 * n_ill)
    if given is not None and len(given):
        draws = np.vstack([draws, given])
        fine = [p for p in given if _condition(scene, p) <= WELL_CONDITIONED]
        well = np.vstack([well, np.array(fine).reshape(len(fine), given.shape[1])])
    if not len(well) and not len(draws):
        raise GyrogenError(
            f"{scene.name}: no valid runtime parameter values found at random: give "
            "[simulate] parameters to compare at"
        )
    conds = [_condition(scene, p) for p in draws]
    ill = draws[[i for i in np.argsort(conds)[-n_ill:] if conds[i] > WELL_CONDITIONED]]
    own = len(fine) if given is not None and len(given) else 0
    report = Report(n_states, {"well": len(well), "ill": len(ill), "own": own})
    label = f"cond <= {WELL_CONDITIONED:g}"
    report.rows += _group(label, backends, scene, states, well, lambda c: TOLERANCE, progress, rng)
    if len(ill):
        report.rows += _group(
            f"cond > {WELL_CONDITIONED:g}",
            backends,
            scene,
            states,
            ill,
            lambda c: ILL_CONDITIONED_ULPS * c * EPS,
            progress,
            rng,
        )
    bases = well if len(well) else draws
    _check_refusals(backends, scene, bases[:3], report)
    return report


def given_parameters(scene: Scene) -> np.ndarray | None:
    """The scene's [simulate] parameters as one runtime vector, if complete."""
    values = scene.simulate.parameters
    if not all(n in values for n in scene.runtime):
        return None
    return np.array([[values[n] for n in scene.runtime]])


def _condition(scene: Scene, p: np.ndarray) -> float:
    return scene_view.condition(scene, p)


def invalid_runtime(scene: Scene, base: np.ndarray) -> list[tuple[str, np.ndarray, int]]:
    """Invalid p[] vectors for a scene, with the code setup must return: the
    full model's invalid cases that change runtime entries only, and NaN in
    each runtime parameter."""
    cases = []
    if scene.rotors:  # the torque laws take any finite value; the inertial ones not
        return sampling.invalid_cluster(scene, base) + _nan_cases(scene, base)
    full = scene_view.full_parameters(scene, base, np.zeros((1, 14)), 0.0)[0]
    index = {n: i for i, n in enumerate(PARAMETERS)}
    for what, p_full, code in sampling.invalid_parameters(full):
        changed = {PARAMETERS[i] for i in np.flatnonzero(~(p_full == full))}
        if changed and changed <= set(scene.runtime):
            p = np.array(
                [p_full[index[r]] if r in index else base[j] for j, r in enumerate(scene.runtime)]
            )
            cases.append((what, p, code))
    return cases + _nan_cases(scene, base)


def _nan_cases(scene: Scene, base: np.ndarray) -> list[tuple[str, np.ndarray, int]]:
    cases = []
    for j, name in enumerate(scene.runtime):
        p = base.copy()
        p[j] = np.nan
        cases.append((f"{name} = NaN", p, 1))
    return cases


def _check_refusals(
    backends: list[Compiled], scene: Scene, bases: np.ndarray, report: Report
) -> None:
    for base in bases:
        for what, p, expected in invalid_runtime(scene, base):
            for b in backends:
                code, _ = b.setup_code(p)
                report.refusals_checked += 1
                if code != expected:
                    report.refusal_failures.append(
                        f"{b.language} setup returned {code} for {what} (expected {expected})"
                    )


CHECK_STATES = 200
CHECK_PARAMS = 5
CHECK_ILL = 2
"""What `gyrogen generate` compares before it writes: states x parameter
sets (well-conditioned, ill-conditioned), as `gyrogen verify` does in full."""


def check_rendered(unit: SceneContext, files: Mapping[str, str]) -> float:
    """Compile every target in files (C with the strict flags, Fortran with
    -std=f2008 -Werror) and compare the rhs, outputs and Jacobian with the
    numpy reference; raise GyrogenError naming the scene and what differs.
    Returns the seconds it took."""
    t0 = time.perf_counter()
    name = unit.scene.name
    try:
        built = build_files(files, unit.scene.targets)
    except BuildError as exc:
        raise GyrogenError(f"{name}: generated code that does not compile: {exc}") from exc
    given = given_parameters(unit.scene)
    report = compare(
        list(built.values()), unit.scene, CHECK_STATES, CHECK_PARAMS, CHECK_ILL, seed=0, given=given
    )
    if report.refusal_failures:
        raise GyrogenError(f"{name}: the generated setup differs: {report.refusal_failures[0]}")
    failed = [r for r in report.rows if not r.passed]
    if failed:
        r = max(failed, key=lambda r: r.error / r.bar)
        raise GyrogenError(
            f"{name}: the generated code differs from the reference: {r.pair}, error "
            f"{r.error:.2e} above {r.bar:.2e} (cond {r.worst_condition:.3g})"
        )
    return time.perf_counter() - t0
