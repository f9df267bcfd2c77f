"""The sweep-file space under a property test: drawn sweep files over three
scenes (the default, a quaternion twin with runtime masses, a cluster),
with drawn overrides, grids, draws and metrics, hostile values among them
(negative or huge masses, spans past double range, spreads that overflow,
zero quaternions, metrics a cluster lacks). Each file is either refused in
one line (SceneError) or gives inputs that are finite, with no warning from
numpy, for its first and last trajectories. `make fuzz` runs more draws."""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gyrogen.analysis.sweep.draws import inputs
from gyrogen.analysis.sweep.spec import METRICS, parse
from gyrogen.errors import SceneError
from gyrogen.scene import builtin_text

EXAMPLES = int(os.environ.get("GYROGEN_SWEEP_EXAMPLES", "150"))
QUAT = builtin_text("gyrostat").replace('name = "gyrostat"', 'name = "gq"').replace(
    'attitude = "euler312"', 'attitude = "quaternion"'
).replace("initial = { q2 = 0.1, ", "initial = { ")  # fmt: skip
SCENES = {"gyrostat": "gyrostat", "quaternion": "gq.toml", "cluster": "rw4_pyramid"}
NUMBERS = st.one_of(
    st.floats(-10, 10, allow_nan=False),
    st.sampled_from([0.0, -1.0, 1e-300, 1e300, -1e300, 1e308, -1e308, 1e30, 5e-324]),
)
NAMES = {
    "gyrostat": ["m_a", "m_b", "I11", "I22", "I13", "J", "u1", "u4", "q2", "T"],
    "quaternion": ["m_a", "I22", "u1", "u3", "e0"],
    "cluster": ["w_ref_1", "u1", "w2", "m_a"],
}


@st.composite
def axis(draw: st.DrawFn) -> str:
    kind = draw(st.sampled_from(["list", "linspace", "logspace"]))
    a, b = draw(NUMBERS), draw(NUMBERS)
    if kind == "list":
        return f"{{ list = [{a!r}, {b!r}] }}"
    n = draw(st.integers(0, 4))
    if kind == "logspace":
        a, b = draw(st.floats(-320, 320)), draw(st.floats(-320, 320))
    return f"{{ {kind} = [{a!r}, {b!r}, {n}] }}"


@st.composite
def distribution(draw: st.DrawFn) -> str:
    kind = draw(st.sampled_from(["uniform", "normal", "lognormal"]))
    a, b = draw(NUMBERS), draw(NUMBERS)
    if kind == "lognormal" and draw(st.booleans()):
        a = draw(st.floats(-800, 800))
    return f"{{ {kind} = [{a!r}, {b!r}] }}"


@st.composite
def sweep_files(draw: st.DrawFn) -> str:
    which = draw(st.sampled_from(list(SCENES)))
    names = NAMES[which]
    lines = [f'scene = "{SCENES[which]}"', "t_end = 1.0"]
    override = [n for n in draw(st.lists(st.sampled_from(names), max_size=2, unique=True))]
    initial = [n for n in override if not n.startswith(("m_", "I", "J", "T", "w_ref"))]
    params = [n for n in override if n not in initial]
    if params:
        lines += ["[parameters]", *(f"{n} = {draw(NUMBERS)!r}" for n in params)]
    if initial:
        lines += ["[initial]", *(f"{n} = {draw(NUMBERS)!r}" for n in initial)]
    swept = [n for n in names if n not in override]
    grid = draw(st.lists(st.sampled_from(swept), max_size=2, unique=True))
    if grid:
        lines += ["[grid]", *(f"{n} = {draw(axis())}" for n in grid)]
    free = [n for n in swept if n not in grid]
    drawn = draw(st.lists(st.sampled_from(free), max_size=2, unique=True)) if free else []
    if drawn:
        lines += ["[draws]", "seed = 3", f"count = {draw(st.integers(1, 5))}"]
        lines += [f"{n} = {draw(distribution())}" for n in drawn]
    keep = draw(st.lists(st.sampled_from([m for m in METRICS if m != "time_to"]), max_size=3,
                         unique=True))  # fmt: skip
    lines += ["[metrics]", f"keep = {keep!r}".replace("'", '"')]
    return "\n".join(lines) + "\n"


@settings(max_examples=EXAMPLES, derandomize="GYROGEN_SWEEP_EXAMPLES" not in os.environ,
          deadline=None, suppress_health_check=[HealthCheck.too_slow])  # fmt: skip
@given(text=sweep_files())
def test_every_drawn_sweep_file_is_refused_in_one_line_or_gives_finite_inputs(text: str) -> None:
    here = Path(os.environ.get("TMPDIR", "/tmp")) / f"gyrogen-sweep-space-{os.getpid()}"
    here.mkdir(exist_ok=True)
    (here / "gq.toml").write_text(QUAT)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a numpy RuntimeWarning fails the draw
        try:
            spec = parse(text, "drawn.toml", "drawn", here)
        except SceneError as exc:
            message = str(exc)
            assert message.startswith("drawn.toml: ") and "\n" not in message, message
            return
        for start in {0, spec.size - 1}:
            inp = inputs(spec, start, start + 1)
            assert np.all(np.isfinite(inp.x0)), (text, inp.x0)
            assert np.all(np.isfinite(inp.p)), (text, inp.p)
