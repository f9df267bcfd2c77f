"""gyrogen from Python (a notebook): compile a scene, simulate it, sweep it.

    from gyrogen import api
    model = api.compile("gyrostat")                   # runtime.compiled.Compiled
    c = model.setup(p)                                 # p in the scene's p[] order
    x, stats, code = model.integrate("dop853", x0, c, 0.0, 10.0, rtol=1e-9, atol=1e-9)
    trajectory = api.simulate("dual_spin", method="dop853")   # pandas: t and the states
    df = api.sweep("stability_map")                    # pandas: one row per trajectory
    df = api.sweep(api.load_sweep(toml_text, name="mine"), workers=2)
    lin = api.linearize("dual_spin")                   # A, B, C, D about a steady spin
    sys = api.state_space("rw4_pyramid", spin=0.0)     # python-control StateSpace (a hold)

The same code as the command line: `compile` is what a sweep's workers do
(sources rendered once and cached, built through the build cache),
`simulate` is `gyrogen simulate`, `sweep` is `gyrogen sweep` (Parquet parts,
summary and figures in out, resumable), then its rows read back.
"""

from __future__ import annotations

import math
import numbers
import os
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gyrogen.analysis.sweep.sweep_spec import Spec, parse
from gyrogen.analysis.sweep.sweep_spec import load as load_spec
from gyrogen.analysis.sweep.sweep_store import Store, store
from gyrogen.errors import GyrogenError
from gyrogen.runtime.compiled import Compiled
from gyrogen.runtime.scene_build import compiled, scene_sources
from gyrogen.scene import Scene
from gyrogen.scene import load as load_scene

if TYPE_CHECKING:
    import control
    import pandas as pd

    from gyrogen.analysis.linearize.linearize import Linear


def _scene(scene: str | Scene) -> Scene:
    return scene if isinstance(scene, Scene) else load_scene(scene)


def compile(scene: str | Scene = "gyrostat") -> Compiled:
    """The scene (a built-in name, a .toml path or a Scene) generated and
    built, C when it has a C target: setup, rhs, outputs, integrators."""
    return compiled(scene_sources(_scene(scene)))


def simulate(
    scene: str | Scene = "gyrostat",
    *,
    method: str = "auto",
    t_end: float | None = None,
    dt: float | None = None,
    out: str | Path | None = None,
) -> pd.DataFrame:
    """`gyrogen simulate`: the trajectory on the output grid as columns t
    and the scene's states (files in out, else in a temporary directory)."""
    import pandas as pd

    from gyrogen.analysis.simulate import simulate as sim

    chosen = _scene(scene)
    settings = sim.checked(
        sim.Settings(
            t_end=chosen.simulate.t_end if t_end is None else t_end,
            dt=chosen.simulate.dt if dt is None else dt,
            method=method,
        )
    )
    with tempfile.TemporaryDirectory() as tmp:
        result = sim.run(chosen, Path(out) if out else Path(tmp), settings)
    traj = result.trajectory
    return pd.DataFrame({"t": traj.t, **{s: traj.x[:, i] for i, s in enumerate(chosen.states)}})


def load_sweep(text: str, name: str = "sweep", here: str | Path = ".") -> Spec:
    """A sweep from TOML text (scene paths in it start from here)."""
    return parse(text, name, name, Path(here))


def sweep(
    spec: str | Path | Spec,
    *,
    out: str | Path | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    chunk: int | None = None,
    progress: bool = False,
    plots: bool = True,
    portable: bool = False,
) -> pd.DataFrame:
    """`gyrogen sweep`: every trajectory of spec (a built-in sweep, a sweep
    file or a Spec) into out (a directory or an fsspec URL) [default:
    sweep/<name>], resuming what is there (portable: code for any CPU,
    `--portable`); its rows, one per trajectory, in sample order."""
    from gyrogen.analysis.sweep import sweep_engine, sweep_report

    chosen = spec if isinstance(spec, Spec) else load_spec(str(spec))
    where = store(out if out is not None else Path("sweep") / chosen.name)
    with sweep_engine.run(
        chosen,
        where,
        scheduler=scheduler,
        threads=workers,
        chunk=chunk,
        progress=progress,
        portable=portable,
        plots=plots,
        meanwhile=sweep_report.load_plots if plots else None,
    ) as record:
        sweep_report.write(chosen, record, plots=plots)
    return read(where)


