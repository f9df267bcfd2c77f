"""gyrogen linearize --along: the state transition matrix on the output grid,
from one integration of the scene's variational system."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gyrogen.analysis.linearize.along import with_sensitivities
from gyrogen.runtime.scene_build import compiled, scene_sources
from gyrogen.scene import load


@pytest.fixture(scope="module")
def along(tmp_path_factory: pytest.TempPathFactory, cli) -> dict[str, np.ndarray]:
    out = tmp_path_factory.mktemp("along")
    code, stdout, err = cli(["linearize", "gyrostat", "--along", "--t-end", "2", "--dt", "0.5",
                             "--plot", "--out", str(out)])  # fmt: skip
    assert code == 0, err
    assert "dx/dx0: largest singular value" in stdout and "along.png" in stdout
    assert (out / "along.png").stat().st_size > 1000
    with np.load(out / "along.npz") as f:
        return dict(f)


@pytest.mark.slow  # a build of the variational system
def test_phi_on_the_grid_is_the_flows_derivative(along: dict[str, np.ndarray]) -> None:
    """Phi(0) = I; the last row is integrate_var's end point bit for bit (the
    grid's last row is the plain call's); a row between is the central
    difference of the compiled flow to 1e-6."""
    t, x, phi = along["t"], along["x"], along["Phi"]
    scene = load("gyrostat")
    nx = len(scene.states)
    assert list(t) == [0.0, 0.5, 1.0, 1.5, 2.0] and phi.shape == (5, nx, nx)
    assert np.array_equal(phi[0], np.eye(nx))
    comp = compiled(scene_sources(with_sensitivities(scene, "dop853")))
    c = comp.setup(np.array([scene.simulate.parameters[n] for n in scene.runtime]))
    x_end, phi_end, _, code = comp.integrate_var("dop853", x[0], c, 0.0, 2.0, rtol=1e-10,
                                                 atol=1e-10)  # fmt: skip
    assert code == 0 and np.array_equal(phi_end, phi[-1]) and np.array_equal(x_end, x[-1])
    h = 1e-6
    for j in (scene.states.index(n) for n in ("q1", "u1", "u4")):
        ends = []
        for sign in (1, -1):
            x0 = x[0].copy()
            x0[j] += sign * h
            ends.append(comp.integrate("dop853", x0, c, 0.0, 1.0, rtol=1e-13, atol=1e-13)[0])
        column = (ends[0] - ends[1]) / (2 * h)
        assert np.allclose(phi[2][:, j], column, rtol=1e-6, atol=1e-6), j


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--along", "--spin", "1"], "--spin and --axis find an equilibrium: not with --along"),
        (["--t-end", "3"], "--t-end is for --along"),
        (["--along", "--method", "rk4"], "rk4 has no output grid"),
        (["--along", "--dt", "20"], "dt"),
    ],
)
def test_along_misuse_is_one_line(tmp_path: Path, cli, argv: list[str], message: str) -> None:
    code, _, err = cli(["linearize", "gyrostat", *argv, "--out", str(tmp_path / "o")])
    assert code == 2 and message in err and len(err.strip().splitlines()) <= 3, err
    assert not (tmp_path / "o").exists()
