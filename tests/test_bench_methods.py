"""benchmarks/methods.py (`make bench-methods`) runs and prints its table at
tiny sizes; with a baseline, both builds side by side. Figures only: no
assertion on time."""

from __future__ import annotations

import re
import runpy
import sys
from pathlib import Path

import pytest
from wide import WIDE

from gyrogen import methods
from gyrogen.scene import load

SCRIPT = Path(__file__).resolve().parent.parent / "benchmarks" / "methods.py"


def run(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], *args: str) -> str:
    monkeypatch.setattr(sys, "argv", [str(SCRIPT), *args])
    runpy.run_path(str(SCRIPT), run_name="__main__")
    return capsys.readouterr().out


def rows(out: str) -> dict[str, list[str]]:
    """The table's rows by method: their cells."""
    found = {}
    for line in out.splitlines():
        cells = [c.strip() for c in line.strip("|").split("|")]
        if line.startswith("| ") and cells[0] in methods.NAMES:
            found[cells[0]] = cells
    return found


def test_every_method_is_timed(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    out = run(monkeypatch, capsys, "--scenes", "torque_free", "--tolerances", "1e-6",
              "--repeats", "1", "--rounds", "1")  # fmt: skip
    assert re.search(r"^before: load average [\d.]+", out, re.M)
    assert re.search(r"^after: load average [\d.]+", out, re.M)
    got = rows(out)
    offered = load("torque_free").integrators
    assert set(got) == set(offered) == set(methods.NAMES)
    for cells in got.values():
        steps, rhs, us, ns = int(cells[2]), int(cells[3]), float(cells[5]), float(cells[6])
        assert steps > 0 and rhs >= steps and us > 0
        assert ns == pytest.approx(us * 1e3 / steps, rel=0.01, abs=1)


@pytest.mark.slow
@WIDE
def test_a_baseline_runs_beside(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """HEAD against itself: gyrogen as of HEAD renders and builds the scene in
    a worktree of its own; each method's row carries both builds' steps (the
    same) and a ratio, and the summary names every method."""
    out = run(monkeypatch, capsys, "--baseline", "HEAD", "--scenes", "torque_free",
              "--tolerances", "1e-6", "--repeats", "1", "--rounds", "1")  # fmt: skip
    got = rows(out)
    assert set(got) == set(methods.NAMES)
    for cells in got.values():
        assert cells[2] == cells[7]  # the steps, new and old
        assert float(cells[10].split()[0]) > 0
    for method in methods.NAMES:
        assert re.search(rf"^  {method} +[\d.]+ \(rows ", out, re.M)


def test_an_unknown_baseline_is_one_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exc:
        run(monkeypatch, capsys, "--baseline", "no-such-rev", "--scenes", "torque_free")
    said = str(exc.value)
    assert said.startswith("bench-methods: cannot check out no-such-rev: ")
    assert "\n" not in said
