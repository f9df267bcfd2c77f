"""The compiled integrators (gyrogen.methods), in C and Fortran:
against scipy's DOP853 on the numpy reference, against the torque-free closed
form, their convergence orders, their failure codes, batch against single
calls, their counters, a stiff case Rodas4 must win, and the strict builds."""

from __future__ import annotations

import itertools
import subprocess
from collections.abc import Callable, Iterator
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from sources import write_sources

from gyrogen import abi, methods, tableaus
from gyrogen.oracle import scene_view
from gyrogen.runtime import build, flags
from gyrogen.runtime.compiled import Compiled
from gyrogen.scene import Scene, load, parse

pytestmark = pytest.mark.slow  # every compiled integrator against scipy's

REPO = Path(__file__).resolve().parents[1]
LANGUAGES = ["c", "fortran"]
SCENES = ["gyrostat", "torque_free", "speed_controlled"]
ADAPTIVE = list(methods.ADAPTIVE)
SMOOTH_ONLY_OUT = [m for m in ADAPTIVE if not methods.get(m).taylor]
"""What a scene whose rhs is not smooth (a torque table) may list."""
OK, UNDERFLOW, MAX_STEPS, NONFINITE, SINGULAR, ARGUMENT, ATTITUDE = range(7)

Get = Callable[[str, str], Compiled]

# A small scene for the tests that render their own: the wheel of
# speed_controlled under a tabled torque T(t) (f depends on t).
TABLED = """
name = "tabled"
description = "momentum wheel under a tabled torque"
integrators = {integrators}

[parameters]
m_a = 300.0
m_b = 4.0
I11 = 60.0
I22 = 75.0
I33 = 55.0
I13 = 1.5
I   = 0.02
J   = 0.03
l1  = 0.1
l3  = 0.25

[effects]
translation = false
torque = "table"
torque_table = [[0.0, 0.0], [0.5, 0.4], [1.5, -0.3]]

[simulate]
initial = {{ u1 = 0.02, u2 = 0.1, u3 = -0.01, u4 = 10.0 }}
"""


def tabled(integrators: list[str]) -> Scene:
    return parse(TABLED.format(integrators=str(integrators).replace("'", '"')), "tabled")


@pytest.fixture(scope="module")
def compiled(backends: dict[str, Compiled], cache_dir: Path) -> Iterator[Get]:
    """(scene, language) -> the backend, built once from generated/<scene>
    (the default scene from the session's fresh copy)."""
    built = {("gyrostat", lang): backends[lang] for lang in LANGUAGES}
    mp = pytest.MonkeyPatch()
    mp.setenv("GYROGEN_CACHE", str(cache_dir))

    def get(scene: str, language: str) -> Compiled:
        if (scene, language) not in built:
            built[scene, language] = build.build(REPO / "generated" / scene, language)
        return built[scene, language]

    yield get
    mp.undo()


def problem(name: str) -> tuple[Scene, np.ndarray, np.ndarray]:
    """The scene's simulate section: initial state and runtime parameters."""
    scene = load(name)
    x0 = np.array([scene.simulate.initial.get(s, 0.0) for s in scene.states])
    p = np.array([scene.simulate.parameters[n] for n in scene.runtime])
    return scene, x0, p


@cache
def scipy_reference(name: str, t1: float) -> np.ndarray:
    scene, x0, p = problem(name)
    sol = solve_ivp(
        lambda t, x: scene_view.rhs(scene, x, p, t)[0],
        (0.0, t1), x0, method="DOP853", rtol=1e-12, atol=1e-12,
    )  # fmt: skip
    assert sol.success
    return sol.y[:, -1]


def mixed_error(x: np.ndarray, ref: np.ndarray) -> float:
    return float(np.max(np.abs(x - ref) / (1.0 + np.abs(ref))))


# --- accuracy ---------------------------------------------------------------


@pytest.mark.parametrize("language", LANGUAGES)
@pytest.mark.parametrize("name", SCENES)
def test_agrees_with_scipy_dop853(compiled: Get, name: str, language: str) -> None:
    b = compiled(name, language)
    _, x0, p = problem(name)
    t1 = 5.0
    ref = scipy_reference(name, t1)
    c = b.setup(p)
    for method in ADAPTIVE:
        x, stats, code = b.integrate(method, x0, c, 0.0, t1, rtol=1e-10, atol=1e-10)
        assert code == OK and stats["t"] == t1
        assert mixed_error(x, ref) < 1e-8, method
    x, stats, code = b.integrate("rk4", x0, c, 0.0, t1, steps=2000)
    assert code == OK and stats["t"] == t1
    assert mixed_error(x, ref) < 1e-8


