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
from sweep_cases import rows

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


def refused(cli, path: Path, out: Path, case: str, message: str) -> None:
    """`gyrogen sweep path` refused: exit 2, one line naming the file and
    saying message, nothing written."""
    code, stdout, err = cli(["sweep", str(path), "--out", str(out)])
    assert code == 2, (case, err)
    assert err.count("\n") == 1 and err.startswith(f"gyrogen: error: {path}: "), err
    assert message in err, err
    assert not out.exists() and stdout == ""


@pytest.mark.parametrize(("case", "text", "message"), BAD, ids=[b[0] for b in BAD])
def test_bad_misalignment_is_one_line_exit_2_nothing_written(
    case: str, text: str, message: str, tmp_path: Path, cli
) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    refused(cli, path, tmp_path / "out", case, message)


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


# A gimbal's pair of runtime axes ([draws.misalign] gimbal_K): the gimbal
# axis tilted within the cone, the spin axis at gimbal angle 0 turned with it.

PYRAMID = load("cmg4_pyramid").rotors


def cmg_runtime(*ks: int) -> str:
    """cmg4_pyramid with rotors ks' spin axis and gimbal axis at run time
    (their values the pyramid's, in simulate.parameters)."""
    head, *tables = builtin_text("cmg4_pyramid").split("[[rotors]]")
    given = []
    for k in ks:
        r = PYRAMID[k - 1]
        assert r.gimbal is not None
        for keys, axis in ((("g1", "g2", "g3"), r.axis), (("gg1", "gg2", "gg3"), r.gimbal.axis)):
            assert f"axis = {list(axis)}" in tables[k - 1]
            tables[k - 1] = tables[k - 1].replace(f"axis = {list(axis)}", 'axis = "runtime"', 1)
            given += [f"{key}_{k} = {x!r}" for key, x in zip(keys, axis, strict=True)]
    text = "[[rotors]]".join([head, *tables]).replace('name = "cmg4_pyramid"', 'name = "cmg_rt"')
    return text.replace("parameters = { ", f"parameters = {{ {', '.join(given)}, ", 1)


CMG_SWEEP = """
scene = "cmg_rt.toml"
t_end = {t_end}
[draws]
seed = 5
count = {count}
[draws.misalign]
gimbal_1 = {{ angle = {{ {angle} }}, max_deg = {max_deg} }}
"""


def cmg_spec(tmp_path: Path, angle: str = "normal = [0.0, 0.2]", max_deg: str = "0.5",
             count: int = 2000, scene: str | None = None, t_end: float = 1.0):  # fmt: skip
    (tmp_path / "cmg_rt.toml").write_text(scene or cmg_runtime(1, 2, 3, 4))
    text = CMG_SWEEP.format(angle=angle, max_deg=max_deg, count=count, t_end=t_end)
    return parse(text, "x", "x", tmp_path)


def pairs(values: dict[str, np.ndarray], k: int) -> tuple[np.ndarray, np.ndarray]:
    """Each draw's gimbal axis g_g and spin axis g_s0 of rotor k."""
    return tuple(np.stack([values[f"{key}{i}_{k}"] for i in (1, 2, 3)], axis=1)  # type: ignore[return-value]
                 for key in ("gg", "g"))  # fmt: skip


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


def test_a_gimbal_misalignment_draws_both_axes_of_the_pair(tmp_path: Path) -> None:
    s = cmg_spec(tmp_path)
    assert s.variables == ("gg1_1", "gg2_1", "gg3_1", "g1_1", "g2_1", "g3_1")
    inp = inputs(s, 0, 10)
    for name in s.variables:
        assert np.array_equal(inp.p[:, s.scene.runtime.index(name)], inp.values[name])
    assert np.all(inp.p[:, s.scene.runtime.index("gg1_2")] == PYRAMID[1].gimbal.axis[0])  # type: ignore[union-attr]


@pytest.mark.parametrize(
    ("angle", "max_deg"), [("normal = [0.0, 0.2]", 0.5), ("uniform = [-30.0, 30.0]", 30.0),
                           ("uniform = [0.0, 90.0]", 90.0)])  # fmt: skip
