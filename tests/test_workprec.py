"""`gyrogen bench --quick`: the work-precision report runs and writes a real
figure and consistent tables (no timing assertions)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

from gyrogen.cli import main


def test_bench_quick_default_scene(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "report"
    try:
        main(["bench", "--quick", "--out", str(out)])
        code = 0
    except SystemExit as exc:
        code = int(exc.code or 0)
    text, _ = capsys.readouterr()
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
    ok = [r for r in rows if r["status"] == "ok"]
    assert all(float(r["seconds"]) > 0 and float(r["error"]) >= 0 for r in ok)
    data = json.loads((out / "workprecision.json").read_text())
    assert data["scene"] == "gyrostat" and len(data["runs"]) == len(rows)
    checks = data["reference_checks"]
    assert checks["scipy DOP853 (compiled RHS) at 1e-13"] < 1e-10
    summary = (out / "summary.md").read_text()
    assert summary.startswith("# Work-precision: gyrostat")


def test_dop853_converges_to_the_reference(tmp_path: Path) -> None:
    """Tighter tolerances give smaller errors against the reference."""
    from gyrogen import workprec, workprec_report
    from gyrogen.scene import default

    prob = workprec_report.problem(default(), tmp_path / "src", workprec.QUICK)
    workprec.reference(prob)
    runs = [
        workprec._compiled_run(prob, prob.compiled["C"], "C", "dop853", tol, 1)
        for tol in (1e-4, 1e-7, 1e-10)
    ]
    errors = [r.error for r in runs]
    assert errors[0] > errors[1] > errors[2] and errors[2] < 1e-9
