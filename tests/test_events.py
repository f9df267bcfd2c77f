"""A scene's [[events]]: declared in TOML, refused in one line when wrong,
and compiled into <prefix>_events (C and Fortran) that agrees with the
numpy reference, which reads the same expressions on its own."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from sources import write_sources
from wide import WIDE

from gyrogen.analysis.simulate import engine
from gyrogen.errors import SceneError
from gyrogen.oracle import scene_view
from gyrogen.runtime import build
from gyrogen.runtime.compiled import Compiled
from gyrogen.scene import Scene, builtin_text, parse
from gyrogen.scene.events import parse as parse_expr

EVENTS = """
[outputs]
kinetic_energy = true
angular_momentum = true
power = true

[[events]]
name = "wheel_fast"
expr = "u4 - u2 - 300"
direction = "up"
terminal = true

[[events]]
name = "tilted"
expr = "cos(q2)*cos(q1) - 0.9"
direction = "down"

[[events]]
name = "energy_and_time"
expr = "kinetic_energy - 2*angular_momentum[2]**2/(I11 + I33) + max(t, 1) * abs(u1) - sqrt(m_a)"
"""


def _scene(name: str, extra: str = EVENTS) -> Scene:
    """A built-in scene (gyrostat: every parameter at run time) with extra."""
    return parse(builtin_text(name) + extra, f"{name}+events")


@pytest.fixture(scope="module")
def generated(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Scene]:
    """gyrostat with EVENTS, generated once for the module's tests."""
    scene = _scene("gyrostat")
    out = tmp_path_factory.mktemp("events")
    write_sources(scene, out)
    return out, scene


@pytest.fixture(scope="module")
def compiled(generated: tuple[Path, Scene]) -> tuple[list[Compiled], Scene]:
    out, scene = generated
    return [build.build(out, lang) for lang in ("c", "fortran")], scene


def test_the_compiled_events_are_the_reference(compiled: tuple[list[Compiled], Scene]) -> None:
    """Every event at 500 drawn states and two times: C = Fortran bit for
    bit, both within a few ulps of the reference's own reading."""
    (c_build, f_build), scene = compiled
    rng = np.random.default_rng(5)
    xs = scene_view.random_states(scene, rng, 500)
    p = np.array([scene.simulate.parameters[n] for n in scene.runtime])
    assert c_build.event_names == ["wheel_fast", "tilted", "energy_and_time"]
    for t in (0.0, 3.5):
        g_c = c_build.events(xs, c_build.setup(p), t)
        g_f = f_build.events(xs, f_build.setup(p), t)
        ref = scene_view.events(scene, xs, p, t)
        assert g_c.shape == (500, 3)
        assert np.array_equal(g_c, g_f)
        scale = 1 + np.abs(ref)
        assert np.max(np.abs(g_c - ref) / scale) < 1e-12


def test_the_manifest_and_header_name_the_events(
    compiled: tuple[list[Compiled], Scene], generated: tuple[Path, Scene]
) -> None:
    (c_build, _), _ = compiled
    out, scene = generated
    listed = c_build.manifest["events"]
    assert [e["name"] for e in listed] == ["wheel_fast", "tilted", "energy_and_time"]
    assert listed[0] == {
        "name": "wheel_fast", "expr": "u4 - u2 - 300", "direction": "up", "terminal": True,
    }  # fmt: skip
    header = (out / f"{scene.name}.h").read_text()
    assert "void gyrostat_events(double t, const double *x, const double *c, double *out);" in (
        header
    )
    assert "out[1]  tilted: cos(q2)*cos(q1) - 0.9 (down)" in header
    ode_h = " ".join((out / f"{scene.name}_ode.h").read_text().replace("*", " ").split())
    assert "at most 1/8 of the step each" in ode_h  # energy_and_time reads t


def test_the_header_says_events_on_the_states_are_searched_from_the_whole_step(
    tmp_path: Path,
) -> None:
    """The header's promise follows the scene: pieces of at most an eighth
    of a step only where an event reads t."""
    scene = _scene("dual_spin", extra='[[events]]\nname = "tilted"\nexpr = "cos(q2) - 0.9"\n')
    write_sources(scene, tmp_path)
    ode_h = " ".join((tmp_path / "dual_spin_ode.h").read_text().replace("*", " ").split())
    assert "from the whole step (the events read the states alone)" in ode_h
    assert "1/8 of the step" not in ode_h and "down to 2^-16 of the step" in ode_h


def test_a_scene_without_events_has_no_event_function(tmp_path: Path) -> None:
    scene = _scene("dual_spin", extra="")
    write_sources(scene, tmp_path)
    assert "_events" not in (tmp_path / "dual_spin.c").read_text()
    assert "events" not in scene.model_dump()  # its build id is as before events


@pytest.mark.slow  # a cluster with events derived and compiled; the compiled events stay fast
@WIDE
def test_a_cluster_reads_its_outputs_and_runtime_axes(tmp_path: Path) -> None:
    """rw4_pyramid's momentum and per-wheel power, and a wheel's rate."""
    extra = """
[[events]]
name = "momentum"
expr = "angular_momentum[0]**2 + angular_momentum[1]**2 - 4"

[[events]]
name = "second_wheel"
expr = "w2 - 100 + power[3]"
"""
    scene = _scene("rw4_pyramid", extra)
    write_sources(scene, tmp_path)
    c_build = build.build(tmp_path, "c")
    rng = np.random.default_rng(2)
    xs = scene_view.random_states(scene, rng, 200)
    p = np.array([scene.simulate.parameters[n] for n in scene.runtime])
    got = c_build.events(xs, c_build.setup(p))
    ref = scene_view.events(scene, xs, p)
    assert np.max(np.abs(got - ref) / (1 + np.abs(ref))) < 1e-12


