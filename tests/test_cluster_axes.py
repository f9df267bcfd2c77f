"""Runtime axes: rw4_hardware, the built-in rw4_pyramid with every cluster
property runtime, its four spin axes too (p's g1_k, g2_k, g3_k). setup checks each axis's length
(within abi_rotors.AXIS_NORM_SLACK of 1, else code 8) and normalizes it;
I~ and its inverse are computed there, the rhs stays solve-free. Held to
the Newton-Euler reference (a slice here; `make verify-axes` runs the
issue's 10^4 states x 100 parameter sets)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from test_cluster_runtime import W_REF
from wide import WIDE

from gyrogen.abi_rotors import AXIS_NORM_SLACK
from gyrogen.analysis.check.engine import axes_span
from gyrogen.codegen.context import make_context
from gyrogen.errors import SceneError
from gyrogen.oracle.compare import compare
from gyrogen.runtime.compiled import Compiled, Language
from gyrogen.runtime.scene_build import build_scene
from gyrogen.scene import Scene, builtin_text, load, parse

BAR = 1e-13
"""The issue's bar for the rhs and outputs against the reference."""
AXES_TEXT = builtin_text("rw4_hardware")
NOMINAL = load("rw4_hardware").simulate.parameters
AXES = {n: v for n, v in NOMINAL.items() if n[0] == "g"}


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> tuple[Scene, dict[Language, Compiled]]:
    scene = load("rw4_hardware")
    backends = build_scene(scene, tmp_path_factory.mktemp("axes"), ["c", "fortran"])
    return scene, backends


def _p(scene: Scene, **change: float) -> np.ndarray:
    return np.array([{**NOMINAL, **change}[n] for n in scene.runtime])


@pytest.mark.slow
@WIDE
def test_p_holds_each_axis_after_its_position(built) -> None:
    scene, backends = built
    assert scene.runtime[7:17] == ("m_1", "I_1", "J_1", "r1_1", "r2_1", "r3_1", "g1_1", "g2_1",
                                   "g3_1", "w_ref_1")  # fmt: skip
    assert len(scene.runtime) == 7 + 4 * 10
    assert backends["fortran"].manifest["parameters"] == list(scene.runtime)


def _verified(backends: dict[Language, Compiled], scene: Scene, states: int, sets: int) -> None:
    report = compare(list(backends.values()), scene, n_states=states, n_params=sets, n_ill=0)
    assert report.n_params["well"] >= sets, report.n_params
    values = [r for r in report.rows if "jac" not in r.pair]
    assert values and all(r.error <= BAR for r in values), values
    assert report.passed, [r for r in report.rows if not r.passed]
    assert not report.refusal_failures and report.refusals_checked >= 100


@pytest.mark.slow
def test_c_and_fortran_match_the_reference_and_refuse_what_setup_must(built) -> None:
    """Random states, parameter sets on random axes of length within the
    slack (oracle.scene_view), every pair within 1e-13; and the refusals,
    axes too long, too short or 0 among them (oracle.sampling.invalid_cluster)."""
    scene, backends = built
    _verified(backends, scene, 2000, 10)


@pytest.mark.skipif(
    not os.environ.get("GYROGEN_VERIFY_AXES"), reason="the issue's full size: make verify-axes"
)
def test_the_issues_size(built) -> None:
    """10^4 states x 100 parameter sets, C and Fortran, to 1e-13."""
    scene, backends = built
    _verified(backends, scene, 10_000, 100)


