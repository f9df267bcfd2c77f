"""Sweep files: what they hold, their draws, and every refusal (one line,
exit 2, nothing written)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from gyrogen.analysis.sweep.draws import grid_values, inputs, uniforms
from gyrogen.analysis.sweep.spec import builtin_sweeps, load, parse

BASE = """
scene = "gyrostat"
t_end = 1.0
{top}
[grid]
u4 = {{ linspace = [0.0, 10.0, 3] }}
I22 = {{ list = [8.0, 9.0] }}
[draws]
seed = 5
count = 2
u1 = {{ normal = [0.0, 0.1] }}
{tail}
"""


def sweep_text(top: str = "", tail: str = "") -> str:
    return BASE.format(top=top, tail=tail)


def test_builtin_sweeps_load() -> None:
    assert set(builtin_sweeps()) >= {"stability_map", "monte_carlo"}
    spin = load("stability_map")
    assert spin.size == 41 * 41 and spin.variables == ("I22", "u4")
    assert load("monte_carlo").size == 10_000


def test_product_grid_runs_the_last_axis_fastest_and_draws_innermost() -> None:
    spec = parse(sweep_text(), "x", "x", None)
    assert spec.size == 3 * 2 * 2
    got = grid_values(spec, np.arange(spec.size) // spec.sweep.count)
    assert list(got["u4"]) == [0.0] * 4 + [5.0] * 4 + [10.0] * 4
    assert list(got["I22"]) == [8.0, 8.0, 9.0, 9.0] * 3


def test_zip_pairs_the_axes() -> None:
    text = sweep_text('combine = "zip"').replace("[8.0, 9.0]", "[8.0, 9.0, 10.0]")
    spec = parse(text, "x", "x", None)
    got = grid_values(spec, np.arange(3))
    assert list(got["u4"]) == [0.0, 5.0, 10.0] and list(got["I22"]) == [8.0, 9.0, 10.0]


def test_inputs_put_values_into_states_and_parameters() -> None:
    spec = parse(sweep_text(), "x", "x", None)
    inp = inputs(spec, 0, spec.size)
    states, runtime = spec.scene.states, spec.scene.runtime
    assert np.array_equal(inp.x0[:, states.index("u4")], inp.values["u4"])
    assert np.array_equal(inp.x0[:, states.index("u1")], inp.values["u1"])
    assert np.array_equal(inp.p[:, runtime.index("I22")], inp.values["I22"])
    given = spec.scene.simulate.parameters  # the rest from the scene's [simulate]
    assert np.all(inp.p[:, runtime.index("m_a")] == given["m_a"])
    assert np.all(inp.x0[:, states.index("q2")] == spec.scene.simulate.initial["q2"])


def test_draws_depend_on_seed_and_index_alone() -> None:
    whole = uniforms(7, 0, 1000, 5)
    pieces = [uniforms(7, a, min(1000, a + 37), 5) for a in range(0, 1000, 37)]
    assert np.array_equal(whole, np.vstack(pieces))
    assert np.array_equal(uniforms(7, 500, 501, 5)[0], whole[500])
    assert not np.array_equal(uniforms(8, 0, 1000, 5), whole)
    assert np.all((whole > 0) & (whole < 1))


@pytest.mark.parametrize(
    ("dist", "frozen", "bounds"),
    [
        ("uniform = [2.0, 5.0]", stats.uniform(2.0, 3.0), (2.0, 5.0)),
        ("normal = [1.0, 0.5]", stats.norm(1.0, 0.5), (-math.inf, math.inf)),
        ("lognormal = [0.5, 0.25]", stats.lognorm(0.25, scale=math.exp(0.5)), (0.0, math.inf)),
        ("normal = [1.0, 0.5], truncate = [0.8, 2.0]",
         stats.truncnorm(-0.4, 2.0, loc=1.0, scale=0.5), (0.8, 2.0)),
    ],
)  # fmt: skip
def test_draws_follow_their_distribution(dist: str, frozen: object, bounds: tuple) -> None:
    text = sweep_text().replace("u1 = { normal = [0.0, 0.1] }", f"u1 = {{ {dist} }}")
    spec = parse(text.replace("count = 2", "count = 20000"), "x", "x", None)
    drawn = inputs(spec, 0, 20000).values["u1"]
    assert np.all((drawn >= bounds[0]) & (drawn <= bounds[1]))
    assert stats.kstest(drawn, frozen.cdf).pvalue > 1e-3  # type: ignore[attr-defined]


TORQUE_FREE_RUNTIME = """
name = "tf_runtime"
description = "torque_free with I22 at run time and no value for it"
[parameters]
m_a = 10.0
m_b = 2.0
I11 = 3.0
I22 = "runtime"
I33 = 3.0
I13 = 0.0
I = 0.05
J = 0.08
l1 = 0.0
l3 = 0.0
[effects]
translation = false
rotor_angle = false
torque = "none"
"""

BAD = [
    ("toml", "scene = ", "invalid TOML"),
    ("integer of 5001 digits", sweep_text("chunk = 1" + "0" * 5000),
     "invalid TOML: an integer of more than 4300 digits"),
    ("unknown key", sweep_text("speed = 1"), "speed: unknown key"),
    ("method", sweep_text('method = "euler"'), "method: 'euler' is not among the scene's"),
    ("rk4 steps", sweep_text('method = "rk4"'), "steps: give it for rk4"),
    ("steps not rk4", sweep_text("steps = 100"), "steps: give it for rk4"),
    ("rk4 few steps", sweep_text('method = "rk4"\nsteps = 5', "[metrics]\nsamples = 10"),
     "steps: 5 is fewer than metrics.samples"),
    ("rtol", sweep_text("rtol = 1e-20"), "rtol: must be above 2.22e-15"),
    ("atol", sweep_text("atol = 0.0"), "atol: Input should be greater than 0"),
    ("chunk", sweep_text("chunk = 0"), "chunk: Input should be greater than or equal to 1"),
    ("unknown name", sweep_text(tail="[grid.u9]\nlist = [1.0]"), "grid.u9: not a state or"),
    ("two kinds", sweep_text().replace("linspace = [0.0, 10.0, 3]", "list = [1.0], "
     "linspace = [0.0, 1.0, 2]"), "grid.u4: give exactly one of list"),
    ("empty axis", sweep_text().replace("[0.0, 10.0, 3]", "[0.0, 10.0, 0]"),
     "0 values: from 1 to 1,000,000"),
    ("logspace range", sweep_text().replace("linspace = [0.0, 10.0, 3]",
     "logspace = [0.0, 400.0, 3]"), "logspace exponents beyond +-300"),
    ("zip lengths", sweep_text('combine = "zip"'), "combine = 'zip' needs axes of one length"),
    ("uniform", sweep_text(tail="u3 = { uniform = [1.0, 1.0] }"), "low must be below high"),
    ("spread", sweep_text(tail="u3 = { normal = [1.0, 0.0] }"), "the spread must be > 0"),
    ("no kind", sweep_text(tail="u3 = { truncate = [0.0, 1.0] }"), "give exactly one of uniform"),
    ("truncate", sweep_text(tail="u3 = { normal = [0.0, 1.0], truncate = [50.0, 60.0] }"),
     "truncate = [50, 60] leaves no probability"),
    ("grid and draws", sweep_text(tail="u4 = { normal = [0.0, 1.0] }"),
     "u4: both on the grid and drawn"),
    ("seed", sweep_text().replace("seed = 5", ""), "draws.seed: Field required"),
    ("count", sweep_text().replace("count = 2", "count = 0"), "draws.count: Input should be"),
    ("parameters", sweep_text(tail="[parameters]\nzz = 1.0"), "parameters.zz: not a runtime"),
    ("initial", sweep_text(tail="[initial]\nq9 = 1.0"), "initial.q9: not a state of scene"),
    ("wound", sweep_text(tail="[initial]\nq4 = 1e7"), "initial.q4 = 1e+07 rad: more than 2607"),
    ("wound grid", sweep_text(tail="[grid.q1]\nlogspace = [0.0, 5.0, 3]"),
     "grid.q1 reaches 100000 rad: more than 2607 turns"),
    ("wound draw", sweep_text(tail="q4 = { normal = [0.0, 3000.0] }"),
     "draws.q4 reaches 27000 rad: more than 2607 turns"),
    ("keep", sweep_text(tail='[metrics]\nkeep = ["energy"]'), "metrics.keep.0: Input should be"),
    ("time_to keep", sweep_text(tail="[metrics]\ntime_to = { rate = 1.0 }"),
     "metrics.time_to.rate: add 'time_to' to metrics.keep"),
    ("time_to name", sweep_text(tail='[metrics]\nkeep = ["time_to"]\ntime_to = { spin = 1.0 }'),
     "metrics.time_to.spin: not one of nutation, rate, q1"),
    ("samples", sweep_text(tail="[metrics]\nsamples = 0"), "metrics.samples: Input should be"),
    ("criterion metric", sweep_text(tail="[criterion.spin_stability]\nband = 0.1"),
     "criterion.spin_stability: add 'max_nutation' to metrics.keep"),
    ("criterion torque", sweep_text(tail='[metrics]\nkeep = ["max_nutation"]\n'
     "[criterion.spin_stability]\nband = 0.1"), "the criterion is for a torque-free spin"),
    ("criterion band", sweep_text(tail="[criterion.spin_stability]\nband = 1.5"),
     "criterion.spin_stability.band: Input should be less than 1"),
    ("too many", sweep_text().replace("[0.0, 10.0, 3]", "[0.0, 10.0, 1000000]")
     .replace("count = 2", "count = 100000"), "200,000,000,000 trajectories: at most"),
    ("scene file", sweep_text().replace('"gyrostat"', '"nope.toml"'),
     "scene: {dir}/nope.toml: no such file, and no built-in scene 'nope.toml'"),
    ("folded", 'scene = "torque_free"\n[grid]\nI22 = { list = [1.0] }',
     'grid.I22: folded into the code as 4.0: make it "runtime" in the scene'),
    ("no value", 'scene = "tf.toml"\n[grid]\nu4 = { list = [1.0] }',
     "parameters: no value for runtime parameter I22"),
    ("cluster metric", 'scene = "rw4_pyramid"\n[metrics]\nkeep = ["max_nutation", "max_rate"]',
     "metrics.keep: max_nutation, max_rate read the paper's single rotor; a cluster scene keeps"),
    ("setup refuses", sweep_text(tail="[parameters]\nm_a = -1.0"),
     "parameters.m_a: must be positive (got -1.0)"),
    ("setup refuses carrier", sweep_text(tail="[parameters]\nI11 = -1.0"),
     "parameters.I11, I22, I33, I13: carrier inertia is not positive definite"),
    ("huge linspace", sweep_text().replace("[0.0, 10.0, 3]", "[-1e308, 1e308, 3]"),
     "grid.u4: values beyond +-1e+300 leave double range on the map"),
    ("huge list", sweep_text().replace("linspace = [0.0, 10.0, 3]", "list = [1e301]"),
     "grid.u4: values beyond +-1e+300"),
    ("lognormal overflow", sweep_text(tail="J = { lognormal = [700.0, 1.0] }"),
     "draws.J: lognormal = [700, 1]: draws would reach inf, beyond 1e+300"),
    ("normal overflow", sweep_text(tail="u3 = { normal = [0.0, 1e300] }"),
     "draws.u3: normal = [0, 1e+300]: draws would reach 9e+300, beyond 1e+300"),
    ("uniform overflow", sweep_text(tail="u3 = { uniform = [-1e308, 1e308] }"),
     "draws.u3: uniform = [-1e+308, 1e+308]: draws would reach inf"),
    ("zero quaternion", 'scene = "tfq.toml"\n[parameters]\nI22 = 4.0\n[initial]\ne0 = 0.0',
     "initial: e0..e3 are all zero: not an attitude"),
    ("long quaternion",
     'scene = "tfq.toml"\n[parameters]\nI22 = 4.0\n[initial]\ne0 = 1.0\ne1 = 1.0',
     "initial: e0..e3 = (1, 1, 0, 0) has norm 1.41421356, not 1"),
]  # fmt: skip


@pytest.mark.parametrize(("case", "text", "message"), BAD, ids=[b[0] for b in BAD])
def test_bad_sweep_is_one_line_exit_2_nothing_written(
    case: str, text: str, message: str, tmp_path: Path, cli
) -> None:
    (tmp_path / "tf.toml").write_text(TORQUE_FREE_RUNTIME)
    (tmp_path / "tfq.toml").write_text(
        TORQUE_FREE_RUNTIME.replace('name = "tf_runtime"', 'name = "tfq"\nattitude = "quaternion"')
    )  # fmt: skip
    path = tmp_path / "bad.toml"
    path.write_text(text)
    out = tmp_path / "out"
    code, stdout, err = cli(["sweep", str(path), "--out", str(out)])
    assert code == 2, (case, err)
    assert err.count("\n") == 1 and err.startswith(f"gyrogen: error: {path}: "), err
    assert message.format(dir=tmp_path) in err, err
    assert not out.exists() and stdout == ""


def test_missing_sweep_file_names_the_builtins(tmp_path: Path, cli) -> None:
    code, _, err = cli(["sweep", str(tmp_path / "none.toml"), "--out", str(tmp_path / "o")])
    assert code == 2
    assert "none.toml: no such file, and no built-in sweep of that name (monte_carlo" in err


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--scheduler", "localhost:8786"], "'localhost:8786' is not tcp://HOST:PORT"),
        (["--scheduler", "tcp://127.0.0.1:1", "--workers", "2"], "--workers sizes the local"),
        (["--chunk", "0"], "0 is not in the range 1<=x<=1000000"),
    ],
)
def test_bad_options_are_usage_errors(args: list[str], message: str, tmp_path: Path, cli) -> None:
    code, _, err = cli(["sweep", "stability_map", "--out", str(tmp_path / "o"), *args])
    assert code == 2 and message in err and err.count("\n") == 1, err
    assert not (tmp_path / "o").exists()
