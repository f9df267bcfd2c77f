"""The command line: outputs, and one clear line per error with its exit code."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from gyrogen import generate as generate_module
from gyrogen.cli import main
from gyrogen.errors import GyrogenError
from gyrogen.scene import default


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    try:
        main(argv)
        code = 0
    except SystemExit as exc:
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


def test_generate_writes_sources_and_manifest(tmp_path: Path, capsys) -> None:
    code, out, _ = run(["generate", "--out", str(tmp_path / "o")], capsys)
    assert code == 0
    names = sorted(p.name for p in (tmp_path / "o").iterdir())
    assert names == [
        "gyrostat.c", "gyrostat.f90", "gyrostat.h",
        "gyrostat_ode.c", "gyrostat_ode.f90", "gyrostat_ode.h", "manifest.json",
    ]  # fmt: skip
    assert "gyrostat" in out and "(full model)" in out


def test_unknown_option_is_one_line_exit_2(capsys) -> None:
    code, out, err = run(["generate", "--bogus"], capsys)
    assert code == 2
    assert err.count("\n") == 1 and "No such option" in err and "--bogus" in err
    assert out == ""


def test_unknown_command_is_one_line_exit_2(capsys) -> None:
    code, _, err = run(["frobnicate"], capsys)
    assert code == 2 and err.count("\n") == 1 and "frobnicate" in err


def test_unwritable_out_is_one_line_exit_1(tmp_path: Path, capsys) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    code, _, err = run(["generate", "--out", str(blocker / "sub")], capsys)
    assert code == 1
    assert (
        err
        == f"gyrogen: error: cannot create output directory {blocker / 'sub'}: Not a directory\n"
    )
    assert blocker.read_text() == "not a directory"


def test_failed_write_leaves_nothing_half_written(
    tmp_path: Path, capsys, monkeypatch: pytest.MonkeyPatch
) -> None:
    out_dir = tmp_path / "o"
    out_dir.mkdir()
    (out_dir / "gyrostat.c").write_text("old")
    real_replace = os.replace
    calls = []

    def fail_second(src: str, dst: Path) -> None:
        calls.append(dst)
        if len(calls) == 1:
            raise OSError(28, "No space left on device")
        real_replace(src, dst)

    monkeypatch.setattr(generate_module.os, "replace", fail_second)
    code, _, err = run(["generate", "--out", str(out_dir)], capsys)
    assert code == 1 and err.startswith("gyrogen: error: cannot write to") and err.count("\n") == 1
    assert sorted(p.name for p in out_dir.iterdir()) == ["gyrostat.c"]
    assert (out_dir / "gyrostat.c").read_text() == "old"


def test_render_failure_writes_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def broken(unit: object) -> dict[str, str]:
        raise GyrogenError("boom")

    monkeypatch.setattr(generate_module.fortran, "files", broken)
    with pytest.raises(GyrogenError):
        generate_module.generate(default(), tmp_path / "o")
    assert not (tmp_path / "o").exists()


def test_prove(capsys) -> None:
    code, out, _ = run(["prove"], capsys)
    assert code == 0
    assert "mass matrix (7x7)" in out and "forcing (7)" in out
    assert "The two formulations are identical." in out


def test_equations_text_and_latex(capsys) -> None:
    code, out, _ = run(["equations"], capsys)
    assert code == 0
    assert "(a) Separate bodies" in out and "(b) Lumped carrier" in out
    assert "IA11 = I + I11 + l3**2*m_a*m_b/(m_a + m_b)" in out
    code, out, _ = run(["equations", "--latex"], capsys)
    assert code == 0 and r"\begin{align}" in out and r"I_{\tilde{A}11}" in out


def test_ops_table(capsys) -> None:
    code, out, _ = run(["ops"], capsys)
    assert code == 0
    assert all(f"({k})" in out for k in ("i", "ii", "iii", "lu", "setup"))


def test_verify_small(tmp_path: Path, capsys) -> None:
    code, out, _ = run(
        ["verify", "--out", str(tmp_path / "v"), "--states", "500", "--params", "5"], capsys
    )
    assert code == 0, out
    assert "C vs reference" in out and "Fortran vs reference" in out and "C vs Fortran" in out
    assert "setup refusals:" in out


def test_missing_compiler_from_the_command_line(tmp_path: Path) -> None:
    """A PATH without gcc: one line naming the package, exit 1."""
    env = dict(os.environ, PATH=str(tmp_path), GYROGEN_CACHE=str(tmp_path / "cache"))
    proc = subprocess.run(
        [sys.executable, "-m", "gyrogen", "verify", "--out", str(tmp_path / "v"), "--states", "10"],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    assert proc.returncode == 1
    assert (
        proc.stderr == "gyrogen: error: gcc not found: install it with `apt-get install -y gcc`\n"
    )


def test_generate_lib_writes_build_files(tmp_path: Path, capsys) -> None:
    code, _, _ = run(["generate", "--lib", "--out", str(tmp_path / "o")], capsys)
    assert code == 0
    names = {p.name for p in (tmp_path / "o").iterdir()}
    assert {"CMakeLists.txt", "gyrostat.mk", "gyrostat.c", "manifest.json"} <= names
    assert "Do not edit" in (tmp_path / "o" / "CMakeLists.txt").read_text()