@pytest.mark.slow
@pytest.mark.parametrize("language", ["c", "fortran"])
@WIDE
def test_at_the_folded_values_it_is_the_folded_scene(
    language: Language, built, tmp_path: Path
) -> None:
    """With p at rw4_pyramid's values (axes as the scene writes them, 15
    digits), rhs and outputs equal its own build's to rounding."""
    scene, backends = built
    theirs = build_scene(load("rw4_pyramid"), tmp_path / "folded", [language])
    rng = np.random.default_rng(4)
    xs = rng.normal(size=(200, len(scene.states)))
    xs[:, -4:] = rng.uniform(-300, 300, (200, 4))
    mine = backends[language].setup(_p(scene))
    own = theirs[language].setup(np.array(list(W_REF.values())))
    for name in ("rhs", "kinetic_energy", "angular_momentum", "power"):
        if name == "rhs":
            a, b = backends[language].rhs(xs, mine), theirs[language].rhs(xs, own)
        else:
            a, b = backends[language].output(name, xs, mine), theirs[language].output(name, xs, own)
        assert np.max(np.abs(a - b) / (1 + np.abs(b))) < BAR, name


@pytest.mark.slow
def test_setup_normalizes_an_axis_within_the_slack(built) -> None:
    """An axis given 0.9 slack long gives the rhs of the unit one."""
    scene, backends = built
    long = {n: v * (1 + 0.9 * AXIS_NORM_SLACK) for n, v in AXES.items() if n.endswith("_2")}
    rng = np.random.default_rng(6)
    xs = rng.normal(size=(50, len(scene.states)))
    for comp in backends.values():
        a = comp.rhs(xs, comp.setup(_p(scene, **long)))
        b = comp.rhs(xs, comp.setup(_p(scene)))
        assert np.max(np.abs(a - b) / (1 + np.abs(b))) < 1e-14, comp.language


@pytest.mark.slow
@pytest.mark.parametrize(
    ("scale", "code"),
    [
        (1 + 0.99 * AXIS_NORM_SLACK, 0),
        (1 - 0.99 * AXIS_NORM_SLACK, 0),
        (1 + 1.01 * AXIS_NORM_SLACK, 8),
        (1 - 1.01 * AXIS_NORM_SLACK, 8),
        (0.0, 8),
        (float("nan"), 1),
        (float("inf"), 1),
    ],
)
def test_setup_codes(scale: float, code: int, built) -> None:
    scene, backends = built
    axis = {n: v * scale for n, v in AXES.items() if n.endswith("_3")}
    for comp in backends.values():
        got = comp.setup_code(_p(scene, **axis))
        assert got[0] == code, (comp.language, scale, got)
    if code:
        with pytest.raises(ValueError, match=r"axis is not of unit length|NaN or infinite"):
            backends["c"].setup(_p(scene, **axis))


@pytest.mark.parametrize(
    ("edits", "message"),
    [
        (
            {"g2_2": 0.0, "g3_2": 0.0},
            "simulate.parameters.g1_2..g3_2: has length 0: not a direction",
        ),
        (
            {"g3_2": 0.818},
            "simulate.parameters.g1_2..g3_2: length 1.00122791 is not 1 (within 0.001)",
        ),
    ],
)
def test_the_scene_checks_the_axes_it_gives(edits: dict[str, float], message: str) -> None:
    text = AXES_TEXT
    for name, value in edits.items():
        line = f"\n{name} = {NOMINAL[name]!r}\n"
        assert line in text
        text = text.replace(line, f"\n{name} = {value!r}\n")
    with pytest.raises(SceneError) as err:
        parse(text, "bad.toml")
    assert message in str(err.value) and "\n" not in str(err.value)


@pytest.mark.slow
def test_op_counts_before_and_after() -> None:
    """The issue's bar: at most 160 ops in the rhs with every cluster
    property runtime, axes included (rw4_pyramid folded: 114)."""
    runtime = make_context(load("rw4_hardware")).ops["rhs"]
    assert runtime <= 160, runtime


def test_the_checks_warning_reads_runtime_axes() -> None:
    """gyrogen check's span of the axes: rw4_hardware's at its nominal
    values is rw4_pyramid's; its axes turned into one plane nearly fail."""
    folded = axes_span(load("rw4_pyramid"), {})
    assert axes_span(load("rw4_hardware"), NOMINAL) == pytest.approx(folded, rel=1e-14)
    flat = {**NOMINAL, **{f"g3_{k}": 1e-3 for k in (1, 2, 3, 4)}}
    assert axes_span(load("rw4_hardware"), flat) < 1e-2 < folded
