"""Torque tables per wheel in reaction-wheel clusters: rotor k's
torque = "table" with its torque_table gives <prefix>_torque_k(t) in C and
Fortran, read by the rhs, the outputs, the Jacobian and the linear model;
the Newton-Euler reference interpolates the same points."""

from __future__ import annotations

import numpy as np
import pytest
from wide import WIDE

from gyrogen.analysis.linearize import engine
from gyrogen.oracle import cluster_reference, scene_view
from gyrogen.oracle.compare import compare
from gyrogen.runtime.compiled import Compiled, Language
from gyrogen.runtime.scene_build import build_scene
from gyrogen.scene import Scene, parse

TABLES = [[0.0, 0.0], [1.0, 0.05], [5.0, 0.05], [6.0, -0.02]], [[0.5, -0.01], [2.0, 0.02]]
TEXT = f"""
name = "rw3_tables"
description = "three wheels: two driven by torque tables, one by a runtime torque"
attitude = "quaternion"
integrators = ["dop853", "radau5"]

[parameters]
m_a = 500.0
I11 = 300.0
I22 = 350.0
I33 = 250.0
I12 = 2.0

[effects]
rotor_angle = true

[outputs]
kinetic_energy = true
angular_momentum = true
power = true

[[rotors]]
m = 4.0
I = 0.02
J = 0.035
axis = [1.0, 0.0, 0.0]
torque = "table"
torque_table = {TABLES[0]}
tau_max = 0.03

[[rotors]]
m = 4.0
I = 0.02
J = 0.035
axis = [0.0, 0.6, 0.8]
position = [0.0, 0.2, 0.0]
b = 1e-4
torque = "table"
torque_table = {TABLES[1]}

[[rotors]]
m = 4.0
I = 0.02
J = 0.035
axis = [0.0, 0.0, 1.0]
torque = "constant"
T = "runtime"

[simulate]
t_end = 8.0
initial = {{ u1 = 0.01, w3 = 10.0 }}
parameters = {{ T_3 = 0.01 }}
"""
TIMES = (-1.0, 0.0, 0.25, 0.5, 0.6, 1.0, 1.7, 2.0, 3.0, 5.5, 6.0, 10.0)


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> tuple[Scene, dict[Language, Compiled]]:
    scene = parse(TEXT, "rw3_tables.toml")
    backends = build_scene(scene, tmp_path_factory.mktemp("tables"), ["c", "fortran"])
    return scene, backends


@pytest.mark.slow
@WIDE
def test_c_and_fortran_match_the_reference_across_the_tables(built) -> None:
    """rhs, outputs and Jacobian at random states, parameters and times
    spanning every table and beyond both ends (oracle.compare)."""
    scene, backends = built
    report = compare(list(backends.values()), scene, n_states=2000, n_params=20, n_ill=0)
    assert report.passed, [r for r in report.rows if not r.passed]
    assert {r.pair for r in report.rows} >= {"C vs Fortran", "C vs reference jac"}


@pytest.mark.slow
@pytest.mark.parametrize("language", ["c", "fortran"])
def test_each_wheel_reads_its_own_table(language: Language, built) -> None:
    """With the carrier and the wheels at rest relative to it, J_k w_k' is
    wheel k's motor torque: its table interpolated at t (held outside it),
    wheel 1's clamped to tau_max = 0.03; both equal the reference's."""
    scene, backends = built
    comp = backends[language]
    p = np.array([0.01])
    c = comp.setup(p)
    x = np.array(scene.initial_state())
    x[scene.states.index("u1")] = 0.0
    w = [scene.states.index(f"w{k}") for k in (1, 2, 3)]
    x[w] = 0.0
    for t in TIMES:
        rate = comp.rhs(x, c, t)
        want = [np.clip(np.interp(t, *np.array(TABLES[0]).T), -0.03, 0.03),
                np.interp(t, *np.array(TABLES[1]).T), 0.01]  # fmt: skip
        assert np.allclose(rate[w] * 0.035, want, rtol=1e-15, atol=1e-18), t
        ref = scene_view.rhs(scene, x, p, t)[0]
        assert np.allclose(rate, ref, rtol=1e-14, atol=1e-17), t


def test_the_reference_interpolates_per_state_times() -> None:
    """cluster_reference takes one time per state (the energy balance's
    quadrature nodes): each state's torque is its own time's."""
    scene = parse(TEXT, "rw3_tables.toml")
    ts = np.array(TIMES)
    xs = np.zeros((ts.size, len(scene.states)))
    xs[:, 0] = 1.0
    torques = cluster_reference.motor_torques(scene, {"T_3": 0.01}, np.zeros((ts.size, 3)), ts)
    assert np.array_equal(torques[:, 1], np.interp(ts, *np.array(TABLES[1]).T))
    assert np.array_equal(
        torques[:, 0], np.clip(np.interp(ts, *np.array(TABLES[0]).T), -0.03, 0.03)
    )


@pytest.mark.slow
@WIDE
def test_a_table_wheel_is_an_input_of_the_linear_model(built) -> None:
    """The linear model adds T_k to a table wheel's motor: B over w_k is
    1/J_k for the wheels whose clamp does not hold at the point."""
    scene, _ = built
    lin = engine.model(scene, spin=0.0)
    assert lin.inputs == ("T_1", "T_2", "T_3")
    w = [lin.states.index(f"w{k}") for k in (1, 2, 3)]
    assert np.allclose(np.diag(lin.B[w]), 1 / 0.035, rtol=1e-14)
