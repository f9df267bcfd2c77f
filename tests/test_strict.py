"""The strictness matrix on the generated default scene: two C
compilers, two standards, every warning an error; the header from C++; the
Fortran module; and the examples under AddressSanitizer + UBSan and valgrind.

No test here is skipped for a missing tool: `make setup` installs clang and
valgrind, so a missing one is a failure that says what to install.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest
from conftest import built_once
from wide import WIDE

from gyrogen.runtime.flags import C_STRICT, FORTRAN_STRICT
from gyrogen.runtime.flags import C_WARNINGS as CXX_WARNINGS

pytestmark = pytest.mark.slow  # every compiler and standard, sanitizers, valgrind

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"
C_WARNINGS = C_STRICT[1:]  # the standard is each test's own


def tool(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        pytest.fail(f"{name} not found: `make setup` installs it (apt-get install -y {name})")
    return path


SANITIZE = ("-fsanitize=address,undefined", "-fno-omit-frame-pointer")
SANITIZER_RUNTIME = {"gcc": "libgcc-12-dev", "clang": "libclang-rt-dev"}
"""The Debian package that holds each compiler's sanitizer runtime (the
Makefile's SYSTEM_PACKAGES installs both): clang's is a separate package."""
DEBUG = {"gcc": "-g -fno-var-tracking-assignments", "clang": "-g"}
"""-g for the sanitizers' reports, without gcc's variable-tracking
assignments: they alone took gcc -O1 -fsanitize on the default scene's
gyrostat_ode.c (one 140 kB function) from 19 s to 70-280 s, and they
change the debug information only, not the code (objdump -d the same)."""
OPT = {"gcc": "-O1", "clang": "-O0"}
"""Each sanitized build's optimization: clang -O1 -fsanitize took 44 s on
gyrostat_ode.c alone (and the whole clang build 230 s of the suite), -O0
3.6 s; ASan and UBSan instrument the same accesses and operations at -O0,
and gcc's build keeps -O1."""


def sanitizer(cc: str, tmp_path: Path) -> str:
    """cc's path, once a small program built with SANITIZE links; else a
    failure that names the package to install."""
    path = tool(cc)
    (tmp_path / "probe.c").write_text("int main(void) { return 0; }\n")
    proc = subprocess.run([path, *SANITIZE, "probe.c", "-o", "probe"], cwd=tmp_path,
                          capture_output=True, text=True, check=False)  # fmt: skip
    if proc.returncode != 0:
        pkg = SANITIZER_RUNTIME[cc]
        pytest.fail(
            f"{cc} cannot link with {' '.join(SANITIZE)}: its sanitizer runtime is missing: "
            f"`make setup` installs it (apt-get install -y {pkg})\n{proc.stderr}"
        )
    return path


def clean(cmd: list[str], cwd: Path, env: dict[str, str] | None = None) -> str:
    """Run cmd; it must succeed and say nothing on stderr. Returns stdout."""
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, f"{' '.join(cmd)}\n{proc.stdout}{proc.stderr}"
    assert proc.stderr == "", proc.stderr
    return proc.stdout


@pytest.mark.parametrize("std", ["c99", "c11"])
@pytest.mark.parametrize("cc", ["gcc", "clang"])
def test_generated_c(source_dir: Path, tmp_path: Path, cc: str, std: str) -> None:
    for name in ("gyrostat.c", "gyrostat_ode.c"):
        clean([tool(cc), f"-std={std}", *C_WARNINGS, "-c", str(source_dir / name),
               "-o", str(tmp_path / "g.o")], tmp_path)  # fmt: skip


@pytest.mark.parametrize("std", ["c99", "c11"])
@pytest.mark.parametrize("cc", ["gcc", "clang"])
def test_c_example(source_dir: Path, tmp_path: Path, cc: str, std: str) -> None:
    """The example holds itself to the same flags as the code it embeds."""
    main = EXAMPLES / "embed_c" / "main.c"
    clean([tool(cc), f"-std={std}", *C_WARNINGS, f"-I{source_dir}", "-c", str(main),
           "-o", str(tmp_path / "main.o")], tmp_path)  # fmt: skip


