"""The edges of the generated integrators, in C and Fortran through cffi:
NULL statistics."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gyrogen import build
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
            (method, x0, {"rtol": 0.0}, ARGUMENT),
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
