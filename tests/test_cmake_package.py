"""The library as an outside developer uses it: installed with
`cmake --install` and found by find_package, or by pkg-config; pulled into a
C-only parent with add_subdirectory on a machine view with no Fortran
compiler; and driven through ctypes from the installed manifest.json alone.

One installed package (shared, with the Fortran library) serves the module;
the examples (tests/test_examples.py) use the static one the same way.
"""

from __future__ import annotations

import ctypes
import json
import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from wide import WIDE

from gyrogen import abi
from gyrogen.codegen.generate import generate
from gyrogen.codegen.render import hash_comment
from gyrogen.oracle import reference
from gyrogen.runtime.flags import C_WARNINGS
from gyrogen.scene import builtin_text, parse

pytestmark = pytest.mark.slow  # the CMake package configured, built and installed

CONSUMERS = Path(__file__).resolve().parent / "consumers"
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def run(cmd: list[str], cwd: Path, env: dict[str, str] | None = None) -> str:
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, f"{' '.join(cmd)}\n{proc.stdout}{proc.stderr}"
    return proc.stdout


def cmake(source: Path, build: Path, cwd: Path, *options: str, install: Path | None = None,
          env: dict[str, str] | None = None) -> None:  # fmt: skip
    """source configured into build with options, built, and installed into install."""
    run(["cmake", "-S", str(source), "-B", str(build), *options], cwd, env)
    run(["cmake", "--build", str(build)], cwd, env)
    if install is not None:
        run(["cmake", "--install", str(build), "--prefix", str(install)], cwd, env)


def consumer(find: str, exe: str, libs: str) -> str:
    """A C project's CMakeLists.txt that finds the package and links exe.c to libs."""
    return (
        "cmake_minimum_required(VERSION 3.15)\n"
        "project(consumer LANGUAGES C)\n"
        f"find_package({find})\n"
        f"add_executable({exe} {exe}.c)\n"
        f"target_link_libraries({exe} PRIVATE {libs} m)\n"
    )


def pairs(stdout: str) -> dict[str, str]:
    return dict(line.split(" ", 1) for line in stdout.splitlines())


