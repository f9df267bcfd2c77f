"""`make fmu-agreement`: the FMU of the default, the quaternion, the stiff
and the CMG pyramid scene, simulated by FMPy in Co-Simulation (the generated integrator) and
Model Exchange (FMPy's CVODE), against `gyrogen simulate` (scipy's DOP853,
or Radau on the stiff scene), over each scene's whole t_end.

    python benchmarks/fmu_agreement.py [--t-end T] [--out DIR]

Prints, per scene and mode, the largest difference over the output grid and
the states, |fmu - simulate| / (1 + |simulate|) and absolute. Exit 1 if
either exceeds BAR. The cases are tests/fmu_cases.py's, which
tests/test_fmu.py runs on a 1 s slice.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the cases

from fmu_cases import BAR, CVODE_SHARPER, MODES, build, by_fmpy, cases, differences, reference


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--t-end", type=float, default=None, help="default: each scene's")
    ap.add_argument("--out", type=Path, default=None, help="default: a temporary directory")
    args = ap.parse_args()
    worst = 0.0
    with tempfile.TemporaryDirectory(prefix="gyrogen-fmu-") as tmp:
        root = args.out or Path(tmp)
        for case in cases():
            t_end = args.t_end or case.scene.simulate.t_end
            fmu = build(case, root / case.label)
            t0 = time.perf_counter()
            ref = reference(case, t_end, root / case.label / "simulate")
            seconds = time.perf_counter() - t0
            print(f"{case.label} ({case.scene.name}, t_end {t_end:g} s, {len(ref)} points): "
                  f"gyrogen simulate --method {case.reference} in {seconds:.2f} s")  # fmt: skip
            for mode in MODES:
                t0 = time.perf_counter()
                x = by_fmpy(case, fmu, mode, t_end)
                scaled, absolute = differences(x, ref)
                worst = max(worst, scaled, absolute)
                cvode = f"FMPy's CVODE, rtol / {CVODE_SHARPER:g}"
                what = case.method if mode == "CoSimulation" else cvode
                print(f"  {mode:14s} ({what}): {scaled:.2e} scaled, {absolute:.2e} absolute, "
                      f"{time.perf_counter() - t0:.2f} s")  # fmt: skip
    print(f"largest difference {worst:.2e} (bar {BAR:g})")
    return 0 if worst <= BAR else 1


if __name__ == "__main__":
    sys.exit(main())
