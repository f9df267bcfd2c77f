"""gyrogen simulate: the trajectory files agree, match the closed form and the
invariants of NOTES.md; the figure is a real image; every error is one line."""

from __future__ import annotations

import io
import json
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from ctrl_c import interrupted
from matplotlib.image import imread
from wide import WIDE

from gyrogen.analysis.simulate import plots, trajectory
from gyrogen.analysis.simulate.engine import check_solution
from gyrogen.analysis.simulate.files import COLUMNS
from gyrogen.analysis.simulate.result import Settings
from gyrogen.analysis.simulate.trajectory import Trajectory, output_grid, running_integrals
from gyrogen.errors import GyrogenError
from gyrogen.oracle import reference, scene_view
from gyrogen.scene import builtin_names, builtin_text, load


@dataclass(frozen=True)
class Run:
    code: int
    out: str
    err: str
    dir: Path


def simulate(cli: Callable[[list[str]], tuple[int, str, str]], argv: list[str], out: Path) -> Run:
    """gyrogen simulate ARGV --out OUT."""
    return Run(*cli(["simulate", *argv, "--out", str(out)]), out)


def torque_free_with(path: Path, old: str, new: str) -> str:
    """The built-in torque_free with old replaced by new, written to path."""
    text = builtin_text("torque_free")
    assert old in text, old
    path.write_text(text.replace(old, new))
    return str(path)


@pytest.fixture(scope="module")
def cache(cache_dir: Path) -> Iterator[None]:
    mp = pytest.MonkeyPatch()
    mp.setenv("GYROGEN_CACHE", str(cache_dir))
    yield
    mp.undo()


@pytest.fixture(scope="module")
def torque_free(tmp_path_factory: pytest.TempPathFactory, cache: None, cli) -> Run:
    out = tmp_path_factory.mktemp("sim") / "torque_free"
    run = simulate(cli, ["torque_free", "--t-end", "2", "--dt", "0.01"], out)
    assert run.code == 0, run.err
    return run


@pytest.fixture(scope="module")
def spinup(tmp_path_factory: pytest.TempPathFactory, cache: None, cli) -> Run:
    out = tmp_path_factory.mktemp("sim") / "wheel_spinup"
    run = simulate(cli, ["wheel_spinup", "--t-end", "5", "--dt", "0.05", "--no-plot"], out)
    assert run.code == 0, run.err
    return run


def _load(run: Run) -> tuple[np.lib.npyio.NpzFile, dict, list[str], np.ndarray]:
    npz = np.load(run.dir / "trajectory.npz")
    summary = json.loads((run.dir / "summary.json").read_text())
    text = (run.dir / "trajectory.csv").read_text()
    header = text.splitlines()[0].split(",")
    return npz, summary, header, np.loadtxt(io.StringIO(text), delimiter=",", skiprows=1)


@pytest.mark.slow
def test_files_exist_and_agree(torque_free: Run) -> None:
    npz, summary, header, csv = _load(torque_free)
    scene = load("torque_free")
    assert header == ["t", *scene.states, *COLUMNS]
    assert list(npz["names"]) == list(scene.states)
    assert npz["t"].shape == (201,) and npz["x"].shape == (201, len(scene.states))
    np.testing.assert_array_equal(csv[:, 0], npz["t"])  # %.17g: the same doubles
    np.testing.assert_array_equal(csv[:, 1 : 1 + len(scene.states)], npz["x"])
    invariants = np.column_stack([npz[name] for name in COLUMNS])  # same names in both
    np.testing.assert_array_equal(csv[:, -len(COLUMNS) :], invariants)
    manifest = json.loads((torque_free.dir / "src" / "manifest.json").read_text())
    assert summary["scene"] == "torque_free" and summary["build_id"] == manifest["build_id"]
    assert (summary["method"], summary["backend"]) == ("taylor", "c")  # auto: compiled, smooth
    assert (summary["rtol"], summary["atol"]) == (scene.simulate.rtol, scene.simulate.atol)
    assert summary["nfev"] > 0 and summary["wall_time_s"] > 0 and summary["t_end"] == 2.0
    worst = summary["invariants"]
    assert worst["H_norm_relative_drift"] == np.max(np.abs(npz["H_drift"]))
    assert worst["energy_balance_relative_residual"] == np.max(np.abs(npz["energy_residual"]))
    assert "Gauss-Legendre" in summary["quadrature"]
    files = ["trajectory.csv", "trajectory.npz", "summary.json", "trajectory.png"]
    assert summary["files"] == files
    assert not list(torque_free.dir.glob(".*"))  # no temporary file left behind


@pytest.mark.slow
def test_printed_summary(torque_free: Run) -> None:
    lines = torque_free.out.splitlines()
    assert lines[0].startswith("torque_free: taylor (rtol 1e-10, atol 1e-10)")
    assert "final time      2 s (201 points" in torque_free.out
    for word in ("nfev", "wall time", "|H| in N", "energy balance", "u4 check"):
        assert word in torque_free.out
    assert lines[-1].startswith(f"wrote {torque_free.dir}/ (trajectory.csv, trajectory.npz")