@pytest.mark.parametrize(
    ("events", "message"),
    [
        ('[[events]]\nname = "a"\nexpr = "__import__(\'os\')"',
         "__import__() is not one of sin, cos, sqrt, abs, min, max"),
        ('[[events]]\nname = "a"\nexpr = "u4 +* 2"', "is not an expression (invalid syntax)"),
        ('[[events]]\nname = "a"\nexpr = "x9 - 1"',
         "'x9': not a state, parameter or output of this scene, nor t"),
        ('[[events]]\nname = "a"\nexpr = "power - 1"', "'power': set outputs.power = true"),
        ('[[events]]\nname = "a"\nexpr = "u4.real"', "'u4.real' is not allowed"),
        ('[[events]]\nname = "a"\nexpr = "u4 if u1 else 2"', "is not allowed"),
        ('[[events]]\nname = "a"\nexpr = "1e999 - u4"', "the number inf is not finite"),
        ('[[events]]\nname = "a"\nexpr = "max(u4)"', "max() takes 2 argument(s)"),
        ('[[events]]\nname = "a"\nexpr = "' + "(" * 300 + "u4" + ")" * 300 + '"',
         "is not an expression"),
        ('[[events]]\nname = "a"\nexpr = "' + "u4 + " * 300 + '1"', "at most 1000 characters"),
        ('[[events]]\nname = "a b"\nexpr = "u4"', "a letter, then letters, digits and underscores"),
        ('[[events]]\nname = "a"\nexpr = "u4"\n[[events]]\nname = "a"\nexpr = "u2"',
         "events.1.name: 'a' names another event too"),
        ('[[events]]\nname = "a"\nexpr = "u4"\ndirection = "sideways"', "direction"),
        ('[[events]]\nname = "a"\nexpr = "u4"\nterminal = "yes"', "terminal"),
        ('[[events]]\nname = "a"\nexpr = "u4"\nwhen = 3', "when"),
        ('[outputs]\nangular_momentum = true\n[[events]]\nname = "a"\n'
         'expr = "angular_momentum - 1"', "has 3 values: write angular_momentum[i]"),
        ('[outputs]\nangular_momentum = true\n[[events]]\nname = "a"\n'
         'expr = "angular_momentum[3]"', "angular_momentum[3]: it has 3 values, from 0"),
    ],
)  # fmt: skip
def test_a_wrong_event_is_one_line(events: str, message: str) -> None:
    with pytest.raises(SceneError) as err:
        parse(builtin_text("gyrostat") + "\n" + events + "\n", "bad.toml")
    text = str(err.value)
    assert message in text and "\n" not in text, text
    assert len(text) < 400, text


def test_a_multi_line_expression_is_one_line_wherever_it_is_shown() -> None:
    """A TOML multi-line string, indented as a user would, is read with its
    line breaks as spaces (it was refused: "unexpected indent")."""
    scene = parse(
        builtin_text("gyrostat") + '\n[[events]]\nname = "a"\nexpr = """u1\n    + u2\n\t- 1"""\n',
        "multi.toml",
    )
    assert scene.events[0].expr == "u1 + u2 - 1"
    assert parse_expr(scene.events[0].expr) == ("-", ("+", ("name", "u1"), ("name", "u2")),
                                                ("num", 1.0))  # fmt: skip


@pytest.fixture(scope="module")
def spin_up(tmp_path_factory: pytest.TempPathFactory) -> tuple[Compiled, Scene]:
    """The built-in wheel_spinup, generated and compiled once for its methods."""
    scene = parse(builtin_text("wheel_spinup"), "wheel_spinup.toml")
    out = tmp_path_factory.mktemp("wheel_spinup")
    write_sources(scene, out)
    return build.build(out, "c"), scene


@pytest.mark.slow  # a built-in scene generated and compiled
@pytest.mark.parametrize("method", ["dop853", "taylor"])
@WIDE
def test_the_builtin_spin_up_logs_its_wheel_at_40_rad_s(
    spin_up: tuple[Compiled, Scene], method: str
) -> None:
    """wheel_spinup declares an event: u4 passes 40 rad/s. Its motor's
    torque gives u4' = T/J exactly, so the crossing is at 40 J/T = 30 s."""
    comp, scene = spin_up
    x0, c = np.array(scene.initial_state()), comp.setup([0.02])
    _, log, _, code = comp.integrate_events(method, x0, c, [0.0, 60.0], rtol=1e-12, atol=1e-12)
    assert code == 0 and log.names == ["wheel_at_40_rad_s"]
    assert abs(log.times[0] - 40 * 0.015 / 0.02) < 1e-12 * 30, log.times


def test_the_grammar_never_evaluates_python() -> None:
    """Names are data: no attribute, call of an unknown function, lambda or
    comprehension gets through."""
    for text in ("().__class__", "[u for u in x]", "lambda: 1", "open('f')", "u4[0]", "'a'"):
        with pytest.raises(ValueError):
            parse_expr(text)


LOCATED = """
[[events]]
name = "third"
expr = "sin(3*t)"

[[events]]
name = "rising"
expr = "sin(3*t)"
direction = "up"

[[events]]
name = "spun"
expr = "q3 - 5"
direction = "up"
terminal = true
"""
ADAPTIVE = ("dopri5", "dop853", "rodas4", "radau5", "taylor")


@pytest.fixture(scope="module")
def located(tmp_path_factory: pytest.TempPathFactory) -> tuple[list[Compiled], Scene]:
    """dual_spin (spinning at 0.05 rad/s about a2, nutating) with events in
    t alone, and a terminal one where the spin angle q3 reaches 5 rad."""
    scene = _scene("dual_spin", LOCATED)
    out = tmp_path_factory.mktemp("located")
    write_sources(scene, out)
    return [build.build(out, lang) for lang in ("c", "fortran")], scene


@pytest.mark.parametrize("method", ADAPTIVE)
def test_crossings_are_located_to_a_few_ulps(
    located: tuple[list[Compiled], Scene], method: str
) -> None:
    """sin(3 t) crosses 0 at k pi/3: every crossing within 4 ulps of its
    time, in time order; "up" only every other one; C = Fortran bit for bit."""
    (c_build, f_build), scene = located
    x0, c = np.array(scene.initial_state()), c_build.setup([])
    times = np.linspace(0.0, 4.0, 9)
    states, log, _, code = c_build.integrate_events(method, x0, c, times, rtol=1e-10, atol=1e-10)
    assert code == 0, code
    third = log.times[np.array(log.names) == "third"]
    k = np.arange(1, 4)  # pi/3, 2 pi/3, pi within (0, 4]
    assert np.all(np.abs(third - k * np.pi / 3) <= 4 * np.spacing(k * np.pi / 3)), third
    rising = log.times[np.array(log.names) == "rising"]
    assert np.all(np.abs(rising - 2 * np.pi / 3) <= 4 * np.spacing(2.0)), rising
    assert list(log.times) == sorted(log.times)
    plain, *_ = c_build.integrate_grid(method, x0, c, times, rtol=1e-10, atol=1e-10)
    assert np.array_equal(states, plain)  # the events leave the trajectory as it was
    f_states, f_log, _, f_code = f_build.integrate_events(method, x0, c, times, rtol=1e-10,
                                                          atol=1e-10)  # fmt: skip
    assert f_code == code and np.array_equal(f_log.times, log.times)
    assert np.array_equal(f_log.states, log.states) and np.array_equal(f_states, states)


