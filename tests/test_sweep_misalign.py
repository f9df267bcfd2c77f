"""Misalignment draws: a sweep tilts a runtime axis by a small random
rotation ([draws.misalign], axis_K = { angle = distribution in degrees,
max_deg }); each draw is a unit vector within the cone, a function of
(seed, index) alone; hostile values are refused in one line naming the
field (also drawn: tests/test_sweep_space.py's files do not reach these
keys, so a property test of their own here). And the pointing metric the
Monte Carlo reads: the angle a3 turned through, in N."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy import stats

from gyrogen.analysis.sweep.draws import inputs
from gyrogen.analysis.sweep.metrics import columns, pointing
from gyrogen.analysis.sweep.spec import load as load_sweep
from gyrogen.analysis.sweep.spec import parse
from gyrogen.errors import SceneError
from gyrogen.scene import builtin_text, load
from gyrogen.sweep_values import MAX_TILT_DEG

NOMINAL = load("rw4_hardware").simulate.parameters
SWEEP = """
scene = "rw4_hardware"
t_end = 1.0
[draws]
seed = 11
count = {count}
I_2 = {{ normal = [0.025, 0.0002] }}
[draws.misalign]
axis_1 = {{ angle = {{ {angle} }}, max_deg = {max_deg} }}
"""


def spec(angle: str = "normal = [0.0, 0.2]", max_deg: str = "0.5", count: int = 5000):
    return parse(SWEEP.format(angle=angle, max_deg=max_deg, count=count), "x", "x", None)


def nominal(k: int) -> np.ndarray:
    g = np.array([NOMINAL[f"g{i}_{k}"] for i in (1, 2, 3)])
    return g / np.linalg.norm(g)


def tilts(values: dict[str, np.ndarray], k: int) -> tuple[np.ndarray, np.ndarray]:
    """Each draw of axis k, and its angle from the nominal (degrees)."""
    g = np.stack([values[f"g{i}_{k}"] for i in (1, 2, 3)], axis=1)
    g0 = nominal(k)
    angle = np.arctan2(np.linalg.norm(np.cross(g, g0), axis=1), g @ g0)
    return g, np.degrees(angle)


def test_the_swept_names_are_the_axis_components_after_the_drawn() -> None:
    s = spec()
    assert s.variables == ("I_2", "g1_1", "g2_1", "g3_1")


def test_a_draw_is_a_unit_vector_within_the_cone() -> None:
    values = inputs(spec(), 0, 5000).values
    g, angle = tilts(values, 1)
    assert np.max(np.abs(np.linalg.norm(g, axis=1) - 1.0)) < 4e-16
    assert np.all(angle <= 0.5 + 1e-9) and angle.max() > 0.45


def test_the_tilt_follows_its_distribution_and_its_direction_is_uniform() -> None:
    """|N(0, 0.2)| within 0.5 deg: a half-normal truncated at 2.5 sd; the
    direction about the nominal axis uniform on the circle."""
    values = inputs(spec(count=20000), 0, 20000).values
    g, angle = tilts(values, 1)
    half = stats.truncnorm(0.0, 2.5, loc=0.0, scale=0.2)
    assert stats.kstest(angle, half.cdf).pvalue > 1e-3
    g0 = nominal(1)
    side = g - np.outer(g @ g0, g0)
    e1 = np.cross(g0, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    phi = np.arctan2(side @ np.cross(g0, e1), side @ e1)
    assert stats.kstest(phi, stats.uniform(-math.pi, 2 * math.pi).cdf).pvalue > 1e-3


def test_draws_depend_on_seed_and_index_alone() -> None:
    s = spec()
    whole = inputs(s, 0, 1000)
    for start in (0, 37, 999):
        part = inputs(s, start, min(1000, start + 37))
        for name in s.variables:
            assert np.array_equal(part.values[name], whole.values[name][start : start + 37])
    other = parse(SWEEP.format(angle="normal = [0.0, 0.2]", max_deg="0.5", count=1000)
                  .replace("seed = 11", "seed = 12"), "x", "x", None)  # fmt: skip
    assert not np.array_equal(inputs(other, 0, 1000).values["g1_1"], whole.values["g1_1"])


def test_the_draws_go_into_p() -> None:
    s = spec()
    inp = inputs(s, 0, 100)
    runtime = s.scene.runtime
    for name in ("g1_1", "g2_1", "g3_1", "I_2"):
        assert np.array_equal(inp.p[:, runtime.index(name)], inp.values[name])
    assert np.all(inp.p[:, runtime.index("g3_2")] == NOMINAL["g3_2"])  # not misaligned


def test_the_nominal_axis_is_normalized_first() -> None:
    """A nominal within the scene's slack of unit length: the draws are unit vectors."""
    text = SWEEP.format(angle="uniform = [0.0, 0.1]", max_deg="0.1", count=100)
    text += "[parameters]\ng1_1 = 0.5778\n"
    g, _ = tilts(inputs(parse(text, "x", "x", None), 0, 100).values, 1)
    assert np.max(np.abs(np.linalg.norm(g, axis=1) - 1.0)) < 4e-16