@pytest.mark.slow
def test_closed_form_of_the_axisymmetric_gyrostat(torque_free: Run) -> None:
    """NOTES.md: u2, u4 constant; (u1, u3) rotate at lambda = ((I~22 - I_t) u2 + J u4)/I_t,
    I_t = I11 + I here (l1 = l3 = 0, I13 = 0, I11 = I33)."""
    npz = np.load(torque_free.dir / "trajectory.npz")
    scene = load("torque_free")
    v, s0 = scene.folded(), scene.simulate.initial
    i_t = v["I11"] + v["I"]
    lam = ((v["I22"] - i_t) * s0["u2"] + v["J"] * s0["u4"]) / i_t
    t, x = npz["t"], npz["x"]
    u = {n: x[:, scene.states.index(n)] for n in ("u1", "u2", "u3", "u4")}
    c, s = np.cos(lam * t), np.sin(lam * t)
    np.testing.assert_allclose(u["u1"], s0["u1"] * c + s0["u3"] * s, rtol=0, atol=1e-8)
    np.testing.assert_allclose(u["u3"], s0["u3"] * c - s0["u1"] * s, rtol=0, atol=1e-8)
    np.testing.assert_allclose(u["u2"], s0["u2"], rtol=1e-8)
    np.testing.assert_allclose(u["u4"], s0["u4"], rtol=1e-8)


@pytest.mark.slow
def test_angular_momentum_is_conserved(torque_free: Run) -> None:
    npz = np.load(torque_free.dir / "trajectory.npz")
    scene = load("torque_free")
    full = scene_view.full_states(scene, npz["x"])
    h = reference.angular_momentum_n(full, scene_view.full_parameters(scene, np.zeros(0), full, 0))
    np.testing.assert_allclose(npz["H"], h, rtol=1e-14, atol=1e-14)
    norm = np.linalg.norm(h, axis=1)
    assert np.max(np.abs(norm / norm[0] - 1)) < 1e-9
    assert np.max(np.abs(npz["H_drift"])) < 1e-9


@pytest.mark.slow
def test_figure_is_a_real_image_of_the_expected_size(torque_free: Run) -> None:
    image = imread(torque_free.dir / "trajectory.png")
    assert image.shape[:2] == plots.PIXELS == (800, 1200)
    assert image[..., :3].std() > 0.05  # not blank


@pytest.mark.slow
def test_wheel_spinup_rotor_rate_and_energy_balance(spinup: Run) -> None:
    """J u4' = T: u4 = u4(0) + T t / J; dK/dt = T (u4 - u2)."""
    npz, summary, _, _ = _load(spinup)
    scene = load("wheel_spinup")
    torque, j = scene.simulate.parameters["T"], scene.folded()["J"]
    u4 = npz["x"][:, scene.states.index("u4")]
    expected = scene.simulate.initial["u4"] + torque * npz["t"] / j
    assert np.max(np.abs(u4 - expected)) <= 1e-9 * np.max(np.abs(expected))
    assert summary["invariants"]["energy_balance_relative_residual"] < 1e-9
    assert summary["invariants"]["u4_relative_residual"] < 1e-9
    assert summary["parameters"] == {"T": torque}
    assert not (spinup.dir / "trajectory.png").exists()  # --no-plot
    assert "trajectory.png" not in summary["files"]


def test_missing_runtime_value_is_one_line_exit_2(tmp_path: Path, cache: None, cli) -> None:
    text = builtin_text("wheel_spinup")
    assert "parameters = { T = 0.02 }\n" in text
    scene = tmp_path / "no_torque.toml"
    scene.write_text(text.replace("parameters = { T = 0.02 }\n", ""))
    run = simulate(cli, [str(scene)], tmp_path / "out")
    assert run.code == 2 and run.out == ""
    assert run.err == (
        "gyrogen: error: wheel_spinup: simulate.parameters: no value for runtime parameter T "
        "(set it under [simulate] parameters)\n"
    )
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_parameters_whose_constants_overflow_are_one_line_exit_2(
    tmp_path: Path, cache: None, cli
) -> None:
    """Each value valid, the setup accepting them, and yet a constant it
    computes overflows (T / J past DBL_MAX): one line naming it, no
    traceback from the integrator's argument check."""
    text = builtin_text("wheel_spinup")
    scene = tmp_path / "overflow.toml"
    scene.write_text(text.replace("parameters = { T = 0.02 }", "parameters = { T = 1e308 }"))
    run = simulate(cli, [str(scene)], tmp_path / "out")
    assert run.code == 2 and run.out == "" and "Traceback" not in run.err, run.err
    last = run.err.splitlines()[-1]  # after the "generating and building" line
    assert last == (
        "gyrogen: error: wheel_spinup: simulate.parameters: setup refused the parameters "
        "(code 9): a constant derived from the parameters is not finite (together they "
        "overflow doubles)"
    )
    assert not (tmp_path / "out").exists()  # src/ was written before setup refused


