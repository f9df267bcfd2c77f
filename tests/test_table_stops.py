"""No adaptive step crosses a torque table's time: a pulse narrower than the
steps the smooth motion allows (0.2 ms among steps of seconds) gives the
wheel its whole impulse in every adaptive method, C and Fortran, single and
batch (the lanes), end point, grid, events and the variational system.
Without the stops each method stepped over the pulse with code 0, u4 = 0."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from wide import WIDE

from gyrogen.runtime.compiled import Compiled
from gyrogen.runtime.scene_build import build_scene
from gyrogen.scene import Scene, parse

pytestmark = pytest.mark.slow

WIDTH, HEIGHT, J = 2e-4, 5.0, 0.015
START = 3.3333
TEXT = f"""
name = "pulse"
description = "a wheel kicked by a 0.2 ms triangular torque pulse"
integrators = ["dopri5", "dop853", "rodas4", "radau5"]

[parameters]
m_a = 150.0
m_b = 3.0
I11 = 20.0
I22 = 25.0
I33 = 18.0
I13 = 0.5
I = 0.01
J = {J}
l1 = 0.3
l3 = 0.1

[effects]
translation = false
rotor_angle = false
torque = "table"
torque_table = [[0.0, 0.0], [{START}, 0.0], [{START + WIDTH / 2}, {HEIGHT}],
                [{START + WIDTH}, 0.0], [10.0, 0.0]]

[sensitivities]
wrt = ["state"]

[[events]]
name = "kicked"
expr = "u4 - 0.02"
direction = "up"

[simulate]
t_end = 10.0
initial = {{ u1 = 0.01, u2 = 0.0, u3 = 0.0, u4 = 0.0 }}
"""
KICK = HEIGHT * WIDTH / 2 / J
"""The wheel's rate after the pulse, relative to the carrier: its impulse over J."""
METHODS = ("dopri5", "dop853", "rodas4", "radau5")
TOL = {"rtol": 1e-9, "atol": 1e-9}


@pytest.fixture(scope="module")
def pulse(tmp_path_factory: pytest.TempPathFactory) -> tuple[Scene, dict[str, Compiled]]:
    scene = parse(TEXT, "pulse")
    comps = build_scene(scene, Path(tmp_path_factory.mktemp("pulse")), ["c", "fortran"])
    return scene, dict(comps)


def start(scene: Scene, comp: Compiled) -> tuple[np.ndarray, np.ndarray]:
    return np.array(scene.initial_state()), comp.setup(np.zeros(comp.n_params))


def u4(scene: Scene) -> int:
    return scene.states.index("u4")


@pytest.mark.parametrize("language", ["c", "fortran"])
@pytest.mark.parametrize("method", METHODS)
@WIDE
def test_the_pulse_is_felt_over_the_whole_span(
    pulse: tuple[Scene, dict[str, Compiled]], method: str, language: str
) -> None:
    scene, comps = pulse
    comp = comps[language]
    x0, c = start(scene, comp)
    x, stats, code = comp.integrate(method, x0, c, 0.0, 10.0, **TOL)
    assert code == 0
    assert stats["t"] == 10.0
    assert x[u4(scene)] == pytest.approx(KICK, rel=1e-7)


@pytest.mark.parametrize("method", METHODS)
def test_grid_events_and_var_stop_at_the_table_times(
    pulse: tuple[Scene, dict[str, Compiled]], method: str
) -> None:
    """The grid's rows after the pulse, the event inside it, and Phi's run."""
    scene, comps = pulse
    comp, k = comps["c"], u4(scene)
    x0, c = start(scene, comp)
    times = np.linspace(0.0, 10.0, 11)
    out, _, code = comp.integrate_grid(method, x0, c, times, **TOL)
    assert code == 0
    assert out[times < START, k] == pytest.approx(0.0, abs=1e-12)
    assert out[times > START + WIDTH, k] == pytest.approx(KICK, rel=1e-7)
    _, log, _, code = comp.integrate_events(method, x0, c, times, **TOL)
    assert code == 0
    assert log.names == ["kicked"]
    assert START < log.times[0] < START + WIDTH
    x, phi, _, code = comp.integrate_var(method, x0, c, 0.0, 10.0, **TOL)
    assert code == 0
    assert x[k] == pytest.approx(KICK, rel=1e-7)
    assert np.all(np.isfinite(phi))


@pytest.mark.parametrize("method", ["dopri5", "dop853", "rodas4"])
def test_the_lanes_stop_where_the_single_calls_do(
    pulse: tuple[Scene, dict[str, Compiled]], method: str
) -> None:
    """A batch of starts (SIMD lanes) equals the single calls bit for bit,
    each lane stopping at the table times from its own t."""
    scene, comps = pulse
    comp, k = comps["c"], u4(scene)
    x0, c = start(scene, comp)
    x0s = np.array([x0 * (1.0 + 0.1 * j) for j in range(5)])
    xs, _, codes = comp.integrate_batch(method, x0s, c, 0.0, 10.0, **TOL)
    assert list(codes) == [0] * 5
    for j, x in enumerate(x0s):
        single, _, _ = comp.integrate(method, x, c, 0.0, 10.0, **TOL)
        assert np.array_equal(xs[j], single)
    assert xs[:, k] == pytest.approx(KICK, rel=1e-7)
    times = np.linspace(0.0, 10.0, 11)
    outs, _, codes = comp.integrate_grid_batch(method, x0s, c, times, **TOL)
    assert list(codes) == [0] * 5
    for j, x in enumerate(x0s):
        single_out, _, _ = comp.integrate_grid(method, x, c, times, **TOL)
        assert np.array_equal(outs[j], single_out)


@pytest.mark.parametrize("mode", ["ModelExchange", "CoSimulation"])
def test_the_fmu_stops_at_the_table_times(tmp_path: Path, mode: str) -> None:
    """Model Exchange announces each table time as a time event (FMPy's
    CVODE stopped nowhere near the pulse, u4 = 0, before); Co-Simulation's
    doStep integrates with the scene's code."""
    import fmpy  # the FMU tests' extra
    from fmu_cases import build_model

    scene = parse(TEXT, "pulse")
    fmu = build_model(scene, "dop853", tmp_path / "fmu")
    out = fmpy.simulate_fmu(str(fmu), fmi_type=mode, stop_time=10.0, output_interval=1.0)
    assert out["u4"][-1] == pytest.approx(KICK, rel=1e-6)
