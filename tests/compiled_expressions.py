"""Expressions as a printer writes them, compiled strictly (gcc: C99 with
-Werror; gfortran: -std=f2008 -Werror) in one small program and run: their
values, for tests that hold a printer to what it means."""

from __future__ import annotations

import subprocess
from pathlib import Path


def values(
    language: str, texts: list[str], tmp_path: Path, x: float = 3.0, prelude: str = ""
) -> list[float]:
    """Each C or Fortran expression text's value, with the double x given
    (C: prelude, the functions they call, before main)."""
    if language == "c":
        body = "".join(f'    printf("%.17g\\n", {t});\n' for t in texts)
        src = tmp_path / "expressions.c"
        src.write_text(f"#include <stdio.h>\n#include <math.h>\n{prelude}int main(void) {{\n"
                       f"    volatile double x = {x!r};\n{body}    return 0;\n}}\n")  # fmt: skip
        command = ["gcc", "-std=c99", "-Wall", "-Wextra", "-Wpedantic", "-Werror"]
    else:
        body = "".join(f"  print '(es26.17e3)', {t}\n" for t in texts)
        src = tmp_path / "expressions.f90"
        src.write_text(f"program expressions\n  use, intrinsic :: iso_c_binding, only: c_double\n"
                       f"  implicit none\n  real(c_double) :: x\n  x = {x!r}_c_double\n{body}"
                       f"end program expressions\n")  # fmt: skip
        command = ["gfortran", "-std=f2008", "-Wall", "-Werror"]
    exe = tmp_path / f"expressions_{language}"
    made = subprocess.run([*command, str(src), "-o", str(exe), "-lm"], capture_output=True,
                          text=True, check=False)  # fmt: skip
    assert made.returncode == 0, made.stderr
    ran = subprocess.run([str(exe)], capture_output=True, text=True, check=True)
    return [float(v) for v in ran.stdout.split()]
