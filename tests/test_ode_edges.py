"""The edges of the generated integrators, in C and Fortran through cffi:
NULL statistics, tolerances no double can meet, a NaN or infinite first
step, and gimbal lock of the 3-1-2 angles (code 6): at the start, where a
step crosses q2 = pi/2, and where a pass comes closer than GIMBAL_LOCK_COS;
the Euler-parameter twin of the same motions integrates through them, and
its starts without a direction (|e| 0 or too large to square) are refused,
others normalized, and a step that loses |e| is not taken."""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from sources import write_sources
from wide import WIDE

from gyrogen import abi, methods
from gyrogen.oracle import reference, scene_view
from gyrogen.runtime import build
from gyrogen.runtime.compiled import Compiled
from gyrogen.scene import Scene, load

pytestmark = pytest.mark.slow  # integrations at the integrators' edges, several scenes compiled

REPO = Path(__file__).resolve().parents[1]
LANGUAGES = ["c", "fortran"]
ADAPTIVE = list(methods.ADAPTIVE)
METHODS = list(methods.NAMES)
OK, UNDERFLOW, MAX_STEPS, NONFINITE, SINGULAR, ARGUMENT, ATTITUDE = range(7)
G = abi.GIMBAL_LOCK_COS

# torque_free turning about a1 (u2 = u4 = 0): its lumped inertia is
# axisymmetric about a2, so any rate (u1, 0, u3) is a steady rotation about a
# fixed axis, and the attitude at time t is known exactly. From q2 = 1.4 with
# u3 = 0, q2 = 1.4 + t crosses pi/2 at T_CROSS with q1 = q3 = 0 throughout.
Q2 = 1.4
T_CROSS = math.pi / 2 - Q2


@pytest.fixture(scope="module")
def angles(cache_dir: Path) -> Iterator[dict[str, Compiled]]:
    """torque_free (3-1-2 angles), from generated/."""
    mp = pytest.MonkeyPatch()
    mp.setenv("GYROGEN_CACHE", str(cache_dir))
    yield {lang: build.build(REPO / "generated" / "torque_free", lang) for lang in LANGUAGES}
    mp.undo()


def quaternion_twin() -> Scene:
    data = load("torque_free").model_dump()
    data.update(name="torque_free_quat", attitude="quaternion")
    return Scene.model_validate(data)


@pytest.fixture(scope="module")
def euler_parameters(
    tmp_path_factory: pytest.TempPathFactory, cache_dir: Path
) -> Iterator[dict[str, Compiled]]:
    """The same scene with Euler parameters for the attitude."""
    src = tmp_path_factory.mktemp("quat") / "torque_free_quat"
    write_sources(quaternion_twin(), src)
    mp = pytest.MonkeyPatch()
    mp.setenv("GYROGEN_CACHE", str(cache_dir))
    yield {lang: build.build(src, lang) for lang in LANGUAGES}
    mp.undo()


def state(scene: Scene, **values: float) -> np.ndarray:
    return np.array([values.get(s, 0.0) for s in scene.states])


def kwargs(method: str) -> dict[str, Any]:
    return {"steps": 1000} if method == "rk4" else {"rtol": 1e-10, "atol": 1e-10}


def raw(
    b: Compiled,
    method: str,
    x: np.ndarray,
    c: np.ndarray,
    t0: float,
    t1: float,
    stats: Any,
    **kw: Any,
) -> int:
    """The single-trajectory function itself, x integrated in place; stats a
    gyrogen_stats * or ffi.NULL."""
    ffi, fn = b.ffi, b.function(method)
    xb, cb = ffi.from_buffer("double[]", x), ffi.from_buffer("double[]", c)
    if method == "rk4":
        return int(fn(t0, t1, kw["steps"], xb, cb, stats))
    args = (
        kw.get("rtol", 1e-8),
        kw.get("atol", 1e-8),
        kw.get("h0", 0.0),
        kw.get("max_steps", 10**7),
    )
    return int(fn(t0, t1, xb, cb, *args, stats))