@pytest.mark.parametrize(
    "obstacle", ["summary.json", "trajectory.png", "trajectory.csv", "src", "src/torque_free.c"]
)
def test_anything_in_the_way_is_refused_before_any_work(
    obstacle: str, tmp_path: Path, cache: None, cli
) -> None:
    """A directory where an output file goes (a file where src/ goes) is one
    line before anything is generated, built or integrated (it was found
    only after integrating, with src/ written), and nothing is written."""
    out = tmp_path / "out"
    (out / obstacle).mkdir(parents=True) if obstacle != "src" else None
    if obstacle == "src":
        out.mkdir()
        (out / "src").write_text("a file")
    before = sorted(p.relative_to(out) for p in out.rglob("*"))
    run = simulate(cli, ["torque_free", "--t-end", "0.1"], out)
    assert (run.code, run.out) == (1, ""), run.err
    why = "Not a directory" if obstacle == "src" else "Is a directory"
    what = (
        f"cannot create output directory {out / 'src'}"
        if obstacle == "src"
        else (f"cannot write {out / obstacle}")
    )
    lines = run.err.splitlines()
    assert lines[-1] == f"gyrogen: error: {what}: {why}" and "integrating" not in run.err
    assert len(lines) == (2 if "/" in obstacle else 1), run.err  # src's files: once rendered
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == before


@pytest.mark.slow
@WIDE
def test_a_huge_start_state_warns_nothing(tmp_path: Path, cache: None, cli) -> None:
    """u1 = 1e308: the stiffness estimate overflowed with a numpy
    RuntimeWarning and read 'decay rates up to inf'; now the rate is a
    number, and the integrator's refusal is the one line."""
    assert cli(["new", "base", "--out", str(tmp_path / "base.toml")]).code == 0
    path = tmp_path / "base.toml"
    text = path.read_text()
    assert "initial = { u1 = 0.01," in text
    path.write_text(text.replace("initial = { u1 = 0.01,", "initial = { u1 = 1e308,"))
    scene = str(path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a warning is an exception: the run would end in it
        run = simulate(cli, [scene, "--no-plot"], tmp_path / "out")
    assert (run.code, run.out) == (1, "") and "inf" not in run.err, run.err
    assert "decay rates up to 2.59e+307 1/s" in run.err
    assert (
        run.err.splitlines()[-1] == "gyrogen: error: radau5 failed at t = 0 s: step size underflow"
    )
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
@WIDE
def test_a_start_state_whose_derivatives_overflow_is_one_line_exit_2(
    tmp_path: Path, cache: None, cli
) -> None:
    """Refused before integrating, naming the largest values (it was the
    integrator's 'non-finite state or derivative' at t = 0, exit 1)."""
    scene = torque_free_with(
        tmp_path / "s.toml", "{ u1 = 0.3, u2 = 1.0,", "{ u1 = 1e308, u2 = -1e308,"
    )
    run = simulate(cli, [scene, "--method", "dop853"], tmp_path / "out")
    assert (run.code, run.out) == (2, ""), run.err
    assert run.err.splitlines()[-1] == (
        "gyrogen: error: torque_free: simulate.initial: the derivatives at the start state are "
        "not finite (u1 = 1e+308, u2 = -1e+308, u4 = 40: together they overflow doubles)"
    )
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
@pytest.mark.parametrize("command", ["fmu", "bench"])
@WIDE
def test_fmu_and_bench_refuse_overflowing_parameters_in_one_line(
    tmp_path: Path, cache: None, cli, command: str
) -> None:
    """Like simulate: setup's code 9 for the scene's [simulate] parameters is
    one line, exit 2, nothing written (each ended in a ValueError traceback)."""
    text = builtin_text("wheel_spinup")
    scene = tmp_path / "overflow.toml"
    scene.write_text(text.replace("parameters = { T = 0.02 }", "parameters = { T = 1e308 }"))
    code, _, err = cli([command, str(scene), "--out", str(tmp_path / "out")])
    assert code == 2 and "Traceback" not in err, err
    assert err.splitlines()[-1] == (
        "gyrogen: error: wheel_spinup: simulate.parameters: setup refused the parameters "
        "(code 9): a constant derived from the parameters is not finite (together they "
        "overflow doubles)"
    )
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_unwritable_out_is_one_line_exit_1(tmp_path: Path, cache: None, cli) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    run = simulate(cli, ["torque_free"], blocker / "sub")
    assert run.code == 1 and run.out == ""
    assert run.err == (
        f"gyrogen: error: cannot create output directory {blocker / 'sub'}: Not a directory\n"
    )


def test_dt_longer_than_span_is_a_usage_error(tmp_path: Path, cli) -> None:
    run = simulate(cli, ["torque_free", "--t-end", "1", "--dt", "2"], tmp_path / "out")
    assert run.code == 2 and run.err.count("\n") == 1
    assert "output step 2 s is longer than the span 1 s" in run.err
    assert not (tmp_path / "out").exists()
    run = simulate(cli, ["torque_free", "--t-end", "0.001"], tmp_path / "out")  # the scene's dt
    assert run.code == 2 and run.err == (
        "gyrogen simulate: error: Invalid value for '--t-end': output step 0.01 s is longer "
        "than the span 0.001 s (see --help)\n"
    )
    short = tmp_path / "short.toml"  # the scene's t_end, with no dt: the default's 0.01 s
    short.write_text(builtin_text("torque_free").replace("dt = 0.01\n", "")
                     .replace("t_end = 20.0", "t_end = 0.001"))  # fmt: skip
    run = simulate(cli, [str(short)], tmp_path / "out")
    assert run.code == 2 and run.err == (
        "gyrogen simulate: error: Invalid value for the scene's [simulate] t_end with dt's "
        "default (give --dt): output step 0.01 s is longer than the span 0.001 s (see --help)\n"
    )


@pytest.mark.parametrize("dt", ["5e-324", "1e-310", "9e-301"])
def test_output_step_too_short_to_resolve_is_a_usage_error(dt: str, tmp_path: Path, cli) -> None:
    """dt = t_end = 5e-324 passed the count of steps (one) but left a grid of one
    point (a reshape traceback, exit 1); 1e-310 failed only after building,
    with src/ left behind. Both are refused before anything is generated."""
    run = simulate(cli, ["torque_free", "--t-end", dt, "--dt", dt], tmp_path / "out")
    assert (run.code, run.out) == (2, "")
    assert run.err.count("\n") == 1 and "Traceback" not in run.err, run.err
    assert run.err.startswith("gyrogen simulate: error: Invalid value for '--t-end' / '--dt': ")
    assert "s is shorter than 1e-300 s: the quadrature samples inside it" in run.err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("options", "blamed", "pair", "steps"),
    [
        (["--t-end", "1e8"], "'--t-end'", "1e+08 s/0.01 s", "1e+10"),
        (["--dt", "1e-7"], "'--dt'", "20 s/1e-07 s", "2e+08"),
        (["--t-end", "1e300", "--dt", "1e-300"], "'--t-end' / '--dt'", "1e+300 s/1e-300 s", "inf"),
    ],
)
def test_too_many_output_points_is_a_usage_error(
    options: list[str], blamed: str, pair: str, steps: str, tmp_path: Path, cli
) -> None:
    """Refused before anything is generated (numpy would be asked for a
    74.5 GiB grid by the first)."""
    run = simulate(cli, ["torque_free", *options], tmp_path / "out")
    assert (run.code, run.out) == (2, "")
    assert run.err == (
        f"gyrogen simulate: error: Invalid value for {blamed}: t_end/dt = {pair} is {steps} "
        "output steps, more than the limit of 1,000,000: raise dt or lower t_end (see --help)\n"
    )
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_spent_budget_is_one_line_with_the_time_reached(tmp_path: Path, cache: None, cli) -> None:
    argv = ["torque_free", "--method", "DOP853", "--max-nfev", "100"]  # scipy's budget
    run = simulate(cli, argv, tmp_path / "out")
    assert run.code == 1 and run.out == ""
    errors = [line for line in run.err.splitlines() if "error" in line]
    assert len(errors) == 1 and run.err.endswith(errors[0] + "\n")
    assert errors[0].startswith("gyrogen: error: DOP853 failed at t = ")
    assert "of 20: 100 RHS calls (--max-nfev) spent" in errors[0]
    assert not (tmp_path / "out" / "trajectory.csv").exists()


