"""`gyrogen fmu`: a scene as a Functional Mock-up SceneContext."""

from __future__ import annotations

from pathlib import Path

import click

from gyrogen import methods
from gyrogen.commands.options import SCENE, directory
from gyrogen.scene import Scene


@click.command()
@click.argument("scene", type=SCENE)
@directory("--out", "Directory to write <scene>.fmu into [default: the current directory].")
@click.option(
    "--method",
    type=click.Choice(methods.ADAPTIVE),
    default=None,
    help="The compiled integrator Co-Simulation steps with, one of the scene's "
    "[default: the one `gyrogen simulate --method auto` would choose for the scene's "
    f"start: the first the scene has of {', '.join(methods.STIFF_CHOICE)} for a stiff "
    f"scene, else of {', '.join(methods.EXPLICIT_CHOICE)}, else its first adaptive one].",
)
def fmu(scene: Scene, out: Path | None, method: str | None) -> None:
    """Write SCENE as <scene>.fmu: FMI 2.0, Model Exchange and Co-Simulation,
    built for this machine with its sources inside. States, derivatives and
    outputs are variables with units, the runtime parameters tunable
    parameters (starting at the scene's simulate.parameters), the start
    state the scene's simulate.initial. Co-Simulation steps with the
    scene's compiled integrator at its simulate.rtol and atol. The FMI
    headers come from FMPy, which must be installed."""
    from gyrogen.analysis.simulate.engine import runtime_values
    from gyrogen.codegen.fmu import default_method
    from gyrogen.codegen.fmu_model import FmuModel, Rendered, Stepping
    from gyrogen.files import can_write, write_atomic
    from gyrogen.runtime import fmu_build
    from gyrogen.runtime.scene_build import scene_sources

    target = out or Path(".")
    fmu_build.fmi_headers()  # refusals first, before the seconds of deriving and compiling
    can_write(target, [f"{scene.name}.fmu"])
    chosen = default_method(scene)
    if method is not None and method not in scene.integrators:
        raise click.BadParameter(
            f"{method} is not among the scene's integrators ({', '.join(scene.integrators)})",
            param_hint="'--method'",
        )
    sim = scene.simulate
    if method is None:
        chosen = _by_stiffness(scene, chosen)
    stepping = Stepping(method or chosen, sim.rtol, sim.atol, sim.t_end, sim.dt)
    rendered = Rendered(scene, scene_sources(scene).files)  # kept: derives nothing
    model = FmuModel(rendered, tuple(runtime_values(scene)), stepping)
    write_atomic(target, fmu_build.build(model, target))
    click.echo(
        f"wrote {target / (scene.name + '.fmu')}: FMI 2.0, Model Exchange and Co-Simulation "
        f"({stepping.method}), {len(model.variables)} variables"
    )


def _by_stiffness(scene: Scene, explicit: str) -> str:
    """What `simulate --method auto` chooses at the scene's start over its
    t_end (analysis.stiffness): the scene's best implicit integrator for a
    stiff problem, else explicit (the default_method)."""
    import tempfile

    import numpy as np

    from gyrogen.analysis.check import stiffness
    from gyrogen.analysis.simulate.engine import given_constants, runtime_values
    from gyrogen.runtime.scene_build import build_scene

    with tempfile.TemporaryDirectory(prefix="gyrogen-fmu-") as tmp:
        built = build_scene(scene, Path(tmp) / scene.name, ["c"])
    comp = built["c"]
    c = given_constants(scene, comp, np.array(runtime_values(scene)))
    choice = stiffness.choose(comp, c, np.array(scene.initial_state()), scene.simulate.t_end)
    if choice.stiff and choice.method is None:
        click.echo(f"{scene.name} is stiff, and the scene has no implicit integrator: {explicit}")
    return choice.method if choice.stiff and choice.method else explicit


command = fmu