def torque_free_closed_form(t: float) -> tuple[np.ndarray, np.ndarray]:
    """u1..u4 of the torque-free axisymmetric gyrostat (NOTES.md): u2 and u4
    constant, (u1, u3) rotating at lambda = ((I~22 - I_t) u2 + J u4) / I_t,
    with I_t = I11 + I and I~22 = I22 (l1 = l3 = 0)."""
    scene, x0, _ = problem("torque_free")
    v = scene.folded()
    u1, u2, u3, u4 = (x0[scene.states.index(n)] for n in ("u1", "u2", "u3", "u4"))
    i_t = v["I11"] + v["I"]
    lam = ((v["I22"] - i_t) * u2 + v["J"] * u4) / i_t
    cl, sl = np.cos(lam * t), np.sin(lam * t)
    u = np.array([u1 * cl + u3 * sl, u2, u3 * cl - u1 * sl, u4])
    return u, np.array([scene.states.index(n) for n in ("u1", "u2", "u3", "u4")])


@pytest.mark.parametrize("language", LANGUAGES)
def test_torque_free_closed_form(compiled: Get, language: str) -> None:
    b = compiled("torque_free", language)
    _, x0, p = problem("torque_free")
    t1 = 20.0
    exact, idx = torque_free_closed_form(t1)
    x, _, code = b.integrate("dop853", x0, b.setup(p), 0.0, t1, rtol=1e-12, atol=1e-12)
    assert code == OK
    np.testing.assert_allclose(x[idx], exact, rtol=0, atol=1e-10)


TURNS = 1000 * 2 * np.pi


def wrapped(a: np.ndarray) -> np.ndarray:
    """Angles' differences into (-pi, pi]."""
    return np.angle(np.exp(1j * a))


@pytest.mark.parametrize("language", LANGUAGES)
def test_a_wound_angle_keeps_its_tolerance(compiled: Get, language: str) -> None:
    """An angle enters every method's error scale by at most pi
    (abi_groups.ANGLE_SCALE): torque_free started with q1 and q3 1000 turns
    on (the same motion) errs, against the Taylor method at 1e-15 from the
    start as given, within a few times the start as given does at rtol
    1e-10. With |x| in full their tolerance was 2e4 times looser: dop853
    erred 1.7e-9 against 3.6e-10 (4.8 times; 2.3 with the cap)."""
    b = compiled("torque_free", language)
    scene, x0, p = problem("torque_free")
    c = b.setup(p)
    angles = [scene.states.index(n) for n in ("q1", "q3")]
    ref, _, code = b.integrate("taylor", x0, c, 0.0, 20.0, rtol=1e-15, atol=1e-15)
    assert code == OK
    far = x0.copy()
    far[angles] += TURNS
    for method in ADAPTIVE:
        errors = []
        for x in (x0, far):
            end, _, code = b.integrate(method, x, c, 0.0, 20.0, rtol=1e-10, atol=1e-10)
            assert code == OK
            diff = end - ref
            diff[angles] = wrapped(diff[angles])
            errors.append(float(np.abs(diff).max()))
        assert errors[1] < 4 * errors[0], (method, errors)


def test_time_dependent_torque(tmp_path: Path, cache_dir: Path) -> None:
    """A torque table makes f depend on t: Rodas4 adds df/dt (a forward
    difference). The table's kinks cost every method accuracy (scipy's RK45
    as much), so the reference integrates piece by piece."""
    scene = tabled(SMOOTH_ONLY_OUT)
    write_sources(scene, tmp_path / "tabled")
    mp = pytest.MonkeyPatch()
    mp.setenv("GYROGEN_CACHE", str(cache_dir))
    try:
        b = build.build(tmp_path / "tabled", "c")
    finally:
        mp.undo()
    x0 = np.array([scene.simulate.initial.get(s, 0.0) for s in scene.states])
    p = np.zeros(0)
    ref = x0
    for span in [(0.0, 0.5), (0.5, 1.5), (1.5, 2.0)]:
        ref = solve_ivp(
            lambda t, x: scene_view.rhs(scene, x, p, t)[0],
            span, ref, method="DOP853", rtol=1e-13, atol=1e-13,
        ).y[:, -1]  # fmt: skip
    for method in SMOOTH_ONLY_OUT:
        x, stats, code = b.integrate(method, x0, b.setup(p), 0.0, 2.0, rtol=1e-10, atol=1e-10)
        assert code == OK
        assert mixed_error(x, ref) < {"rodas4": 2e-9}.get(method, 1e-7), method
    # one rhs call more per accepted step: the time derivative
    _, stats, _ = b.integrate("rodas4", x0, b.setup(p), 0.0, 2.0, rtol=1e-6, atol=1e-6)
    steps = stats["accepted"] + stats["rejected"]
    assert stats["rhs_calls"] == 2 + 5 * steps + 2 * stats["accepted"] - 1


