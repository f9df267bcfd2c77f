"""The library build files (gyrogen.codegen.buildfiles.files): a CMakeLists.txt that
builds lib<prefix>.a and .so alone or under add_subdirectory, and a Makefile
fragment that builds the same with make. The libraries are checked by
calling them, against the cffi-built backend."""

from __future__ import annotations

import ctypes
import json
import shutil
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from wide import WIDE

from gyrogen.codegen import buildfiles
from gyrogen.errors import GyrogenError
from gyrogen.runtime.compiled import Compiled

REPO = Path(__file__).resolve().parents[1]
P = np.array([500.0, 10.0, 100.0, 80.0, 120.0, 5.0, 0.05, 0.1, 0.2, -0.1, 0.0, 0.01])


def manifest(source_dir: Path) -> dict[str, Any]:
    return dict(json.loads((source_dir / "manifest.json").read_text()))


@pytest.fixture
def lib_dir(source_dir: Path, tmp_path: Path) -> Path:
    """A copy of the generated sources with the build files written beside them."""
    out = tmp_path / "gyrostat"
    shutil.copytree(source_dir, out)
    for name, text in buildfiles.files(manifest(source_dir)).items():
        (out / name).write_text(text)
    return out


def run(cmd: list[str], cwd: Path) -> str:
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, f"{' '.join(cmd)}\n{proc.stdout}{proc.stderr}"
    return proc.stdout


def check_shared(so: Path, backend: Compiled) -> None:
    """Load the shared library and call setup: the same constants as cffi's."""
    lib = ctypes.CDLL(str(so))
    c = np.zeros(backend.nc)
    dptr = ctypes.POINTER(ctypes.c_double)
    code = lib.gyrostat_setup(P.ctypes.data_as(dptr), c.ctypes.data_as(dptr))
    assert code == 0
    np.testing.assert_array_equal(c, backend.setup(P))


def test_every_file_says_where_it_came_from(source_dir: Path) -> None:
    out = buildfiles.files(manifest(source_dir))
    assert set(out) == {
        "CMakeLists.txt",
        "gyrostat.mk",
        "gyrostatConfig.cmake.in",
        "gyrostat.pc.in",
    }
    for name, text in out.items():
        head = "\n".join(text.splitlines()[:6])
        assert head.startswith(f"# {name}:")
        assert "Do not edit" in head
        assert "template lib/" in head
    assert buildfiles.files(manifest(source_dir)) == out  # deterministic


def test_without_fortran_there_is_no_fortran_library(source_dir: Path) -> None:
    m = manifest(source_dir)
    m["files"] = {k: v for k, v in m["files"].items() if k != "fortran"}
    out = buildfiles.files(m)
    assert "gyrostat_f" not in out["CMakeLists.txt"]
    assert "gyrostat_f" not in out["gyrostat.mk"]


def test_a_manifest_without_files_is_an_error(source_dir: Path) -> None:
    m = manifest(source_dir)
    del m["files"]
    with pytest.raises(GyrogenError, match=r"manifest\.json lacks 'files'"):
        buildfiles.files(m)


def test_a_scene_without_c_is_an_error(source_dir: Path) -> None:
    m = manifest(source_dir)
    m["files"] = {"fortran": "gyrostat.f90"}
    with pytest.raises(GyrogenError, match="has no C sources"):
        buildfiles.files(m)


COMPILE_COMMANDS = "-DCMAKE_EXPORT_COMPILE_COMMANDS=ON"


def compile_flags(build: Path, source: str) -> str:
    """The command CMake compiles a source file with (compile_commands.json)."""
    commands = json.loads((build / "compile_commands.json").read_text())
    return next(c["command"] for c in commands if c["file"].endswith(f"/{source}"))