@pytest.mark.slow
@pytest.mark.parametrize("method", ["taylor", "rk4"])
def test_compiled_methods_spend_the_budget_over_the_whole_run(
    tmp_path: Path, cache: None, cli, method: str
) -> None:
    """--max-nfev bounds the RHS calls of the whole run, not of each output
    interval (where a compiled method took it as its max_steps and passed).
    The line names the scene's stiff methods to try (and, for taylor, its
    explicit pairs: its error norm is the largest state of each group)."""
    run = simulate(cli, ["torque_free", "--method", method, "--max-nfev", "10"], tmp_path / "out")
    assert run.code == 1 and run.out == ""
    assert [line for line in run.err.splitlines() if "error" in line] == [run.err.splitlines()[-1]]
    assert run.err.splitlines()[-1].startswith(f"gyrogen: error: {method} failed at t = ")
    assert ": 10 RHS calls (--max-nfev) spent; the state may be blowing up, or the scene is " in (
        run.err
    )
    assert "stiff (try --method radau5 or rodas4)" in run.err
    assert ("(try --method dop853 or dopri5)\n" in run.err) == (method == "taylor"), run.err
    assert not (tmp_path / "out").exists()  # not even src/


def test_a_spent_budget_suggests_what_the_build_offers() -> None:
    """hostile4 (x9): auto took taylor (stiffness index 1, rightly: its decay
    rates over 1e-3 s stay near 100) and spent 10^7 RHS calls, the error
    naming nothing to try: its u4 grows to 5e20 beside u1 ~ 1e3. dop853
    takes 5e4 calls."""
    from gyrogen.methods import instead

    assert instead("radau5", ["radau5", "taylor"]) == ""
    assert instead("dop853", ["dop853", "rodas4"]).endswith("(try --method rodas4)")
    assert instead("dopri5", ["dopri5"]).endswith("(try --method Radau)")
    said = instead("taylor", ["taylor", "dop853", "radau5"])
    assert "(try --method radau5)" in said and said.endswith(
        "the largest state of each group (try --method dop853)"
    )
    assert "error norm" not in instead("taylor", ["taylor", "rk4"])


