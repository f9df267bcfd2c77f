"""`make bench-lib`: what the CMake package's build type does to the rhs
(with no build type the library once built with no -O flag).

    python benchmarks/bench_cmake_default.py [--rounds N] [--out DIR]

A C-only parent project pulls generated/gyrostat in with add_subdirectory
and links benchmarks/rhs_timing.c (itself always at -O2) against it,
configured three ways side by side:

- no build type: what a parent that gives none gets now (the package adds -O2);
- Release: what the package on its own defaults to (CMake's -O3);
- None: a build type with no flags, i.e. `-std=c99 -fPIC` alone, the
  library's flags before the package added -O2 (the peer).

Each program reports its best of 7 runs of 2e6 calls, timed by the
process's CPU time (the machine is shared); the programs run in turn for N
rounds and the best of each is printed, in ns per rhs call.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIBRARY = ROOT / "generated" / "gyrostat"
TIMING = Path(__file__).resolve().parent / "rhs_timing.c"
BUILD_TYPES = {"no build type": None, "Release": "Release", "None (no -O flag)": "None"}
PARENT = """cmake_minimum_required(VERSION 3.15)
project(timing LANGUAGES C)
add_subdirectory(gyrostat)
add_executable(rhs_timing rhs_timing.c)
target_compile_options(rhs_timing PRIVATE -O2)
target_link_libraries(rhs_timing PRIVATE gyrostat::gyrostat)
"""


def run(cmd: list[str]) -> str:
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{proc.stdout}{proc.stderr}")
    return proc.stdout


def build(parent: Path, build_type: str | None, out: Path) -> tuple[Path, str]:
    """The timing program against the library configured with build_type,
    and the flags the library's rhs source was compiled with."""
    cmd = ["cmake", "-S", str(parent), "-B", str(out)]
    if build_type is not None:
        cmd.append(f"-DCMAKE_BUILD_TYPE={build_type}")
    run(cmd)
    run(["cmake", "--build", str(out)])
    flags = out / "gyrostat" / "CMakeFiles" / "gyrostat.dir" / "flags.make"
    c_flags = next(
        line.split("=", 1)[1].strip()
        for line in flags.read_text().splitlines()
        if line.startswith("C_FLAGS")
    )
    return out / "rhs_timing", c_flags


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=10)
    ap.add_argument("--out", type=Path, default=None, help="default: a temporary directory")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="gyrogen-bench-lib-") as tmp:
        root = args.out or Path(tmp)
        parent = root / "parent"
        shutil.copytree(LIBRARY, parent / "gyrostat", dirs_exist_ok=True)
        shutil.copy(TIMING, parent)
        (parent / "CMakeLists.txt").write_text(PARENT)
        programs = {}
        for label, build_type in BUILD_TYPES.items():
            program, c_flags = build(parent, build_type, root / f"build-{build_type or 'none'}")
            programs[label] = program
            print(f"{label}: library compiled with {c_flags}")
        best = dict.fromkeys(programs, float("inf"))
        for _ in range(args.rounds):
            for label, program in programs.items():
                ns = float(run([str(program)]).split()[1])
                best[label] = min(best[label], ns)
        for label, ns in best.items():
            print(f"{label:24s} {ns:6.1f} ns per rhs call (best of {args.rounds} rounds)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