def exact_dcm(u1: float, u3: float, t: float) -> np.ndarray:
    """C(t) (a_i = sum_j C[i, j] n_j) of the steady rotation from (0, Q2, 0):
    the axis is w = u1 a1 + u3 a3, fixed in N."""
    c0 = reference.direction_cosines(np.array([0.0, Q2, *[0.0] * 12]))
    w = c0.T @ np.array([u1, 0.0, u3])  # N components
    return c0 @ Rotation.from_rotvec(w * t).as_matrix().T


def angle_dcm(scene: Scene, x: np.ndarray) -> np.ndarray:
    return reference.direction_cosines(scene_view.full_states(scene, x)[0])


# --- NULL statistics -------------------------------------------------------------


@pytest.mark.parametrize("language", LANGUAGES)
def test_null_stats_gives_the_same_state(backends: dict[str, Compiled], language: str) -> None:
    """Every single-trajectory integrator takes NULL stats, succeeding or
    failing: the same x and code as with them."""
    b = backends[language]
    scene = load("gyrostat")
    x0 = state(scene, **scene.simulate.initial)
    c = b.setup(np.array([scene.simulate.parameters[n] for n in scene.runtime]))
    at_lock = state(scene, **{**scene.simulate.initial, "q2": math.pi / 2})
    runs: list[tuple[str, np.ndarray, dict[str, Any], int]] = []
    for method in METHODS:
        if method == "rk4":
            runs += [
                (method, x0, {"steps": 100}, OK),
                (method, x0, {"steps": 0}, ARGUMENT),
                (method, at_lock, {"steps": 100}, ATTITUDE),
            ]
            continue
        runs += [
            (method, x0, {"rtol": 1e-8, "atol": 1e-8}, OK),
            (method, x0, {"max_steps": 3}, MAX_STEPS),
            (method, x0, {"rtol": 1e-20}, ARGUMENT),
            (method, at_lock, {}, ATTITUDE),
        ]
    for method, start, kw, expected in runs:
        want, stats, code = b.integrate(method, start, c, 0.0, 2.0, **kw)
        assert code == expected, (method, kw)
        for ptr in (b.ffi.NULL, b.ffi.new("gyrogen_stats *")):
            x = start.copy()
            assert raw(b, method, x, c, 0.0, 2.0, ptr, **kw) == expected, (method, kw)
            np.testing.assert_array_equal(x, want)
            if ptr != b.ffi.NULL:
                assert (ptr.t, ptr.accepted, ptr.rhs_calls) == (
                    stats["t"],
                    stats["accepted"],
                    stats["rhs_calls"],
                )


# --- arguments ---------------------------------------------------------------------


BAD = [
    {"rtol": 1e-20},
    {"rtol": math.nan},
    {"rtol": math.inf},
    {"atol": 0.0},
    {"atol": math.nan},
    {"atol": math.inf},
    {"h0": math.nan},
    {"h0": math.inf},
    {"h0": -math.inf},
]


@pytest.mark.parametrize("language", LANGUAGES)
def test_tolerances_no_double_meets_and_a_bad_first_step(
    angles: dict[str, Compiled], language: str
) -> None:
    """rtol <= the method's bound (10 DBL_EPSILON; the Taylor method's
    DBL_EPSILON), atol <= 0, a NaN or infinite tolerance or h0: code 5 at
    once (x as given, nothing called). The first rtol above the bound is
    accepted, and h0 <= 0 still means an automatic first step."""
    b = angles[language]
    scene = load("torque_free")
    x0 = state(scene, **scene.simulate.initial)
    c = b.setup(np.zeros(0))
    for method in ADAPTIVE:
        floor = methods.get(method).rtol_floor
        for bad in [*BAD, {"rtol": floor}]:
            kw = {"rtol": 1e-8, "atol": 1e-8, "max_steps": 1000} | bad
            x, stats, code = b.integrate(method, x0, c, 0.5, 1.5, **kw)
            assert code == ARGUMENT, (method, bad)
            assert np.array_equal(x, x0) and stats["t"] == 0.5 and stats["rhs_calls"] == 0
        just_above = float(np.nextafter(floor, 1.0))
        x, stats, code = b.integrate(method, x0, c, 0.0, 1.0, rtol=just_above, atol=1e-12)
        assert code == OK and stats["t"] == 1.0
        auto = b.integrate(method, x0, c, 0.0, 1.0, h0=0.0)
        negative = b.integrate(method, x0, c, 0.0, 1.0, h0=-1.0)
        np.testing.assert_array_equal(auto[0], negative[0])
        assert auto[1] == negative[1] and auto[2] == negative[2] == OK


