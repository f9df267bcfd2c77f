"""The output grid (<prefix>_<method>_grid and _grid_batch, Compiled.
integrate_grid): each adaptive method's dense output at its own order, the
grid against one plain integration per grid time, its last state against
the plain call's bit for bit, C against Fortran and batch against single
calls bit for bit, and hostile grids (a one-line error in Python, a code in
C and Fortran). On the default scene, built once per session (conftest)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sources import write_sources
from wide import WIDE

from gyrogen import abi, methods
from gyrogen.runtime import build
from gyrogen.runtime.compiled import Compiled
from gyrogen.scene import builtin_text, default, parse

ADAPTIVE = list(methods.ADAPTIVE)
ERR_GRID = next(c.value for c in abi.ODE_CODES if c.name == "ODE_ERR_GRID")
MAX_STEPS = next(c.value for c in abi.ODE_CODES if c.name == "ODE_ERR_MAX_STEPS")
NONFINITE = next(c.value for c in abi.ODE_CODES if c.name == "ODE_ERR_NONFINITE")
INTERPOLANT_ORDER = {"dopri5": 4, "dop853": 7, "rodas4": 3, "radau5": 3, "taylor": 5}
"""The order of each method's dense output: Hairer's CONTD5 and CONTD8,
rodas.f's CONTRO, radau5's collocation polynomial (stage order 3), and the
Taylor series at the order rtol = 1e-3 gives (Jorba and Zou's p = 5)."""
SPANS = {"dopri5": (0.4, 0.2, 0.1), "dop853": (1.0, 0.7, 0.5), "taylor": (0.35, 0.25, 0.175)}
"""One step's lengths for the order test (the rest: 0.2, 0.1, 0.05), each error
above the reference's rounding. dop853's
error within a step of 0.2 is at rounding already, and over these longer
steps it falls faster than h^8 (slopes near 10: the h^8 term is not yet the
largest), so it is held to its order from below only."""
TOL = 1e-8
"""rtol = atol of the grid-against-plain comparisons."""


@pytest.fixture(scope="module")
def problem(backends: dict[str, Compiled]) -> tuple[np.ndarray, np.ndarray]:
    """The default scene's start state and its constants."""
    scene = default()
    x0 = np.array([scene.simulate.initial.get(s, 0.0) for s in scene.states])
    p = np.array([scene.simulate.parameters[n] for n in scene.runtime])
    return x0, backends["c"].setup(p)


@pytest.mark.parametrize("method", ADAPTIVE)
def test_the_interpolant_has_the_methods_order(
    backends: dict[str, Compiled], problem: tuple[np.ndarray, np.ndarray], method: str
) -> None:
    """One step over [0, T] (h0 = T, a loose tolerance: accepted at once);
    the state at T/2 from the interpolant, against a tight reference: its
    error shrinks as T^(order + 1) with T (at least so fast for
    dop853, see SPANS)."""
    x0, c = problem
    model, errors = backends["c"], []
    for span in SPANS.get(method, (0.2, 0.1, 0.05)):
        times = np.array([0.0, 0.5 * span, span])
        states, stats, code = model.integrate_grid(
            method, x0, c, times, rtol=1e-3, atol=1e-3, h0=span
        )
        assert (code, stats["accepted"], stats["rejected"]) == (0, 1, 0)
        ref, _, ref_code = model.integrate("dop853", x0, c, 0.0, 0.5 * span, rtol=1e-14, atol=1e-14)
        assert ref_code == 0
        errors.append(np.max(np.abs(states[1] - ref)))
    assert min(errors) > 1e-11, errors  # above the reference's rounding
    spans = np.array(SPANS.get(method, (0.2, 0.1, 0.05)))
    slopes = np.log(np.array(errors[:-1]) / errors[1:]) / np.log(spans[:-1] / spans[1:])
    order = INTERPOLANT_ORDER[method]
    assert np.all(slopes > order + 0.5), (slopes, errors)
    assert method == "dop853" or np.all(slopes < order + 1.5), (slopes, errors)


@pytest.mark.parametrize("method", ADAPTIVE)
def test_the_grid_agrees_with_a_plain_call_per_time(
    backends: dict[str, Compiled], problem: tuple[np.ndarray, np.ndarray], method: str
) -> None:
    """Each grid state within the tolerance's scale of _integrate stopped at
    its time; the last one equal to _integrate's end state bit for bit, with
    the same steps taken."""
    x0, c = problem
    model = backends["c"]
    times = np.linspace(0.0, 5.0, 51)
    states, stats, code = model.integrate_grid(method, x0, c, times, rtol=TOL, atol=TOL)
    assert code == 0 and states.shape == (51, model.nx)
    assert np.array_equal(states[0], x0)
    single = [model.integrate(method, x0, c, 0.0, t, rtol=TOL, atol=TOL) for t in times[1:]]
    assert all(code == 0 for _, _, code in single)
    scale = 1.0 + np.abs(states)
    assert np.max(np.abs(states[1:] - np.array([x for x, _, _ in single])) / scale[1:]) < 1e-5
    end, end_stats, _ = single[-1]
    assert np.array_equal(states[-1], end)
    for field in ("t", "accepted", "rejected", "jac_calls", "decompositions"):
        assert stats[field] == end_stats[field], field


@pytest.mark.parametrize("method", ADAPTIVE)
def test_c_and_fortran_write_the_same_grid(
    backends: dict[str, Compiled], problem: tuple[np.ndarray, np.ndarray], method: str
) -> None:
    x0, c = problem
    times = np.concatenate([[0.0], np.sort(np.random.default_rng(7).uniform(0.0, 3.0, 40)), [3.0]])
    got = [
        backends[lang].integrate_grid(method, x0, c, times, rtol=1e-9) for lang in ("c", "fortran")
    ]
    (sc, stc, cc), (sf, stf, cf) = got
    assert cc == cf == 0
    assert np.array_equal(sc, sf)
    assert dict(stc) == dict(stf)


@pytest.mark.parametrize("method", ["dop853", "radau5", "taylor"])
@pytest.mark.parametrize("language", ["c", "fortran"])
def test_a_batch_equals_its_single_grids(
    backends: dict[str, Compiled],
    problem: tuple[np.ndarray, np.ndarray],
    method: str,
    language: str,
) -> None:
    x0, c = problem
    model = backends[language]
    starts = x0 + np.random.default_rng(3).normal(0.0, 0.05, (5, model.nx))
    times = np.linspace(0.0, 2.0, 9)
    for threads in (1, 2):
        states, stats, codes = model.integrate_grid_batch(method, starts, c, times, threads)
        assert states.shape == (5, 9, model.nx) and list(codes) == [0] * 5
        for k, start in enumerate(starts):
            one, one_stats, _ = model.integrate_grid(method, start, c, times)
            assert np.array_equal(states[k], one)
            assert stats[k]["accepted"] == one_stats["accepted"]


def test_one_time_is_the_start(
    backends: dict[str, Compiled], problem: tuple[np.ndarray, np.ndarray]
) -> None:
    x0, c = problem
    states, stats, code = backends["fortran"].integrate_grid("dopri5", x0, c, [0.25])
    assert code == 0 and np.array_equal(states, x0[None, :])
    assert (stats["t"], stats["accepted"]) == (0.25, 0)


HOSTILE = {
    "unsorted": ([0.0, 2.0, 1.0], "strictly increasing (times[2] = 1.0 after times[1] = 2.0)"),
    "repeated": ([0.0, 1.0, 1.0], "strictly increasing (times[2] = 1.0 after times[1] = 1.0)"),
    "nan": ([0.0, np.nan, 1.0], "finite (times[1] = nan)"),
    "infinite": ([0.0, 1.0, np.inf], "finite (times[2] = inf)"),
    "empty": ([], "a 1-D array of at least one time, not shape (0,)"),
    "matrix": ([[0.0, 1.0], [2.0, 3.0]], "a 1-D array of at least one time, not shape (2, 2)"),
}


@pytest.mark.parametrize("case", list(HOSTILE))
def test_a_hostile_grid_is_one_line_in_python(
    backends: dict[str, Compiled], problem: tuple[np.ndarray, np.ndarray], case: str
) -> None:
    x0, c = problem
    times, words = HOSTILE[case]
    for call in (backends["c"].integrate_grid, backends["c"].integrate_grid_batch):
        start = x0 if call == backends["c"].integrate_grid else x0[None, :]
        with pytest.raises(ValueError) as err:
            call("dop853", start, c, times)
        assert str(err.value) == f"the grid times must be {words}"


@pytest.mark.parametrize("language", ["c", "fortran"])
@pytest.mark.parametrize("case", ["unsorted", "repeated", "nan", "infinite", "empty"])
def test_a_hostile_grid_is_a_code_in_c_and_fortran(
    backends: dict[str, Compiled],
    problem: tuple[np.ndarray, np.ndarray],
    language: str,
    case: str,
) -> None:
    """The raw call returns ODE_ERR_GRID, writes no row and leaves x as given."""
    x0, c = problem
    model = backends[language]
    times = np.array(HOSTILE[case][0] or [0.0])  # a buffer even when ntimes is 0
    ntimes = len(HOSTILE[case][0])
    for method in ADAPTIVE:
        x, out = x0.copy(), np.full((len(times), model.nx), -7.0)
        stats = model.ffi.new("gyrogen_stats *")
        code = model.function(f"{method}_grid")(
            ntimes, model.doubles(times), model.doubles(x), model.doubles(c), 1e-8, 1e-8, 0.0,
            1000, model.doubles(out), stats,
        )  # fmt: skip
        assert code == ERR_GRID, method
        assert np.all(out == -7.0) and np.array_equal(x, x0)
        assert np.isnan(stats.t)


def test_a_negative_count_is_a_code(
    backends: dict[str, Compiled], problem: tuple[np.ndarray, np.ndarray]
) -> None:
    x0, c = problem
    model, times, out = backends["c"], np.zeros(1), np.zeros((1, backends["c"].nx))
    code = model.function("taylor_grid")(
        -3, model.doubles(times), model.doubles(x0.copy()), model.doubles(c), 1e-8, 1e-8, 0.0,
        1000, model.doubles(out), model.ffi.NULL,
    )  # fmt: skip
    assert code == ERR_GRID


LANED = [name for name, m in methods.METHODS.items() if m.laned(default().lanes)]
"""The methods whose _grid_batch runs over lanes in the default scene."""


@pytest.mark.parametrize("method", LANED)
def test_a_lanes_batch_equals_its_single_grids(
    backends: dict[str, Compiled], problem: tuple[np.ndarray, np.ndarray], method: str
) -> None:
    """_grid_batch over SIMD lanes: 37 states (no multiple of a lane width,
    so lanes are refilled mid-batch) whose rates span a factor of 30 (their
    steps too), one not finite (refused at the start), a step budget some
    of them run out of: each state's rows (NaN past a failure), stats and
    code equal its _grid call's bit for bit, on one thread and on two."""
    x0, c = problem
    model = backends["c"]
    rng = np.random.default_rng(11)
    starts = np.tile(x0, (37, 1))
    rates = [i for i, name in enumerate(default().states) if name.startswith("u")]
    starts[:, rates] *= rng.uniform(0.3, 10.0, (37, 1))
    starts[5, 0] = np.nan
    times = np.concatenate([[0.0], np.sort(rng.uniform(0.0, 3.0, 12)), [3.0]])
    budget = int(np.median([model.integrate(method, x, c, 0.0, 3.0)[1]["accepted"]
                            for x in starts[[0, 1, 2, 3, 4, 6]]]))  # fmt: skip
    for threads in (1, 2):
        states, stats, codes = model.integrate_grid_batch(
            method, starts, c, times, threads, max_steps=budget
        )
        assert set(codes) == {0, MAX_STEPS, NONFINITE}
        for k, start in enumerate(starts):
            one, one_stats, code = model.integrate_grid(method, start, c, times, max_steps=budget)
            assert np.array_equal(states[k], one, equal_nan=True), k
            assert {f: stats[k][f] for f in one_stats} == dict(one_stats), k
            assert codes[k] == code, k


@pytest.mark.parametrize("method", LANED)
def test_a_lanes_batch_keeps_the_grids_start(
    backends: dict[str, Compiled], problem: tuple[np.ndarray, np.ndarray], method: str
) -> None:
    """One grid time: each row the start, code OK; a bad grid: every state
    ERR_GRID, no row written."""
    x0, c = problem
    model = backends["c"]
    starts = x0 * np.linspace(0.5, 1.5, 11)[:, None]
    states, _, codes = model.integrate_grid_batch(method, starts, c, [0.0])
    assert list(codes) == [0] * 11 and np.array_equal(states[:, 0], starts)
    fn = model.function(method + "_grid_batch")
    bad = np.array([0.0, 2.0, 1.0])
    out = np.full((11, 3, model.nx), np.nan)
    codes = np.zeros(11, dtype=np.intc)
    buf = model.ffi.from_buffer
    failed = fn(11, 3, buf("double[]", bad), buf("double[]", starts.copy()), buf("double[]", c),
                1e-6, 1e-6, 0.0, 100000, buf("double[]", out), model.ffi.NULL,
                buf("int[]", codes))  # fmt: skip
    assert failed == 11 and list(codes) == [ERR_GRID] * 11 and np.all(np.isnan(out))


def test_a_fixed_step_method_has_no_grid(
    backends: dict[str, Compiled], problem: tuple[np.ndarray, np.ndarray]
) -> None:
    x0, c = problem
    with pytest.raises(ValueError, match=r"^rk4 has no output grid: it is a fixed-step method$"):
        backends["c"].integrate_grid("rk4", x0, c, [0.0, 1.0])
    with pytest.raises(ValueError, match=r"^no integrator 'euler' in this build"):
        backends["c"].integrate_grid("euler", x0, c, [0.0, 1.0])


def test_a_failure_leaves_the_rows_past_it_unwritten(
    backends: dict[str, Compiled], problem: tuple[np.ndarray, np.ndarray]
) -> None:
    x0, c = problem
    times = np.linspace(0.0, 5.0, 11)
    states, stats, code = backends["c"].integrate_grid("dopri5", x0, c, times, max_steps=5)
    assert code == next(c.value for c in abi.ODE_CODES if c.name == "ODE_ERR_MAX_STEPS")
    reached = times <= stats["t"]
    assert np.all(np.isfinite(states[reached])) and np.all(np.isnan(states[~reached]))


QUATERNION_SPINUP = builtin_text("wheel_spinup").replace(
    'name = "wheel_spinup"', 'name = "wheel_spinup_e"\nattitude = "quaternion"'
)


@pytest.mark.slow  # a scene of its own, generated and built in C and Fortran
@WIDE
def test_euler_parameters_on_the_grid(tmp_path: Path, cache_dir: Path) -> None:
    """Euler parameters between step ends are the interpolant's: |e| = 1 to
    within the tolerance's scale; at the end, projected, as _integrate's."""
    scene = parse(QUATERNION_SPINUP, "wheel_spinup_e")
    write_sources(scene, tmp_path / scene.name)
    mp = pytest.MonkeyPatch()
    mp.setenv("GYROGEN_CACHE", str(cache_dir))
    try:
        models = [build.build(tmp_path / scene.name, lang) for lang in ("c", "fortran")]
    finally:
        mp.undo()
    x0 = np.array(scene.initial_state())
    c = models[0].setup(np.array([scene.simulate.parameters[n] for n in scene.runtime]))
    times = np.linspace(0.0, 5.0, 41)
    for method in ADAPTIVE:
        (states, _, code), (fortran, _, _) = (
            m.integrate_grid(method, x0, c, times, rtol=1e-9, atol=1e-9) for m in models
        )
        end, _, _ = models[0].integrate(method, x0, c, 0.0, 5.0, rtol=1e-9, atol=1e-9)
        assert code == 0 and np.array_equal(states, fortran), method
        assert np.array_equal(states[-1], end), method
        assert np.max(np.abs(np.linalg.norm(states[:, :4], axis=1) - 1.0)) < 1e-6, method