@pytest.mark.parametrize("method", ADAPTIVE)
def test_a_terminal_event_stops_the_run_there(
    located: tuple[list[Compiled], Scene], method: str
) -> None:
    """q3 reaches 5 rad near t = 100 s: the event's time agrees with a
    bisection of plain runs, the state there is the log's, and the grid's
    rows past it stay NaN (code 8)."""
    (c_build, _), scene = located
    x0, c = np.array(scene.initial_state()), c_build.setup([])
    times = np.linspace(0.0, 200.0, 201)
    states, log, stats, code = c_build.integrate_events(method, x0, c, times, rtol=1e-11,
                                                         atol=1e-11)  # fmt: skip
    assert code == 8 and log.names[-1] == "spun"
    t_event = log.times[-1]
    assert stats["t"] == t_event and 90.0 < t_event < 110.0
    assert np.all(np.isnan(states[times > t_event])) and not np.isnan(states[times < t_event]).any()
    assert abs(log.states[-1, 2] - 5.0) < 1e-12
    lo, hi = 90.0, 110.0  # the crossing by bisection on plain runs from 0
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        x, _, _ = c_build.integrate(method, x0, c, 0.0, mid, rtol=1e-12, atol=1e-12)
        lo, hi = (mid, hi) if x[2] < 5.0 else (lo, mid)
    assert abs(t_event - hi) < 1e-8 * hi


def test_a_full_log_stops_with_its_code(located: tuple[list[Compiled], Scene]) -> None:
    (c_build, _), scene = located
    x0, c = np.array(scene.initial_state()), c_build.setup([])
    times = np.linspace(0.0, 10.0, 11)
    states, log, stats, code = c_build.integrate_events("dop853", x0, c, times, capacity=2)
    assert code == 9 and len(log) == 2
    assert stats["t"] == pytest.approx(2 * np.pi / 3, rel=1e-12)  # the third crossing's time
    assert np.all(np.isnan(states[times > stats["t"]]))
    _, none, _, code = c_build.integrate_events("dop853", x0, c, times, capacity=0)
    assert code == 9 and len(none) == 0


@pytest.mark.parametrize("method", ["dop853", "dopri5", "taylor", "rodas4"])
def test_a_batch_is_its_single_calls(located: tuple[list[Compiled], Scene], method: str) -> None:
    """_events_batch, C and Fortran, on one and two threads: each state's
    rows, log, statistics and code are its _events call's bit for bit, over
    drawn spins (a terminal event for the fast ones), a NaN start, a step
    budget some runs exhaust and logs that fill (codes 0, 2, 3, 8 and 9);
    and C's batch (over lanes) is Fortran's (a loop of single calls) bit
    for bit."""
    builds, scene = located
    rng = np.random.default_rng(11)
    x0s = np.tile(np.array(scene.initial_state()), (13, 1))
    x0s[:, 4] = rng.uniform(0.0, 3.0, 13)  # u2: q3 reaches 5 rad before t = 4 above ~1.3 rad/s
    x0s[:, 3] = rng.uniform(-0.1, 0.1, 13)
    x0s[5, 3] = np.nan
    times = np.linspace(0.0, 4.0, 9)
    c = builds[0].setup([])
    steps = [builds[0].integrate_events(method, x, c, times)[2] for x in x0s]
    budget = int(np.median([s["accepted"] + s["rejected"] for s in steps]))
    codes, runs = set(), []
    for comp in builds:
        for capacity, max_steps, threads in ((3, 10**6, 1), (5, budget, 2), (0, 10**6, 1)):
            given = {"rtol": 1e-10, "atol": 1e-10, "max_steps": max_steps}
            ends = np.empty_like(x0s)
            states, logs, stats, code = comp.integrate_events_batch(
                method, x0s, c, times, threads, capacity=capacity, ends=ends, **given
            )
            runs.append((states, ends, stats, code, logs))
            assert len(logs) == len(x0s)
            for i, x0 in enumerate(x0s):
                end = np.empty(comp.nx)
                one, log, one_stats, one_code = comp.integrate_events(
                    method, x0, c, times, capacity=capacity, end=end, **given
                )
                assert code[i] == one_code and np.array_equal(states[i], one, equal_nan=True)
                assert np.array_equal(ends[i], end, equal_nan=True)
                assert dict(one_stats) == {k: stats[k][i] for k in one_stats}
                assert logs[i].names == log.names and np.array_equal(logs[i].times, log.times)
                assert np.array_equal(logs[i].states, log.states)
            codes |= set(code.tolist())
    assert {0, 2, 3, 8, 9} <= codes, codes
    half = len(runs) // 2
    for c_run, f_run in zip(runs[:half], runs[half:], strict=True):  # C = Fortran
        for a, b in zip((*c_run[:2], c_run[3]), (*f_run[:2], f_run[3]), strict=True):
            assert np.array_equal(a, b, equal_nan=True)
        for k in c_run[2].dtype.names:
            assert np.array_equal(c_run[2][k], f_run[2][k], equal_nan=True), k
        for one, other in zip(c_run[4], f_run[4], strict=True):
            assert one.names == other.names and np.array_equal(one.times, other.times)
            assert np.array_equal(one.states, other.states)