def test_a_gimbal_pair_stays_orthonormal_and_turns_rigidly_within_the_cone(
    angle: str, max_deg: float, tmp_path: Path
) -> None:
    """Each drawn pair is orthonormal; the gimbal axis is within the cone; the
    pair is the nominal one turned by one rotation about an axis
    perpendicular to the nominal gimbal axis (no twist about it: that would
    be a gimbal angle), by the gimbal axis's tilt, so the spin axis moves no
    farther than the gimbal axis."""
    s = cmg_spec(tmp_path, angle=angle, max_deg=str(max_deg))
    g_g, g_s = pairs(inputs(s, 0, 2000).values, 1)
    assert np.max(np.abs(np.linalg.norm(g_g, axis=1) - 1.0)) < 4e-16
    assert np.max(np.abs(np.linalg.norm(g_s, axis=1) - 1.0)) < 4e-16
    assert np.max(np.abs(np.sum(g_g * g_s, axis=1))) < 4e-16
    r = PYRAMID[0]
    g0, s0 = (np.array(v) for v in (r.gimbal.axis, r.axis))  # type: ignore[union-attr]
    tilt = angle_between(g_g, g0)
    assert 0.9 * max_deg < np.degrees(tilt.max()) <= max_deg * (1 + 1e-12)
    before = np.stack([g0, s0, np.cross(g0, s0)], axis=1)
    after = np.stack([g_g, g_s, np.cross(g_g, g_s)], axis=2)
    turn = after @ before.T  # the rotation taking the nominal pair to each drawn one
    assert np.allclose(turn @ turn.transpose(0, 2, 1), np.eye(3), rtol=0, atol=1e-15)
    size = 2.0 * np.arcsin(np.linalg.norm(turn - np.eye(3), axis=(1, 2)) / np.sqrt(8.0))
    assert np.max(np.abs(size - tilt)) < 1e-14
    assert np.all(angle_between(g_s, s0) <= tilt + 1e-14)


def test_drawn_pairs_pass_setups_axis_checks(tmp_path: Path) -> None:
    """setup's code 8 (each axis of unit length) and 10 (perpendicular) on
    every drawn pair, tilted up to 30 degrees; the spin axis tilted alone
    by as little as 0.06 degrees fails code 10 (the refusal gimbal_K
    avoids, and axis_K on a gimbal is refused for)."""
    from gyrogen.setup_checks import cluster_checks, failure

    s = cmg_spec(tmp_path, angle="uniform = [-30.0, 30.0]", max_deg="30.0")
    checks = [c for c in cluster_checks(dict.fromkeys(s.variables, "runtime"), 1)
              if c.code in (8, 10)]  # fmt: skip
    assert [c.code for c in checks] == [8, 8, 10]
    values = inputs(s, 0, 200).values
    for i in range(200):
        row = {name: float(v[i]) for name, v in values.items()}
        assert [failure(c, row) for c in checks] == [None] * 3
        alone = {**row, **{f"gg{j}_1": PYRAMID[0].gimbal.axis[j - 1] for j in (1, 2, 3)}}  # type: ignore[union-attr]
        g_g, g_s = pairs({n: np.array([v]) for n, v in alone.items()}, 1)
        if np.degrees(angle_between(g_g, g_s)[0]) < 89.94:
            assert failure(checks[2], alone) is not None


def test_gimbal_draws_depend_on_seed_and_index_alone(tmp_path: Path) -> None:
    s = cmg_spec(tmp_path, count=500)
    whole = inputs(s, 0, 500)
    part = inputs(s, 123, 200)
    for name in s.variables:
        assert np.array_equal(part.values[name], whole.values[name][123:200])


def test_a_nominal_pair_off_perpendicular_within_the_slack_is_made_orthonormal(
    tmp_path: Path,
) -> None:
    """Nominal axes within setup's slacks (a length off by 5e-4, the spin
    axis 5e-4 off perpendicular) are drawn as setup would make them: g_g
    normalized, g_s0 made perpendicular to it."""
    s = cmg_spec(tmp_path, scene=cmg_runtime(1).replace("g3_1 = 0.0", "g3_1 = 0.0005")
                 .replace("gg1_1 = 0.8165408118857462", "gg1_1 = 0.8170"))  # fmt: skip
    g_g, g_s = pairs(inputs(s, 0, 500).values, 1)
    assert np.max(np.abs(np.linalg.norm(g_s, axis=1) - 1.0)) < 4e-16
    assert np.max(np.abs(np.sum(g_g * g_s, axis=1))) < 4e-16