MISALIGN = SWEEP.format(angle="normal = [0.0, 0.2]", max_deg="0.5", count=10)
BAD = [
    ("negative", MISALIGN.replace("max_deg = 0.5", "max_deg = -1.0"),
     "draws.misalign.axis_1.max_deg: must be in (0, 90] degrees (got -1)"),
    ("zero", MISALIGN.replace("max_deg = 0.5", "max_deg = 0.0"),
     "draws.misalign.axis_1.max_deg: must be in (0, 90] degrees (got 0)"),
    ("past 90", MISALIGN.replace("max_deg = 0.5", "max_deg = 90.5"),
     "draws.misalign.axis_1.max_deg: must be in (0, 90] degrees (got 90.5)"),
    ("nan", MISALIGN.replace("max_deg = 0.5", "max_deg = nan"),
     "draws.misalign.axis_1.max_deg: Input should be a finite number"),
    ("infinite", MISALIGN.replace("max_deg = 0.5", "max_deg = inf"),
     "draws.misalign.axis_1.max_deg: Input should be a finite number"),
    ("no max", MISALIGN.replace(", max_deg = 0.5", ""), "draws.misalign.axis_1.max_deg: Field"),
    ("angle nan", MISALIGN.replace("[0.0, 0.2]", "[nan, 0.2]"),
     "draws.misalign.axis_1.angle.normal.0: Input should be a finite number"),
    ("angle outside", MISALIGN.replace("normal = [0.0, 0.2]", "uniform = [1.0, 2.0]"),
     "draws.misalign.axis_1: angle: leaves no probability within +-max_deg = 0.5 degrees"),
    ("not an axis", MISALIGN.replace("axis_1 =", "I_1 ="),
     "draws.misalign.I_1: not a rotor axis of scene rw4_hardware (axis_1..axis_4)"),
    ("no such rotor", MISALIGN.replace("axis_1 =", "axis_5 ="),
     "draws.misalign.axis_5: not a rotor axis of scene rw4_hardware (axis_1..axis_4)"),
    ("leading zero", MISALIGN.replace("axis_1 =", "axis_01 ="), "draws.misalign.axis_01: not a"),
    ("folded axis", MISALIGN.replace('"rw4_hardware"', '"rw4_pyramid"').replace("I_2 = ", "w2 = "),
     "draws.misalign.axis_1: rotor 1's axis is folded into the code: make it \"runtime\""),
    ("single rotor", MISALIGN.replace('"rw4_hardware"', '"gyrostat"').replace("I_2 = ", "u1 = "),
     "draws.misalign.axis_1: not a rotor axis of scene gyrostat (none: not a cluster)"),
    ("also drawn", MISALIGN.replace("I_2 = ", "g2_1 = "),
     "draws.misalign.axis_1: g2_1 also on the grid or drawn"),
    ("also on the grid", MISALIGN + "[grid]\ng3_1 = { list = [0.8, 0.81] }\n",
     "draws.misalign.axis_1: g3_1 also on the grid or drawn"),
    ("nominal", MISALIGN + "[parameters]\ng1_1 = 0.7\n",
     "draws.misalign.axis_1: nominal g1_1..g3_1: length 1.07548439 is not 1 (within 0.001)"),
]  # fmt: skip


@pytest.mark.parametrize(("case", "text", "message"), BAD, ids=[b[0] for b in BAD])
def test_bad_misalignment_is_one_line_exit_2_nothing_written(
    case: str, text: str, message: str, tmp_path: Path, cli
) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    out = tmp_path / "out"
    code, stdout, err = cli(["sweep", str(path), "--out", str(out)])
    assert code == 2, (case, err)
    assert err.count("\n") == 1 and err.startswith(f"gyrogen: error: {path}: "), err
    assert message in err, err
    assert not out.exists() and stdout == ""


HOSTILE = st.one_of(
    st.floats(-200.0, 200.0),
    st.sampled_from([0.0, -0.0, 1e-300, 90.0, 90.0000001, 1e308, -1e308, 5e-324]),
    st.just(math.nan),
    st.just(math.inf),
    st.just(-math.inf),
)


def _toml(x: float) -> str:
    return "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf") if math.isinf(x) else repr(x)