# --- gimbal lock ---------------------------------------------------------------------


@pytest.mark.parametrize("language", LANGUAGES)
def test_start_at_gimbal_lock(angles: dict[str, Compiled], language: str) -> None:
    """|cos q2| < GIMBAL_LOCK_COS at the start: code 6 before anything is
    called, x as given, for every method (an empty interval too); just
    outside the bound, and for a NaN q2 (code 3), it is not."""
    b = angles[language]
    scene = load("torque_free")
    c = b.setup(np.zeros(0))
    moving = scene.simulate.initial
    for method in METHODS:
        kw = kwargs(method)
        for q2 in (math.pi / 2, -math.pi / 2, math.pi / 2 + 0.5 * G, 3 * math.pi / 2):
            assert abs(math.cos(q2)) < G
            x0 = state(scene, **moving, q2=q2)
            for t1 in (1.5, 0.5):
                x, stats, code = b.integrate(method, x0, c, 0.5, t1, **kw)
                assert code == ATTITUDE, (method, q2, t1)
                assert np.array_equal(x, x0) and stats["t"] == 0.5
                assert stats["rhs_calls"] == stats["accepted"] == 0
        # at rest, |cos q2| = 2 GIMBAL_LOCK_COS: accepted, and nothing moves
        x0 = state(scene, q2=math.pi / 2 - 2 * G)
        x, stats, code = b.integrate(method, x0, c, 0.0, 1.0, **kw)
        assert code == OK and stats["t"] == 1.0 and np.array_equal(x, x0)
        nan = state(scene, **moving, q2=math.nan)
        assert b.integrate(method, nan, c, 0.0, 1.0, **kw)[2] == NONFINITE


@pytest.mark.parametrize("language", LANGUAGES)
def test_gimbal_lock_far_from_its_points_needs_no_cosine(
    angles: dict[str, Compiled], language: str
) -> None:
    """The check computes cos q2 only within 1e-6 pi of a point of gimbal
    lock, or beyond |q2| = 1e6 (common.gimbal_at): its verdict is still
    |cos q2| < GIMBAL_LOCK_COS at points near and far, over every turn
    from -3e5 to 3e5 and beyond the pretest's range."""
    b = angles[language]
    scene = load("torque_free")
    c = b.setup(np.zeros(0))
    rng = np.random.default_rng(11)
    turns = np.concatenate([rng.integers(-300_000, 300_000, 40), [0, -1, 3e6, -3e7]])
    offsets = (0.0, 0.2 * G, -0.3 * G, 5 * G, -5 * G, 3e-6, -4e-6, 0.5, 1.5)
    for k in turns:
        point = (float(k) + 0.5) * math.pi
        for d in offsets:
            q2 = point + d
            cos = abs(math.cos(q2))
            if 0.5 * G < cos < 2 * G:
                continue  # libm and gyrogen's cosine may round apart at the bar
            x0 = state(scene, q2=q2)
            code = b.integrate("dop853", x0, c, 0.5, 0.5)[2]
            assert code == (ATTITUDE if cos < G else OK), (k, d, cos)