# --- convergence order --------------------------------------------------------


def log_slope(n: list[int], err: list[float]) -> float:
    return float(np.polyfit(np.log(n), np.log(err), 1)[0])


@pytest.mark.parametrize("language", LANGUAGES)
def test_rk4_is_fourth_order(compiled: Get, language: str) -> None:
    """Step halving on the torque-free scene against its closed form: the
    error falls by 16 per halving."""
    b = compiled("torque_free", language)
    _, x0, p = problem("torque_free")
    exact, idx = torque_free_closed_form(20.0)
    steps = [200, 400, 800, 1600]
    err = []
    for n in steps:
        x, _, code = b.integrate("rk4", x0, b.setup(p), 0.0, 20.0, steps=n)
        assert code == OK
        err.append(float(np.max(np.abs(x[idx] - exact))))
    assert abs(log_slope(steps, err) + 4.0) < 0.3
    assert all(14.0 < a / b < 18.0 for a, b in itertools.pairwise(err))


@pytest.mark.parametrize("language", LANGUAGES)
@pytest.mark.parametrize(
    ("method", "order", "slack", "tolerances"),
    [
        ("dopri5", 5, 0.7, [1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11]),
        ("dop853", 8, 1.5, [1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12]),
        ("radau5", 5, 0.7, [1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11]),
    ],
)
def test_adaptive_order(
    compiled: Get, language: str, method: str, order: int, slack: float, tolerances: list[float]
) -> None:
    """Over a tolerance sweep, log(error) against log(steps) has slope -order."""
    b = compiled("torque_free", language)
    _, x0, p = problem("torque_free")
    exact, idx = torque_free_closed_form(20.0)
    steps, err = [], []
    for tol in tolerances:
        x, stats, code = b.integrate(method, x0, b.setup(p), 0.0, 20.0, rtol=tol, atol=tol)
        assert code == OK
        steps.append(stats["accepted"])
        err.append(float(np.max(np.abs(x[idx] - exact))))
    assert abs(log_slope(steps, err) + order) < slack


# --- failures -----------------------------------------------------------------


@pytest.mark.parametrize("language", LANGUAGES)
def test_bad_arguments(compiled: Get, language: str) -> None:
    b = compiled("torque_free", language)
    _, x0, p = problem("torque_free")
    c = b.setup(p)
    for method in ADAPTIVE:
        for kw in (
            {"t1": -1.0},
            {"t1": np.nan},
            {"rtol": 0.0},
            {"atol": -1e-9},
            {"rtol": np.nan},
            {"rtol": 1e-20},
            {"atol": 0.0},
            {"h0": np.nan},
            {"max_steps": 0},
        ):
            args = {"t1": 1.0, "rtol": 1e-8, "atol": 1e-8, "max_steps": 100} | kw
            t1 = args.pop("t1")
            x, stats, code = b.integrate(method, x0, c, 0.0, t1, **args)
            assert code == ARGUMENT, (method, kw)
            assert np.array_equal(x, x0) and stats["t"] == 0.0 and stats["rhs_calls"] == 0
    assert b.integrate("rk4", x0, c, 0.0, 1.0, steps=0)[2] == ARGUMENT
    assert b.integrate("rk4", x0, c, 1.0, 0.0, steps=10)[2] == ARGUMENT


