"""What a sweep writes beside its Parquet parts: summary.json and
summary.md (the run's figures, return codes, each metric's spread, the
criterion's agreement share), histograms.png and, for a 2-D grid, map.png.

The parts are read back one column at a time (analysis/sweep/columns.py):
those the run found whole or made (Run.parts), nothing else that is there.

The spin-stability criterion (NOTES.md, analysis/check/engine.spin_axes):
a trajectory is observed unstable when its max nutation angle exceeds
grows_by times its start's; it is judged when its H_a / Omega lies outside
band of both transverse inertias (near the boundary the growth is too slow
to see in t_end) and its run finished.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from typing import TYPE_CHECKING, Any

import numpy as np

from gyrogen.abi import UNITS
from gyrogen.analysis.check.engine import spin_axes, spin_stable
from gyrogen.analysis.sweep.columns import PARTS, Histogram, in_order, scan, spreads
from gyrogen.analysis.sweep.draws import axis_values
from gyrogen.analysis.sweep.engine import Run
from gyrogen.analysis.sweep.parts import HISTOGRAMS_PNG, MAP_PNG, SUMMARY_JSON, SUMMARY_MD
from gyrogen.analysis.sweep.spec import Spec
from gyrogen.analysis.sweep.store import Store
from gyrogen.physics import lumped_inertias

if TYPE_CHECKING:
    from gyrogen.analysis.sweep.plots import MapData

HISTOGRAMS = ("max_nutation", "max_rate", "H_drift", "pointing", "rhs_calls")
"""Metric columns shown as histograms (with every time_to_ column)."""
SPIN_NAMES = ("m_a", "m_b", "I11", "I22", "I33", "I13", "I", "J", "l1", "l3", "u2", "u4")
MESH = 200


def spin_values(spec: Spec, data: dict[str, np.ndarray]) -> dict[str, Any]:
    """Every value the criterion reads: a swept name's column, else the
    sweep's base value (parameters folded or runtime; start states, 0 when
    not given)."""
    base = {**spec.scene.folded(), **spec.base_parameters(), **spec.base_state()}
    return {n: data[n] if n in data else np.float64(base.get(n, 0.0)) for n in SPIN_NAMES}


def spin_agreement(spec: Spec, out: Store, parts: list[str]) -> dict[str, Any]:
    """The criterion against the observed growth, counted part by part."""
    crit = spec.sweep.criterion.spin_stability
    assert crit is not None
    swept = [n for n in SPIN_NAMES if n in spec.variables]
    found = dict.fromkeys(("cells", "judged", "in_band", "not_finished", "agree"), 0)
    found |= dict.fromkeys(("predicted_unstable", "observed_unstable"), 0)
    for data in scan(out, parts, [*swept, "code", "nutation_0", "max_nutation"]):
        v = spin_values(spec, data)
        omega = np.broadcast_to(v["u2"], data["code"].shape)
        spinning = omega != 0
        safe = np.where(spinning, omega, 1.0)
        sigma, it1, it3 = spin_axes(v, safe, v["u4"])
        near = (np.abs(sigma / it1 - 1) < crit.band) | (np.abs(sigma / it3 - 1) < crit.band)
        predicted = np.broadcast_to(spin_stable(v, safe, v["u4"]), omega.shape)
        observed = data["max_nutation"] <= crit.grows_by * data["nutation_0"]
        judged = spinning & ~near & (data["code"] == 0)
        found["cells"] += int(omega.size)
        found["judged"] += int(judged.sum())
        found["in_band"] += int(np.sum(near & spinning))
        found["not_finished"] += int(np.sum(data["code"] != 0))
        found["agree"] += int(np.sum(judged & (predicted == observed)))
        found["predicted_unstable"] += int(np.sum(~predicted))
        found["observed_unstable"] += int(np.sum(~observed))
    share = found["agree"] / found["judged"] if found["judged"] else float("nan")
    return {**found, "share": share, "grows_by": crit.grows_by, "band": crit.band}


def timing(record: Run) -> dict[str, Any]:
    """This run's figures: chunks skipped and computed, start-up, wall, the
    seconds inside tasks, and busy_share: task seconds over wall x threads
    (what scheduling, transfers and writing the parts leave to compute)."""
    tasks = np.array(record.task_seconds)
    busy = float(tasks.sum())
    return {
        "engine": record.engine,
        "threads": record.threads,
        "chunks_skipped": record.skipped,
        "chunks_computed": int(tasks.size),
        "trajectories_computed": record.rows,
        "startup_s": record.startup,
        "wall_s": record.wall,
        "trajectories_per_s": record.rows / record.wall if record.wall > 0 else 0.0,
        "task_s_total": busy,
        "task_s_mean": float(tasks.mean()) if tasks.size else 0.0,
        "task_s_max": float(tasks.max()) if tasks.size else 0.0,
        "busy_share": busy / (record.wall * record.threads) if record.wall > 0 else 0.0,
    }


def metric_columns(spec: Spec, columns: list[str]) -> list[str]:
    wanted = [*HISTOGRAMS, *(f"time_to_{q}" for q in spec.sweep.metrics.time_to)]
    return [c for c in wanted if c in columns]


def summary(
    spec: Spec, record: Run, shown: list[str]
) -> tuple[dict[str, Any], dict[str, Histogram]]:
    """The summary's data, and the histograms of the metric columns shown."""
    out, sweep = record.out, spec.sweep
    data: dict[str, Any] = {
        "sweep": spec.name,
        "scene": spec.scene.name,
        "build_id": record.job.sources.build_id,
        "identity": record.job.identity,
        "seed": sweep.draws.seed if sweep.draws else None,
        "spec": json.loads(sweep.model_dump_json()),
        "method": sweep.method,
        "t_end": sweep.t_end,
        "rtol": sweep.rtol,
        "atol": sweep.atol,
        "samples": sweep.metrics.points,
        "trajectories": spec.size,
        "chunk": record.job.chunk,
        "parts": len(record.parts),
        "run": timing(record),
        "metrics": {},
    }
    codes, found = spreads(out, record.parts, shown, ("setup_code", "code"))  # streamed
    data["setup_codes"], data["integrator_codes"] = codes["setup_code"], codes["code"]
    histograms = {}
    for name, (stats, histogram) in found.items():
        data["metrics"][name], histograms[name] = stats, histogram
    if sweep.criterion.spin_stability is not None:
        data["spin_stability"] = spin_agreement(spec, out, record.parts)
    return data, histograms


