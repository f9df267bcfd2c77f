"""The embedding examples (examples/) build with their own Makefile through
the generated library's CMake package, and print what the Python path
computes: the same RK4 run with the numpy reference as the right-hand side."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from wide import WIDE

from gyrogen import abi
from gyrogen.oracle import reference, scene_view
from gyrogen.scene import load

pytestmark = pytest.mark.slow  # the embedding examples built with CMake and run

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"

# The run the examples document: parameters in abi.PARAMETERS order, the
# initial state (everything else zero), and the fixed RK4 step.
PARAMS = np.array([500.0, 10.0, 100.0, 80.0, 120.0, 5.0, 0.05, 0.1, 0.2, -0.1, 0.0, 0.01])
INITIAL = {"u1": 0.01, "u2": 0.5, "u3": -0.02, "u4": 100.0}
DT, STEPS = 1e-3, 10_000
H_NAMES = ("H_n1", "H_n2", "H_n3")


def initial_state() -> np.ndarray:
    x = np.zeros(len(abi.STATES))
    for name, value in INITIAL.items():
        x[abi.STATES.index(name)] = value
    return x


def rk4(x: np.ndarray, p: np.ndarray, dt: float, steps: int) -> np.ndarray:
    """The examples' integrator, step for step, on the reference RHS."""
    for _ in range(steps):
        k1 = reference.rhs(x, p)
        k2 = reference.rhs(x + 0.5 * dt * k1, p)
        k3 = reference.rhs(x + 0.5 * dt * k2, p)
        k4 = reference.rhs(x + dt * k3, p)
        x = x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return x


def parse(stdout: str) -> dict[str, float]:
    """'name value' lines, in order (dicts keep it)."""
    pairs = [line.split() for line in stdout.splitlines()]
    assert all(len(pair) == 2 for pair in pairs), stdout
    return {name: float(value) for name, value in pairs}