def test_bad_input_in_python(compiled: Get) -> None:
    """What C cannot see is refused in Python with one line: a state or
    constants of the wrong length or shape (no reshape), complex values
    (numpy would drop their imaginary parts), non-finite constants, an
    unknown method, function or output, steps with the wrong kind of method,
    a control cffi cannot hand to C (naming it); a non-finite state is C's
    code. An empty batch, [] included, gives empty results."""
    b = compiled("gyrostat", "c")
    _, x0, p = problem("gyrostat")
    c = b.setup(p)
    bad_c = c.copy()
    bad_c[1] = np.inf
    cases = [
        (lambda: b.integrate("dop853", x0[:-1], c, 0.0, 1.0), r"initial state must have shape"),
        (lambda: b.integrate("dop853", x0, c[:-1], 0.0, 1.0), r"constants c must have shape"),
        (lambda: b.integrate("dop853", x0, bad_c, 0.0, 1.0), r"not all finite \(index 1\)"),
        (lambda: b.integrate("nope", x0, c, 0.0, 1.0), r"no integrator 'nope' in this build"),
        (lambda: b.integrate("rk4", x0, c, 0.0, 1.0), r"rk4 is a fixed-step method: give"),
        (lambda: b.integrate("dop853", x0, c, 0.0, 1.0, steps=3), r"steps= goes with"),
        (lambda: b.integrate_batch("dop853", x0[None, :-1], c, 0.0, 1.0), r"shape \(n, 14\)"),
        (lambda: b.integrate_batch("dop853", x0[None], c[:-1], 0.0, 1.0), r"constants c must"),
        # rhs, jacobian (outputs alike) and setup read exactly nx, nc and np values
        (lambda: b.rhs(x0, c[:2]), r"constants c must have shape \(12,\)"),
        (lambda: b.rhs(np.ones(3), c), r"states must have shape \(14,\) or \(n, 14\)"),
        (lambda: b.rhs(np.ones(15), c), r"not \(15,\)"),
        (lambda: b.rhs(np.ones((2, 2, 14)), c), r"not \(2, 2, 14\)"),
        (lambda: b.jacobian(x0, c[:1]), r"constants c must"),
        (lambda: b.jacobian(x0[:5], c), r"state x \(one state\) must have shape"),
        # a batch where one state goes, a reshape, complex values, C's integers
        (lambda: b.jacobian(np.tile(x0, (3, 1)), c), r"one state\) must have shape"),
        (lambda: b.integrate("dop853", x0.reshape(2, 7), c, 0.0, 1.0), r"not \(2, 7\)"),
        (lambda: b.integrate("dop853", x0[:, None], c, 0.0, 1.0), r"not \(14, 1\)"),
        (lambda: b.integrate("dop853", x0 + 0j, c, 0.0, 1.0), r"state must be real"),
        (lambda: b.integrate("dop853", x0, c + 0j, 0.0, 1.0), r"c must be real"),
        (lambda: b.integrate_batch("dop853", x0[None] + 0j, c, 0.0, 1.0), r"must be real"),
        (lambda: b.integrate("dop853", x0, c, 0.0, 1.0, max_steps=2**63), r"max_steps=9223"),
        (lambda: b.integrate("dop853", x0, c, 0.0, 1.0, max_steps=1e5), r"max_steps=100000.0"),
        (lambda: b.integrate("rk4", x0, c, 0.0, 1.0, steps=2**64), r"steps=1844"),
        (lambda: b.integrate("dop853", x0, c, 0.0, "1", rtol=1e-6), r"t1='1'"),
        (
            lambda: b.integrate_batch("dop853", x0[None], c, 0.0, 1.0, max_steps=-(2**70)),
            r"max_steps=-1180",
        ),
        (lambda: b.integrate_batch("dop853", x0[None], c, 0.0, 1.0, threads=2**31), r"4096"),
        (lambda: b.output("kinetic_energy", x0, c), r"no output 'kinetic_energy' \(its"),
        (lambda: b.function("nosuch"), r"no function 'nosuch' \(it has"),
        (lambda: b.setup(p[:3]), r"parameters p must have shape \(12,\), not \(3,\)"),
        (lambda: b.setup_code(np.append(p, 1.0)), r"parameters p must have shape"),
    ]
    for call, message in cases:
        with pytest.raises(ValueError, match=message) as info:
            call()
        assert "\n" not in str(info.value)
    for empty in ([], np.zeros((0, 14))):
        xs, stats, codes = b.integrate_batch("dop853", empty, c, 0.0, 1.0)
        assert xs.shape == (0, 14) and stats.shape == codes.shape == (0,)


def test_constants_are_read_at_each_call(compiled: Get) -> None:
    """c's buffer is kept for the next call with the same array: a change
    in place is seen, and another array (a list too) replaces it."""
    b = compiled("gyrostat", "c")
    _, x0, p = problem("gyrostat")
    c = b.setup(p)
    first, _, _ = b.integrate("dop853", x0, c, 0.0, 1.0)
    other = b.setup(p * 1.5)
    changed, _, _ = b.integrate("dop853", x0, other, 0.0, 1.0)
    c[:] = other
    assert np.array_equal(b.integrate("dop853", x0, c, 0.0, 1.0)[0], changed)
    assert np.array_equal(b.integrate("dop853", list(x0), list(b.setup(p)), 0.0, 1.0)[0], first)
    assert not np.array_equal(first, changed)


