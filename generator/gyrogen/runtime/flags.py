"""The compiler flags of a local build (the cffi backends): the strict base
every build uses, plus what makes this machine's code fast where the
compiler takes it: -O3 -march=native, and -fopenmp (the _batch integrators
then run on every core), with nothing fused into an FMA
(-ffp-contract=off -fno-tree-slp-vectorize, see FAST), so that the numbers
do not depend on the CPU model. Each optional flag is probed once per
process with the compiler itself, the probes at once. The portable build files (`gyrogen
generate --lib`) keep plain -O2."""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
from concurrent.futures import ThreadPoolExecutor
from functools import cache
from pathlib import Path

from gyrogen.errors import BuildError

C_WARNINGS = ("-Wall", "-Wextra", "-Wpedantic", "-Werror")
"""Every warning an error: what gyrogen's own builds and the C++ view of a
header are held to."""
C_STRICT = ("-std=c99", "-Wall", "-Wextra", "-Wpedantic", "-Wconversion", "-Wshadow", "-Werror")
"""The strictness matrix's C (tests/test_strict.py, `make strict`): the generated C
compiles clean under it."""
FORTRAN_WARNINGS = ("-Wall", "-Wextra", "-Werror")
FORTRAN_STRICT = ("-std=f2008", "-Wall", "-Wextra", "-Wimplicit-interface", "-Werror")
"""The strictness matrix's Fortran."""
C_BASE = ("-std=c99", "-fPIC", "-fno-math-errno", *C_WARNINGS)
FORTRAN_BASE = ("-std=f2008", "-fPIC", "-fno-math-errno", *FORTRAN_WARNINGS)
FAST = ("-O3", "-march=native", "-ffp-contract=off", "-fno-tree-slp-vectorize")
"""-ffp-contract=off: each a * b + c rounds twice, in C and in Fortran,
whatever -march=native selects; with contraction (=fast, gcc's default for
Fortran and GNU C) which products become FMAs depends on the code the
vectorizer and the -march's cost model choose. -fno-tree-slp-vectorize:
gcc 12's straight-line (SLP) vectorizer fuses a * b - c, a * b + c in
neighbouring lanes into one vfmaddsub/vfmsubadd even under
-ffp-contract=off, and only under some -march (Intel's and x86-64-v3, not
znver3). Either made Fortran radau5 step differently from C on an Intel
CPU; loops are still vectorized, but a short loop with a
constant count is unrolled whole first and then left scalar unless the
description keeps it a loop (codegen.ir.nodes.For.vector)."""

OPENMP = "-fopenmp"

_PROBES = {
    "c": ("probe.c", "int main(void) { return 0; }\n"),
    "fortran": ("probe.f90", "program probe\nend program probe\n"),
}
_OPENMP_PROBES = {
    "c": ("probe.c", "#include <omp.h>\nint main(void) { return omp_get_max_threads() < 1; }\n"),
    "fortran": (
        "probe.f90",
        "program probe\n  use omp_lib\n  print *, omp_get_max_threads()\nend program probe\n",
    ),
}


@cache
def accepts(tool: str, language: str, flag: str) -> bool:
    """Whether tool compiles and links a small program with flag."""
    path = shutil.which(tool)
    if path is None:
        return False
    name, text = (_OPENMP_PROBES if flag == OPENMP else _PROBES)[language]
    with tempfile.TemporaryDirectory(prefix="gyrogen-flags-") as tmp:
        (Path(tmp) / name).write_text(text)
        proc = subprocess.run(
            [path, flag, "-Werror", name, "-o", "probe"],
            cwd=tmp,
            capture_output=True,
            check=False,
        )
    return proc.returncode == 0


PORTABLE = "GYROGEN_PORTABLE"
"""Set (to anything but empty or 0), a local build leaves out -march=native:
code for any CPU of the architecture (and a check that the numbers do not
depend on the instructions the CPU offers)."""


def env_portable() -> bool:
    return os.environ.get(PORTABLE, "") not in ("", "0")


OPT_LEVEL = "GYROGEN_OPT_LEVEL"
"""Set to 0, 1 or 2, a local build optimizes at that level instead of FAST's
-O3. The numbers are the same bits at every level (nothing is reassociated
or fused), the build is faster and the code slower: gcc 12 compiled the
default scene's largest file with events 2.6x faster at -O2 (22.5 s
against 8.5 s; gfortran 2.1x), and the explicit methods on stiff_wheel
took up to 2x longer per step (benchmarks/methods.py). The test suite
builds at -O2 (tests/conftest.py; `make test-fast` at -O3), the default
scene's backends at -O3."""


def opt_level() -> str:
    """The -O flag of a local build: -O3 unless GYROGEN_OPT_LEVEL says another."""
    value = os.environ.get(OPT_LEVEL, "").strip()
    if value in ("", "3"):
        return "-O3"
    if value in ("0", "1", "2"):
        return f"-O{value}"
    raise BuildError(f"{OPT_LEVEL}={value!r}: not an optimization level (0, 1, 2 or 3)")


def _optional(tool: str, language: str, native: bool) -> tuple[str, ...]:
    level = opt_level()
    wanted = [level if f == "-O3" else f for f in FAST if native or not f.startswith("-march")]
    with ThreadPoolExecutor(len(wanted) + 1) as pool:  # the probes at once: ~50 ms each
        taken = list(pool.map(lambda f: accepts(tool, language, f), [*wanted, OPENMP]))
    fast = tuple(f for f, ok in zip(wanted, taken, strict=False) if ok)
    return (fast or ("-O2",)) + ((OPENMP,) if taken[-1] else ())


def openmp(tool: str, language: str) -> bool:
    """Whether tool builds OpenMP code (omp.h and the runtime present)."""
    return accepts(tool, language, OPENMP)


def c_flags(tool: str = "gcc", portable: bool = False) -> tuple[str, ...]:
    """portable: without -march=native even when GYROGEN_PORTABLE is not set."""
    return C_BASE + _optional(tool, "c", not (portable or env_portable()))


def fortran_flags(tool: str = "gfortran", portable: bool = False) -> tuple[str, ...]:
    return FORTRAN_BASE + _optional(tool, "fortran", not (portable or env_portable()))


def flags_for(language: str, portable: bool = False) -> tuple[str, ...]:
    """A local build's flags for language ("c" or "fortran")."""
    return c_flags(portable=portable) if language == "c" else fortran_flags(portable=portable)


@cache
def native_target(tool: str = "gcc") -> str:
    """What -march=native means on this CPU to tool: its -march value and a
    digest of every target option it resolves to (the instruction sets the
    code may use). Two CPUs with another value may round differently."""
    path = shutil.which(tool)
    if path is None:
        return "unknown"
    proc = subprocess.run([path, "-march=native", "-Q", "--help=target"],
                          capture_output=True, text=True, check=False)  # fmt: skip
    options = sorted(" ".join(line.split()) for line in proc.stdout.splitlines()
                     if line.strip().startswith("-m"))  # fmt: skip
    march = next((o.split()[1] for o in options if o.startswith("-march=") and " " in o), "?")
    return f"{march}-{hashlib.sha256(chr(10).join(options).encode()).hexdigest()[:12]}"