@pytest.mark.slow
@WIDE
def test_cmake_alone(lib_dir: Path, tmp_path: Path, backends: dict[str, Compiled]) -> None:
    """On its own: Release, one static C library, no Fortran unless asked for;
    with BUILD_SHARED_LIBS a shared one with a SOVERSION."""
    out = tmp_path / "build"
    run(
        ["cmake", "-S", str(lib_dir), "-B", str(out), "-DCMAKE_EXPORT_COMPILE_COMMANDS=ON"],
        tmp_path,
    )
    run(["cmake", "--build", str(out)], tmp_path)
    assert sorted(p.name for p in out.glob("lib*")) == ["libgyrostat.a"]
    assert "-O3" in compile_flags(out, "gyrostat.c")  # CMake's Release
    assert "GYROSTAT_FORTRAN:BOOL=OFF" in (out / "CMakeCache.txt").read_text()
    shared = tmp_path / "shared"
    run(["cmake", "-S", str(lib_dir), "-B", str(shared), "-DBUILD_SHARED_LIBS=ON"], tmp_path)
    run(["cmake", "--build", str(shared)], tmp_path)
    assert sorted(p.name for p in shared.glob("lib*")) == [
        "libgyrostat.so",
        "libgyrostat.so.0.1",
        "libgyrostat.so.0.1.0",
    ]
    assert "SONAME               libgyrostat.so.0.1" in run(
        ["objdump", "-p", str(shared / "libgyrostat.so")], tmp_path
    )
    check_shared(shared / "libgyrostat.so", backends["c"])


@pytest.mark.slow
def test_cmake_add_subdirectory(lib_dir: Path, tmp_path: Path) -> None:
    """A parent project that enables Fortran gets both libraries through
    their alias targets; the C and Fortran examples print the same. The
    parent gives no build type, and the library is still optimised."""
    parent = tmp_path / "parent"
    parent.mkdir()
    shutil.move(lib_dir, parent / "gyrostat")
    shutil.copy(REPO / "examples" / "embed_c" / "main.c", parent / "app.c")
    shutil.copy(REPO / "examples" / "embed_fortran" / "main.f90", parent / "fapp.f90")
    (parent / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.15)\n"
        "project(app LANGUAGES C Fortran)\n"
        "add_subdirectory(gyrostat)\n"
        "add_executable(app app.c)\n"
        "target_link_libraries(app PRIVATE gyrostat::gyrostat)\n"
        "add_executable(fapp fapp.f90)\n"
        "target_link_libraries(fapp PRIVATE gyrostat::gyrostat_f)\n"
    )
    out = tmp_path / "build"
    run(
        ["cmake", "-S", str(parent), "-B", str(out), "-DCMAKE_EXPORT_COMPILE_COMMANDS=ON"], tmp_path
    )
    run(["cmake", "--build", str(out)], tmp_path)
    assert "-O2" in compile_flags(out, "gyrostat_ode.c")
    assert "-O" not in compile_flags(out, "app.c")  # the parent's own choice is left alone
    c = run([str(out / "app")], tmp_path)
    fortran = run([str(out / "fapp")], tmp_path)
    values = [[float(line.split()[1]) for line in o.splitlines()] for o in (c, fortran)]
    np.testing.assert_allclose(values[1], values[0], rtol=1e-12, atol=1e-15)
    assert not list((out / "gyrostat" / "include").glob("*.c"))  # headers only


@pytest.mark.slow
@WIDE
def test_make_fragment(lib_dir: Path, tmp_path: Path, backends: dict[str, Compiled]) -> None:
    """Included from a user's Makefile in another directory, outputs elsewhere."""
    user = tmp_path / "user"
    user.mkdir()
    shutil.copy(REPO / "examples" / "embed_c" / "main.c", user / "app.c")
    (user / "Makefile").write_text(
        "GYROSTAT_BUILD := out\n"
        f"include {lib_dir}/gyrostat.mk\n"
        "app: app.c $(GYROSTAT_BUILD)/libgyrostat.a\n"
        "\t$(CC) $(GYROSTAT_CPPFLAGS) -o $@ app.c $(GYROSTAT_BUILD)/libgyrostat.a"
        " $(GYROSTAT_LDLIBS)\n"
    )
    # No goal: the user's first rule, not the fragment's, is the default.
    run(["make", "-s"], user)
    assert (user / "app").is_file()
    assert len(run([str(user / "app")], user).splitlines()) == 18
    run(["make", "-s", "out/libgyrostat.so", "out/libgyrostat_f.a"], user)
    assert (user / "out" / "gyrostat_mod.mod").is_file()
    check_shared(user / "out" / "libgyrostat.so", backends["c"])
    assert not list(lib_dir.glob("*.o"))  # nothing written beside the sources