@pytest.mark.parametrize("language", LANGUAGES)
def test_a_step_across_q2_pi_over_2(angles: dict[str, Compiled], language: str) -> None:
    """q2 = 1.4 + t crosses pi/2 at T_CROSS (q1 = q3 = 0, the rates exact):
    the step that takes cos q2 below zero is refused with code 6, and x is
    the exact state at stats.t, before the crossing. RK4's last good state
    lies within its step of 1e-3 s of the crossing."""
    b = angles[language]
    scene = load("torque_free")
    c = b.setup(np.zeros(0))
    x0 = state(scene, q2=Q2, u1=1.0)
    for method in METHODS:
        x, stats, code = b.integrate(method, x0, c, 0.0, 1.0, **kwargs(method))
        assert code == ATTITUDE, method
        t = stats["t"]
        assert 0.0 < t < T_CROSS and stats["accepted"] > 0
        assert math.cos(x[1]) > 0.0
        np.testing.assert_allclose(x[1], Q2 + t, rtol=0, atol=1e-12)
        expected = x0.copy()
        expected[1] = x[1]
        np.testing.assert_array_equal(x, expected)  # q1, q3 and the rates untouched
        if method == "rk4":
            assert stats["accepted"] == int(T_CROSS / 1e-3) and t == pytest.approx(0.170)
            assert 0.0 < math.cos(x[1]) < 1e-3


@pytest.mark.parametrize("language", LANGUAGES)
def test_a_pass_closer_than_the_bound(angles: dict[str, Compiled], language: str) -> None:
    """u3 = 1e-10 tilts the axis: a2 passes n3 at |cos q2| = 1.7e-11, below
    GIMBAL_LOCK_COS, while q1' and q3' grow as 1/cos q2. Every method stops
    with code 6 before the closest approach, x a finite state on the
    trajectory at stats.t (its attitude the exact one). DOP853 and Rodas4
    follow the spike to |cos q2| < 1e-8; DOPRI5 and RK4 step over it, which
    the sign of cos q2 gives away."""
    b = angles[language]
    scene = load("torque_free")
    c = b.setup(np.zeros(0))
    u3 = 1e-10
    x0 = state(scene, q2=Q2, u1=1.0, u3=u3)
    for method in METHODS:
        x, stats, code = b.integrate(method, x0, c, 0.0, 1.0, **kwargs(method))
        assert code == ATTITUDE, method
        t = stats["t"]
        assert 0.0 < t < T_CROSS + 1e-9 and np.all(np.isfinite(x))
        assert 0.0 < math.cos(x[1]) < 0.2
        np.testing.assert_allclose(angle_dcm(scene, x), exact_dcm(1.0, u3, t), rtol=0, atol=1e-8)
        np.testing.assert_allclose(x[3:6], x0[3:6], rtol=0, atol=1e-14)  # u1, u2, u3
        if method in ("dop853", "rodas4"):
            assert math.cos(x[1]) < 1e-8, method


GIMBAL_DRAWS = int(os.environ.get("GYROGEN_GIMBAL_DRAWS", "500"))
"""(start, step) pairs the gimbal property test draws: 500 in CI, 10,000 in
`make fuzz` (which sets GYROGEN_GIMBAL_DRAWS and a fresh seed)."""


def crosses_gimbal_lock(q2a: float, q2b: float) -> bool:
    """Whether [q2a, q2b] (either order) holds a point pi/2 + k pi."""
    lo, hi = min(q2a, q2b), max(q2a, q2b)
    k = math.ceil((lo - math.pi / 2) / math.pi)
    return math.pi / 2 + k * math.pi <= hi


