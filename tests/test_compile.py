"""The generated sources compile clean under the strict flags, as C and as
C++, and the build cache and its errors behave."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from gyrogen import build
from gyrogen.errors import BuildError


def _compile(cmd: list[str], cwd: Path) -> None:
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == "", proc.stderr


def test_c99_strict(source_dir: Path, tmp_path: Path) -> None:
    _compile(
        ["gcc", "-std=c99", "-Wall", "-Wextra", "-Wpedantic", "-Werror", "-c",
         str(source_dir / "gyrostat.c"), "-o", str(tmp_path / "g.o")],
        source_dir,
    )  # fmt: skip


def test_source_compiles_as_cxx(source_dir: Path, tmp_path: Path) -> None:
    _compile(
        ["g++", "-x", "c++", "-std=c++17", "-Wall", "-Wextra", "-Wpedantic", "-Werror", "-c",
         str(source_dir / "gyrostat.c"), "-o", str(tmp_path / "g.o")],
        source_dir,
    )  # fmt: skip


def test_header_from_cxx(source_dir: Path, tmp_path: Path) -> None:
    """A C++ program includes the header, links the C object, and calls it."""
    main = tmp_path / "main.cpp"
    main.write_text(
        '#include "gyrostat.h"\n#include <cstdio>\n'
        "int main() {\n"
        "  double p[GYROSTAT_NP] = {10, 2, 3, 4, 5, 0.3, 0.5, 0.8, 0.2, -0.1, 9.81, 0.5};\n"
        "  double c[GYROSTAT_NC], x[GYROSTAT_NX] = {0}, d[GYROSTAT_NX];\n"
        "  if (gyrostat_setup(p, c) != GYROSTAT_OK) return 1;\n"
        "  gyrostat_rhs(0.0, x, c, d);\n"
        '  std::printf("%.6f\\n", d[13]);\n  return 0;\n}\n'
    )
    _compile(
        ["gcc", "-std=c99", "-O2", "-c", str(source_dir / "gyrostat.c"), "-o", "g.o"], tmp_path
    )
    _compile(
        ["g++", "-std=c++17", "-Wall", "-Wextra", "-Werror", f"-I{source_dir}", "main.cpp", "g.o",
         "-lm", "-o", "main"],
        tmp_path,
    )  # fmt: skip
    out = subprocess.run([str(tmp_path / "main")], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "9.810000"


def test_fortran_2008_strict(source_dir: Path, tmp_path: Path) -> None:
    _compile(
        ["gfortran", "-std=f2008", "-Wall", "-Wextra", "-Wimplicit-interface", "-Werror",
         "-J", str(tmp_path), "-c", str(source_dir / "gyrostat.f90"), "-o", str(tmp_path / "f.o")],
        source_dir,
    )  # fmt: skip


def test_rebuild_hits_the_cache(
    source_dir: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    first = build.build(source_dir, "c")
    entries = sorted((tmp_path / "cache").iterdir())
    assert len(entries) == 1

    def no_compile(*args: object, **kwargs: object) -> None:
        raise AssertionError("unchanged sources were compiled again")

    monkeypatch.setattr(build, "_compile", no_compile)
    second = build.build(source_dir, "c")
    assert second.lib is first.lib
    assert sorted((tmp_path / "cache").iterdir()) == entries


def test_changed_source_gets_a_new_cache_entry(
    source_dir: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    src = tmp_path / "src"
    shutil.copytree(source_dir, src)
    build.build(src, "c")
    with open(src / "gyrostat.c", "a") as fh:
        fh.write("/* touched */\n")
    build.build(src, "c")
    assert len(list((tmp_path / "cache").iterdir())) == 2


@pytest.mark.parametrize(("tool", "language"), [("gcc", "c"), ("gfortran", "fortran")])
def test_missing_compiler_names_the_package(
    source_dir: Path, monkeypatch: pytest.MonkeyPatch, tool: str, language: str
) -> None:
    real_which = shutil.which
    monkeypatch.setattr(shutil, "which", lambda name: None if name == tool else real_which(name))
    with pytest.raises(
        BuildError, match=rf"^{tool} not found: install it with `apt-get install -y {tool}`$"
    ):
        build.build(source_dir, language)  # type: ignore[arg-type]


def test_compile_error_shows_the_compiler_message(
    source_dir: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    src = tmp_path / "src"
    shutil.copytree(source_dir, src)
    text = (src / "gyrostat.c").read_text().replace("return GYROSTAT_OK;", "return GYROSTAT_OK")
    (src / "gyrostat.c").write_text(text)
    with pytest.raises(BuildError) as info:
        build.build(src, "c")
    msg = str(info.value)
    assert msg.startswith("gcc failed on gyrostat.c:")
    assert "error: expected" in msg and "before" in msg
    assert not [p for p in (tmp_path / "cache").iterdir() if not p.name.startswith(".")]


def test_missing_manifest(tmp_path: Path) -> None:
    with pytest.raises(BuildError, match=r"no manifest\.json in"):
        build.build(tmp_path, "c")
