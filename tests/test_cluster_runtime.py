"""Runtime cluster properties, the subset built: a wheel's axial inertia
J_k = "runtime". It stays out of the lumped inertia I~ (folded, inverted in
numbers as before); setup checks 0 < J_k <= 2 I_k (codes 3 and 6) and
computes 1/J_k; the Newton-Euler reference reads J_k from p[]."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gyrogen.analysis.linearize import linearize as engine
from gyrogen.oracle.compare import compare
from gyrogen.runtime.compiled import Compiled, Language
from gyrogen.runtime.scene_build import build_scene
from gyrogen.scene import Scene, builtin_text, load, parse

PYRAMID = builtin_text("rw4_pyramid")
RUNTIME = (
    PYRAMID.replace('name = "rw4_pyramid"', 'name = "rw4_runtime_j"')
    .replace("J = 0.045", 'J = "runtime"')
    .replace("w_ref_4 = 30.0 }", "w_ref_4 = 30.0, J_1 = 0.045, J_2 = 0.045, J_3 = 0.045, "
             "J_4 = 0.045 }")
)  # fmt: skip


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> tuple[Scene, dict[Language, Compiled]]:
    scene = parse(RUNTIME, "rw4_runtime_j.toml")
    _, backends = build_scene(scene, tmp_path_factory.mktemp("runtime_j"), ["c", "fortran"])
    return scene, backends


def test_p_holds_each_rotors_j_then_its_law(built) -> None:
    scene, backends = built
    assert scene.runtime == ("J_1", "w_ref_1", "J_2", "w_ref_2", "J_3", "w_ref_3", "J_4", "w_ref_4")
    assert backends["c"].manifest["parameters"] == list(scene.runtime)


def test_c_and_fortran_match_the_reference_and_refuse_bad_j(built) -> None:
    """Random states and parameter sets (J_k within (0.1, 2] I_k), and the
    refusals: J_k = 0 or negative (code 3), above 2 I_k (code 6), NaN."""
    scene, backends = built
    report = compare(list(backends.values()), scene, n_states=2000, n_params=20, n_ill=0)
    assert report.passed, [r for r in report.rows if not r.passed]
    assert not report.refusal_failures and report.refusals_checked >= 2 * 4 * 3


@pytest.mark.parametrize("language", ["c", "fortran"])
def test_at_the_folded_values_it_is_the_folded_scene(
    language: Language, built, tmp_path: Path
) -> None:
    """With p's J_k at the folded 0.045, rhs and outputs equal rw4_pyramid's
    to rounding (its own build: folded scenes keep their bytes)."""
    scene, backends = built
    folded = load("rw4_pyramid")
    _, theirs = build_scene(folded, tmp_path / "folded", [language])
    rng = np.random.default_rng(3)
    xs = rng.normal(size=(200, len(scene.states)))
    xs[:, -4:] = rng.uniform(-300, 300, (200, 4))
    w_ref = np.array([100.0, -50.0, 80.0, 30.0])
    mine = backends[language].setup(np.ravel(np.column_stack([np.full(4, 0.045), w_ref])))
    own = theirs[language].setup(w_ref)
    a, b = backends[language].rhs(xs, mine), theirs[language].rhs(xs, own)
    assert np.max(np.abs(a - b) / (1 + np.abs(b))) < 1e-13
    for name in ("kinetic_energy", "angular_momentum", "power"):
        a = backends[language].output(name, xs, mine)
        b = theirs[language].output(name, xs, own)
        assert np.max(np.abs(a - b) / (1 + np.abs(b))) < 1e-13, name


def test_setup_codes_name_the_axial_inertia(built) -> None:
    _, backends = built
    comp = backends["c"]
    good = np.ravel(np.column_stack([np.full(4, 0.045), [100.0, -50.0, 80.0, 30.0]]))
    for j, value, code in ((2, 0.0, 3), (4, -1e-3, 3), (6, 0.0501, 6), (0, 0.05, 0)):
        p = good.copy()
        p[j] = value
        assert comp.setup_code(p)[0] == code, (j, value)
    assert comp.manifest["setup_codes"]["3"].startswith("a rotor inertia")


def test_the_linear_model_reads_j_from_p(built) -> None:
    """B over each wheel rate is k_k / J_k at a hold (its speed controller's
    reference enters as -k (rel - w_ref)), J_k from p."""
    scene, _ = built
    j = [0.03, 0.04, 0.045, 0.05]
    given = {f"J_{k}": v for k, v in enumerate(j, 1)}
    lin = engine.model(scene, parameters=given, spin=0.0)
    rows = [lin.states.index(f"w{k}") for k in (1, 2, 3, 4)]
    assert np.allclose(np.diag(lin.B[rows]), [0.05 / v for v in j], rtol=1e-12)
