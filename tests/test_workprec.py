"""`gyrogen bench --quick`: the work-precision report runs and writes a real
figure and consistent tables (no timing assertions)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest
from wide import WIDE

from gyrogen.analysis.bench import workprec
from gyrogen.analysis.bench.workprec import Run
from gyrogen.scene import builtin_text


@pytest.mark.parametrize("name", ["summary.md", "workprecision.png"])
def test_anything_in_the_way_is_refused_before_measuring(
    name: str, tmp_path: Path, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A directory where a report file goes is one line before the minutes of
    measuring (it was found only when writing, after them)."""
    from gyrogen.analysis.bench import workprec_report

    def measured(*args: object) -> None:
        raise AssertionError("measured with a directory in the way")

    monkeypatch.setattr(workprec_report, "measure", measured)
    (tmp_path / "report" / name).mkdir(parents=True)
    code, text, err = cli(["bench", "torque_free", "--quick", "--out", str(tmp_path / "report")])
    assert (code, text) == (1, "")
    assert err == f"gyrogen: error: cannot write {tmp_path / 'report' / name}: Is a directory\n"
    assert [p.name for p in (tmp_path / "report").iterdir()] == [name]


@pytest.mark.slow
@WIDE
def test_bench_quick_default_scene(tmp_path: Path, cli) -> None:
    out = tmp_path / "report"
    code, text, _ = cli(["bench", "--quick", "--out", str(out)])
    assert code == 0, text
    assert "| error at most | fastest |" in text
    img = matplotlib.image.imread(out / "workprecision.png")
    assert img.shape[:2] == (700, 1400) and float(np.std(img)) > 0.01
    rows = list(csv.DictReader((out / "workprecision.csv").open()))
    labels = {(r["method"], r["backend"]) for r in rows}
    for m in ("rk4", "dopri5", "dop853", "rodas4"):
        assert (m, "C") in labels
    for m in ("RK45", "DOP853", "Radau", "LSODA"):
        assert (f"scipy {m}", "numpy RHS") in labels and (f"scipy {m}", "C RHS via cffi") in labels
    for m in ("DOP853", "LSODA"):  # the compiled peers (the test extra installs them)
        for rhs in ("gyrogen's C RHS", "numba RHS"):
            assert (f"numbalsoda {m}", rhs) in labels
    assert any(m == "CasADi cvodes Adams" for m, _ in labels)
    assert ("heyoka taylor_adaptive", "JIT, from Python") in labels  # the test extra has it
    assert "## gyrogen against its peers" in text and "numbalsoda DOP853 (numba RHS)" in text
    ok = [r for r in rows if r["status"] == "ok"]
    assert all(float(r["seconds"]) > 0 and float(r["error"]) >= 0 for r in ok)
    data = json.loads((out / "workprecision.json").read_text())
    assert data["scene"] == "gyrostat" and len(data["runs"]) == len(rows)
    checks = data["reference_checks"]
    assert checks["scipy DOP853 (compiled RHS) at 1e-13"] < 1e-10
    assert checks["DOP853 in C at 1e-13 against heyoka real128"] < 1e-10
    assert "reference: heyoka real128 (quadruple precision)" in text and "| 1e-14 |" in text
    assert "gyrogen generate and build:" in text and "heyoka JIT" in text
    summary = (out / "summary.md").read_text()
    assert summary.startswith("# Work-precision: gyrostat")


@pytest.mark.slow
def test_dop853_converges_to_the_reference(tmp_path: Path) -> None:
    """Tighter tolerances give smaller errors against the reference."""
    from gyrogen.analysis.bench import workprec, workprec_report
    from gyrogen.scene import default

    prob = workprec_report.problem(default(), tmp_path / "src", workprec.QUICK)
    workprec.reference(prob)
    runs = [
        workprec._compiled_run(prob, prob.compiled["C"], "C", "dop853", tol, 1)
        for tol in (1e-4, 1e-7, 1e-10)
    ]
    errors = [r.error for r in runs]
    assert errors[0] > errors[1] > errors[2] and errors[2] < 1e-9