def test_a_batch_takes_a_set_of_constants_per_state(
    compiled: tuple[list[Compiled], Scene],
) -> None:
    """c of shape (n, nc): _events_batch and _grid_batch run each stretch of
    states with equal constants in one call, each state its own single
    call's bit for bit (three sets of inertias, one of them twice apart,
    one start NaN); a wrong shape or a NaN constant is one line."""
    (c_build, f_build), scene = compiled
    rng = np.random.default_rng(3)
    p = np.array([scene.simulate.parameters[n] for n in scene.runtime])
    sets = []
    for scale in (1.0, 1.02, 0.97):
        q = p.copy()
        q[scene.runtime.index("I11")] *= scale
        sets.append(c_build.setup(q))
    cs = np.array([sets[k] for k in (0, 0, 1, 1, 1, 2, 0)])
    x0s = scene_view.random_states(scene, rng, 7)
    x0s[3, 0] = np.nan
    times = np.linspace(0.0, 3.0, 7)
    for comp in (c_build, f_build):
        for threads in (1, 2):
            states, logs, stats, codes = comp.integrate_events_batch("dop853", x0s, cs, times,
                                                                     threads)  # fmt: skip
            grid, grid_stats, grid_codes = comp.integrate_grid_batch("dop853", x0s, cs, times,
                                                                     threads)  # fmt: skip
            for i, (x0, c) in enumerate(zip(x0s, cs, strict=True)):
                one, log, one_stats, code = comp.integrate_events("dop853", x0, c, times)
                assert codes[i] == code and np.array_equal(states[i], one, equal_nan=True)
                assert logs[i].names == log.names and np.array_equal(logs[i].times, log.times)
                assert dict(one_stats) == {k: stats[k][i] for k in one_stats}
                one, one_stats, code = comp.integrate_grid("dop853", x0, c, times)
                assert grid_codes[i] == code and np.array_equal(grid[i], one, equal_nan=True)
                assert dict(one_stats) == {k: grid_stats[k][i] for k in one_stats}
    assert set(codes) == {0, 3} and sum(len(logs[i]) for i in range(7))
    with pytest.raises(ValueError, match=r"the constants c must have shape \(\d+,\) or \(7, "):
        c_build.integrate_events_batch("dop853", x0s, cs[:6], times)
    cs[4, 2] = np.nan
    with pytest.raises(ValueError, match=r"the constants c are not all finite \(row 4\)"):
        c_build.integrate_grid_batch("dop853", x0s, cs, times)