def test_header_from_cxx(source_dir: Path, tmp_path: Path) -> None:
    """A C++ program includes the header, takes both functions by their
    types, links the C object and calls them."""
    main = tmp_path / "main.cpp"
    main.write_text(
        '#include "gyrostat.h"\n#include <cstdio>\n'
        "int (*const setup)(const double *, double *) = gyrostat_setup;\n"
        "void (*const rhs)(double, const double *, const double *, double *) = gyrostat_rhs;\n"
        "int main() {\n"
        "  double p[GYROSTAT_NP] = {10, 2, 3, 4, 5, 0.3, 0.5, 0.8, 0.2, -0.1, 9.81, 0.5};\n"
        "  double c[GYROSTAT_NC], x[GYROSTAT_NX] = {0}, d[GYROSTAT_NX];\n"
        "  if (setup(p, c) != GYROSTAT_OK) return 1;\n"
        "  rhs(0.0, x, c, d);\n"
        '  std::printf("%.6f\\n", d[13]);\n  return 0;\n}\n'
    )
    clean([tool("gcc"), "-std=c99", "-O2", "-c", str(source_dir / "gyrostat.c"), "-o", "g.o"],
          tmp_path)  # fmt: skip
    clean([tool("g++"), "-std=c++17", *CXX_WARNINGS,
           f"-I{source_dir}", "main.cpp", "g.o", "-lm", "-o", "main"], tmp_path)  # fmt: skip
    assert clean([str(tmp_path / "main")], tmp_path).strip() == "9.810000"


def test_cpp_example(source_dir: Path, tmp_path: Path) -> None:
    clean([tool("g++"), "-std=c++17", *CXX_WARNINGS,
           f"-I{source_dir}", "-c", str(EXAMPLES / "embed_cpp" / "main.cpp"), "-o", "m.o"],
          tmp_path)  # fmt: skip


def test_fortran(source_dir: Path, tmp_path: Path) -> None:
    """The modules and the example that uses them."""
    flags = [*FORTRAN_STRICT, "-J", "."]
    gf = tool("gfortran")
    clean([gf, *flags, "-c", str(source_dir / "gyrostat.f90"), "-o", "g.o"], tmp_path)
    clean([gf, *flags, "-c", str(source_dir / "gyrostat_ode.f90"), "-o", "o.o"], tmp_path)
    clean([gf, *flags, "-c", str(EXAMPLES / "embed_fortran" / "main.f90"), "-o", "m.o"], tmp_path)


def build_examples(source_dir: Path, build: Path, *overrides: str, target: str = "all") -> None:
    clean(["make", "-s", "-C", str(EXAMPLES), f"BUILD={build}", f"GEN={source_dir}",
           *overrides, target], EXAMPLES)  # fmt: skip


def sanitized_examples(source_dir: Path, tmp_path_factory: pytest.TempPathFactory, cc: str) -> Path:
    """The C example built by examples/Makefile with ASan and UBSan by cc,
    with the default scene's library under the same flags installed in its
    prefix/: built once per run and compiler (its rhs, one 140 kB function,
    is the long compile), for the example and the verify harness alike."""
    sanitize = " ".join(SANITIZE)

    def make(build: Path) -> None:
        build.mkdir()
        build_examples(
            source_dir,
            build,
            f"CC={sanitizer(cc, build)}",
            f"CFLAGS=-std=c99 {OPT[cc]} {DEBUG[cc]} {sanitize}",
            f"LDFLAGS={sanitize}",
            # no -O3 of Release after CFLAGS' -O1 or -O0: 90 s of ASan compiles were that
            "BUILD_TYPE=Debug",
            target=str(build / "embed_c"),
        )

    return built_once(tmp_path_factory, f"sanitized-{cc}", make)


SANITIZER_ENV = {"ASAN_OPTIONS": "detect_leaks=1", "UBSAN_OPTIONS": "halt_on_error=1"}