def test_scene_without_the_reference_integrator_is_one_line(tmp_path: Path, cli) -> None:
    """Refused before any progress line (it reached a ValueError traceback)."""
    scene = tmp_path / "scene.toml"
    text = builtin_text("torque_free")
    scene.write_text(
        text.replace('targets = ["c", "fortran"]', 'targets = ["c"]\nintegrators = ["rk4"]')
    )
    code, out, err = cli(["bench", "--quick", str(scene), "--out", str(tmp_path / "r")])
    assert (code, out) == (2, "")
    assert err == (
        "gyrogen: error: torque_free: the work-precision report needs the c target and the "
        "dop853 integrator (its reference)\n"
    )
    assert not (tmp_path / "r").exists()


@pytest.mark.slow
@WIDE
def test_failed_reference_run_is_one_line(
    tmp_path: Path,
    cli,
    cache_dir: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A state that overflows at once: the reference DOP853 fails (it was a
    RuntimeError traceback)."""
    monkeypatch.setenv("GYROGEN_CACHE", str(cache_dir))
    scene = tmp_path / "scene.toml"
    scene.write_text(builtin_text("torque_free").replace("u4 = 40.0", "u4 = 1e300"))
    code, out, err = cli(["bench", "--quick", str(scene), "--out", str(tmp_path / "r")])
    assert (code, out) == (1, "")
    assert err.splitlines()[-1] == (
        "gyrogen: error: torque_free: reference DOP853 failed at t = 0 s: step size underflow"
    )
    assert "Traceback" not in err and not (tmp_path / "r").exists()


def _run(error: float, seconds: float) -> Run:
    return Run("m", "C", 0.0, error, seconds, 0)


def test_time_at_an_error_is_read_along_the_front() -> None:
    """Interpolated in log-log between the two front runs around the level;
    a slower and less accurate run is off the front; a contender already
    below the level is charged its fastest run; none reaching it: None."""
    runs = [_run(1e-3, 1e-6), _run(1e-5, 4e-6), _run(1e-4, 9e-6), _run(1e-7, 16e-6)]
    assert [r.seconds for r in workprec.front(runs)] == [1e-6, 4e-6, 16e-6]
    assert workprec.seconds_at(runs, 1e-4) == pytest.approx(2e-6)  # halfway in log: sqrt(1*4)
    assert workprec.seconds_at(runs, 1e-6) == pytest.approx(8e-6)
    assert workprec.seconds_at(runs, 1e-2) == 1e-6
    assert workprec.seconds_at(runs, 1e-8) is None
    failed = Run("m", "C", 0.0, 1e-9, 1e-9, 0, "code 2")
    assert workprec.seconds_at([*runs, failed], 1e-8) is None


@pytest.mark.slow
def test_casadi_takes_a_clamped_motor() -> None:
    """rw4_pyramid's rhs clamps its motors (Min, Max): in CasADi's SX they
    are fmin and fmax, and the SX rhs equals the block evaluated on floats,
    at random states and constants (Python's min of SX asked an SX for its
    truth: `gyrogen bench rw4_pyramid` ended in a traceback)."""
    import math

    ca = pytest.importorskip("casadi")
    from gyrogen.analysis.bench.peer_rhs import rhs_values
    from gyrogen.analysis.bench.workprec_peers import _sx_rhs
    from gyrogen.codegen.generate import unit_of
    from gyrogen.scene import load

    unit = unit_of(load("rw4_pyramid"))
    x, c = ca.SX.sym("x", unit.nx), ca.SX.sym("c", unit.nc)
    f = ca.Function("rhs", [x, c], [_sx_rhs(ca, unit, x, c)])
    floats = {"sin": math.sin, "cos": math.cos, "sqrt": math.sqrt}
    rng = np.random.default_rng(5)
    for _ in range(10):
        xv, cv = rng.normal(size=unit.nx) * 10.0, rng.uniform(0.1, 2.0, unit.nc)
        want = np.array(rhs_values(unit, list(xv), list(cv), floats), dtype=float)
        got = np.asarray(f(xv, cv)).ravel()
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13)