@settings(
    max_examples=int(os.environ.get("GYROGEN_SWEEP_EXAMPLES", "150")),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(
    kind=st.sampled_from(["uniform", "normal", "lognormal"]),
    a=HOSTILE,
    b=HOSTILE,
    max_deg=HOSTILE,
)
def test_drawn_misalignments_are_refused_in_one_line_or_stay_in_their_cone(
    kind: str, a: float, b: float, max_deg: float
) -> None:
    angle = f"{kind} = [{_toml(a)}, {_toml(b)}]"
    try:
        s = spec(angle=angle, max_deg=_toml(max_deg), count=64)
    except SceneError as exc:
        text = str(exc)
        assert "\n" not in text and "draws.misalign.axis_1" in text, text
        return
    assert 0.0 < max_deg <= MAX_TILT_DEG
    g, tilt = tilts(inputs(s, 0, 64).values, 1)
    assert np.all(np.isfinite(g)) and np.max(np.abs(np.linalg.norm(g, axis=1) - 1.0)) < 4e-16
    assert np.all(tilt <= max_deg * (1 + 1e-9) + 1e-9)


QUATERNION = builtin_text("gyrostat").replace('name = "gyrostat"', 'name = "gq"').replace(
    'attitude = "euler312"', 'attitude = "quaternion"'
).replace("initial = { q2 = 0.1, ", "initial = { ")  # fmt: skip


@pytest.mark.parametrize("attitude", ["euler312", "quaternion"])
def test_pointing_is_the_angle_a3_turned_through(attitude: str, tmp_path: Path) -> None:
    """A turn about a1 by 0.3 tilts a3 by 0.3, one about a3 (q1) not at all;
    from one tilted start a further 0.2 about the same a1 is 0.2."""
    if attitude == "euler312":
        s = spec(count=1)
        x0, x = np.zeros((3, len(s.scene.states))), np.zeros((3, len(s.scene.states)))
        q = [s.scene.states.index(f"q{i}") for i in (1, 2, 3)]
        x[0, q[1]], x[1, q[0]] = 0.3, 1.0  # q2: about a1 (after q1 = 0); q1: about a3
        x0[2, q[1]], x[2, q[1]] = 0.1, 0.3
    else:
        (tmp_path / "gq.toml").write_text(QUATERNION)
        s = parse('scene = "gq.toml"\n[metrics]\nkeep = ["pointing"]', "x", "x", tmp_path)
        x0, x = np.zeros((3, len(s.scene.states))), np.zeros((3, len(s.scene.states)))
        x0[:, 0] = 1.0
        x[0, :2] = math.cos(0.15), math.sin(0.15)  # about a1 (e1) by 0.3
        x[1, 0], x[1, 3] = math.cos(0.5), math.sin(0.5)  # about a3 (e3) by 1.0
        x0[2, :2] = math.cos(0.05), math.sin(0.05)
        x[2, :2] = math.cos(0.15), math.sin(0.15)
        assert "pointing" in columns(s)
    assert np.allclose(pointing(s, x0, x), [0.3, 0.0, 0.2], rtol=0, atol=1e-15)


def test_a_sweeps_pointing_column_is_the_turn_from_its_start(tmp_path: Path) -> None:
    """run_chunk's pointing: a3's angle between each row's start (its inputs)
    and its final state, not zero (the start is integrated in place; the
    column once read the end twice)."""
    from gyrogen.analysis.sweep.metrics import run_chunk
    from gyrogen.runtime.scene_build import compiled, scene_sources

    (tmp_path / "gq.toml").write_text(QUATERNION)
    text = 'scene = "gq.toml"\nt_end = 1.0\n[grid]\nu1 = { list = [0.0, 0.3] }\n'
    s = parse(text + '[metrics]\nkeep = ["pointing", "final_state"]', "x", "x", tmp_path)
    cols = run_chunk(compiled(scene_sources(s.scene, False)), s, 0, 2)
    end = np.column_stack([cols[f"final_{n}"] for n in s.scene.states])
    want = pointing(s, inputs(s, 0, 2).x0, end)
    assert np.all(cols["code"] == 0) and np.all(want > 0.05)
    np.testing.assert_array_equal(cols["pointing"], want)


def test_the_builtin_misalignment_sweep_keeps_its_hardware_within_bounds() -> None:
    """sweeps/rw4_misalignment: 10^5 trajectories of one build, every axis
    within 0.5 degrees of the pyramid's, the inertias within 2%."""
    s = load_sweep("rw4_misalignment")
    assert s.size == 100_000 and s.scene.name == "rw4_hardware"
    inp = inputs(s, 99_000, 100_000)
    for k in (1, 2, 3, 4):
        g, angle = tilts(inp.values, k)
        assert np.all(angle <= 0.5 + 1e-9) and np.allclose(np.linalg.norm(g, axis=1), 1.0)
    for name in ("I11", "I22", "I33", "I_1", "J_4"):
        ratio = inp.values[name] / NOMINAL[name]
        assert np.all(np.abs(ratio - 1.0) <= 0.02 + 1e-12), name
