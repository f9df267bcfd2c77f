"""The text files of a scene's FMU: modelDescription.xml and the sources
(the scene's C and the FMI wrapper), by their paths inside the FMU. The
binary is compiled from these (runtime/fmu_build.py)."""

from __future__ import annotations

from gyrogen import methods
from gyrogen.codegen.fmu_model import FmuModel
from gyrogen.codegen.render import render
from gyrogen.errors import SceneError
from gyrogen.scene import Scene

FMI_VERSION = "2.0"


def default_method(scene: Scene) -> str:
    """What Co-Simulation steps with unless told: the explicit method
    simulate picks (gyrogen.methods.EXPLICIT_CHOICE: taylor where the scene
    offers it, else dop853), else the scene's first adaptive integrator; a
    scene that cannot make an FMU is refused."""
    if "c" not in scene.targets:
        raise SceneError(f'{scene.name}: an FMU is built from the C sources: add "c" to targets')
    adaptive = [m for m in scene.integrators if not methods.get(m).fixed_step]
    if not adaptive:
        given = ", ".join(scene.integrators) or "none"
        raise SceneError(
            f"{scene.name}: Co-Simulation steps with an adaptive integrator, and the scene "
            f"has none (integrators: {given})"
        )
    return methods.pick(adaptive, stiff=False) or adaptive[0]


def files(model: FmuModel) -> dict[str, str]:
    """Path inside the FMU -> text."""
    p = model.prefix
    sources = {f"sources/{name}": text for name, text in model.unit.c_sources.items()}
    wrapper = f"{p}_fmi2.c"
    c_sources = sorted(name[len("sources/") :] for name in sources if name.endswith(".c"))
    ctx = {
        "model": model,
        "guid": model.guid(FMI_VERSION),
        "versions": model.unit.versions,
        "c_sources": [*c_sources, wrapper],
        "unit": model.unit,
    }
    sources[f"sources/{wrapper}"] = render("fmu/fmi2.c.jinja", **ctx)
    return {"modelDescription.xml": render("fmu/modelDescription2.xml.jinja", **ctx), **sources}
