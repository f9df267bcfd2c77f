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

from gyrogen.analysis.sweep.spec import Spec, parse
from gyrogen.analysis.sweep.spec import load as load_spec
from gyrogen.analysis.sweep.store import Store, store
from gyrogen.errors import GyrogenError
from gyrogen.runtime.compiled import Compiled
from gyrogen.runtime.scene_build import compiled, scene_sources
from gyrogen.scene import Scene
from gyrogen.scene import load as load_scene

if TYPE_CHECKING:
    import control
    import pandas as pd

    from gyrogen.analysis.linearize.engine import Linear


def _scene(scene: str | Scene) -> Scene:
    return scene if isinstance(scene, Scene) else load_scene(scene)


def compile(scene: str | Scene = "gyrostat") -> Compiled:
    """Generate a scene's code, build it and load it.

    The sources are rendered once and cached, and built through the build
    cache, so a second call with the same scene compiles nothing. The
    backend is C when the scene has a C target, else Fortran.

    Parameters
    ----------
    scene : str or Scene, default "gyrostat"
        A built-in scene's name, the path of a .toml scene file, or a Scene.

    Returns
    -------
    Compiled
        The loaded backend: setup, rhs, Jacobian, outputs and integrators.

    Raises
    ------
    SceneError
        The scene is unknown, unreadable or invalid (one line naming the key).
    BuildError
        The compiler refused the code (its first lines; the full log in the
        build cache).

    Examples
    --------
    >>> from gyrogen import api
    >>> model = api.compile("dual_spin")
    >>> model.nx, model.n_params
    (7, 0)
    """
    return compiled(scene_sources(_scene(scene)))