def test_quadrature_and_grid_do_not_overflow_near_dbl_max() -> None:
    """The quadrature's samples in an interval ending near DBL_MAX are finite
    (0.5 (a + b) overflowed with a RuntimeWarning), and so is the grid
    (t_end + dt/2 overflowed)."""
    grid = np.array([0.0, 1e308, 1.7e308])
    asked: list[np.ndarray] = []
    traj = _exact(grid, lambda t: t[:, None], asked)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = running_integrals(traj, lambda t, x: np.zeros_like(x), np.array([1.0]))
        ends = [output_grid(t, dt) for t, dt in ((1.79e308, 1.79e308), (1.797e308, 1.1e308))]
    assert np.all(got.values == 0.0) and len(asked) == 1
    assert np.all(np.isfinite(asked[0])) and np.all((asked[0] >= 0) & (asked[0] <= 1.7e308))
    for grid, t_end in zip(ends, (1.79e308, 1.797e308), strict=True):  # arange's ValueError
        assert grid[0] == 0.0 and grid[-1] == t_end and np.all(np.diff(grid) > 0)


def test_failed_or_non_finite_solution_is_one_line() -> None:
    failed = SimpleNamespace(status=-1, message="Required step size is too small.")
    with pytest.raises(GyrogenError, match=r"^Radau failed at t = 1\.5 s of 3: Required step"):
        check_solution(failed, "Radau", 1.5, 3.0, 10)
    y = np.ones((2, 4))
    y[1, 2] = np.nan
    nan = SimpleNamespace(status=0, t=np.array([0.0, 0.5, 1.0, 1.5]), y=y)
    with pytest.raises(GyrogenError, match=r"^LSODA: non-finite state at t = 1 s$"):
        check_solution(nan, "LSODA", 1.5, 3.0, 10)
    with pytest.raises(GyrogenError, match=r"spent; the state may be blowing up$"):
        check_solution(None, "Radau", 1.5, 3.0, 10)  # a stiff method: no advice to take it
    with pytest.raises(GyrogenError, match=r"or the scene is stiff \(try --method Radau\)$"):
        check_solution(None, "DOP853", 1.5, 3.0, 10)


@pytest.mark.slow
@WIDE
def test_fortran_only_scene_with_radau(tmp_path: Path, cache: None, cli) -> None:
    scene = torque_free_with(
        tmp_path / "fortran_only.toml", 'targets = ["c", "fortran"]', 'targets = ["fortran"]'
    )
    run = simulate(cli, [scene, "--t-end", "1", "--method", "Radau", "--no-plot"], tmp_path / "o")
    assert run.code == 0, run.err
    summary = json.loads((run.dir / "summary.json").read_text())
    assert (summary["backend"], summary["method"]) == ("fortran", "Radau")
    assert summary["invariants"]["H_norm_relative_drift"] < 1e-8
    assert "on the Fortran RHS" in run.out


@pytest.mark.slow
def test_simulate_with_a_compiled_integrator(tmp_path: Path) -> None:
    """--method dop853 runs the generated integrator between output points:
    no interpolation, so the invariants hold to the tolerance."""
    from gyrogen import scene as scenes
    from gyrogen.analysis.simulate import engine

    res = engine.run(
        scenes.load("torque_free"),
        tmp_path / "out",
        Settings(t_end=2.0, dt=0.05, method="dop853", plot=False),
    )
    assert res.trajectory.nfev > 0 and res.trajectory.x.shape == (41, 7)
    assert res.invariants.worst()["H_norm_relative_drift"] < 1e-12


@pytest.mark.slow
@WIDE
def test_compiled_integrator_at_gimbal_lock_is_one_line(tmp_path: Path, cache: None, cli) -> None:
    """A 3-1-2 scene started at q2 = pi/2: the compiled integrator's code 6
    becomes one line with its meaning; nothing is written."""
    scene = torque_free_with(
        tmp_path / "locked.toml", "initial = { u1", "initial = { q2 = 1.5707963267948966, u1"
    )
    run = simulate(cli, [scene, "--method", "dop853", "--t-end", "1", "--no-plot"], tmp_path / "o")
    assert run.code == 1 and run.out == ""
    errors = [line for line in run.err.splitlines() if "error" in line]
    assert errors == [
        "gyrogen: error: dop853 failed at t = 0 s: the 3-1-2 attitude reached gimbal lock: "
        'use attitude = "quaternion"'
    ]
    assert not (tmp_path / "o" / "trajectory.csv").exists()


@pytest.mark.slow
def test_simulate_refuses_an_integrator_the_scene_lacks(tmp_path: Path) -> None:
    from gyrogen import scene as scenes
    from gyrogen.analysis.simulate import engine
    from gyrogen.errors import SceneError

    text = scenes.builtin_text("torque_free").replace(
        'targets = ["c", "fortran"]', 'targets = ["c"]\nintegrators = ["rk4"]'
    )
    with pytest.raises(SceneError, match="rodas4 is not among the scene's integrators"):
        engine.run(
            scenes.parse(text, "t.toml"),
            tmp_path / "out",
            Settings(t_end=1.0, dt=0.1, method="rodas4", plot=False),
        )