def markdown(data: dict[str, Any]) -> str:
    run = data["run"]
    lines = [
        f"# sweep {data['sweep']}: {data['trajectories']:,} trajectories of {data['scene']}",
        "",
        f"{data['method']} to t = {data['t_end']:g} s (rtol {data['rtol']:g}, atol "
        f"{data['atol']:g}), {data['samples']} samples each; {data['parts']} parts, this "
        f"run's chunks of {data['chunk']:,}; build {data['build_id']}.",
        "",
        f"This run: {run['engine']}; {run['chunks_computed']} chunks computed, "
        f"{run['chunks_skipped']} already written; start-up {run['startup_s']:.2f} s, then "
        f"{run['wall_s']:.2f} s for {run['trajectories_computed']:,} trajectories "
        f"({run['trajectories_per_s']:,.0f} per s); tasks {run['task_s_mean']:.3f} s on "
        f"average, busy {100 * run['busy_share']:.1f}% of wall x threads.",
        "",
        f"Setup codes {data['setup_codes']}; integrator codes {data['integrator_codes']}.",
        "",
        "| metric | finite | min | median | p99 | max |",
        "|---|---|---|---|---|---|",
    ]
    for name, s in data["metrics"].items():
        cells = [f"{s[k]:.4g}" if k in s else "-" for k in ("min", "median", "p99", "max")]
        lines.append(f"| {name} | {s['finite']:,} | " + " | ".join(cells) + " |")
    if spin := data.get("spin_stability"):
        lines += [
            "",
            f"Spin stability (NOTES.md): {spin['agree']} of {spin['judged']} cells outside a "
            f"{100 * spin['band']:g}% band around the boundary agree with the criterion "
            f"({100 * spin['share']:.2f}%); {spin['in_band']} cells in the band, "
            f"{spin['not_finished']} not finished; unstable means the nutation grew "
            f"{spin['grows_by']:g}-fold.",
        ]
    return "\n".join(lines) + "\n"