@pytest.mark.parametrize("cc", ["gcc", "clang"])
@WIDE
def test_c_example_under_sanitizers(
    source_dir: Path, tmp_path_factory: pytest.TempPathFactory, tmp_path: Path, cc: str
) -> None:
    build = sanitized_examples(source_dir, tmp_path_factory, cc)
    out = clean([str(build / "embed_c")], tmp_path, dict(os.environ, **SANITIZER_ENV))
    assert out.count("\n") == 18  # 14 states, 3 components of H, its norm


@pytest.mark.parametrize("program", ["embed_c", "embed_fortran"])
def test_examples_under_valgrind(examples_build: Path, program: str) -> None:
    """The examples as `make examples` builds them (conftest.examples_build)."""
    proc = subprocess.run(
        [tool("valgrind"), "-q", "--error-exitcode=1", "--leak-check=full",
         str(examples_build / program)],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == "", proc.stderr  # -q: memcheck speaks only of errors


@pytest.mark.parametrize("cc", [pytest.param("gcc", marks=WIDE), "clang"])
def test_verify_path_under_sanitizers(
    source_dir: Path, tmp_path_factory: pytest.TempPathFactory, tmp_path: Path, cc: str
) -> None:
    """setup, rhs and two integrators on random valid and invalid inputs,
    built with ASan and UBSan (the library of sanitized_examples) and
    checked against the numpy reference (clang's in the suite, gcc's in
    `make test-wide`: 80 s of ASan compiles)."""
    import numpy as np
    from scipy.integrate import solve_ivp

    from gyrogen.oracle import reference, sampling

    rng = np.random.default_rng(12)
    valid = sampling.random_parameters(rng, 8, max_condition=100)
    invalid = [p for _, p, _ in sampling.invalid_parameters(valid[0])]
    params = np.vstack([valid, invalid])
    states = sampling.random_states(rng, 50)
    states[:, 10] = np.clip(states[:, 10], -20, 20)  # keep the short integrations cheap
    blob = np.array([len(params), len(states)], dtype=np.int32).tobytes()
    (tmp_path / "in.bin").write_bytes(blob + params.tobytes() + states.tobytes())
    prefix = sanitized_examples(source_dir, tmp_path_factory, cc) / "prefix"
    (library,) = prefix.glob("lib*/libgyrostat.a")  # setup and rhs built with the sanitizers
    sanitize = [*SANITIZE, *DEBUG[cc].split(), OPT[cc]]
    harness = Path(__file__).parent / "harness" / "verify.c"
    clean([sanitizer(cc, tmp_path), "-std=c99", *sanitize, f"-I{prefix / 'include' / 'gyrostat'}",
           str(harness), str(library), "-lm", "-o", "verify"], tmp_path)  # fmt: skip
    clean(
        [str(tmp_path / "verify"), "in.bin", "out.bin"], tmp_path, dict(os.environ, **SANITIZER_ENV)
    )
    out, pos = (tmp_path / "out.bin").read_bytes(), 0
    nx = 14
    for p in params:
        code = int(np.frombuffer(out, np.int32, 1, pos)[0])
        pos += 4
        assert code == sampling.setup_code(p)
        if code:
            continue
        got = np.frombuffer(out, np.float64, len(states) * nx, pos).reshape(-1, nx)
        pos += got.nbytes
        ref = reference.rhs(states, p)
        assert np.max(np.abs(got - ref) / (1 + np.abs(ref))) < 1e-12
        finals = np.frombuffer(out, np.float64, 6 * nx, pos).reshape(6, nx)
        pos += finals.nbytes
        for k in range(3):
            sol = solve_ivp(lambda t, y, p=p: reference.rhs(y, p), (0, 0.5), states[k],
                            method="DOP853", rtol=1e-12, atol=1e-12)  # fmt: skip
            for final in (finals[k], finals[3 + k]):
                assert np.max(np.abs(final - sol.y[:, -1]) / (1 + np.abs(sol.y[:, -1]))) < 1e-7
    assert pos == len(out)