def read(out: str | Path | Store) -> pd.DataFrame:
    """The rows of the sweep in out (a directory or an fsspec URL), in
    sample order: its parts, each checked as a resume checks it (a part
    whose footer disagrees with its name or the sweep is one line)."""
    import pyarrow.parquet as pq

    from gyrogen.analysis.sweep.sweep_columns import PARTS
    from gyrogen.analysis.sweep.sweep_parts import trusted

    where = store(out)
    names = trusted(where)
    if not names:
        raise GyrogenError(f"{where.show(PARTS)}: no parts yet")
    # the paths themselves, never re-read as URLs (./s3:x is a directory; FILE:/// is file:///)
    if where.local:
        table = pq.read_table([os.path.abspath(where.path(PARTS, n)) for n in names])
    else:
        table = pq.read_table([where.path(PARTS, n) for n in names], filesystem=where.fs)
    frame = table.to_pandas()
    return frame.sort_values("sample", kind="stable").reset_index(drop=True)


def linearize(
    scene: str | Scene = "dual_spin",
    *,
    state: list[float] | None = None,
    at: dict[str, float] | None = None,
    parameters: dict[str, float] | None = None,
    spin: float | None = None,
    axis: int | None = None,
) -> Linear:
    """`gyrogen linearize`: the linear model (A, B, C, D over its kept
    states, names, the point, eigenvalues) about the point given (state:
    every value; at: by name), else the scene's equilibrium, else the steady
    spin found (spin rad/s about the principal axis nearest a_axis)."""
    from gyrogen.analysis.linearize.linearize import model

    _numbers("parameters", parameters)
    _numbers("at", at)
    if state is not None:
        _numbers("state", {f"x[{i}]": v for i, v in enumerate(state)})
    if spin is not None and not (_real(spin) and math.isfinite(spin)):
        raise GyrogenError(f"spin: {spin!r} is not a finite number (rad/s)")
    if axis is not None and (isinstance(axis, bool) or axis not in (1, 2, 3)):
        raise GyrogenError(f"axis: {axis!r} is not 1, 2 or 3 (a1, a2, a3)")
    return model(_scene(scene), state=state, at=at, parameters=parameters, spin=spin, axis=axis)


def _real(v: Any) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


def _numbers(what: str, values: Any) -> None:
    """values: None, or a mapping of names to real numbers (a one-line
    GyrogenError otherwise, where float() would say it in its own words)."""
    if values is None:
        return
    if not isinstance(values, Mapping):
        raise GyrogenError(f"{what}: give a dict of names to numbers, not {type(values).__name__}")
    for k, v in values.items():
        if not _real(v):
            raise GyrogenError(f"{what}: {k} is {v!r}, not a real number")


def state_space(scene: str | Scene | Linear = "dual_spin", **point: Any) -> control.StateSpace:
    """linearize()'s model (or a Linear) as a python-control StateSpace, with
    the states, inputs and outputs named (the extra gyrogen[linear])."""
    from gyrogen.analysis.linearize.linearize import Linear

    try:
        import control
    except ImportError:
        raise GyrogenError(
            "python-control is not installed: pip install 'gyrogen[linear]'"
        ) from None
    lin = scene if isinstance(scene, Linear) else linearize(scene, **point)
    return control.ss(
        lin.A, lin.B, lin.C, lin.D,
        states=list(lin.states), inputs=list(lin.inputs), outputs=list(lin.outputs),
        name=lin.scene.name,
    )  # fmt: skip