def write(spec: Spec, record: Run, plots: bool = True) -> dict[str, Any]:
    """summary.json, summary.md and the figures into the sweep's directory
    (parts.summary_files: kept clear before any work)."""
    import pyarrow.parquet as pq

    with record.out.open(PARTS, record.parts[0]) as source:
        columns = list(pq.read_schema(source).names)
    data, histograms = summary(spec, record, metric_columns(spec, columns))
    files: dict[str, str | bytes] = {SUMMARY_MD: markdown(data)}
    if plots:
        from gyrogen.analysis.sweep.plots import histograms_png, map_png  # matplotlib

        files[HISTOGRAMS_PNG] = histograms_png(f"sweep {spec.name}", histograms)
        if (grid := map_data(spec, record, columns)) is not None:
            files[MAP_PNG] = map_png(grid)
    data["files"] = [SUMMARY_JSON, *files]
    files[SUMMARY_JSON] = json.dumps(data, indent=1) + "\n"
    record.out.write(files)
    return data


def load_plots() -> None:
    """Import the figures' module (matplotlib: 0.4 s), ahead of need."""
    import gyrogen.analysis.sweep.plots  # noqa: F401


def map_data(spec: Spec, record: Run, columns: list[str]) -> MapData | None:
    """A 2-D product grid's map of its first metric (the median over the
    draws of each cell), with NOTES.md's boundary when the sweep has the
    spin criterion; None for other sweeps, and when no cell has a value
    (setup refused every parameter set, say)."""
    from gyrogen.analysis.sweep.plots import MapData

    sweep = spec.sweep
    metric = next((c for c in HISTOGRAMS if c in columns), None)
    if len(sweep.grid) != 2 or sweep.combine != "product" or metric is None:
        return None
    (y_name, y_axis), (x_name, x_axis) = sweep.grid.items()
    y, x = axis_values(y_axis), axis_values(x_axis)
    z = in_order(record.out, record.parts, [metric])[metric].reshape(len(y), len(x), sweep.count)
    ys, xs = np.argsort(y, kind="stable"), np.argsort(x, kind="stable")  # listed in any order
    y, x, z = y[ys], x[xs], z[ys][:, xs]
    if not np.isfinite(z).any():
        return None
    x_label, y_label = (f"{n} ({UNITS[n][0]})" if n in UNITS else n for n in (x_name, y_name))
    data = MapData(
        f"sweep {spec.name}: {metric}", x_label, x, y_label, y, metric, np.median(z, axis=2)
    )
    if sweep.criterion.spin_stability is None:
        return data
    X, Y = np.meshgrid(np.linspace(x[0], x[-1], MESH), np.linspace(y[0], y[-1], MESH))
    v = spin_values(spec, {x_name: X, y_name: Y})
    sigma, it1, it3 = spin_axes(v, v["u2"], v["u4"])
    boundary = (X, Y, (sigma - it1) * (sigma - it3))
    label = "NOTES.md: (H_a - I_t1 Omega)(H_a - I_t3 Omega) = 0"
    return MapData(**{**asdict(data), "boundary": boundary, "boundary_label": label,
                      "second_y": _ratio_scale(spec, y_name)})  # fmt: skip


def _ratio_scale(spec: Spec, y_name: str) -> Any:
    """For an I22 axis: a second scale, the inertia ratio I~22 / I_t1."""
    if y_name != "I22":
        return None
    v = spin_values(spec, {})
    names = ("m_a", "m_b", "I11", "I22", "I33", "I13", "I", "l1", "l3")
    a22 = lumped_inertias(*(v[n] for n in names))[1]
    it1 = float(spin_axes(v, 1.0, 0.0)[1])
    shift = float(a22 - v["I22"])
    return ("I~22 / I_t1", lambda i22: (i22 + shift) / it1, lambda r: r * it1 - shift)