@pytest.fixture(scope="module")
def prefix(source_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """generated/gyrostat built shared with Fortran, installed into a prefix."""
    work = tmp_path_factory.mktemp("package")
    build, prefix = work / "build", work / "prefix"
    cmake(
        source_dir, build, work, "-DBUILD_SHARED_LIBS=ON", "-DGYROSTAT_FORTRAN=ON", install=prefix
    )
    return prefix


@WIDE
def test_install_lays_out_a_package(prefix: Path) -> None:
    files = {str(p.relative_to(prefix)) for p in prefix.rglob("*") if not p.is_dir()}
    expected = {
        "include/gyrostat/gyrostat.h",
        "include/gyrostat/gyrostat_ode.h",
        "include/gyrostat/gyrostat_f.h",
        "include/gyrostat/gyrostat_mod.mod",
        "include/gyrostat/gyrostat_ode_mod.mod",
        "lib/libgyrostat.so",
        "lib/libgyrostat_f.so",
        "lib/cmake/gyrostat/gyrostatConfig.cmake",
        "lib/cmake/gyrostat/gyrostatConfigVersion.cmake",
        "lib/cmake/gyrostat/gyrostatTargets.cmake",
        "lib/pkgconfig/gyrostat.pc",
        "share/gyrostat/manifest.json",
    }
    assert expected <= files
    assert not [f for f in files if f.endswith((".c", ".f90"))]  # no sources


def test_find_package_from_c_calling_c_and_fortran(prefix: Path, tmp_path: Path) -> None:
    """A consumer project finds the package (version and Fortran component),
    and a C program calls the C library and, through gyrostat_f.h, the
    Fortran one: the same numbers, the same refusals."""
    project = tmp_path / "consumer"
    project.mkdir()
    shutil.copy(CONSUMERS / "c_and_fortran.c", project / "mixed.c")
    libs = "gyrostat::gyrostat gyrostat::gyrostat_f"
    (project / "CMakeLists.txt").write_text(
        consumer("gyrostat 0.1 REQUIRED COMPONENTS Fortran", "mixed", libs)
    )
    build = tmp_path / "build"
    cmake(project, build, tmp_path, f"-DCMAKE_PREFIX_PATH={prefix}")
    out = pairs(run([str(build / "mixed")], tmp_path))
    assert out["setup_codes"] == "0" and out["dop853_codes"] == "0"
    assert float(out["rhs_difference"]) <= 1e-14
    assert float(out["jac_difference"]) <= 1e-14
    assert float(out["dop853_difference"]) <= 1e-12
    assert out["refused"] == f"5 {abi.message(abi.ODE_CODES, 5)}"  # the last one printed
    assert run([str(build / "mixed")], tmp_path).splitlines()[-2] == (
        f"refused 2 {abi.message(abi.SETUP_CODES, 2)}"
    )


def test_pkg_config(prefix: Path, tmp_path: Path) -> None:
    """cc app.c $(pkg-config --cflags --libs gyrostat): the C example."""
    env = dict(os.environ, PKG_CONFIG_PATH=str(prefix / "lib" / "pkgconfig"))
    flags = run(["pkg-config", "--cflags", "--libs", "gyrostat"], tmp_path, env).split()
    assert f"-I{prefix}/lib/pkgconfig/../../include/gyrostat" in flags
    libdir = run(["pkg-config", "--variable=libdir", "gyrostat"], tmp_path, env).strip()
    app = tmp_path / "app"
    run(["gcc", "-std=c99", *C_WARNINGS, str(EXAMPLES / "embed_c" / "main.c"), "-o",
         str(app), *flags, "-lm", f"-Wl,-rpath,{libdir}"], tmp_path)  # fmt: skip
    lines = run([str(app)], tmp_path).splitlines()
    assert [line.split()[0] for line in lines][:2] == ["q1", "q2"] and len(lines) == 18


HOSTILE = (
    "@CMAKE_INSTALL_PREFIX@ ${x} $ENV{HOME} @PACKAGE_INIT@ @GYROSTAT_PC_LIBS@ a@b@c @@ @\n"
    "#cmakedefine FOO\ncmakedefine01 BAR\n  #cmakedefine BAZ 1\nset(x 1) \\\n"
    "Libs: -lhostile\n#[[ not a bracket comment\n]] a trailing backslash \\"
)
"""A description CMake's configure_file would act on in a comment: @VAR@
substituted (@PACKAGE_INIT@'s lines live), #cmakedefine lines made live;
and lines that would be live out of a comment (a backslash ending one)."""


def live(path: Path) -> list[str]:
    """The lines of a CMake or pkg-config file that are not comments."""
    return [line for line in path.read_text().splitlines() if not line.startswith("#")]


def test_a_hostile_description_stays_in_the_comments(prefix: Path, tmp_path: Path) -> None:
    """The scene's description is copied into the comments of the config and
    the .pc file that configure_file writes: installed, each holds it as
    written, in comments only; their live lines are the plain scene's; a
    consumer finds the package and runs, and pkg-config reads it."""
    text = builtin_text("gyrostat")
    line = next(line for line in text.splitlines() if line.startswith("description = "))
    scene = parse(text.replace(line, f"description = {json.dumps(HOSTILE)}"), "hostile.toml")
    assert scene.description == HOSTILE
    source, build, mine = tmp_path / "gyrostat", tmp_path / "build", tmp_path / "prefix"
    generate(scene, source, lib=True)
    # Debug (-O0): the comments are what is tested here; the package's Release build is prefix's
    cmake(source, build, tmp_path, "-DBUILD_SHARED_LIBS=ON", "-DCMAKE_BUILD_TYPE=Debug",
          install=mine)  # fmt: skip
    for where in ("lib/cmake/gyrostat/gyrostatConfig.cmake", "lib/pkgconfig/gyrostat.pc"):
        name = Path(where).name + ".in"
        installed = (mine / where).read_text()
        assert installed.startswith(f"# {name}: builds gyrostat ({hash_comment(HOSTILE)}) as a")
        assert live(mine / where) == live(prefix / where)
    project = tmp_path / "consumer"
    project.mkdir()
    shutil.copy(EXAMPLES / "embed_c" / "main.c", project / "app.c")
    (project / "CMakeLists.txt").write_text(
        consumer("gyrostat 0.1 REQUIRED", "app", "gyrostat::gyrostat")
    )
    out = tmp_path / "consumer-build"
    cmake(project, out, tmp_path, f"-DCMAKE_PREFIX_PATH={mine}")
    assert len(run([str(out / "app")], tmp_path).splitlines()) == 18
    env = dict(os.environ, PKG_CONFIG_PATH=str(mine / "lib" / "pkgconfig"))
    flags = run(["pkg-config", "--cflags", "--libs", "gyrostat"], tmp_path, env).split()
    assert flags == [f"-I{mine}/lib/pkgconfig/../../include/gyrostat",
                     f"-L{mine}/lib/pkgconfig/../../lib", "-lgyrostat"]  # fmt: skip


VIEW = "-DCMAKE_FIND_USE_CMAKE_SYSTEM_PATH=OFF"
"""CMake looks for programs on PATH and, beyond it, in the system's own
directories (/usr/bin): in the machine view, only on PATH."""


def machine_view(tmp_path: Path) -> dict[str, str]:
    """An environment whose PATH holds the C toolchain, make and CMake, but
    no Fortran compiler: a machine without gfortran, as CMake sees it (with
    VIEW). The tools are scripts that run the real ones, not links: CMake
    resolves a link and would look for a Fortran compiler beside gcc."""
    view = tmp_path / "bin"
    view.mkdir()
    for tool in ("cmake", "make", "gcc", "cc", "ar", "ranlib", "as", "ld"):
        found = shutil.which(tool)
        assert found, f"{tool} not found"
        script = view / tool
        script.write_text(f'#!/bin/sh\nexec {Path(found).resolve()} "$@"\n')
        script.chmod(0o755)
    assert shutil.which("gfortran", path=str(view)) is None
    return {"PATH": str(view), "HOME": str(tmp_path)}


def test_add_subdirectory_from_a_c_only_parent_without_gfortran(
    source_dir: Path, tmp_path: Path
) -> None:
    """The parent enables C only: the library never looks for Fortran, so
    no Fortran compiler is needed; asking for it there fails, which shows
    the view really has none."""
    parent = tmp_path / "parent"
    parent.mkdir()
    shutil.copytree(source_dir, parent / "gyrostat")
    shutil.copy(EXAMPLES / "embed_c" / "main.c", parent / "app.c")
    (parent / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.15)\n"
        "project(app LANGUAGES C)\n"
        "add_subdirectory(gyrostat)\n"
        "add_executable(app app.c)\n"
        "target_link_libraries(app PRIVATE gyrostat::gyrostat)\n"
    )
    env = machine_view(tmp_path)
    build = tmp_path / "build"
    cmake(parent, build, tmp_path, VIEW, env=env)
    assert len(run([str(build / "app")], tmp_path).splitlines()) == 18
    cache = (build / "CMakeCache.txt").read_text()
    assert "GYROSTAT_FORTRAN:BOOL=OFF" in cache and "CMAKE_Fortran_COMPILER" not in cache
    asked = subprocess.run(
        ["cmake", "-S", str(parent), "-B", str(tmp_path / "asked"), VIEW, "-DGYROSTAT_FORTRAN=ON"],
        cwd=tmp_path, env=env, capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert asked.returncode != 0
    assert "No CMAKE_Fortran_COMPILER could be found" in asked.stderr


CTYPES = {
    "void": None,
    "int": ctypes.c_int,
    "long": ctypes.c_long,
    "size_t": ctypes.c_size_t,
    "double": ctypes.c_double,
    "const char *": ctypes.c_char_p,
    "double *": ctypes.POINTER(ctypes.c_double),
    "const double *": ctypes.POINTER(ctypes.c_double),
    "int *": ctypes.POINTER(ctypes.c_int),
}
"""The C types the manifest's signatures and structs use, as ctypes has them."""


class Library:
    """A shared library bound from the manifest alone: every function's
    argument and result types, and the stats struct's fields."""

    def __init__(self, path: Path, manifest: dict[str, Any], language: str) -> None:
        lib = ctypes.CDLL(str(path))
        self.types = dict(CTYPES)
        for name, fields in manifest["structs"].items():
            layout = [(f["name"], CTYPES[f["ctype"]]) for f in fields]
            self.types[f"{name} *"] = ctypes.POINTER(
                type(name, (ctypes.Structure,), {"_fields_": layout})
            )
        self.signatures = manifest["signatures"][language]
        self.functions = {}
        for key, sig in self.signatures.items():
            fn = getattr(lib, manifest["functions"][language][key])
            fn.restype = self.types[sig["returns"]]
            fn.argtypes = [self.types[a["ctype"]] for a in sig["args"]]
            self.functions[key] = fn

    def call(self, key: str, *scalars: float, **arrays: Any) -> tuple[Any, dict[str, Any]]:
        """Call key with its scalar arguments in order and its pointer
        arguments by name, each allocated from its count (and filled with
        the values given): the result, and every array by name."""
        filled, args, scalar = {}, [], iter(scalars)
        for arg in self.signatures[key]["args"]:
            if "count" not in arg:
                args.append(next(scalar))
                continue
            pointer = self.types[arg["ctype"]]
            array = (pointer._type_ * arg["count"])(*arrays.get(arg["name"], ()))
            filled[arg["name"]] = array
            args.append(ctypes.cast(array, pointer))
        return self.functions[key](*args), filled


def test_ctypes_from_the_manifest_alone(prefix: Path) -> None:
    """The installed manifest.json drives ctypes (no cffi): setup, rhs and
    dop853 of the C and the Fortran library, on the scene's own simulate
    values, against the numpy reference and each other; the refusals and
    what strerror says of every code."""
    m = json.loads((prefix / "share" / "gyrostat" / "manifest.json").read_text())
    sim = m["scene"]["simulate"]
    p = [sim["parameters"][name] for name in m["parameters"]]
    x0 = [sim["initial"].get(name, 0.0) for name in m["states"]]
    final = {}
    for language, name in (("c", "libgyrostat.so"), ("fortran", "libgyrostat_f.so")):
        lib = Library(prefix / "lib" / name, m, language)
        code, out = lib.call("setup", p=p)
        assert code == 0
        c = list(out["c"])
        _, out = lib.call("rhs", 0.0, x=x0, c=c)
        expected = reference.rhs(np.array(x0), np.array(p))
        np.testing.assert_allclose(list(out["dxdt"]), expected, rtol=1e-13, atol=1e-13)
        code, out = lib.call("dop853", 0.0, 1.0, 1e-10, 1e-10, 0.0, 10**5, x=x0, c=c)
        assert code == 0 and out["stats"][0].t == 1.0 and out["stats"][0].accepted > 0
        final[language] = list(out["x"])
        assert lib.call("setup", p=[-1.0, *p[1:]])[0] == 2
        assert lib.call("dop853", 0.0, 1.0, 0.0, 1e-10, 0.0, 10**5, x=x0, c=c)[0] == 5
    np.testing.assert_allclose(final["fortran"], final["c"], rtol=1e-12, atol=1e-12)
    lib = Library(prefix / "lib" / "libgyrostat.so", m, "c")
    for key, codes in (("strerror", m["setup_codes"]), ("ode_strerror", m["ode_codes"])):
        for value, message in codes.items():
            assert lib.call(key, int(value))[0].decode() == message
        assert lib.call(key, 99)[0].decode() == abi.UNKNOWN_CODE