@pytest.mark.parametrize("language", LANGUAGES)
def test_max_steps(compiled: Get, language: str) -> None:
    b = compiled("gyrostat", language)
    _, x0, p = problem("gyrostat")
    for method in ADAPTIVE:
        x, stats, code = b.integrate(method, x0, b.setup(p), 0.0, 10.0, max_steps=10)
        assert code == MAX_STEPS
        assert stats["accepted"] + stats["rejected"] == 10
        assert 0.0 < stats["t"] < 10.0 and np.all(np.isfinite(x))


@pytest.mark.parametrize("language", LANGUAGES)
def test_near_gimbal_lock_is_never_nan(compiled: Get, language: str) -> None:
    """q2 a hair below pi/2 with u1 large: the Euler-angle rates are ~1e8.
    From 1e-6 below, the methods step through (the angular momentum in N, a
    function of the angles, is then conserved); from 1e-8 below, the path
    comes within GIMBAL_LOCK_COS of cos q2 = 0 and they stop with code 6, a
    finite state on the trajectory (H still conserved) and the time reached.
    With too few steps allowed, code 2, as finite."""
    b = compiled("gyrostat", language)
    scene, _, p = problem("gyrostat")
    c = b.setup(p)
    for eps, expected in ((1e-6, OK), (1e-8, ATTITUDE)):
        x0 = np.zeros(b.nx)
        for name, value in {"q2": np.pi / 2 - eps, "u1": 10.0, "u2": 1.0, "u3": 1.0}.items():
            x0[scene.states.index(name)] = value
        h0 = scene_view.output(scene, "angular_momentum", x0, p)
        for method in ADAPTIVE:
            x, stats, code = b.integrate(method, x0, c, 0.0, 1.0, rtol=1e-10, atol=1e-10)
            assert code == expected and np.all(np.isfinite(x)), (method, eps)
            assert (stats["t"] == 1.0) == (expected == OK)
            h1 = scene_view.output(scene, "angular_momentum", x, p)
            np.testing.assert_allclose(h1, h0, rtol=0, atol=1e-6)
        for method in ADAPTIVE:
            x, stats, code = b.integrate(method, x0, c, 0.0, 1.0, max_steps=50)
            assert code in (MAX_STEPS, expected) and stats["t"] < 1.0 and np.all(np.isfinite(x))


@pytest.mark.parametrize("language", LANGUAGES)
def test_step_underflow(compiled: Get, language: str) -> None:
    """At t0 = 2^45 s, 16 eps |t| = 0.12 s: the steps rtol = 1e-12 needs
    (~0.05 s) are lost in the rounding of t, and h shrinks below it."""
    b = compiled("torque_free", language)
    _, x0, p = problem("torque_free")
    t0 = 2.0**45
    for method in SMOOTH_ONLY_OUT:
        x, stats, code = b.integrate(
            method, x0, b.setup(p), t0, t0 + 1000.0, rtol=1e-12, atol=1e-12, h0=1.0
        )
        assert code == UNDERFLOW and stats["rejected"] > 0
        assert stats["t"] == t0 and np.array_equal(x, x0)
    # the Taylor steps are seconds long here: it goes on until t's rounding stops it
    x, stats, code = b.integrate("taylor", x0, b.setup(p), t0, t0 + 1000.0, rtol=1e-12, atol=1e-12)
    assert code in (OK, UNDERFLOW) and np.all(np.isfinite(x)) and stats["t"] > t0


@pytest.mark.parametrize("language", LANGUAGES)
def test_nonfinite(compiled: Get, language: str) -> None:
    """A NaN state, or a derivative that overflows: code 3 at t0, x as given."""
    b = compiled("torque_free", language)
    scene, x0, p = problem("torque_free")
    c = b.setup(p)
    nan = x0.copy()
    nan[0] = np.nan
    huge = x0.copy()
    for name in ("u1", "u2", "u3"):
        huge[scene.states.index(name)] = 1e200  # their products overflow
    for bad in (nan, huge):
        for method in ADAPTIVE:
            x, stats, code = b.integrate(method, bad, c, 0.0, 1.0)
            assert code == NONFINITE and stats["t"] == 0.0
            np.testing.assert_array_equal(x, bad)
    x, stats, code = b.integrate("rk4", huge, c, 0.0, 1.0, steps=10)
    assert code == NONFINITE and stats["t"] == 0.0 and np.array_equal(x, huge)