GIMBAL_BAD = [
    ("spin axis alone", "gimbal_1 =", "axis_1 =", cmg_runtime(1),
     "draws.misalign.axis_1: rotor 1 is on a gimbal, whose spin axis turns with its gimbal "
     "axis (tilted alone setup refuses it: code 10): misalign the pair with gimbal_1"),
    ("no gimbal", "gimbal_1 =", "gimbal_1 =", builtin_text("rw4_hardware").replace(
        'name = "rw4_hardware"', 'name = "cmg_rt"'),
     "draws.misalign.gimbal_1: rotor 1 has no gimbal: misalign its axis with axis_1"),
    ("folded gimbal axis", "gimbal_1 =", "gimbal_1 =", cmg_runtime(1).replace(
        'axis = "runtime"\ninertia', "axis = [0.8165408118857462, 0.0, 0.5772877120855479]\n"
        "inertia", 1).replace("gg1_1 = 0.8165408118857462, gg2_1 = 0.0, "
                              "gg3_1 = 0.5772877120855479, ", ""),
     "draws.misalign.gimbal_1: rotor 1's gimbal axis is folded into the code: make axis and "
     'gimbal.axis "runtime" in the scene to misalign the pair'),
    ("folded pair", "gimbal_1 =", "gimbal_1 =", builtin_text("cmg4_pyramid").replace(
        'name = "cmg4_pyramid"', 'name = "cmg_rt"'),
     "draws.misalign.gimbal_1: rotor 1's spin axis and gimbal axis are folded into the code"),
    ("no such gimbal", "gimbal_1 =", "gimbal_5 =", cmg_runtime(1),
     "draws.misalign.gimbal_5: not a rotor axis of scene cmg_rt (gimbal_1..gimbal_4)"),
    ("also drawn", "[draws.misalign]", "gg2_1 = { normal = [0.0, 0.01] }\n[draws.misalign]",
     cmg_runtime(1), "draws.misalign.gimbal_1: gg2_1 also on the grid or drawn"),
    ("spin also drawn", "[draws.misalign]", "g3_1 = { normal = [0.0, 0.01] }\n[draws.misalign]",
     cmg_runtime(1), "draws.misalign.gimbal_1: g3_1 also on the grid or drawn"),
    ("not perpendicular", "[draws]", "[parameters]\ng3_1 = 0.01\n[draws]", cmg_runtime(1),
     "draws.misalign.gimbal_1: nominal gg1_1..gg3_1: not perpendicular to the spin axis "
     "(|g_s0 . g_g| = 0.00577"),
    ("nominal length", "[draws]", "[parameters]\ngg3_1 = 0.6\n[draws]", cmg_runtime(1),
     "draws.misalign.gimbal_1: nominal gg1_1..gg3_1: length 1.01"),
]  # fmt: skip


@pytest.mark.parametrize(("case", "old", "new", "scene", "message"), GIMBAL_BAD,
                         ids=[b[0] for b in GIMBAL_BAD])  # fmt: skip
def test_bad_gimbal_misalignment_is_one_line_exit_2_nothing_written(
    case: str, old: str, new: str, scene: str, message: str, tmp_path: Path, cli
) -> None:
    (tmp_path / "cmg_rt.toml").write_text(scene)
    text = CMG_SWEEP.format(angle="normal = [0.0, 0.2]", max_deg=0.5, count=10, t_end=1.0)
    assert old in text
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(old, new))
    refused(cli, path, tmp_path / "out", case, message)


@pytest.mark.slow
@pytest.mark.skipif(
    not os.environ.get("GYROGEN_VERIFY_AXES"),
    reason="runtime gimbal axes take minutes to derive: make verify-axes",
)
def test_a_sweep_with_a_cone_on_a_pyramid_gimbal_runs(
    tmp_path: Path, cache_dir: Path, monkeypatch: pytest.MonkeyPatch, cli
) -> None:
    """cmg4_pyramid with its first gimbal's axes at run time (minutes to
    derive), its pair tilted within 2 degrees: every row set up and run
    (the spin axis tilted alone by 0.5 degrees: setup's code 10)."""
    from gyrogen.runtime.scene_build import compiled, scene_sources

    monkeypatch.setenv("GYROGEN_CACHE", str(cache_dir))
    s = cmg_spec(tmp_path, angle="uniform = [-2.0, 2.0]", max_deg="2.0", count=6, t_end=0.5,
                 scene=cmg_runtime(1))  # fmt: skip
    path = tmp_path / "cone.toml"
    path.write_text(CMG_SWEEP.format(angle="uniform = [-2.0, 2.0]", max_deg=2, count=6, t_end=0.5))
    code, _, err = cli(["sweep", str(path), "--out", str(tmp_path / "out"), "--workers", "1",
                        "--quiet", "--no-plots"])  # fmt: skip
    assert code == 0, err
    got = rows(tmp_path / "out").sort_values("sample")
    assert list(got["setup_code"]) == [0] * 6 and list(got["code"]) == [0] * 6
    want = inputs(s, 0, 6).values
    for name in s.variables:
        np.testing.assert_array_equal(got[name].to_numpy(), want[name])
    assert np.all(np.isfinite(got[[f"final_{n}" for n in s.scene.states]].to_numpy()))
    comp = compiled(scene_sources(s.scene))
    p = inputs(s, 0, 1).p[0]
    g_s = [s.scene.runtime.index(f"g{i}_1") for i in (1, 2, 3)]
    p[g_s] = [0.0, np.cos(np.radians(0.5)), np.sin(np.radians(0.5))]  # off the gimbal's plane
    assert comp.setup_code(p)[0] == 10