SIMULATED = ("gyrostat", "stiff_wheel", "rw4_pyramid", "cmg4_pyramid")
"""The built-in scenes the suite simulates: one per method auto picks
(taylor, radau5, dop853) and a gimbal's; `make test-wide` simulates the rest."""


@pytest.mark.slow
@pytest.mark.parametrize(
    "name", [n if n in SIMULATED else pytest.param(n, marks=WIDE) for n in builtin_names()]
)
def test_every_builtin_scene_simulates(name: str, tmp_path: Path, cache: None) -> None:
    """Each built-in scene generates, builds and simulates (a short span)
    with the method it picks (the default, auto): the stiff one with the
    compiled Radau IIA its stiffness calls for, and says why; the others with
    the compiled Taylor method where the scene offers it (a smooth rhs), else
    the compiled dop853 (scipy's only where a scene compiled none). The
    suite runs SIMULATED; `make test-wide` every built-in scene."""
    from gyrogen.analysis.simulate import engine

    scene = load(name)
    t_end = min(1.0, scene.simulate.t_end)
    said: list[str] = []
    res = engine.run(
        scene, tmp_path / "o", Settings(t_end, t_end / 20, plot=False), echo=said.append
    )
    method = "radau5" if name == "stiff_wheel" else "dop853" if scene.not_smooth else "taylor"
    assert res.settings.method == method
    assert any(line.startswith(f"method {method}: ") for line in said)
    assert np.all(np.isfinite(res.trajectory.x)) and res.trajectory.x.shape[0] == 21
    assert res.invariants.worst()["H_norm_relative_drift"] < 1e-9


@pytest.mark.slow
def test_a_cluster_is_plotted_wheel_by_wheel(tmp_path: Path) -> None:
    """rw4_pyramid's figure: its rotor panel shows the four wheels' rates
    relative to the carrier (a cluster has no u4)."""
    from matplotlib.image import imread

    from gyrogen.analysis.simulate import engine, plots

    scene = load("rw4_pyramid")
    engine.run(scene, tmp_path / "o", Settings(2.0, 0.1, "dop853", True))
    assert imread(tmp_path / "o" / "trajectory.png").shape[:2] == plots.PIXELS


def _exact(
    grid: np.ndarray, f: Callable[[np.ndarray], np.ndarray], asked: list | None = None
) -> Trajectory:
    """A trajectory whose states at any times t are f(t) (m, nx), known to
    1e-14, one step an interval; each sampling's times appended to asked."""

    def sample(t: np.ndarray) -> np.ndarray:
        if asked is not None:
            asked.append(t)
        return f(np.asarray(t))

    return Trajectory(grid, f(grid), 0, 0.0, sample, (1e-14, 1e-14), (grid, np.diff(grid)))