def test_python_threads_cut_the_stretches_of_constants(
    compiled: tuple[list[Compiled], Scene],
) -> None:
    """A build without OpenMP splits a batch over Python threads: slices of
    the states that cut a stretch of equal constants give what one call
    gives, for the grid's and the events' batches."""
    import dataclasses

    class NoOpenMP:
        def __init__(self, lib: object) -> None:
            self.lib = lib

        def gyrogen_threads(self, n: int) -> int:
            return 0  # what the glue says when built without OpenMP

        def __getattr__(self, name: str) -> object:
            return getattr(self.lib, name)

    comp, scene = compiled[0][0], compiled[1]
    threaded = dataclasses.replace(comp, lib=NoOpenMP(comp.lib))
    p = np.array([scene.simulate.parameters[n] for n in scene.runtime])
    cs = np.array([comp.setup(p * (1 + 0.01 * (k // 4))) for k in range(11)])  # stretches of 4
    x0s = scene_view.random_states(scene, np.random.default_rng(8), 11)
    times = np.linspace(0.0, 2.0, 5)
    for name in ("integrate_grid_batch", "integrate_events_batch"):
        one = getattr(comp, name)("dop853", x0s, cs, times, 1)
        split = getattr(threaded, name)("dop853", x0s, cs, times, 3)  # rows 0-2, 3-6, 7-10
        assert np.array_equal(one[0], split[0], equal_nan=True)
        assert all(np.array_equal(a, b) for a, b in zip(one[-2:], split[-2:], strict=True))


def test_zero_at_the_start_and_nan_never_fire(tmp_path: Path) -> None:
    """g = t is 0 at t0 (not a crossing) and positive after; g NaN everywhere
    never crosses: the runs end with code 0 and empty logs."""
    extra = """
[[events]]
name = "start"
expr = "t"

[[events]]
name = "never"
expr = "sqrt(u1 - 1000)"
"""
    scene = _scene("dual_spin", extra)
    write_sources(scene, tmp_path)
    c_build = build.build(tmp_path, "c")
    x0, c = np.array(scene.initial_state()), c_build.setup([])
    _, log, _, code = c_build.integrate_events("taylor", x0, c, np.linspace(0.0, 5.0, 6))
    assert code == 0 and len(log) == 0


def test_integrate_events_refuses_what_it_cannot_do(
    located: tuple[list[Compiled], Scene],
) -> None:
    (c_build, scene) = located[0][0], located[1]
    x0, c = np.array(scene.initial_state()), c_build.setup([])
    with pytest.raises(ValueError, match="capacity must be an integer from 0 to 10"):
        c_build.integrate_events("dop853", x0, c, [0.0, 1.0], capacity=-1)
    with pytest.raises(ValueError, match="fixed-step"):
        c_build.integrate_events("rk4", x0, c, [0.0, 1.0])
    with pytest.raises(ValueError):
        c_build.integrate_events("dop853", x0, c, [1.0, 0.0])
    # an int array took the end state truncated (u1 = 0.002 -> 0), a list or
    # a wrong shape failed only after the run, in numpy's words
    wrong = [(np.zeros(7, dtype=np.int64), "int64 array of shape (7,)"), ([0.0] * 7, "list"),
             (np.zeros((7, 1)), "float64 array of shape (7, 1)")]  # fmt: skip
    for end, got in wrong:
        with pytest.raises(ValueError) as err:
            c_build.integrate_events("dop853", x0, c, [0.0, 1.0], end=end)
        assert str(err.value) == f"end must be a float64 numpy array of shape (7,) (got: {got})"
    with pytest.raises(ValueError, match=r"ends must be a float64 numpy array of shape \(2, 7\)"):
        c_build.integrate_grid_batch("dop853", [x0, x0], c, [0.0, 1.0], ends=np.zeros((2, 7), "i8"))
    with pytest.raises(ValueError, match=r"ends must be a float64 numpy array of shape \(2, 7\)"):
        c_build.integrate_events_batch("dop853", [x0, x0], c, [0, 1], ends=np.zeros((2, 7), "i8"))


def test_simulate_writes_and_prints_the_event_log(tmp_path: Path, cli) -> None:
    """A terminal event ends simulate's run there (the output grid's last
    time is the event's); the summary lists the log and events.csv holds it."""
    scene = tmp_path / "spun.toml"
    scene.write_text(builtin_text("dual_spin").replace('name = "dual_spin"', 'name = "spun"')
                     + LOCATED)  # fmt: skip
    code, out, err = cli(["simulate", str(scene), "--out", str(tmp_path / "sim"), "--no-plot",
                          "--t-end", "200", "--dt", "1", "--method", "dop853"])  # fmt: skip
    assert code == 0, err
    assert "terminal spun at t = 99.95" in out and "ended the run" in out
    rows = (tmp_path / "sim" / "events.csv").read_text().splitlines()
    assert rows[0].startswith("t,event,q1,") and rows[-1].split(",")[1] == "spun"
    t_event = float(rows[-1].split(",")[0])
    assert sum(r.split(",")[1] == "third" for r in rows[1:]) == int(t_event * 3 / np.pi)
    traj = np.load(tmp_path / "sim" / "trajectory.npz")
    assert traj["t"][-1] == t_event


def test_a_sweep_counts_each_event_and_keeps_its_first_time(tmp_path: Path) -> None:
    """run_chunk's event columns: sin(3 t) crosses at k pi/3; the terminal
    event (q3 passing 0.3 rad, near 3 s at u2 = 0.1) ends the count."""
    from gyrogen.analysis.sweep.metrics import column_docs, columns, run_chunk
    from gyrogen.analysis.sweep.spec import parse as parse_sweep
    from gyrogen.runtime.scene_build import compiled, scene_sources

    events = LOCATED.replace('expr = "q3 - 5"', 'expr = "q3 - 0.3"')
    (tmp_path / "ev.toml").write_text(builtin_text("dual_spin") + events)
    grid = "[grid]\nu2 = { list = [0.05, 0.1] }\n"
    text = 'scene = "ev.toml"\nt_end = 4.0\nmethod = "dop853"\n' + grid
    s = parse_sweep(text, "x", "x", tmp_path)
    assert {"first_third", "count_third", "first_spun", "count_spun"} <= set(columns(s))
    assert column_docs(s)["first_spun"][0] == "s"
    cols = run_chunk(compiled(scene_sources(s.scene, False)), s, 0, 2)
    assert list(cols["count_third"]) == [3, 2] and list(cols["count_spun"]) == [0, 1]
    assert list(cols["code"]) == [0, 8]  # the terminal event ends the run: ODE_EVENT
    assert cols["t"][0] == 4.0 and cols["t"][1] == cols["first_spun"][1]
    assert np.allclose(cols["first_third"], np.pi / 3, rtol=1e-14)
    assert np.isnan(cols["first_spun"][0]) and 2.5 < cols["first_spun"][1] < 3.5
    fixed = 'scene = "ev.toml"\nt_end = 4.0\nmethod = "rk4"\nsteps = 100\n' + grid
    rk4 = parse_sweep(fixed, "x", "x", tmp_path)
    assert not any(c.startswith(("first_", "count_")) for c in columns(rk4))


def test_a_sweeps_event_rows_are_its_events_calls(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """run_chunk's events come from one _events_batch call: each row's code,
    time, final state, statistics and event columns are its own _events
    call's, also for the rows whose first log (2 entries here) fills and
    which are run again with EVENT_CAPACITY."""
    from gyrogen.analysis.sweep import metrics
    from gyrogen.analysis.sweep.draws import inputs
    from gyrogen.analysis.sweep.spec import parse as parse_sweep
    from gyrogen.runtime.scene_build import compiled, scene_sources

    events = LOCATED.replace('expr = "q3 - 5"', 'expr = "q3 - 3"')
    (tmp_path / "ev.toml").write_text(builtin_text("dual_spin") + events)
    grid = "[grid]\nu2 = { list = [0.05, 0.3, 0.6, 0.9, 1.5, 3.0] }\n"
    text = 'scene = "ev.toml"\nt_end = 6.0\nmethod = "dop853"\n' + grid
    s = parse_sweep(text, "x", "x", tmp_path)
    comp = compiled(scene_sources(s.scene, False))
    whole = metrics.run_chunk(comp, s, 0, 6)
    monkeypatch.setattr(metrics, "FIRST_CAPACITY", 2)
    cols = metrics.run_chunk(comp, s, 0, 6)
    assert all(np.array_equal(cols[k], whole[k], equal_nan=True) for k in whole)
    inp = inputs(s, 0, 6)
    c, times = comp.setup([]), np.linspace(0.0, 6.0, s.sweep.metrics.points + 1)
    given = {"rtol": s.sweep.rtol, "atol": s.sweep.atol, "max_steps": s.sweep.max_steps}
    for i in range(6):
        states, log, stats, code = comp.integrate_events("dop853", inp.x0[i], c, times,
                                                         capacity=100, **given)  # fmt: skip
        assert cols["code"][i] == code and cols["t"][i] == stats["t"]
        assert cols["rhs_calls"][i] == stats["rhs_calls"]
        finals = [cols[f"final_{n}"][i] for n in s.scene.states]
        assert np.array_equal(finals, log.states[-1] if code == 8 else states[-1])
        for e in ("third", "rising", "spun"):
            at = [t for t, n in zip(log.times, log.names, strict=True) if n == e]
            assert cols[f"count_{e}"][i] == len(at)
            assert np.array_equal(cols[f"first_{e}"][i], at[0] if at else np.nan, equal_nan=True)
    assert set(cols["code"]) == {0, 8} and max(cols["count_third"]) > 2  # a log filled


@pytest.mark.slow  # the sensitivities' unit of a scene of its own: seconds of sympy
def test_the_longest_name_keeps_fortran_within_its_columns() -> None:
    """Every Fortran line of a scene named at the longest a name may be, with
    events (their _events twins and wrappers) and sensitivities (the unit
    <name>_var), fits 132 columns (a drawn scene's 32-letter name once put
    the _grid wrappers' heads past them, the _var unit's use line too)."""
    from gyrogen.abi import NAME_MAX_LENGTH
    from gyrogen.codegen.generate import render_all, unit_of

    name = "a" * NAME_MAX_LENGTH
    text = builtin_text("dual_spin").replace('name = "dual_spin"', f'name = "{name}"')
    sensitivities = '\n[sensitivities]\nwrt = ["state"]\n'  # its unit is <name>_var
    files = render_all(unit_of(parse(text + LOCATED + sensitivities, "long")))
    long = [(f, n) for f, body in files.items() if f.endswith(".f90")
            for n, line in enumerate(body.splitlines(), 1) if len(line) > 132]  # fmt: skip
    assert not long, long[:5]


@pytest.mark.slow  # heyoka's JIT
@pytest.mark.parametrize("method", ADAPTIVE)
def test_the_events_agree_with_heyokas(located: tuple[list[Compiled], Scene], method: str) -> None:
    """heyoka's t_event and nt_event on the same rhs (tol 1e-15) against the
    _events call at 1e-13: every sin(3 t) crossing within 1e-15 relative,
    the terminal crossing of q3 = 5 within 1e-11. heyoka also reports sin(3
    t)'s 0 at t0, which gyrogen does not count (a g of 0 at the start is no
    crossing)."""
    hy = pytest.importorskip("heyoka")
    from gyrogen.analysis.bench import heyoka_peer
    from gyrogen.codegen.generate import unit_of

    (c_build, _), scene = located
    peer = heyoka_peer.system(hy, unit_of(scene))
    x0, c = np.array(scene.initial_state()), c_build.setup([])
    q3 = peer.pairs[2][0]
    seen: list[float] = []
    ta = hy.taylor_adaptive(
        peer.pairs, x0, tol=1e-15, pars=c[: peer.npars],
        t_events=[hy.t_event(q3 - 5.0, direction=hy.event_direction.positive)],
        nt_events=[hy.nt_event(hy.sin(3.0 * hy.time), lambda ta, t, d: seen.append(t))],
    )  # fmt: skip
    ta.propagate_until(200.0)
    _, log, _, code = c_build.integrate_events(method, x0, c, [0.0, 200.0], rtol=1e-13,
                                               atol=1e-13)  # fmt: skip
    assert code == 8 and seen[0] == 0.0
    third = np.array([t for t, n in zip(log.times, log.names, strict=True) if n == "third"])
    assert len(third) == len(seen) - 1
    assert np.max(np.abs(third - np.array(seen[1:])) / third) < 1e-15
    assert abs(log.times[-1] - ta.time) < 1e-11 * ta.time


@pytest.mark.parametrize(
    ("expr", "message"),
    [
        ("u4/0", "is not a finite real number everywhere"),
        ("sqrt(-1) + u4", "is not a finite real number everywhere"),
        ("(-8)**(1/3) - u4", "is not a finite real number everywhere"),
        ("0**(-1)", "is not a finite real number everywhere"),
        ("t**t", "an exponent must be a number, not 't'"),
        ("2**2**2**2**2 - u4", "is outside double range"),
    ],
)
def test_an_event_no_code_can_compute_is_one_line(
    tmp_path: Path, cli, expr: str, message: str
) -> None:
    """Refused at generate in one line (exit 2, or 1 for a constant past
    double range), nothing written; an event that is NaN where the state
    makes it so (sqrt(u1)) is no error: it agrees with the reference."""
    scene = tmp_path / "bad.toml"
    scene.write_text(builtin_text("dual_spin") + f'\n[[events]]\nname = "e"\nexpr = "{expr}"\n')
    code, _, err = cli(["generate", str(scene), "--out", str(tmp_path / "out")])
    assert code in (1, 2) and message in err and err.count("\n") == 1, err
    assert not (tmp_path / "out").exists()


def test_an_event_nan_where_the_state_makes_it_so_generates(tmp_path: Path, cli) -> None:
    """sqrt(u1) is NaN at the drawn states with u1 < 0, in the compiled code
    and in the reference alike: generate's comparison counts that as
    agreement (it once read it as an error of NaN)."""
    scene = tmp_path / "nan.toml"
    scene.write_text(
        builtin_text("dual_spin") + '\n[[events]]\nname = "e"\nexpr = "sqrt(u1) - 0.1"\n'
    )
    code, _, err = cli(["generate", str(scene), "--out", str(tmp_path / "out")])
    assert code == 0, err


@pytest.mark.parametrize(
    ("events", "pieces"),
    [
        ('[[events]]\nname = "spun"\nexpr = "q3 - 5"\n', 1),
        pytest.param(
            '[[events]]\nname = "slow"\nexpr = "u4 - 40"\n[[events]]\nname = "e"\n'
            'expr = "kinetic_energy - 1"\n',
            1,
            marks=pytest.mark.slow,
        ),
        pytest.param(LOCATED, 8, marks=pytest.mark.slow),
        ('[[events]]\nname = "late"\nexpr = "q3 - t"\n', 8),
    ],
)
def test_an_event_that_reads_the_time_is_searched_in_pieces_of_each_step(
    events: str, pieces: int
) -> None:
    """Events on the states alone are searched from the whole step, halved
    as needed; one that reads t, which may change faster than the motion the
    steps follow, in pieces of at most 1/EV_SUBINTERVALS of each step."""
    from gyrogen.codegen.context import make_context
    from gyrogen.codegen.integrators.driver import EV_SUBINTERVALS

    text = builtin_text("dual_spin").replace("kinetic_energy = false", "kinetic_energy = true")
    grid = make_context(parse(text + "\n" + events, "ev.toml")).event_grid
    assert grid is not None and grid.pieces == (EV_SUBINTERVALS if pieces > 1 else 1)


def test_simulate_says_when_the_log_is_full(tmp_path: Path, cli, monkeypatch) -> None:
    """A log full before the run's end (here at 2 events: sin(3 t)'s second
    crossing at pi/3 fills it, and rising at 2 pi/3 has no room) is
    said in the summary and summary.json, never passed off as every event."""
    monkeypatch.setattr(engine, "EVENT_CAPACITY", 2)
    scene = tmp_path / "spun.toml"
    scene.write_text(builtin_text("dual_spin").replace('name = "dual_spin"', 'name = "spun"')
                     + LOCATED)  # fmt: skip
    code, out, err = cli(["simulate", str(scene), "--out", str(tmp_path / "sim"), "--no-plot",
                          "--t-end", "10", "--dt", "1", "--method", "dop853"])  # fmt: skip
    assert code == 0, err
    assert "2 located (events.csv); the log is full (at most 2): none located from t = 2.094" in out
    said = json.loads((tmp_path / "sim" / "summary.json").read_text())["events"]
    assert said["located"] == 2 and said["terminal"] is None
    assert said["log_full_from_t"] == pytest.approx(2 * np.pi / 3, rel=1e-12)
    assert len((tmp_path / "sim" / "events.csv").read_text().splitlines()) == 3


@pytest.mark.parametrize(
    ("expr", "crossing"),
    [
        ("sqrt(2 - t) - 0.5", "t == 1.75"),
        pytest.param("sqrt(5.01 - q3) - 0.05", "q3 == 5.0075", marks=pytest.mark.slow),
    ],
)
def test_a_crossing_before_g_turns_nan_in_the_step_is_located(
    tmp_path: Path, expr: str, crossing: str
) -> None:
    """g crosses 0 and turns NaN a little later, within one step (or one of
    its pieces, for an event that reads t): the crossing is located (it was
    seen only where a step ended between the two), in C and Fortran alike."""
    scene = _scene("dual_spin", f'[[events]]\nname = "gone"\nexpr = "{expr}"\n')
    write_sources(scene, tmp_path)
    builds = [build.build(tmp_path, lang) for lang in ("c", "fortran")]
    x0, c = np.array(scene.initial_state()), builds[0].setup([])
    for method in ADAPTIVE:
        logs = [b.integrate_events(method, x0, c, [0.0, 200.0])[1] for b in builds]
        assert logs[0].names == ["gone"], (method, logs[0].times)
        assert np.array_equal(logs[0].times, logs[1].times)
        if crossing.startswith("t"):
            assert abs(logs[0].times[0] - 1.75) <= 4 * np.spacing(1.75), method
        else:
            assert abs(logs[0].states[0, 2] - 5.0075) < 1e-12, method


@pytest.mark.parametrize(
    ("expr", "crossing"),
    [("sqrt(t - 1.5) - 0.5", "t == 1.75"), ("sqrt(q3 - 5) - 0.05", "q3 == 5.0025")],
)
def test_a_crossing_after_g_turns_finite_in_the_step_is_located(
    tmp_path: Path, expr: str, crossing: str
) -> None:
    """The mirror: g is NaN at a step's (or piece's) start, turns finite and
    crosses 0 within it. The crossing is located, in C and Fortran alike (it
    was missed by every method but one that happened to end a step between
    the two)."""
    scene = _scene("dual_spin", f'[[events]]\nname = "born"\nexpr = "{expr}"\n')
    write_sources(scene, tmp_path)
    builds = [build.build(tmp_path, lang) for lang in ("c", "fortran")]
    x0, c = np.array(scene.initial_state()), builds[0].setup([])
    for method in ADAPTIVE:
        logs = [b.integrate_events(method, x0, c, [0.0, 200.0])[1] for b in builds]
        assert logs[0].names == ["born"], (method, logs[0].times)
        assert np.array_equal(logs[0].times, logs[1].times)
        if crossing.startswith("t"):
            assert abs(logs[0].times[0] - 1.75) <= 4 * np.spacing(1.75), method
        else:
            assert abs(logs[0].states[0, 2] - 5.0025) < 1e-12, method


ON_STATES = """
[[events]]
name = "half"
expr = "q3 - 2"

[[events]]
name = "spun"
expr = "q3 - 5"
direction = "up"
terminal = true
"""


@pytest.mark.parametrize(
    "method, lanes",
    [("dop853", 1), ("dop853", 4), ("dop853", 8), ("radau5", 4), ("taylor", 4), ("rodas4", 4),
     pytest.param("radau5", 1, marks=WIDE), pytest.param("radau5", 8, marks=WIDE),
     pytest.param("taylor", 1, marks=WIDE), pytest.param("taylor", 8, marks=WIDE),
     pytest.param("rodas4", 1, marks=WIDE), pytest.param("rodas4", 8, marks=WIDE)],
)  # fmt: skip
def test_a_batch_over_lanes_is_its_single_calls(tmp_path: Path, method: str, lanes: int) -> None:
    """Events on the states alone (searched at the steps' ends: a lane's
    interpolant only where it needs it) in _events_batch over lanes of
    width 1, 4 and 8, C (the pairs', the Taylor method's, rodas4's and
    radau5's where the scene asks for its lanes):
    each state's rows, log (times, events, states), statistics and code
    are its _events call's bit for bit, with a terminal event on some
    lanes only, lanes that never fire, an event at t0 (q3 = 2 there: no
    crossing), a NaN start and logs that fill."""
    text = builtin_text("dual_spin")
    if method == "radau5":
        text = text.replace("\n[", '\nlanes = ["radau5"]\n\n[', 1)
    scene = parse(text + ON_STATES, "dual_spin+events")
    write_sources(scene, tmp_path)
    assert f"pair_batch({method}_events_step_lanes" in next(tmp_path.glob("*_ode.c")).read_text()
    header = next(tmp_path.glob("*_ode.h"))
    text = header.read_text()
    default = next(line for line in text.splitlines() if line.endswith("_LANES 8"))
    header.write_text(text.replace(default, default.removesuffix("8") + str(lanes)))
    comp = build.build(tmp_path, "c")
    rng = np.random.default_rng(5)
    x0s = np.tile(np.array(scene.initial_state()), (11, 1))
    x0s[:, 4] = rng.uniform(0.0, 3.0, 11)  # u2: q3 reaches 5 rad before t = 4 above ~1.3 rad/s
    x0s[2, 2] = 2.0
    x0s[6, 3] = np.nan
    times = np.linspace(0.0, 4.0, 9)
    c = comp.setup([])
    codes = set()
    for capacity in (8, 1):
        states, logs, stats, code = comp.integrate_events_batch(
            method, x0s, c, times, 1, capacity=capacity, rtol=1e-9, atol=1e-9
        )
        for i, x0 in enumerate(x0s):
            one, log, one_stats, one_code = comp.integrate_events(
                method, x0, c, times, capacity=capacity, rtol=1e-9, atol=1e-9
            )
            assert code[i] == one_code and np.array_equal(states[i], one, equal_nan=True)
            assert dict(one_stats) == {k: stats[k][i] for k in one_stats}
            assert logs[i].names == log.names and np.array_equal(logs[i].times, log.times)
            assert np.array_equal(logs[i].states, log.states)
        codes |= set(code.tolist())
        lengths = [len(logs[i]) for i in range(len(x0s))]
        assert 0 in lengths and max(lengths) > 0
    assert {0, 3, 8, 9} <= codes, codes


SPINNING = """
[[events]]
name = "wheel_turn"
expr = "sin(q4)"
direction = "up"

[[events]]
name = "fast_t"
expr = "sin(3*t)"
"""


@pytest.fixture(scope="module")
def spinning(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Scene]:
    """wheel_spinup with an event on its wheel's angle and one on t: the
    wheel spins up to 80 rad/s in 60 s, turning 382 times, while the
    carrier's slow motion lets the error control take steps of several
    seconds (several periods of sin(3 t) too)."""
    scene = parse(builtin_text("wheel_spinup") + SPINNING, "spinning")
    out = tmp_path_factory.mktemp("spinning")
    write_sources(scene, out)
    return out, scene


def _turns(comp: Compiled, x0: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The times sin(q4) rises through 0 in 0-60 s, from a tight run's grid
    of 1 ms (the wheel turns at most 0.08 rad between its points)."""
    times = np.linspace(0.0, 60.0, 60001)
    states, *_ = comp.integrate_grid("dop853", x0, c, times, rtol=1e-12, atol=1e-12)
    s = np.sin(states[:, 3])
    return times[1:][(s[:-1] < 0) & (s[1:] >= 0)]


@pytest.mark.parametrize("lang", ["c", pytest.param("fortran", marks=pytest.mark.slow)])
@WIDE
def test_an_event_faster_than_the_motion_loses_no_crossing(
    spinning: tuple[Path, Scene], lang: str
) -> None:
    """sin(q4) on a wheel that turns up to 95 times within one step: every
    one of its 382 up-crossings is logged, by every method, each at its
    time. Before pieces were halved by g's rate, the steps' ends alone saw
    9 (dop853) to 102 (rodas4) of them, with code 0."""
    out, scene = spinning
    comp = build.build(out, lang)
    x0, c = np.array(scene.initial_state()), comp.setup([0.02])
    want = _turns(comp, x0, c)
    assert len(want) == 382
    for method in ADAPTIVE:
        _, log, _, code = comp.integrate_events(method, x0, c, [0.0, 60.0], rtol=1e-8,
                                                atol=1e-8, capacity=1000)  # fmt: skip
        turn = np.array(log.names) == "wheel_turn"  # wheel_spinup's own is at 30 s
        assert code == 0 and np.sum(turn) == len(want), (method, np.sum(turn))
        assert np.max(np.abs(log.times[turn] - want)) < 1e-3, method  # within a grid step
        assert np.max(np.abs(np.sin(log.states[turn, 3]))) < 1e-9, method
        third = log.times[np.array(log.names) == "fast_t"]  # k pi / 3, 57 of them
        assert np.array_equal(np.round(third * 3 / np.pi), np.arange(1, 58)), method
        assert np.max(np.abs(third - np.arange(1, 58) * np.pi / 3)) < 1e-9, method


@pytest.mark.slow  # the lanes' batch beside the single calls
def test_an_event_faster_than_the_motion_is_found_over_lanes_as_alone(
    spinning: tuple[Path, Scene],
) -> None:
    """The batch over SIMD lanes logs what the single calls log, bit for
    bit, for torques that spin the wheel at different rates."""
    out, scene = spinning
    comp = build.build(out, "c")
    x0 = np.array(scene.initial_state())
    for method in ("dopri5", "dop853", "taylor", "rodas4"):
        for torque in (0.02, 0.013):
            c = comp.setup([torque])
            batch = comp.integrate_events_batch(method, np.tile(x0, (5, 1)), c,
                                                np.array([0.0, 60.0]), rtol=1e-8, atol=1e-8,
                                                capacity=1000)  # fmt: skip
            _, log, _, code = comp.integrate_events(method, x0, c, [0.0, 60.0], rtol=1e-8,
                                                    atol=1e-8, capacity=1000)  # fmt: skip
            turns = np.sum(np.array(log.names) == "wheel_turn")
            assert code == 0 and turns == len(_turns(comp, x0, c)), (method, torque, turns)
            log_b = batch[1]
            for i in range(5):
                n = int(log_b.counts[i])
                assert np.array_equal(log_b.times[i, :n], log.times), (method, torque, i)


HANG = """
import sys
import numpy as np
from pathlib import Path
from gyrogen.runtime import build
comp = build.build(Path(sys.argv[1]), sys.argv[2])
x0 = np.zeros(8)
x0[4] = 0.01
for method in ("dopri5", "dop853", "rodas4", "radau5", "taylor"):
    t0 = float(sys.argv[3])
    code = comp.integrate_events(method, x0, comp.setup([0.02]), [t0, t0 + 10.0], rtol=1e-8,
                                 atol=1e-8)[3]
    print(method, code)
"""


@pytest.mark.parametrize("lang", ["c", pytest.param("fortran", marks=pytest.mark.slow)])
def test_an_event_at_a_time_t_cannot_resolve_ends(
    spinning: tuple[Path, Scene], cache_dir: Path, lang: str
) -> None:
    """At t = 1e12 sin(3 t) changes in steps of t's rounding (1.2e-4 s), so
    pieces are never resolved; halving one until half of it is lost in t's
    rounding made dop853's search loop for ever. Every method now ends the
    run (code 0, or 1: the step lost in t), in a child with a deadline."""
    out, _ = spinning
    env = {**os.environ, "GYROGEN_CACHE": str(cache_dir)}
    run = subprocess.run([sys.executable, "-c", HANG, str(out), lang, "1e12"], env=env,
                         capture_output=True, text=True, timeout=300)  # fmt: skip
    assert run.returncode == 0, run.stderr
    codes = dict(line.split() for line in run.stdout.splitlines())
    assert len(codes) == 5 and set(codes.values()) <= {"0", "1"}, codes
