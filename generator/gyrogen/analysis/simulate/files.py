"""What `gyrogen simulate` writes: the trajectory with its invariants as CSV
and npz (the same doubles), summary.json, and the figure."""

from __future__ import annotations

import io
import json
from typing import Any

import numpy as np

from gyrogen.analysis.simulate.invariants import Invariants, words
from gyrogen.analysis.simulate.result import Result
from gyrogen.analysis.simulate.trajectory import QUADRATURE, Trajectory
from gyrogen.runtime.compiled import EventLog
from gyrogen.scene import Scene

COLUMNS = ("H_norm", "K", "H_drift", "H_vector_drift", "energy_residual", "u4_residual")
"""Invariant columns of trajectory.csv, after t and the states."""


def file_names(plot: bool, events: bool = False) -> list[str]:
    """The files a run writes, in the order the summary lists them."""
    names = ["trajectory.csv", "trajectory.npz", "summary.json"]
    return names + (["events.csv"] if events else []) + (["trajectory.png"] if plot else [])


def events_csv(scene: Scene, log: EventLog) -> str:
    """The event log: time, the event's name, the state there."""
    lines = [",".join(("t", "event", *scene.states))]
    for t, name, x in zip(log.times, log.names, log.states, strict=True):
        lines.append(",".join((f"{t:.17g}", name, *(f"{v:.17g}" for v in x))))
    return "\n".join(lines) + "\n"


def _columns(inv: Invariants) -> np.ndarray:
    h_norm = np.linalg.norm(inv.h, axis=1)
    cols = (h_norm, inv.kinetic, inv.h_drift, inv.h_vector_drift, inv.energy, inv.u4)
    return np.column_stack(cols)


def csv_text(scene: Scene, traj: Trajectory, inv: Invariants) -> str:
    buf = io.StringIO()
    data = np.column_stack([traj.t, traj.x, _columns(inv)])
    header = ",".join(("t", *scene.states, *COLUMNS))
    # %.17g: the CSV holds the same doubles as the npz.
    np.savetxt(buf, data, fmt="%.17g", delimiter=",", header=header, comments="")
    return buf.getvalue()


def npz_bytes(scene: Scene, traj: Trajectory, inv: Invariants) -> bytes:
    buf = io.BytesIO()
    np.savez(
        buf,
        t=traj.t,
        x=traj.x,
        names=np.array(scene.states),  # a str array: loads without allow_pickle
        H=inv.h,
        H_norm=np.linalg.norm(inv.h, axis=1),
        K=inv.kinetic,
        P=inv.power,
        H_drift=inv.h_drift,
        H_vector_drift=inv.h_vector_drift,
        energy_residual=inv.energy,
        u4_residual=inv.u4,
    )
    return buf.getvalue()


def summary(res: Result, p: np.ndarray) -> dict[str, Any]:
    s, traj = res.scene, res.trajectory
    return {
        "scene": s.name,
        "description": s.description,
        "build_id": res.build_id,
        "backend": res.language,
        "method": res.settings.method,
        "rtol": s.simulate.rtol,
        "atol": s.simulate.atol,
        "t_end": float(traj.t[-1]),
        "dt": res.settings.dt,
        "points": len(traj.t),
        "nfev": traj.nfev,
        "wall_time_s": traj.wall,
        "initial": dict(zip(s.states, s.initial_state(), strict=True)),
        "parameters": dict(zip(s.runtime, map(float, p), strict=True)),
        "invariants": res.invariants.worst(),
        "quadrature": QUADRATURE,
        "quadrature_unresolved": list(res.invariants.unresolved),
        "invariants_note": note(s),
        "files": [f.name for f in res.files],
        **({} if res.events is None else {"events": events_summary(res)}),
    }


def events_summary(res: Result) -> dict[str, Any]:
    """summary.json's events: how many events.csv holds, the terminal one
    that ended the run (or null), and the time from which a full log
    located none (or null: events.csv holds every crossing)."""
    log = res.events
    assert log is not None
    return {
        "located": len(log),
        "terminal": log.names[-1] if res.stopped else None,
        "log_full_from_t": res.full,
    }


def note(scene: Scene) -> str:
    """What summary.json's invariants are, for this scene (a cluster's
    power and rate check are its wheels', wheel 1's)."""
    said = words(scene)
    return (
        "largest |value| over the output grid. H_norm_relative_drift: (|H| - |H(0)|)/|H(0)|, "
        "H about AB* in N; H_vector_relative_drift: |H - H(0)|/|H(0)|. "
        "energy_balance_relative_residual: (K - K(0) - int P dt)/max|K|, "
        f"P = {said.power}. u4_relative_residual: ({said.balance})/max|{said.rate}|."
    )


def contents(res: Result, p: np.ndarray) -> dict[str, bytes]:
    """Every file of the run by name (those of file_names)."""
    scene, traj, inv = res.scene, res.trajectory, res.invariants
    blobs = {
        "trajectory.csv": csv_text(scene, traj, inv).encode(),
        "trajectory.npz": npz_bytes(scene, traj, inv),
        "summary.json": (json.dumps(summary(res, p), indent=2) + "\n").encode(),
    }
    if res.events is not None:
        blobs["events.csv"] = events_csv(scene, res.events).encode()
    if res.settings.plot:
        from gyrogen.analysis.simulate import plots  # matplotlib: loaded only when a plot is wanted

        blobs["trajectory.png"] = plots.trajectory_png(
            scene, traj.t, traj.x, _drifts(scene, inv), dict(zip(scene.runtime, p, strict=True))
        )
    return blobs


def _drifts(scene: Scene, inv: Invariants) -> dict[str, np.ndarray]:
    rate = words(scene).rate
    return {
        "|H| relative drift": inv.h_drift,
        "|H - H(0)| / |H(0)|": inv.h_vector_drift,
        "energy balance residual / max K": inv.energy,
        f"{rate} residual / max |{rate}|": inv.u4,
    }