@pytest.mark.parametrize("language", LANGUAGES)
def test_gimbal_lock_is_never_stepped_over(angles: dict[str, Compiled], language: str) -> None:
    """q2 = q2(0) + u1 t exactly (torque_free about a1, q1 = q3 = 0): drawn
    starts, rates and step sizes, steps of a whole turn and more among them
    (RK4 with 1 to 3 steps, the adaptive methods from a first step h0 up to
    the interval). Every method, single and in a batch: code 6 with x short
    of the first crossing exactly when [q2(0), q2(t1)] holds a point pi/2 +
    k pi, else code 0 at t1."""
    b = angles[language]
    scene = load("torque_free")
    c = b.setup(np.zeros(0))
    seed = int(os.environ.get("GYROGEN_GIMBAL_SEED", "20"))
    rng = np.random.default_rng(seed)
    for n in range(GIMBAL_DRAWS):
        method = METHODS[n % len(METHODS)]
        q2, u1 = rng.uniform(-1.5, 1.5), rng.choice([-1, 1]) * 10 ** rng.uniform(-2, 1.5)
        t1 = 10 ** rng.uniform(-2, 1)
        end = q2 + u1 * t1
        if min(abs(math.cos(end)), abs(math.cos(q2))) < 1e-6:
            continue  # within reach of the lock's bar at an end: either code is right
        if method == "rk4":
            kw: dict[str, Any] = {"steps": int(rng.integers(1, 4))}
        else:
            kw = {"rtol": 1e-8, "atol": 1e-8, "h0": t1 * 10 ** rng.uniform(-3, 0)}
        x0 = state(scene, q2=q2, u1=u1)
        x, stats, code = b.integrate(method, x0, c, 0.0, t1, **kw)
        why = (seed, n, method, q2, u1, t1, kw, code, stats["t"])
        if crosses_gimbal_lock(q2, end):
            assert code == ATTITUDE, why
            assert stats["t"] < t1 and not crosses_gimbal_lock(q2, x[1]), why
        else:
            assert code == OK and stats["t"] == t1, why
        xs, _, codes = b.integrate_batch(method, np.tile(x0, (3, 1)), c, 0.0, t1, **kw)
        assert np.array_equal(xs, np.tile(x, (3, 1))) and set(codes) == {code}, why


@pytest.mark.parametrize("language", LANGUAGES)
@WIDE
def test_euler_parameters_pass_where_the_angles_stop(
    euler_parameters: dict[str, Compiled], language: str
) -> None:
    """The same two motions with Euler parameters: every method reaches
    t1 = 1 with code 0 and the exact attitude; code 6 never comes."""
    b = euler_parameters[language]
    scene = quaternion_twin()
    c = b.setup(np.zeros(0))
    half = Q2 / 2  # (0, Q2, 0) in 3-1-2 angles: a rotation of Q2 about a1
    for u3 in (0.0, 1e-10):
        x0 = state(scene, e0=math.cos(half), e1=math.sin(half), u1=1.0, u3=u3)
        for method in METHODS:
            x, stats, code = b.integrate(method, x0, c, 0.0, 1.0, **kwargs(method))
            assert code == OK and stats["t"] == 1.0, method
            assert abs(np.linalg.norm(x[:4]) - 1.0) < 1e-15
            np.testing.assert_allclose(
                scene_view.quaternion_dcm(x[:4]), exact_dcm(1.0, u3, 1.0), rtol=0, atol=1e-9
            )


# --- Euler parameters: the start, and a step that loses them ---------------------------

NO_DIRECTION = [(0.0, 0.0, 0.0, 0.0), (1e-170, 0.0, 0.0, 0.0), (1e200, 1.0, 0.0, 0.0)]
"""|e| of 0, below sqrt(DBL_MIN) (its square 0), too large to square."""


@pytest.mark.parametrize("language", LANGUAGES)
def test_euler_parameters_without_a_direction_are_refused(
    euler_parameters: dict[str, Compiled], language: str
) -> None:
    """Every method, single and batch: code 5 and x as given at t0 (before:
    taylor returned 0 with NaN, the others 3 with x NaN at stats.t); NaN
    in e: code 3. A batch's good trajectory between two such is its single
    call's."""
    b = euler_parameters[language]
    scene = quaternion_twin()
    c = b.setup(np.zeros(0))
    good = state(scene, e0=1.0, u1=1.0, u3=0.5)
    for e in [*NO_DIRECTION, (math.nan, 0.0, 0.0, 0.0)]:
        x0 = state(scene, u1=1.0, u3=0.5, **dict(zip(("e0", "e1", "e2", "e3"), e, strict=True)))
        want = NONFINITE if math.isnan(e[0]) else ARGUMENT
        for method in METHODS:
            x, stats, code = b.integrate(method, x0, c, 0.0, 1.0, **kwargs(method))
            assert (code, stats["t"], stats["accepted"]) == (want, 0.0, 0), (e, method)
            np.testing.assert_array_equal(x, x0)
            one, _, _ = b.integrate(method, good, c, 0.0, 1.0, **kwargs(method))
            xb, _, codes = b.integrate_batch(
                method, np.array([x0, good, x0]), c, 0.0, 1.0, **kwargs(method)
            )
            assert list(codes) == [want, OK, want], (e, method)
            np.testing.assert_array_equal(xb, np.array([x0, one, x0]))