# --- batch, counters ------------------------------------------------------------


@pytest.mark.parametrize("language", LANGUAGES)
def test_batch_equals_single_calls(compiled: Get, language: str) -> None:
    b = compiled("gyrostat", language)
    _, x0, p = problem("gyrostat")
    c = b.setup(p)
    rng = np.random.default_rng(4)
    x0s = x0 + 0.1 * rng.standard_normal((3, b.nx))
    x0s[2, 0] = np.nan  # one failure in the batch
    for method in ["rk4", *ADAPTIVE]:
        kw = {"steps": 100} if method == "rk4" else {"rtol": 1e-8, "atol": 1e-8}
        xs, stats, codes = b.integrate_batch(method, x0s, c, 0.0, 2.0, **kw)
        for i in range(3):
            x, st, code = b.integrate(method, x0s[i], c, 0.0, 2.0, **kw)
            np.testing.assert_array_equal(xs[i], x)
            assert code == codes[i]
            assert {f.name: stats[f.name][i] for f in abi.STATS_FIELDS} == st
        assert list(codes[:2]) == [OK, OK] and codes[2] != OK


@pytest.mark.slow
def test_rodas4_lanes_equal_single_calls(compiled: Get, tmp_path: Path, cache_dir: Path) -> None:
    """rodas4_batch runs the states in SIMD lanes: each state's end, stats
    and code equal rodas4's on it alone, bit for bit, on a quaternion scene
    and under a tabled torque (f_t over lanes), with a NaN start and a step
    budget that some states exhaust."""
    write_sources(tabled(["rodas4"]), tmp_path / "tabled")
    mp = pytest.MonkeyPatch()
    mp.setenv("GYROGEN_CACHE", str(cache_dir))
    try:
        scenes = [(compiled("rw3_orthogonal", "c"), problem("rw3_orthogonal")[1:], 5.0),
                  (build.build(tmp_path / "tabled", "c"), (None, np.zeros(0)), 2.0)]  # fmt: skip
    finally:
        mp.undo()
    rng = np.random.default_rng(5)
    for b, (x0, p), t1 in scenes:
        start = np.array(x0 if x0 is not None else [0.0] * b.nx)
        if x0 is None:
            start[[b.manifest["states"].index(s) for s in ("u1", "u2", "u3", "u4")]] = (
                0.02, 0.1, -0.01, 10.0)  # fmt: skip
        x0s = start * (1 + 0.1 * rng.uniform(-1, 1, (19, b.nx)))
        x0s[4, 0] = np.nan
        c = b.setup(p)
        for budget in (100000, 3):
            kw = {"rtol": 1e-8, "atol": 1e-8, "max_steps": budget}
            xs, stats, codes = b.integrate_batch("rodas4", x0s, c, 0.0, t1, 1, **kw)
            for i in range(len(x0s)):
                x, st, code = b.integrate("rodas4", x0s[i], c, 0.0, t1, **kw)
                np.testing.assert_array_equal(xs[i], x)
                assert code == codes[i]
                assert {f.name: stats[f.name][i] for f in abi.STATS_FIELDS} == st
            assert codes[4] == NONFINITE
            assert set(codes) == ({OK, NONFINITE} if budget > 3 else {MAX_STEPS, NONFINITE})


@pytest.mark.parametrize("language", LANGUAGES)
def test_batch_accepts_null_stats_and_codes(compiled: Get, language: str) -> None:
    b = compiled("gyrostat", language)
    _, x0, p = problem("gyrostat")
    c = np.ascontiguousarray(b.setup(p))
    xs = np.array([x0, x0, x0])
    xs[1, 0] = np.nan
    names = b.manifest["functions"][language]
    ffi = b.ffi
    buf = ffi.from_buffer("double[]", xs)
    cb = ffi.from_buffer("double[]", c)
    fn = getattr(b.lib, names["dop853_batch"])
    assert fn(3, 0.0, 1.0, buf, cb, 1e-8, 1e-8, 0.0, 1000, ffi.NULL, ffi.NULL) == 1
    fn = getattr(b.lib, names["rk4_batch"])
    assert fn(3, 0.0, 1.0, 10, buf, cb, ffi.NULL, ffi.NULL) == 1
    expected, _, _ = b.integrate("dop853", x0, c, 0.0, 1.0, rtol=1e-8, atol=1e-8)
    expected, _, _ = b.integrate("rk4", expected, c, 0.0, 1.0, steps=10)
    np.testing.assert_array_equal(xs[0], expected)


