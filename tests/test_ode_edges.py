"""The edges of the generated integrators, in C and Fortran through cffi:
NULL statistics, tolerances no double can meet, a NaN or infinite first
step."""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gyrogen import build, layout
from gyrogen.scene import Scene, load

REPO = Path(__file__).resolve().parents[1]
LANGUAGES = ["c", "fortran"]
ADAPTIVE = ["dopri5", "dop853", "rodas4"]
METHODS = ["rk4", *ADAPTIVE]
OK, UNDERFLOW, MAX_STEPS, NONFINITE, SINGULAR, ARGUMENT = range(6)


@pytest.fixture(scope="module")
def angles(cache_dir: Path) -> Iterator[dict[str, build.Compiled]]:
    """torque_free (3-1-2 angles), from generated/."""
    mp = pytest.MonkeyPatch()
    mp.setenv("GYROGEN_CACHE", str(cache_dir))
    yield {lang: build.build(REPO / "generated" / "torque_free", lang) for lang in LANGUAGES}
    mp.undo()


def state(scene: Scene, **values: float) -> np.ndarray:
    return np.array([values.get(s, 0.0) for s in scene.states])


def raw(
    b: build.Compiled,
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


# --- NULL statistics -------------------------------------------------------------


@pytest.mark.parametrize("language", LANGUAGES)
def test_null_stats_gives_the_same_state(
    backends: dict[str, build.Compiled], language: str
) -> None:
    """Every single-trajectory integrator takes NULL stats, succeeding or
    failing: the same x and code as with them."""
    b = backends[language]
    scene = load("gyrostat")
    x0 = state(scene, **scene.simulate.initial)
    c = b.setup(np.array([scene.simulate.parameters[n] for n in scene.runtime]))
    runs: list[tuple[str, np.ndarray, dict[str, Any], int]] = []
    for method in METHODS:
        if method == "rk4":
            runs += [(method, x0, {"steps": 100}, OK), (method, x0, {"steps": 0}, ARGUMENT)]
            continue
        runs += [
            (method, x0, {"rtol": 1e-8, "atol": 1e-8}, OK),
            (method, x0, {"max_steps": 3}, MAX_STEPS),
            (method, x0, {"rtol": 1e-20}, ARGUMENT),
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
    {"rtol": layout.MIN_RTOL},
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
    angles: dict[str, build.Compiled], language: str
) -> None:
    """rtol <= 10 DBL_EPSILON, atol <= 0, a NaN or infinite tolerance or h0:
    code 5 at once (x as given, nothing called). The first rtol above the
    bound is accepted, and h0 <= 0 still means an automatic first step."""
    b = angles[language]
    scene = load("torque_free")
    x0 = state(scene, **scene.simulate.initial)
    c = b.setup(np.zeros(0))
    for method in ADAPTIVE:
        for bad in BAD:
            kw = {"rtol": 1e-8, "atol": 1e-8, "max_steps": 1000} | bad
            x, stats, code = b.integrate(method, x0, c, 0.5, 1.5, **kw)
            assert code == ARGUMENT, (method, bad)
            assert np.array_equal(x, x0) and stats["t"] == 0.5 and stats["rhs_calls"] == 0
        just_above = float(np.nextafter(layout.MIN_RTOL, 1.0))
        x, stats, code = b.integrate(method, x0, c, 0.0, 1.0, rtol=just_above, atol=1e-12)
        assert code == OK and stats["t"] == 1.0
        auto = b.integrate(method, x0, c, 0.0, 1.0, h0=0.0)
        negative = b.integrate(method, x0, c, 0.0, 1.0, h0=-1.0)
        np.testing.assert_array_equal(auto[0], negative[0])
        assert auto[1] == negative[1] and auto[2] == negative[2] == OK


# --- the interface states the numbers -------------------------------------------------


def test_header_and_module_carry_the_registry(source_dir: Path) -> None:
    """The bound in gyrostat_ode.h and gyrostat_ode.f90 is layout's, and the
    codes are build.ODE_CODES."""
    h = (source_dir / "gyrostat_ode.h").read_text()
    f = (source_dir / "gyrostat_ode.f90").read_text()
    for name, value in (("MIN_RTOL", layout.MIN_RTOL),):
        (c_text,) = re.findall(rf"#define GYROSTAT_ODE_{name} (\S+)", h)
        (f_text,) = re.findall(rf"GYROSTAT_ODE_{name} = (\S+)_c_double", f)
        assert float(c_text) == float(f_text) == value
    c_codes = {int(v) for v in re.findall(r"#define GYROSTAT_ODE_(?:OK|ERR_\w+) +(\d+)", h)}
    f_codes = {int(v) for v in re.findall(r"GYROSTAT_ODE_(?:OK|ERR_\w+) = (\d+)", f)}
    assert c_codes == f_codes == set(build.ODE_CODES)