def run(program: Path) -> dict[str, float]:
    proc = subprocess.run([str(program)], capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    return parse(proc.stdout)


@pytest.fixture
def programs(examples_build: Path) -> Path:
    """examples/Makefile's `all` (conftest.examples_build), outside the tree."""
    return examples_build


@pytest.fixture(scope="module")
def python_final() -> np.ndarray:
    return rk4(initial_state(), PARAMS, DT, STEPS)


@pytest.mark.parametrize("program", ["embed_c", "embed_fortran"])
@WIDE
def test_final_state_matches_python(programs: Path, python_final: np.ndarray, program: str) -> None:
    out = run(programs / program)
    assert list(out) == [*abi.STATES, *H_NAMES, "H_norm"]
    x = np.array([out[name] for name in abi.STATES])
    np.testing.assert_allclose(x, python_final, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("program", ["embed_c", "embed_fortran"])
def test_angular_momentum(programs: Path, python_final: np.ndarray, program: str) -> None:
    """The printed H is NOTES.md's, at the final state, and (T internal, g = 0)
    the one the run started with."""
    out = run(programs / program)
    h = np.array([out[name] for name in H_NAMES])
    np.testing.assert_allclose(h, reference.angular_momentum_n(python_final, PARAMS), rtol=1e-9)
    h0 = reference.angular_momentum_n(initial_state(), PARAMS)
    assert np.linalg.norm(h - h0) <= 1e-9 * np.linalg.norm(h0)
    assert out["H_norm"] == pytest.approx(np.linalg.norm(h), rel=1e-15)


def test_c_and_fortran_agree(programs: Path) -> None:
    c, f = run(programs / "embed_c"), run(programs / "embed_fortran")
    assert list(c) == list(f)
    np.testing.assert_allclose(list(f.values()), list(c.values()), rtol=1e-12, atol=1e-15)


def test_cpp_prints_the_reference_rhs(programs: Path) -> None:
    out = run(programs / "embed_cpp")
    assert list(out) == [f"d{name}" for name in abi.STATES]
    expected = reference.rhs(initial_state(), PARAMS)
    np.testing.assert_allclose(list(out.values()), expected, rtol=1e-12, atol=1e-15)


def test_make_run_prints_each_program(source_dir: Path, programs: Path) -> None:
    """`make -C examples run` (what `make examples` calls) builds and runs all
    four (in the build directory `programs` made, so nothing is rebuilt)."""
    proc = subprocess.run(
        ["make", "-s", "-C", str(EXAMPLES), f"BUILD={programs}", f"GEN={source_dir}", "run"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    headers = [line for line in proc.stdout.splitlines() if line.startswith("== ")]
    names = [Path(h[3:]).name for h in headers]
    assert names == ["embed_c", "embed_fortran", "embed_cpp", "embed_cluster", "steer_cmg"]


def test_programs_come_from_the_installed_package(programs: Path) -> None:
    """The examples link the library CMake installed, found by find_package."""
    cache = (programs / "app" / "CMakeCache.txt").read_text()
    assert f"gyrostat_DIR:PATH={programs}/prefix/lib/cmake/gyrostat" in cache
    assert (programs / "prefix" / "include" / "gyrostat" / "gyrostat_mod.mod").is_file()
    assert f"rw4_pyramid_DIR:PATH={programs}/prefix/lib/cmake/rw4_pyramid" in cache
    assert f"cmg4_pyramid_DIR:PATH={programs}/prefix/lib/cmake/cmg4_pyramid" in cache


def test_cmg_steering_converges_and_its_damping_rises_near_the_singular_set(
    programs: Path,
) -> None:
    """steer_cmg: the pyramid slewed 12 deg by the singularity-robust law,
    from gimbal angles near the singular set: the pointing error falls by
    three orders of magnitude in 60 s; lambda = 0.01 exp(-10 det) peaks where
    det(A A^T) is least, which stays above 0 (the law never meets the
    singularity), and the gimbals end far from it."""
    proc = subprocess.run([str(programs / "steer_cmg")], capture_output=True, text=True,
                          check=False)  # fmt: skip
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    lines = proc.stdout.splitlines()
    table = [line.split() for line in lines[1:] if len(line.split()) == 8]
    rows = np.array([[float(v) for v in row] for row in table])
    out = parse("\n".join(line for line in lines if len(line.split()) == 2))
    assert rows[0, 0] == 0.0 and rows[-1, 0] == 60.0 and rows[0, 1] > 10.0
    assert out["final_error_deg"] == pytest.approx(rows[-1, 1], rel=1e-3)
    assert out["final_error_deg"] < 1e-3 * rows[0, 1]
    assert 0.0 < out["min_det"] < 0.01 < 0.1 < out["final_det"]
    assert out["max_lambda"] == pytest.approx(0.01 * np.exp(-10.0 * out["min_det"]), rel=1e-5)
    assert np.all(np.abs(rows[:, 3] - 0.01 * np.exp(-10.0 * rows[:, 2])) <= 1e-3 * rows[:, 3])


CLUSTER = "rw4_pyramid"
CLUSTER_P = np.array([100.0, -50.0, 80.0, 30.0])
CLUSTER_X0 = np.array([0.0, 0.0, 0.0, 0.01, 0.02, -0.01, 90.0, -40.0, 60.0, 30.0])


@WIDE
def test_cluster_example_matches_python(programs: Path) -> None:
    """embed_cluster: the same RK4 run on the cluster's numpy reference; H
    about the mass center held (the clamped motors are internal torques);
    each motor's power as the reference has it."""
    scene = load(CLUSTER)
    out = run(programs / "embed_cluster")
    assert list(out) == [*scene.states, *H_NAMES, "H_norm", "H_drift", "P1", "P2", "P3", "P4"]
    x = CLUSTER_X0
    for _ in range(STEPS):  # the example's RK4, step for step, on the reference
        k1 = scene_view.rhs(scene, x, CLUSTER_P)[0]
        k2 = scene_view.rhs(scene, x + 0.5 * DT * k1, CLUSTER_P)[0]
        k3 = scene_view.rhs(scene, x + 0.5 * DT * k2, CLUSTER_P)[0]
        k4 = scene_view.rhs(scene, x + DT * k3, CLUSTER_P)[0]
        x = x + DT / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    got = np.array([out[name] for name in scene.states])
    np.testing.assert_allclose(got, x, rtol=1e-9, atol=1e-12)
    assert out["H_drift"] <= 1e-12 * out["H_norm"]
    power = scene_view.output(scene, "power", x[None, :], CLUSTER_P)[0]
    np.testing.assert_allclose([out[f"P{k}"] for k in (1, 2, 3, 4)], power, rtol=1e-9, atol=1e-12)


@WIDE
def test_cluster_example_links_the_lib_package(programs: Path, tmp_path: Path, cli) -> None:
    """`gyrogen generate rw4_pyramid --lib`: a parent CMake project adds the
    package and links embed_cluster against it, built static and shared
    (BUILD_SHARED_LIBS); both print what the installed-package program prints."""
    parent = tmp_path / "parent"
    code, _, err = cli(["generate", CLUSTER, "--lib", "--out", str(parent / CLUSTER)])
    assert code == 0, err
    shutil.copy(EXAMPLES / "embed_cluster" / "main.c", parent / "app.c")
    (parent / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.15)\n"
        "project(app LANGUAGES C)\n"
        f"add_subdirectory({CLUSTER})\n"
        "add_executable(app app.c)\n"
        f"target_link_libraries(app PRIVATE {CLUSTER}::{CLUSTER} m)\n"
    )
    made = run(programs / "embed_cluster")
    for shared in ("OFF", "ON"):
        build = tmp_path / f"build-{shared}"
        for cmd in (
            ["cmake", "-S", str(parent), "-B", str(build), f"-DBUILD_SHARED_LIBS={shared}"],
            ["cmake", "--build", str(build)],
        ):
            proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
            assert proc.returncode == 0, proc.stdout + proc.stderr
        linked = run(build / "app")
        assert list(linked) == list(made)
        np.testing.assert_allclose(list(linked.values()), list(made.values()), rtol=1e-12)
