"""Smoke test of gyrogen.analysis.bench.rhs on a tiny workload: it runs and reports
sane numbers.

Never asserts a speed: timings depend on the machine and its load.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import pytest

from gyrogen.analysis.bench import rhs

pytestmark = pytest.mark.slow  # the benchmark command on a tiny run

NAMES = [
    "cffi_c_call",
    "compiled_c_rhs",
    "batch_c",
    "cffi_fortran_call",
    "compiled_fortran_rhs",
    "batch_fortran",
    "numpy_batch",
    "numpy_call",
]


def _tiny(tmp: Path | None = None, **kw: bool) -> tuple[list[rhs.Measurement], list[str]]:
    lines: list[str] = []
    ms = rhs.run(out=tmp, repeats=1, echo=lines.append, calls=1000, batch=1000, **kw)
    return ms, lines


def test_tiny_run_reports_every_row(tmp_path: Path, cli) -> None:
    """Every row, sane numbers, and the one file `gyrogen bench-rhs --help` names."""
    ms, lines = _tiny(tmp_path, pydy=False)
    assert [m.name for m in ms] == NAMES
    for m in ms:
        assert math.isfinite(m.ns) and m.ns > 0, m
        assert m.unit in ("call", "state")
        assert "MISMATCH" not in m.detail
    text = "\n".join(lines)
    assert "one call through cffi (C) vs PyDy cython:" in text
    assert "batched C:" in text
    (written,) = (p.name for p in tmp_path.iterdir())
    assert f"Write {written} here." in cli(["bench-rhs", "--help"]).out
    doc = json.loads((tmp_path / written).read_text())
    assert [m["name"] for m in doc["measurements"]] == NAMES
    assert doc["machine"]["c_flags"]


def test_missing_pydy_skips_only_its_row(monkeypatch: pytest.MonkeyPatch) -> None:
    # None makes `import pydy...` raise ImportError, also when an earlier test loaded it
    for name in ("pydy", "pydy.codegen", "pydy.codegen.ode_function_generators"):
        monkeypatch.setitem(sys.modules, name, None)
    ms, lines = _tiny(pydy=True)
    assert [m.name for m in ms] == NAMES
    assert any("pip install -e '.[bench]'" in line for line in lines)