def simulate(
    scene: str | Scene = "gyrostat",
    *,
    method: str = "auto",
    t_end: float | None = None,
    dt: float | None = None,
    out: str | Path | None = None,
) -> pd.DataFrame:
    """Integrate a scene from its start, as `gyrogen simulate` does.

    Parameters
    ----------
    scene : str or Scene, default "gyrostat"
        A built-in scene's name, a .toml path, or a Scene; the start state,
        runtime parameters and tolerances are its `[simulate]` table's.
    method : str, default "auto"
        A compiled integrator of the scene (rk4, dopri5, dop853, rodas4,
        radau5, taylor), scipy's (RK45, DOP853, Radau, LSODA), or "auto":
        the scene's best compiled integrator of the kind its stiffness
        calls for.
    t_end : float, optional
        End time, s (default: the scene's).
    dt : float, optional
        Output step, s (default: the scene's).
    out : str or Path, optional
        Where to keep the command's files (trajectory.csv, trajectory.npz,
        summary.json, trajectory.png and the sources); by default they go to
        a temporary directory, removed afterwards.

    Returns
    -------
    pandas.DataFrame
        One row per output time: the column t, then one column per state.

    Raises
    ------
    SceneError
        The scene is invalid, or t_end, dt or method is not one simulate
        takes.
    GyrogenError
        The integration failed (its return code's reason).

    Examples
    --------
    >>> from gyrogen import api
    >>> trajectory = api.simulate("dual_spin", t_end=1.0, dt=0.5)
    >>> list(trajectory.columns)
    ['t', 'q1', 'q2', 'q3', 'u1', 'u2', 'u3', 'u4']
    >>> trajectory["t"].tolist()
    [0.0, 0.5, 1.0]
    """
    import pandas as pd

    from gyrogen.analysis.simulate import engine as sim
    from gyrogen.analysis.simulate.result import Settings, checked

    chosen = _scene(scene)
    settings = checked(
        Settings(
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
    """Read a sweep from the text of a sweep file.

    Parameters
    ----------
    text : str
        The sweep file's TOML text.
    name : str, default "sweep"
        The sweep's name (its default output directory is sweep/<name>).
    here : str or Path, default "."
        Where a scene path in the text starts from.

    Returns
    -------
    Spec
        The validated sweep, for `sweep`.

    Raises
    ------
    SceneError
        The text is no valid sweep (one line naming the key).

    Examples
    --------
    >>> from gyrogen import api
    >>> spec = api.load_sweep('''
    ... scene = "dual_spin"
    ... [grid]
    ... u4 = { list = [0.0, 600.0] }
    ... ''', name="two")
    >>> spec.size
    2
    """
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
    """Integrate every trajectory of a sweep, as `gyrogen sweep` does.

    The Parquet parts, summary and figures go to `out`; a sweep already
    begun there by the same build is resumed (only what is left is
    computed).

    Parameters
    ----------
    spec : str, Path or Spec
        A built-in sweep's name, a sweep file's path, or a Spec from
        `load_sweep`.
    out : str or Path, optional
        A directory or an fsspec URL (default: sweep/<name>).
    scheduler : str, optional
        A dask.distributed scheduler's address (tcp://HOST:PORT); by default
        a local engine in this process.
    workers : int, optional
        Threads of the local engine (default: one per core).
    chunk : int, optional
        Trajectories per task (default: the sweep's chunk).
    progress : bool, default False
        Show a progress bar on stderr.
    plots : bool, default True
        Write histograms.png (and map.png for a 2-D grid).
    portable : bool, default False
        Build for any CPU of the architecture (as `--portable`), not for
        this one.

    Returns
    -------
    pandas.DataFrame
        The rows, one per trajectory, in sample order (as `read` gives them).

    Raises
    ------
    SceneError
        The sweep, its scene or `out` is invalid, or `out` holds a sweep
        begun by another build.
    GyrogenError
        The sweep could not run (a place that cannot be written, a
        scheduler that does not answer).

    Examples
    --------
    >>> from gyrogen import api
    >>> spec = api.load_sweep('''
    ... scene = "dual_spin"
    ... t_end = 5.0
    ... [grid]
    ... u4 = { list = [0.0, 600.0] }
    ... [metrics]
    ... keep = ["final_state"]
    ... ''', name="two")
    >>> import tempfile
    >>> rows = api.sweep(spec, out=tempfile.mkdtemp(), workers=1, plots=False)
    >>> rows["u4"].tolist(), rows["code"].tolist()
    ([0.0, 600.0], [0, 0])
    """
    from gyrogen.analysis.sweep import engine, report

    chosen = spec if isinstance(spec, Spec) else load_spec(str(spec))
    where = store(out if out is not None else Path("sweep") / chosen.name)
    with engine.run(
        chosen,
        where,
        scheduler=scheduler,
        threads=workers,
        chunk=chunk,
        progress=progress,
        portable=portable,
        plots=plots,
        meanwhile=report.load_plots if plots else None,
    ) as record:
        report.write(chosen, record, plots=plots)
    return read(where)


def read(out: str | Path | Store) -> pd.DataFrame:
    """Read back the rows of a sweep already run.

    Parameters
    ----------
    out : str, Path or Store
        The sweep's directory or fsspec URL.

    Returns
    -------
    pandas.DataFrame
        Its rows, one per trajectory computed, in sample order. Each part
        is checked as a resume checks it.

    Raises
    ------
    SceneError
        `out` is no valid place (a URL gyrogen cannot use).
    FileNotFoundError
        `out` holds no sweep's parts.
    GyrogenError
        A part whose footer disagrees with its name or the sweep.

    Examples
    --------
    >>> from gyrogen import api
    >>> rows = api.read("sweep/mine")  # doctest: +SKIP
    """

    import pyarrow.parquet as pq

    from gyrogen.analysis.sweep.columns import PARTS
    from gyrogen.analysis.sweep.parts import trusted

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
    """Linearize a scene about an equilibrium, as `gyrogen linearize` does.

    The point is `state` or `at` if given, else the scene's `equilibrium`,
    else a steady spin found about a principal axis (each wheel at the rate
    its torque law holds there).

    Parameters
    ----------
    scene : str or Scene, default "dual_spin"
        A built-in scene's name, a .toml path, or a Scene.
    state : list of float, optional
        The point as the whole state vector, in the scene's order.
    at : dict of str to float, optional
        The point by state name (others 0, e0 1).
    parameters : dict of str to float, optional
        The runtime parameters (default: the scene's `[simulate] parameters`).
    spin : float, optional
        Find a steady spin at this rate, rad/s (default: the start's rate).
    axis : {1, 2, 3}, optional
        Find the spin about the principal axis nearest a1, a2 or a3
        (default: nearest the start's angular velocity).

    Returns
    -------
    Linear
        A, B, C, D over the kept states (about a spin the turning angles are
        left out, in `dropped`), the names of states, inputs and outputs,
        the point `x`, the parameters `p` and the `eigenvalues`.

    Raises
    ------
    GyrogenError
        An argument that is not what it should be (a number that is not
        real or finite, an axis outside 1..3, parameters not a dict), or a
        point linearize refuses (unknown names, gimbal lock, Euler
        parameters off |e| = 1, speeds past 1e100 rad/s).

    Examples
    --------
    >>> from gyrogen import api
    >>> lin = api.linearize("dual_spin")
    >>> lin.states, lin.dropped, lin.A.shape
    (('u1', 'u2', 'u3', 'u4'), ('q1', 'q2', 'q3'), (4, 4))
    """
    from gyrogen.analysis.linearize.engine import model

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
    """The linear model as a python-control StateSpace.

    Needs python-control (the extra `gyrogen[linear]`).

    Parameters
    ----------
    scene : str, Scene or Linear, default "dual_spin"
        A scene to linearize, or a Linear from `linearize`.
    **point
        `linearize`'s keywords (state, at, parameters, spin, axis), for a
        scene.

    Returns
    -------
    control.StateSpace
        A, B, C, D with the states, inputs and outputs named, and the
        scene's name.

    Raises
    ------
    GyrogenError
        python-control is not installed, or `linearize` refused the point.

    Examples
    --------
    >>> from gyrogen import api
    >>> sys = api.state_space("dual_spin")
    >>> sys.nstates, sys.ninputs, sys.noutputs
    (4, 1, 4)
    """
    from gyrogen.analysis.linearize.engine import Linear

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