@pytest.mark.parametrize("language", LANGUAGES)
def test_euler_parameters_off_the_sphere_are_normalized_at_the_start(
    euler_parameters: dict[str, Compiled], language: str
) -> None:
    """A start 2 e integrates as e, bit for bit (2 |e| is exact), with every
    method; an integration over no time returns e / |e| with code 0 (the
    FMU's initialization), and a NaN start code 3 (before: code 0)."""
    b = euler_parameters[language]
    scene = quaternion_twin()
    c = b.setup(np.zeros(0))
    half = Q2 / 2
    x0 = state(scene, e0=math.cos(half), e1=math.sin(half), u1=1.0, u3=0.5)
    twice = x0.copy()
    twice[:4] *= 2.0
    for method in METHODS:
        want, _, code = b.integrate(method, x0, c, 0.0, 1.0, **kwargs(method))
        x, _, code2 = b.integrate(method, twice, c, 0.0, 1.0, **kwargs(method))
        assert code == code2 == OK, method
        np.testing.assert_array_equal(x, want)
        if method != "rk4":
            x, _, code = b.integrate(method, twice, c, 0.5, 0.5, **kwargs(method))
            assert code == OK
            np.testing.assert_array_equal(x[:4], x0[:4] / np.linalg.norm(x0[:4]))
            nan = x0.copy()
            nan[5] = math.nan
            assert b.integrate(method, nan, c, 0.5, 0.5, **kwargs(method))[2] == NONFINITE


@pytest.mark.parametrize("language", LANGUAGES)
def test_a_step_that_loses_the_attitude_is_not_taken(
    euler_parameters: dict[str, Compiled], language: str
) -> None:
    """rk4 with two steps at u1 = 1e40: the first step's e is finite but too
    large to square. Before: projected to 0, then 0/0, and code 0 with NaN;
    now code 3 with x the start at stats.t = 0."""
    b = euler_parameters[language]
    scene = quaternion_twin()
    c = b.setup(np.zeros(0))
    x0 = state(scene, e0=1.0, u1=1e40)
    x, stats, code = b.integrate("rk4", x0, c, 0.0, 1.0, steps=2)
    assert (code, stats["t"], stats["accepted"]) == (NONFINITE, 0.0, 0)
    np.testing.assert_array_equal(x, x0)


# --- the interface states the numbers -------------------------------------------------


def test_header_and_module_carry_the_registry(source_dir: Path) -> None:
    """The bounds in gyrostat_ode.h and gyrostat_ode.f90 are layout's, and
    the codes are abi.ODE_CODES."""
    h = (source_dir / "gyrostat_ode.h").read_text()
    f = (source_dir / "gyrostat_ode.f90").read_text()
    bounds = (("MIN_RTOL", abi.MIN_RTOL), ("TAYLOR_MIN_RTOL", abi.TAYLOR_MIN_RTOL))
    for name, value in (*bounds, ("GIMBAL_LOCK_COS", G)):
        (c_text,) = re.findall(rf"#define GYROSTAT_ODE_{name} (\S+)", h)
        (f_text,) = re.findall(rf"GYROSTAT_ODE_{name} = (\S+)_c_double", f)
        assert float(c_text) == float(f_text) == value
    c_codes = {int(v) for v in re.findall(r"#define GYROSTAT_ODE_(?:OK|EVENT|ERR_\w+) +(\d+)", h)}
    f_codes = {int(v) for v in re.findall(r"GYROSTAT_ODE_(?:OK|EVENT|ERR_\w+) = (\d+)", f)}
    assert c_codes == f_codes == {c.value for c in abi.ODE_CODES}
    assert "#define GYROSTAT_ODE_ERR_ATTITUDE_SINGULAR 6" in h