@pytest.mark.parametrize("language", LANGUAGES)
def test_counters(compiled: Get, language: str) -> None:
    """What each step costs: rhs calls, Jacobians and decompositions."""
    b = compiled("gyrostat", language)
    _, x0, p = problem("gyrostat")
    c = b.setup(p)
    _, st, _ = b.integrate("rk4", x0, c, 0.0, 1.0, steps=37)
    assert (st["accepted"], st["rejected"], st["rhs_calls"], st["h"]) == (37, 0, 148, 1.0 / 37)
    for method, h0, first in (("dopri5", 0.0, 2), ("dopri5", 1e-3, 1), ("dop853", 0.0, 2)):
        _, st, code = b.integrate(method, x0, c, 0.0, 3.0, rtol=1e-9, atol=1e-9, h0=h0)
        trials = st["accepted"] + st["rejected"]
        assert code == OK and st["jac_calls"] == st["decompositions"] == 0
        if method == "dopri5":  # 6 new stages a trial, the 7th is the next step's first
            assert st["rhs_calls"] == first + 6 * trials
        else:  # 11 new stages a trial, then f at each accepted point but t1
            assert st["rhs_calls"] == first + 11 * trials + st["accepted"] - 1
    _, st, code = b.integrate("rodas4", x0, c, 0.0, 3.0, rtol=1e-7, atol=1e-7)
    trials = st["accepted"] + st["rejected"]
    assert code == OK and st["accepted"] > 10
    assert st["jac_calls"] == st["accepted"] and st["decompositions"] == trials
    assert st["rhs_calls"] == 2 + 5 * trials + st["accepted"] - 1
    # radau5 keeps J while Newton contracts fast, and E1, E2 while h does not
    # change; 3 rhs calls a Newton iteration (1 to 7 a trial), f at each
    # accepted point but t1, and at most one more a trial for the error
    _, st, code = b.integrate("radau5", x0, c, 0.0, 3.0, rtol=1e-7, atol=1e-7)
    trials = st["accepted"] + st["rejected"]
    assert code == OK and st["accepted"] > 5
    assert (
        1 <= st["jac_calls"] < st["accepted"] and st["jac_calls"] <= st["decompositions"] <= trials
    )
    base = 2 + st["accepted"] - 1
    assert base + 3 * trials <= st["rhs_calls"] <= base + (3 * 7 + 1) * trials


# --- stiffness --------------------------------------------------------------------


@pytest.mark.parametrize("language", LANGUAGES)
@pytest.mark.parametrize("method", methods.IMPLICIT)
def test_stiff_wheel_favours_the_implicit_methods(
    compiled: Get, language: str, method: str
) -> None:
    """k/J = 1e5: the explicit methods crawl at their stability limit."""
    b = compiled("speed_controlled", language)
    scene, x0, _ = problem("speed_controlled")
    p = np.array([1e5 * float(scene.parameters["J"]), 200.0])
    c = b.setup(p)
    xr, sr, code_r = b.integrate(method, x0, c, 0.0, 1.0, rtol=1e-8, atol=1e-8)
    xd, sd, code_d = b.integrate("dopri5", x0, c, 0.0, 1.0, rtol=1e-8, atol=1e-8)
    assert code_r == code_d == OK
    assert sr["accepted"] < sd["accepted"] / 20
    assert mixed_error(xr, xd) < 1e-6
    ref = solve_ivp(
        lambda t, x: scene_view.rhs(scene, x, p, t)[0], (0.0, 1.0), x0, method="Radau",
        jac=lambda t, x: b_jac(b, c, x), rtol=1e-10, atol=1e-10,
    ).y[:, -1]  # fmt: skip
    assert mixed_error(xr, ref) < 1e-7


