"""The FMU agreement cases: the FMU of the default, the quaternion, the
stiff and the control-moment-gyro pyramid scene, simulated by FMPy in
Co-Simulation (the generated integrator) and Model Exchange (FMPy's
CVODE), against `gyrogen simulate` (scipy's DOP853, or Radau on the stiff
scene). tests/test_fmu.py runs them on a 1 s slice,
benchmarks/fmu_agreement.py (`make fmu-agreement`) over each scene's whole
t_end.

Model Exchange runs CVODE at a tenth of the scene's rtol (CVODE_SHARPER):
the FMU gives only derivatives there, and at the scene's own rtol CVODE's
error, not the FMU's, is what shows (1.1e-8 absolute on the quaternion
scene over 10 s, shrinking to 3.6e-9 at a tenth).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import fmpy
import numpy as np

from gyrogen.analysis.check.cases import quaternion_scene
from gyrogen.analysis.simulate import engine
from gyrogen.analysis.simulate.result import Settings
from gyrogen.codegen.fmu_model import FmuModel, Rendered, Stepping
from gyrogen.files import write_atomic
from gyrogen.runtime import fmu_build
from gyrogen.runtime.scene_build import scene_sources
from gyrogen.scene import Scene, default, load

BAR = 1e-8
MODES = ("CoSimulation", "ModelExchange")
CVODE_SHARPER = 10.0
"""Model Exchange: CVODE's rtol is the scene's divided by this."""


@dataclass(frozen=True)
class Case:
    label: str
    scene: Scene
    method: str
    """The compiled integrator the FMU's Co-Simulation steps with."""
    reference: str
    """`gyrogen simulate --method`: scipy's, independent of the FMU."""


def cases() -> list[Case]:
    return [
        Case("default", default(), "taylor", "DOP853"),  # auto: smooth, not stiff
        Case("quaternion", quaternion_scene(), "taylor", "DOP853"),
        Case("stiff", load("stiff_wheel"), "rodas4", "Radau"),
        Case("cmg", load("cmg4_pyramid"), "dop853", "DOP853"),  # auto: a clamped gimbal servo
    ]


def build(case: Case, out: Path) -> Path:
    """The case's FMU (what `gyrogen fmu SCENE --method M` writes) in out."""
    return build_model(case.scene, case.method, out)


def build_model(scene: Scene, method: str, out: Path) -> Path:
    """The scene's FMU stepping with method (what `gyrogen fmu SCENE --method
    M` writes) in out."""
    sim = scene.simulate
    stepping = Stepping(method, sim.rtol, sim.atol, sim.t_end, sim.dt)
    rendered = Rendered(scene, scene_sources(scene).files)
    model = FmuModel(rendered, tuple(engine.runtime_values(scene)), stepping)
    write_atomic(out, fmu_build.build(model, out))
    return out / f"{scene.name}.fmu"


def reference(case: Case, t_end: float, out: Path) -> np.ndarray:
    """`gyrogen simulate`'s trajectory on the scene's output grid."""
    settings = Settings(t_end, case.scene.simulate.dt, case.reference, plot=False)
    return engine.run(case.scene, out, settings).trajectory.x


def by_fmpy(case: Case, fmu: Path, mode: str, t_end: float) -> np.ndarray:
    """The states on the same grid: Co-Simulation at the scene's rtol,
    Model Exchange at CVODE_SHARPER times finer (CVODE's atol is rtol times
    the nominal 1)."""
    sim = case.scene.simulate
    rtol = sim.rtol if mode == "CoSimulation" else sim.rtol / CVODE_SHARPER
    result = fmpy.simulate_fmu(
        str(fmu),
        fmi_type=mode,
        stop_time=t_end,
        output_interval=sim.dt,
        relative_tolerance=rtol,
        output=list(case.scene.states),
    )
    return np.column_stack([result[name] for name in case.scene.states])


def differences(x: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """The largest |x - ref| / (1 + |ref|), and the largest |x - ref|."""
    assert x.shape == ref.shape, (x.shape, ref.shape)
    gap = np.abs(x - ref)
    return float(np.max(gap / (1.0 + np.abs(ref)))), float(np.max(gap))