def _rate(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    return x[:, :1]


def test_the_quadrature_finds_a_transient_at_a_pieces_edge() -> None:
    """A layer of width 1e-5 s at the start of a 0.01 s interval
    (stiff_wheel's wheel locking on): the Gauss nodes see none of it (one
    pass: int_0^1 e^(-1e5 t) dt = 1e-5, found 0); Gauss-Lobatto's ends see
    it, and the pieces cut there find it to 1e-12 of the scale. A smooth
    rate takes one pass."""
    grid = output_grid(1.0, 0.01)
    layer = _exact(grid, lambda t: np.exp(-1e5 * t)[:, None])
    exact = (1.0 - np.exp(-1e5 * grid)) / 1e5
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(trajectory, "MAX_PASSES", 0)
        blind = running_integrals(layer, _rate, np.array([1e-5]))
    assert abs(blind.values[-1, 0] - exact[-1]) > 0.99 * exact[-1] and blind.unresolved
    found = running_integrals(layer, _rate, np.array([1e-5]))
    assert np.max(np.abs(found.values[:, 0] - exact)) <= 1e-12 * 1e-5 and not found.unresolved
    asked: list[np.ndarray] = []
    smooth = _exact(grid, lambda t: np.exp(-t)[:, None], asked)
    got = running_integrals(smooth, _rate, np.array([1.0])).values[:, 0]
    assert np.max(np.abs(got - (1.0 - np.exp(-grid)))) <= 1e-15 and len(asked) == 1


def test_the_quadrature_cuts_down_to_a_kink() -> None:
    """|t - k| (a clamp's kink at k, anywhere in an interval): the rules
    differ until the piece holding it is short; the integral to 1e-14."""
    traj = _exact(output_grid(1.0, 0.1), lambda t: t[:, None])
    for k in np.random.default_rng(1).uniform(0.05, 0.95, 50):
        got = running_integrals(traj, lambda t, x, k=k: np.abs(x[:, :1] - k), np.array([1.0]))
        assert abs(got.values[-1, 0] - (k**2 + (1 - k) ** 2) / 2) <= 1e-14, k
        assert not got.unresolved


def _spinning(t: np.ndarray) -> np.ndarray:
    """x = (cos w t, sin w t), 22.3 periods a second."""
    w = 2 * np.pi * 22.3
    return np.column_stack([np.cos(w * t), np.sin(w * t)])


def test_the_quadrature_cuts_an_oscillation_it_aliases() -> None:
    """cos^2(w t) with 22.3 periods an output interval (stiff_wheel's
    nutation at --dt 1000): one Gauss rule an interval aliases it, 0.05
    off; Gauss-Lobatto aliases it otherwise, and the pieces cut where they
    disagree find it to 1e-12."""
    w = 2 * np.pi * 22.3
    traj = _exact(output_grid(10.0, 1.0), _spinning)
    exact = traj.t / 2 + np.sin(2 * w * traj.t) / (4 * w)
    rate = lambda t, x: x[:, :1] ** 2  # noqa: E731
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(trajectory, "MAX_PASSES", 0)
        blind = running_integrals(traj, rate, np.array([1.0]))
    assert np.max(np.abs(blind.values[:, 0] - exact)) > 0.04
    got = running_integrals(traj, rate, np.array([1.0]))
    assert np.max(np.abs(got.values[:, 0] - exact)) <= 1e-12 and not got.unresolved


def test_the_quadrature_cuts_at_the_knots() -> None:
    """A torque table's pulse of 1e-4 s inside a 0.01 s interval, between
    its nodes (a table with points at 2.003, 2.00305 and 2.0031 s): the
    rules both miss it, and agree. With the table's points as knots, the
    pieces end there: exact in one pass (to the rounding of the times near
    2 s: 4e-16 s, times the slope 1e4 N m/s, over 1e-4 s)."""
    table = np.array([[0.0, 0.0], [2.003, 0.0], [2.00305, 0.5], [2.0031, 0.0]])
    rate = lambda t, x: np.interp(x[:, 0], table[:, 0], table[:, 1])[:, None]  # noqa: E731
    asked: list[np.ndarray] = []
    traj = _exact(output_grid(4.0, 0.01), lambda t: t[:, None], asked)
    blind = running_integrals(traj, rate, np.array([1.0]))
    assert abs(blind.values[-1, 0]) < 1e-9 and not blind.unresolved  # 2.5e-5 missed
    asked.clear()
    got = running_integrals(traj, rate, np.array([1.0]), table[:, 0])
    assert abs(got.values[-1, 0] - 2.5e-5) <= 1e-16 and len(asked) == 1  # times' rounding


def test_the_quadrature_says_what_it_could_not_resolve(monkeypatch: pytest.MonkeyPatch) -> None:
    """With its passes spent it keeps the Gauss sums (the layer's integral:
    0 for 1e-5) and says so; past MAX_PIECES, the pieces left uncut."""
    layer = _exact(output_grid(1.0, 0.01), lambda t: np.exp(-1e5 * t)[:, None])
    monkeypatch.setattr(trajectory, "MAX_PASSES", 2)
    got = running_integrals(layer, _rate, np.array([1e-5]))
    assert len(got.unresolved) == 1 and "pieces still disagreed after 2 passes" in got.unresolved[0]
    monkeypatch.setattr(trajectory, "MAX_PASSES", 16)
    monkeypatch.setattr(trajectory, "MAX_PIECES", 16)
    traj = _exact(output_grid(10.0, 1.0), _spinning)
    got = running_integrals(traj, lambda t, x: x[:, :1] ** 2, np.array([1.0]))
    assert len(got.unresolved) == 1 and "left uncut past the 16 a pass" in got.unresolved[0]


TABLE = (
    "[[0.0, 0.0], [0.1234, 0.02], [1.5, 0.02], [2.003, 0.0], [2.00305, 0.5], [2.0031, 0.0], "
    "[3.33333, -0.01], [3.33334, 0.03], [9.0, 0.0]]"
)
"""Kinks between the grid's points and on them (1.5, 9.0), a steep ramp
(1e-5 s) and a pulse of 1e-4 s between the quadrature's nodes."""


@pytest.mark.slow
@pytest.mark.parametrize("method", ["dop853", "DOP853"])
@WIDE
def test_the_balances_close_on_a_torque_table(tmp_path: Path, cli, method: str) -> None:
    """gyrostat driven by a T(t) table: the run stepped across the table's
    points (segments of an eighth of an interval), its slope jumps and its
    pulse between the nodes, the u4 balance 7.6e-9 and 1.4e-8 of max |u4|
    off. Now the run stops and starts again at each point (solve_ivp too),
    the quadrature's pieces end there, and both balances close to 1e-13."""
    text = builtin_text("gyrostat").replace('T   = "runtime"', "").replace("T   = 0.01", "")
    text = text.replace('torque = "constant"', f'torque = "table"\ntorque_table = {TABLE}')
    (tmp_path / "table.toml").write_text(text)
    argv = [str(tmp_path / "table.toml"), "--method", method, "--t-end", "4", "--no-plot"]
    run = simulate(cli, argv, tmp_path / "out")
    assert run.code == 0, run.err
    summary = json.loads((run.dir / "summary.json").read_text())
    worst = summary["invariants"]
    assert worst["energy_balance_relative_residual"] < 1e-13, worst
    assert worst["u4_relative_residual"] < 1e-13, worst
    assert summary["quadrature_unresolved"] == []


@pytest.mark.slow
def test_stiff_wheel_balance_does_not_hang_on_the_output_step(tmp_path: Path, cli) -> None:
    """stiff_wheel to 2000 s at --dt 1000 (22 nutation periods an interval):
    the energy balance read 1.6e-4 (5.7e-9 at --dt 10). Now near rtol."""
    argv = ["stiff_wheel", "--t-end", "2000", "--dt", "1000", "--no-plot"]
    run = simulate(cli, argv, tmp_path)
    assert run.code == 0, run.err
    summary = json.loads((run.dir / "summary.json").read_text())
    assert summary["invariants"]["energy_balance_relative_residual"] < 1e-9, summary
    assert summary["invariants"]["u4_relative_residual"] < 1e-9, summary
    assert summary["quadrature_unresolved"] == [] and "NOT RESOLVED" not in run.out


@pytest.mark.slow
def test_stiff_wheel_balances_hold_across_its_transient(tmp_path: Path, cli) -> None:
    """stiff_wheel's wheel spins up 150 rad/s within 1e-5 s: the energy and
    u4 balances read 1.0 (the quadrature saw none of it) while the run was
    right; `gyrogen check` agrees. Now both are at the integrator's rtol."""
    run = simulate(cli, ["stiff_wheel", "--t-end", "1", "--dt", "0.05", "--no-plot"], tmp_path)
    assert run.code == 0, run.err
    worst = json.loads((run.dir / "summary.json").read_text())["invariants"]
    assert worst["energy_balance_relative_residual"] < 1e-9, worst
    assert worst["u4_relative_residual"] < 1e-9, worst


@pytest.mark.slow
def test_a_cluster_is_summarized_with_its_own_balances(tmp_path: Path, cli) -> None:
    """rw3_orthogonal has no u4: its rate check is wheel 1's w1 and its P the
    wheels' (the summary said u4 and T (u4 - u2) + M g u7)."""
    run = simulate(cli, ["rw3_orthogonal", "--t-end", "1", "--dt", "0.1", "--no-plot"], tmp_path)
    assert run.code == 0, run.err
    assert "  w1 check        w1 - w1(0) - int net_1 dt/J_1: " in run.out and "u4" not in run.out
    note = json.loads((run.dir / "summary.json").read_text())["invariants_note"]
    assert "P = sum_k net_k (w_k - g_k . w_A)" in note and "(w1 - w1(0) - int net_1" in note
    assert "u4 - u2" not in note and "int T dt/J" not in note


@pytest.mark.slow  # a build (on a cold cache) and a process of its own
@pytest.mark.parametrize("where", ["src", "."])
def test_ctrl_c_while_writing_leaves_nothing_in_out(
    where: str, tmp_path: Path, cache_dir: Path
) -> None:
    """A real SIGINT as the generated sources (src) or the results are
    written, after the integration: before, exit 130 left out/src (and,
    held until placed, the results too). Now exit 130 and nothing new in
    out, which existed before and is empty again."""
    out = tmp_path / "out"
    out.mkdir()
    argv = ["simulate", "torque_free", "--t-end", "1", "--no-plot", "--out", str(out)]
    code, err = interrupted(out / where, argv, cache_dir)
    assert code == 130 and err.endswith("gyrogen: aborted\n") and "Traceback" not in err
    assert list(out.iterdir()) == []


@pytest.mark.slow
@WIDE
def test_an_event_only_a_table_pulse_makes_happen_is_located(tmp_path: Path, cache: None) -> None:
    """A wheel-rate event only a torque table's pulse of 5e-5 s (2.003 to
    2.0031 s, 0.5 N m at its peak) makes happen, located by simulate's
    _events call over the whole run: once, within the pulse (no step
    crosses a table time), where the trajectory is at the threshold."""
    from gyrogen import api
    from gyrogen.analysis.simulate import engine

    pulse = "[[0.0, 0.0], [2.003, 0.0], [2.00305, 0.5], [2.0031, 0.0], [9.0, 0.0]]"
    text = builtin_text("gyrostat").replace('T   = "runtime"', "").replace("T   = 0.01", "")
    text = text.replace('torque = "constant"', f'torque = "table"\ntorque_table = {pulse}')
    text += '\n[[events]]\nname = "spun"\nexpr = "u4 - 50.0004"\ndirection = "up"\n'
    (tmp_path / "pulse.toml").write_text(text)
    scene = load(tmp_path / "pulse.toml")
    comp = api.compile(scene)
    c = engine.given_constants(scene, comp, engine.runtime_values(scene))
    breaks = scene_view.table_times(scene)
    start = engine.Start(comp, c, np.array(scene.initial_state()), (1e-10, 1e-10), breaks)
    settings = Settings(t_end=4.0, dt=0.01, method="dop853", plot=False)
    log, stopped, full = engine.located(start, settings)
    assert log.names == ["spun"] and not stopped and full is None
    assert 2.003 < log.times[0] < 2.0031  # within the pulse
    traj = engine.integrate(start, settings, lambda n: None)
    u4 = scene.states.index("u4")
    np.testing.assert_allclose(traj.sample(log.times)[:, u4], 50.0004, rtol=1e-10)
