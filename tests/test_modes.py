"""The modes' verdicts on spectra spread over many decades: each eigenvalue
is judged against its own rounding error, so a stiff mode (-1e8) neither
merges a slow pair with a zero (a false Jordan block, "grows like t") nor
hides a slow growth, while a Jordan block that rounding splits is still
found (alone, beside a stiff mode, on the imaginary axis, of size 3)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gyrogen.analysis.linearize import modes

PAIR = np.array([[-0.015, 0.41], [-0.355, 0.015]])
"""A gyroscopic nutation block: eigenvalues +-0.38i (no damping)."""


def _hidden(*blocks: np.ndarray, seed: int = 3) -> np.ndarray:
    """The block diagonal of blocks, seen in a random orthonormal basis (so
    rounding touches every entry)."""
    n = sum(len(b) for b in blocks)
    a = np.zeros((n, n))
    at = 0
    for b in blocks:
        a[at : at + len(b), at : at + len(b)] = b
        at += len(b)
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(n, n)))
    return q @ a @ q.T


def _found(a: np.ndarray) -> list[modes.Mode]:
    return modes.modes(a, tuple(f"x{i}" for i in range(len(a))))


def _summary(found: list[modes.Mode]) -> list[tuple[str, int, bool, float]]:
    return [(m.verdict, m.multiplicity, m.secular, round(m.eigenvalue.imag, 3)) for m in found]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_stiff_mode_leaves_a_slow_pair_and_a_zero_apart(seed: int) -> None:
    """stiff_wheel's spectrum: +-0.38i, 0, -1e8. Measured against the
    largest eigenvalue, all three slow ones fell within 10 of each other:
    "unstable (x3), grows like t"."""
    found = _found(_hidden(PAIR, np.zeros((1, 1)), -1e8 * np.ones((1, 1)), seed=seed))
    assert modes.overall(found) == "marginal"
    assert _summary(found) == [
        ("marginal", 1, False, 0.381),
        ("marginal", 1, False, 0.0),
        ("stable", 1, False, 0.0),
    ]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_stiff_mode_does_not_hide_a_slow_growth(seed: int) -> None:
    """+0.145, -0.145, 0, -1e8 (a saddle beside a stiff wheel): the growth
    is its own mode, exponential, not a Jordan block with its neighbours."""
    saddle = np.array([[0.0, 0.145], [0.145, 0.0]])
    found = _found(_hidden(saddle, np.zeros((1, 1)), -1e8 * np.ones((1, 1)), seed=seed))
    assert modes.overall(found) == "unstable"
    growing = found[0]
    assert (growing.verdict, growing.multiplicity, growing.secular) == ("unstable", 1, False)
    assert growing.eigenvalue.real == pytest.approx(0.145, rel=1e-6)
    assert "growing: doubles every 4.78 s" in growing.words()
    assert [m.verdict for m in found[1:]] == ["marginal", "stable", "stable"]


@pytest.mark.parametrize("gamma", [1.0, 1e-3])
def test_a_jordan_block_beside_a_stiff_mode_grows_like_t(gamma: float) -> None:
    """0 twice with one eigenvector (coupling gamma), the pair, -1e8:
    rounding splits the zeros by ~sqrt(gamma eps 1e8), yet they stay one
    cluster, found defective; the pair stays apart and marginal."""
    jordan = np.array([[0.0, gamma], [0.0, 0.0]])
    found = _found(_hidden(jordan, PAIR, -1e8 * np.ones((1, 1))))
    assert modes.overall(found) == "unstable"
    assert _summary(found) == [
        ("unstable", 2, True, 0.0),
        ("marginal", 1, False, 0.381),
        ("stable", 1, False, 0.0),
    ]
    assert "repeated without a full set of eigenvectors: grows like t" in found[0].words()


def test_jordan_blocks_alone_grow_like_t() -> None:
    exact = np.array([[0.0, 1.0], [0.0, 0.0]])
    triple = _hidden(np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]]))
    rotation = np.array([[0.0, 1.0], [-1.0, 0.0]])
    collision = _hidden(np.block([[rotation, np.eye(2)], [np.zeros((2, 2)), rotation]]))
    for a, imag, times in ((exact, 0.0, 2), (_hidden(exact), 0.0, 2), (triple, 0.0, 3)):
        assert _summary(_found(a)) == [("unstable", times, True, imag)]
    # two pairs at +-i with one eigenvector each (a stability boundary)
    assert _summary(_found(collision)) == [("unstable", 2, True, 1.0)]


def test_repeated_eigenvalues_with_every_eigenvector_are_marginal() -> None:
    rotation = np.array([[0.0, 1.0], [-1.0, 0.0]])
    twice = _hidden(np.block([[rotation, np.zeros((2, 2))], [np.zeros((2, 2)), rotation]]))
    assert _summary(_found(twice)) == [("marginal", 2, False, 1.0)]
    assert _summary(_found(np.zeros((3, 3)))) == [("marginal", 3, False, 0.0)]
    beside = _found(_hidden(np.zeros((2, 2)), -1e8 * np.ones((1, 1))))
    assert _summary(beside) == [("marginal", 2, False, 0.0), ("stable", 1, False, 0.0)]


def test_a_decaying_jordan_block_is_stable() -> None:
    found = _found(_hidden(np.array([[-1e-3, 1.0], [0.0, -1e-3]])))
    assert _summary(found) == [("stable", 2, False, 0.0)]
    assert found[0].eigenvalue.real == pytest.approx(-1e-3, rel=1e-6)


def test_the_verdicts_do_not_depend_on_the_units() -> None:
    """A in other units (times 1e200, 1e-200) has the same modes, scaled:
    A's norm is taken without overflow or underflow (squared, 1e200's
    entries made it inf, one cluster of everything, marginal)."""
    saddle = np.array([[0.0, 0.145], [0.145, 0.0]])
    a = _hidden(saddle, PAIR, np.array([[0.0, 1.0], [0.0, 0.0]]), -1e8 * np.ones((1, 1)))
    found = _found(a)
    assert [(m.verdict, m.multiplicity, m.secular) for m in found] == [
        ("unstable", 1, False),
        ("unstable", 2, True),
        ("marginal", 1, False),
        ("stable", 1, False),
        ("stable", 1, False),
    ]
    for scale in (1e200, 1e-200):
        scaled = _found(scale * a)
        assert [(m.verdict, m.multiplicity, m.secular, m.states) for m in scaled] == [
            (m.verdict, m.multiplicity, m.secular, m.states) for m in found
        ]
        for m, n in zip(scaled, found, strict=True):
            if not n.secular:  # a Jordan block's mean is rounding
                assert abs(m.eigenvalue - scale * n.eigenvalue) <= 1e-5 * scale * abs(n.eigenvalue)


def _nutation_beside(omega: float) -> np.ndarray:
    """speed_controlled's A with a wheel at w_ref: a nutation pair at
    +-omega i (omega ~ J w_ref / I), a speed loop at -10 and the momentum
    about a2's zero as the model's rounding leaves it (-8 eps), in the
    structure the model has."""
    a = np.zeros((4, 4))
    a[0, 1], a[1, 0] = omega, -omega
    a[2, 2], a[2, 3], a[3, 3] = -10.0, 10.0, -8 * np.finfo(float).eps
    return a


@pytest.mark.parametrize("power", range(0, 101, 5))
def test_a_loop_beside_a_fast_pair_is_stable_while_a_resolves_it(power: int) -> None:
    """-10 is stable while A's error (SLACK n eps ||A||) is below it. Past
    that, the loop and the zero are one eigenvalue to A's precision: a
    backward-stable solver may return them anywhere within the error, in
    either order, so they are one marginal cluster (x2), judged by their mean
    against that error, whatever the CPU (they read "cannot judge" when the
    solver happened to return them apart, as LAPACK does from this exact
    structure, and not when turned or perturbed by rounding)."""
    a = _nutation_beside(10.0**power)
    found = _found(a)
    verdicts = {(m.verdict, m.multiplicity) for m in found}
    assert ("marginal", 1) in verdicts  # the pair: its |Re| is 1e-7 of it at most
    if 10.0**power * 1e-13 < 10.0:
        assert {("stable", 1)} <= verdicts and ("marginal", 2) not in verdicts, found
    else:
        assert verdicts == {("marginal", 1), ("marginal", 2)}, found
        merged = next(m for m in found if m.multiplicity == 2)
        assert abs(merged.eigenvalue) <= modes._schur(a).error
    q, _ = np.linalg.qr(np.random.default_rng(power).normal(size=(4, 4)))
    turned = _found(q @ a @ q.T)
    assert [(m.verdict, m.multiplicity) for m in turned] == [
        (m.verdict, m.multiplicity) for m in found
    ]


def test_a_loop_swallowed_by_the_error_does_not_depend_on_the_units() -> None:
    a = _nutation_beside(1e90)
    for scale in (1.0, 1e-200, 1e200):
        assert [(m.verdict, m.multiplicity) for m in _found(scale * a)] == [
            ("marginal", 1),
            ("marginal", 2),
        ]


def test_members_judged_apart_beyond_their_rounding_cannot_be_judged() -> None:
    """A cluster whose members, each allowed what rounding may move it,
    still get different verdicts stands for no one eigenvalue."""
    values = np.array([-1.0, 0.0, 1.0])
    assert modes._faces(values, 0.5) == {"stable", "marginal", "unstable"}
    assert modes._faces(values, 2.0) == {"marginal"}


ROTATION = np.array([[0.0, 1.0], [-1.0, 0.0]])
KINDS = ("zero", "zeros", "pair", "pair twice", "stable", "unstable", "spiral in",
         "spiral out", "jordan", "jordan pair", "stiff")  # fmt: skip
"""Blocks whose verdict A's precision settles: exact zeros and pure
oscillations (marginal, repeated with every eigenvector too), real and
complex modes far off the axis, Jordan blocks on it, a stiff mode."""


def _block(kind: str, size: float) -> np.ndarray:
    """One block of KINDS at the magnitude size."""
    pair = size * ROTATION
    blocks = {
        "zero": np.zeros((1, 1)),
        "zeros": np.zeros((2, 2)),
        "pair": pair,
        "pair twice": np.block([[pair, np.zeros((2, 2))], [np.zeros((2, 2)), pair]]),
        "stable": -size * np.ones((1, 1)),
        "unstable": size * np.ones((1, 1)),
        "spiral in": pair - 0.1 * size * np.eye(2),
        "spiral out": pair + 0.1 * size * np.eye(2),
        "jordan": np.array([[0.0, size], [0.0, 0.0]]),
        "jordan pair": np.block([[pair, size * np.eye(2)], [np.zeros((2, 2)), pair]]),
        "stiff": -1e8 * size * np.ones((1, 1)),
    }
    return blocks[kind]


@st.composite
def _spectra(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray]:
    """A (blocks of KINDS at distinct magnitudes 1, 3, 5, ... times a unit,
    seen in a random orthonormal basis) and A as a backward-stable solver
    may see it: turned by another orthogonal similarity, plus a perturbation
    of 0 to 3 n eps ||A||_F."""
    kinds = draw(st.lists(st.sampled_from(KINDS), min_size=1, max_size=5))
    unit = 10.0 ** draw(st.integers(-6, 6))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    blocks = [_block(k, unit * (2 * i + 1)) for i, k in enumerate(kinds)]
    a = _hidden(*blocks, seed=int(rng.integers(2**32)))
    n = len(a)
    q, _ = np.linalg.qr(rng.normal(size=(n, n)))
    noise = rng.normal(size=(n, n))
    size = draw(st.floats(0.0, 3.0)) * n * np.finfo(float).eps * np.linalg.norm(a)
    return a, q @ (a + size * noise / np.linalg.norm(noise)) @ q.T


@settings(derandomize=True, max_examples=300, deadline=None)
@given(_spectra())
def test_the_verdicts_hold_for_any_backward_stable_solver(drawn: tuple) -> None:
    """What a solver may return for A (the eigenvalues of A + E, ||E|| a few
    n eps ||A||, in any orthonormal basis) gets A's verdicts: on an AVX-512
    BLAS a double zero beside -1e8 came out as -7e-10 and +1.7e-9, whose own
    verdicts differ, and read "cannot judge" where other CPUs said marginal."""
    a, seen = drawn
    verdicts = lambda m: sorted((v.verdict, v.multiplicity, v.secular) for v in _found(m))  # noqa: E731
    assert verdicts(seen) == verdicts(a)