def b_jac(b: Compiled, c: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The generated Jacobian through cffi, row-major (nx, nx)."""
    out = np.empty(b.nx * b.nx)
    fn = getattr(b.lib, b.manifest["functions"][b.language]["jac"])
    x = np.ascontiguousarray(x, dtype=np.float64)
    fn(0.0, b.ffi.from_buffer("double[]", x), b.ffi.from_buffer("double[]", c),
       b.ffi.from_buffer("double[]", out))  # fmt: skip
    return out.reshape(b.nx, b.nx)


@pytest.mark.parametrize("language", LANGUAGES)
@pytest.mark.parametrize("name", SCENES)
def test_jacobian_matches_differences(compiled: Get, name: str, language: str) -> None:
    b = compiled(name, language)
    _, x0, p = problem(name)
    c = b.setup(p)
    x = x0 + 0.3 * np.random.default_rng(1).standard_normal(b.nx)
    step = 1e-6 * (1.0 + np.abs(x))
    fd = np.empty((b.nx, b.nx))
    for j in range(b.nx):
        e = np.zeros(b.nx)
        e[j] = step[j]
        fd[:, j] = (b.rhs(x + e, c) - b.rhs(x - e, c)) / (2 * step[j])
    np.testing.assert_allclose(b_jac(b, c, x), fd, rtol=1e-6, atol=1e-6)


# --- the sources ----------------------------------------------------------------


def test_tableaus_match_scipy() -> None:
    """The pairs' coefficients are scipy's (RK45 = DOPRI5, DOP853)."""
    from scipy.integrate import DOP853, RK45

    for s in range(1, 6):
        assert tableaus.DOPRI5.a[s] == tuple(RK45.A[s, :s])
    assert tableaus.DOPRI5.b == (*RK45.B, 0.0)
    np.testing.assert_array_equal(tableaus.DOPRI5.e, -RK45.E)
    for s in range(1, 12):
        assert tableaus.DOP853.a[s] == tuple(DOP853.A[s, :s])
    assert tableaus.DOP853.b == tuple(DOP853.B)
    assert tableaus.DOP853.nodes == tuple(DOP853.C)
    assert tableaus.DOP853.e == tuple(DOP853.E5[:12])
    assert tableaus.DOP853.e3 == tuple(DOP853.E3[:12])


def test_radau5_constants() -> None:
    """Radau IIA 5: the nodes, the eigenvalues of A^-1 and the error weights
    are scipy's Radau's; T (radau5.f's DATA decimals) diagonalizes A^-1 to
    blocks (gamma) and (alpha -beta; beta alpha), and TI is its inverse."""
    from scipy.integrate._ivp import radau

    r = tableaus.RADAU5
    np.testing.assert_allclose(r.nodes, radau.C, rtol=2e-16)
    np.testing.assert_allclose(r.e, radau.E, rtol=1e-15)  # scipy rounds in double arithmetic
    np.testing.assert_allclose(r.gamma, radau.MU_REAL, rtol=2e-16)
    np.testing.assert_allclose(r.alpha + 1j * r.beta, np.conj(radau.MU_COMPLEX), rtol=2e-16)
    s6 = np.sqrt(6.0)
    a = np.array([
        [(88 - 7 * s6) / 360, (296 - 169 * s6) / 1800, (-2 + 3 * s6) / 225],
        [(296 + 169 * s6) / 1800, (88 + 7 * s6) / 360, (-2 - 3 * s6) / 225],
        [(16 - s6) / 36, (16 + s6) / 36, 1 / 9],
    ])  # fmt: skip
    t, ti = np.array(r.t), np.array(r.ti)
    np.testing.assert_allclose(t @ ti, np.eye(3), rtol=0, atol=2e-15)
    blocks = [[r.gamma, 0, 0], [0, r.alpha, -r.beta], [0, r.beta, r.alpha]]
    np.testing.assert_allclose(ti @ np.linalg.inv(a) @ t, blocks, rtol=0, atol=5e-15)


STRICT_C = [
    ["gcc", *flags.C_STRICT],
    ["clang", *flags.C_STRICT],
    ["g++", "-x", "c++", "-std=c++17", *flags.C_WARNINGS],
]
FORTRAN = ["gfortran", *flags.FORTRAN_STRICT]


def _run(cmd: list[str], cwd: Path) -> None:
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=False)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr


@pytest.mark.parametrize(
    "integrators", [None, ["rk4"], ["dop853"], ["rodas4"], ["dopri5", "rodas4"]], ids=str
)
def test_strict_builds(integrators: list[str] | None, tmp_path: Path) -> None:
    """The default scene (all four methods) and subsets of the methods on a
    time-dependent scene compile clean: no helper is left unused."""
    if integrators is None:
        src = REPO / "generated" / "gyrostat"
    else:
        src = tmp_path / "src"
        write_sources(tabled(integrators), src)
    name = next(src.glob("*_ode.c")).name[: -len("_ode.c")]
    for cc in STRICT_C:
        _run([*cc, "-c", f"{name}_ode.c", "-o", str(tmp_path / "ode.o")], src)
    for f in (f"{name}.f90", f"{name}_ode.f90"):
        _run([*FORTRAN, "-J", str(tmp_path), "-c", f, "-o", str(tmp_path / f"{f}.o")], src)
