"""Which explicit method `simulate --method auto` should pick: the Taylor
method against dop853 on every built-in scene that offers it (a smooth rhs),
one trajectory over the scene's t_end, tolerance by tolerance, interleaved
(`make bench-auto`). Each cell: the raw cffi call's best time, the accepted
steps, and the scaled error against dop853 at rtol = atol = 1e-14 (the
Taylor method at 1e-14 beside it: the two references' agreement). The load
average is printed before and after.

usage: python benchmarks/bench_auto.py [REPEATS]
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from gyrogen.abi import MAX_STEPS
from gyrogen.analysis.bench.timing import best_time
from gyrogen.analysis.simulate.engine import runtime_values
from gyrogen.errors import SceneError
from gyrogen.oracle.compare import scaled_error
from gyrogen.runtime.compiled import Compiled
from gyrogen.runtime.scene_build import build_scene
from gyrogen.scene import Scene, builtin_names, load

LEVELS = (1e-4, 1e-6, 1e-8, 1e-10, 1e-12)
METHODS = ("dop853", "taylor")


def both(scene: Scene) -> Scene | None:
    """The scene built with dop853 and taylor, C only; None where the Taylor
    method is not offered."""
    data = {**scene.model_dump(), "integrators": list(METHODS), "targets": ["c"]}
    try:
        return Scene.model_validate(data)
    except (SceneError, ValueError):
        return None


def timed(comp: Compiled, method: str, start: np.ndarray, c: np.ndarray, t1: float,
          tol: float, repeats: int) -> tuple[float, np.ndarray, int]:  # fmt: skip
    """Best time of the raw cffi call, its final state and accepted steps."""
    fn, x = comp.function(method), start.copy()
    xb, cb = comp.doubles(x), comp.doubles(np.ascontiguousarray(c))
    stats = comp.ffi.new("gyrogen_stats *")

    def run() -> None:
        x[:] = start
        fn(0.0, t1, xb, cb, tol, tol, 0.0, MAX_STEPS, stats)

    run()
    final, steps = x.copy(), int(stats.accepted)
    return best_time(run, repeats, min_total=0.05), final, steps


def main(repeats: int) -> None:
    print(f"load {os.getloadavg()[0]:.2f}; best of {repeats}, raw cffi calls")
    print("| scene | rtol = atol | dop853 us | steps | error | taylor us | steps | error |")
    print("|---|---|---|---|---|---|---|---|")
    for name in builtin_names():
        scene = both(load(name))
        if scene is None:
            print(f"| {name} | taylor not offered (rhs not smooth) |||||||")
            continue
        with tempfile.TemporaryDirectory() as tmp:
            built = build_scene(scene, Path(tmp), ("c",))
        comp = built["c"]
        c = comp.setup(runtime_values(scene))
        x0, t1 = np.array(scene.initial_state()), scene.simulate.t_end
        ref = comp.integrate("dop853", x0, c, 0.0, t1, rtol=1e-14, atol=1e-14)[0]
        other = comp.integrate("taylor", x0, c, 0.0, t1, rtol=1e-14, atol=1e-14)[0]
        for i, tol in enumerate(LEVELS):
            cells = []
            for method in METHODS:
                t, final, steps = timed(comp, method, x0, c, t1, tol, repeats)
                cells += [f"{t * 1e6:.2f}", str(steps), f"{scaled_error(final, ref):.1e}"]
            head = f"{name}, {t1:g} s (refs {scaled_error(ref, other):.0e})" if i == 0 else ""
            print(f"| {head} | {tol:.0e} | {' | '.join(cells)} |")
    print(f"after: load {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 7)
