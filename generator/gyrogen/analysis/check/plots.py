"""The figure of one `gyrogen check` case: what the case is about.

Four panels on t: the integrator's mean step per output interval (from each
interval's statistics) with the cumulative rhs calls, the invariants'
relative drift, the quantity that makes the case extreme (Case.extreme, set
next to the case in cases.py), and the numbers and the diagnosis in
words. A case setup refuses has no run: its figure says why, in words.
Imported only when plots are asked for (matplotlib is slow to load).
"""

from __future__ import annotations

import math
import textwrap

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from gyrogen.abi import ODE_CODES, Code, message, setup_codes_of
from gyrogen.analysis.check.engine import Result
from gyrogen.analysis.simulate.plots import DPI, FLOOR, SIZE_INCHES, invariant_drifts, png_bytes


def _words(ax: Axes, y: float, text: str, size: float = 10, width: int = 68) -> None:
    """Monospaced lines from the top left of ax, at height y (axes
    fraction), folded at width characters."""
    folded = "\n".join(textwrap.fill(line, width) or line for line in text.split("\n"))
    ax.text(0.02, y, folded, transform=ax.transAxes, family="monospace", fontsize=size, va="top")


def png(res: Result) -> bytes:
    """The case's figure as PNG bytes of exactly plots.PIXELS."""
    fig = Figure(figsize=SIZE_INCHES, dpi=DPI, layout="constrained")
    fig.suptitle(f"gyrogen check: {res.case.name}")
    if res.setup_code != 0 or res.case.refused_by:
        _refused(fig.subplots(), res)
        return png_bytes(fig)
    (steps, drift), (extreme, summary) = fig.subplots(2, 2)
    _steps(steps, res)
    _drift(drift, res)
    _extreme(extreme, res)
    _summary(summary, res)
    for ax in (steps, drift, extreme):
        ax.grid(True, alpha=0.3)
        ax.set_xlabel("t (s)")
        if res.code != 0 and ax.axison:
            stop = float(res.stats.get("t", math.nan))
            ax.axvline(stop, color="red", linestyle=":", label=f"stopped: code {res.code}")
            ax.legend(loc="best", fontsize="small")
    return png_bytes(fig)


def _code_line(codes: tuple[Code, ...], value: int) -> str:
    name = next((c.name for c in codes if c.value == value), "?")
    return f"code {value} ({name}): {message(codes, value)}"


def _refused(ax: Axes, res: Result) -> None:
    ax.axis("off")
    case = res.case
    verdict = "as expected" if res.passed else f"NOT as expected (expected {case.expect})"
    params = ", ".join(f"{k} = {v:.3g}" for k, v in case.params.items())
    lines = [
        f"REFUSED by setup, {verdict}: nothing was integrated.",
        "",
        f"setup returned {_code_line(setup_codes_of(bool(case.scene.rotors)), res.setup_code)}",
        "",
        "parameters: " + params,
        f"scene: {case.scene.name}",
    ]
    if case.refused_by:  # the scene's own rules refused the values folded into it
        lines = [
            f"REFUSED at generation, {verdict}: nothing was built or integrated.",
            "",
            case.refused_by,
        ]
    if case.extreme is not None and case.extreme.values is None:
        lines += ["", case.extreme.label]
    _words(ax, 0.95, "\n".join(lines), 13, width=100)


def _interval_ends(res: Result) -> np.ndarray:
    """The start of each interval run, and the time the last one reached."""
    assert res.times is not None
    ends = np.asarray(res.times[: len(res.intervals) + 1], dtype=float)
    if res.intervals:
        ends = np.append(ends[: len(res.intervals)], float(res.intervals[-1]["t"]))
    return ends


def _steps(ax: Axes, res: Result) -> None:
    """Mean accepted step per output interval (log), rejected steps marked,
    cumulative rhs calls on a twin axis."""
    ends = _interval_ends(res)
    accepted = np.array([max(1, int(s["accepted"])) for s in res.intervals])
    rejected = np.array([int(s["rejected"]) for s in res.intervals])
    mean_h = np.maximum(np.diff(ends) / accepted, FLOOR)
    shown = np.append(mean_h, mean_h[-1:])
    ax.step(ends, shown, where="post", label="mean accepted step h")
    bad = rejected > 0
    mids = (ends[:-1] + ends[1:]) / 2
    label = f"intervals with rejections ({int(rejected.sum())} in all)"
    ax.plot(mids[bad], mean_h[bad], "rx", label=label)
    ax.set_yscale("log")
    ax.set(title="step size per output interval", ylabel="h (s)")
    calls = ax.twinx()
    cumulative = np.concatenate([[0], np.cumsum([int(s["rhs_calls"]) for s in res.intervals])])
    calls.plot(ends, cumulative, color="tab:gray", linestyle="--", label="rhs calls (cumulative)")
    calls.set_ylabel("rhs calls")
    lines = ax.get_legend_handles_labels()
    more = calls.get_legend_handles_labels()
    ax.legend(lines[0] + more[0], lines[1] + more[1], loc="lower right", fontsize="small")


def _drift(ax: Axes, res: Result) -> None:
    if not res.drift_series or res.times is None:
        ax.axis("off")
        words = f"not judged: the run stopped at t = {res.stats.get('t', math.nan):.3g} s"
        _words(ax, 0.9, words, 12)
        ax.set(title="invariants")
        return
    invariant_drifts(ax, res.times, res.drift_series)


def _extreme(ax: Axes, res: Result) -> None:
    extreme = res.case.extreme
    if extreme is None or extreme.values is None or res.trajectory is None:
        ax.axis("off")
        words = extreme.label if extreme else f"{res.case.scene.description}"
        ax.set_title("what makes the case extreme (constant along the run)")
        _words(ax, 0.9, words, 12)
        return
    assert res.times is not None
    times, states = res.times, res.trajectory
    if res.stopped is not None:  # and the last good state, where it stopped
        times = np.append(times, float(res.stats["t"]))
        states = np.vstack([states, res.stopped])
    values = extreme.values(res.case, states)
    if extreme.log:
        ax.semilogy(times, np.maximum(np.abs(values), FLOOR), "o-", markersize=3)
    else:
        ax.plot(times, values, "o-", markersize=3)
    for level, what in extreme.marks:
        ax.axhline(level, color="red", linestyle="--", linewidth=0.9, label=what)
    if extreme.marks:
        ax.legend(loc="best", fontsize="small")
    ax.set(title=extreme.label, ylabel=extreme.label.split(" (")[0])


def _summary(ax: Axes, res: Result) -> None:
    ax.axis("off")
    case, stats = res.case, res.stats
    ok = "as expected" if res.passed else f"NOT as expected (expected {case.expect})"
    drift = f"{max(res.drift.values()):.2e}" if res.drift else "not judged"
    lines = [
        f"verdict: {res.verdict}, {ok}",
        f"method: {res.method}",
        f"  {res.recommended}",
        f"steps: {stats.get('accepted', 0)} accepted, {stats.get('rejected', 0)} rejected",
        f"rhs calls: {stats.get('rhs_calls', 0)}, Jacobians: {stats.get('jac_calls', 0)}",
        f"largest invariant drift: {drift}",
        f"stiffness index: {res.stiffness:.3g}",
        f"mass matrix condition number: {res.condition:.3g}",
    ]
    if res.code != 0:
        name = next((c.name for c in ODE_CODES if c.value == res.code), "?")
        lines.append(f"integrator returned code {res.code} ({name})")
    if res.diagnosis:
        lines += ["", res.diagnosis]
    ax.set_title("summary")
    _words(ax, 1.0, "\n".join(lines))
