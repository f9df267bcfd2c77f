"""<prefix>_f.h, the C declarations of the Fortran bind(C) procedures, against
what gfortran itself says they are (-fc-prototypes), and the Fortran
strerror functions against the registry."""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import pytest

from gyrogen import abi
from gyrogen.runtime.flags import FORTRAN_STRICT

PROTOTYPE = re.compile(r"([A-Za-z_][\w ]*?\**)\s*\b(\w+)\s*\(([^()]*)\)\s*;")


def run(cmd: list[str], cwd: Path) -> str:
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, f"{' '.join(cmd)}\n{proc.stdout}{proc.stderr}"
    return proc.stdout


def normalized(ctype: str) -> str:
    """A C type as the ABI sees it, in gfortran's spelling: its c_size_t is
    long (the same width on every ABI gfortran serves), and a type(c_ptr)
    argument is void *, which any object pointer passes as."""
    ctype = " ".join(ctype.replace("*", " * ").split())
    if ctype.endswith("*") and not ctype.startswith(("double", "const double")):
        return "void *"
    return ctype.replace("size_t", "long")


def prototypes(text: str) -> dict[str, tuple[str, ...]]:
    """name -> (result type, argument types...) of every declaration."""
    out = {}
    lines = [line for line in text.splitlines() if not line.startswith("#")]
    for ret, name, args in PROTOTYPE.findall(re.sub(r"/\*.*?\*/", " ", " ".join(lines))):
        types = [a.strip().rsplit(" ", 1)[0] if "*" not in a else a[: a.rindex("*") + 1]
                 for a in args.split(",")]  # fmt: skip
        out[name] = tuple(normalized(t) for t in [ret, *types])
    return out


def test_the_header_declares_what_gfortran_compiled(source_dir: Path, tmp_path: Path) -> None:
    sources = [str(source_dir / f) for f in ("gyrostat.f90", "gyrostat_ode.f90")]
    fortran = run(["gfortran", "-fc-prototypes", "-fsyntax-only", *sources], tmp_path)
    ours = prototypes((source_dir / "gyrostat_f.h").read_text())
    theirs = prototypes(fortran)
    methods = json.loads((source_dir / "manifest.json").read_text())["integrators"]
    adaptive = [m for m in methods if m != "rk4"]  # each with _grid and _grid_batch
    assert set(ours) == set(theirs)
    assert len(ours) == 3 + 2 * len(methods) + 2 * len(adaptive)  # setup, rhs, jac
    for name, types in ours.items():
        assert types == theirs[name], name


@pytest.fixture
def strerror_program(source_dir: Path, tmp_path: Path) -> Path:
    """A Fortran program printing each code's message, setup's then the
    integrators', from -1 to 8."""
    (tmp_path / "codes.f90").write_text(
        "program codes\n"
        "  use gyrostat_mod, only: gyrostat_strerror\n"
        "  use gyrostat_ode_mod, only: gyrostat_ode_strerror\n"
        "  implicit none\n"
        "  integer :: k\n"
        "  do k = -1, 8\n"
        "    write (*, '(a)') trim(gyrostat_strerror(k))\n"
        "  end do\n"
        "  do k = -1, 8\n"
        "    write (*, '(a)') trim(gyrostat_ode_strerror(k))\n"
        "  end do\n"
        "end program codes\n"
    )
    sources = [str(source_dir / f) for f in ("gyrostat.f90", "gyrostat_ode.f90")]
    run(["gfortran", *FORTRAN_STRICT, "-O0", *sources, "codes.f90", "-o", "codes"],
        tmp_path)  # fmt: skip
    return tmp_path / "codes"


def test_fortran_strerror(strerror_program: Path, source_dir: Path) -> None:
    """Each code the scene's setup can return (the manifest's: a cluster's
    axis code 8 not among the default scene's) and every integrator code."""
    lines = run([str(strerror_program)], strerror_program.parent).splitlines()
    made = json.loads((source_dir / "manifest.json").read_text())["setup_codes"]
    setup = tuple(c for c in abi.SETUP_CODES if str(c.value) in made)
    assert [c.value for c in setup] == [*range(8), 9]
    for codes, printed in ((setup, lines[:10]), (abi.ODE_CODES, lines[10:])):
        expected = [abi.message(codes, k) if k in {c.value for c in codes} else abi.UNKNOWN_CODE
                    for k in range(-1, 9)]  # fmt: skip
        assert printed == expected
