"""The compiled backends agree with the numpy reference and refuse what is
not physical, with the documented codes."""

from __future__ import annotations

import numpy as np
import pytest
from wide import WIDE

from gyrogen.oracle import reference, sampling
from gyrogen.oracle.compare import TOLERANCE, compare, scaled_error
from gyrogen.runtime.build import Compiled
from gyrogen.scene import builtin_names, default


def test_compare_passes_at_the_issue_bar(backends: dict[str, Compiled]) -> None:
    report = compare(
        list(backends.values()), default(), n_states=2000, n_params=20, n_ill=5, seed=7
    )
    assert report.passed, report
    well = [r for r in report.rows if r.group.startswith("cond <=")]
    assert {r.pair for r in well} == {
        "C vs reference", "Fortran vs reference", "C vs Fortran",
        "C vs reference jac", "Fortran vs reference jac",
    }  # fmt: skip
    assert all(r.error <= TOLERANCE for r in well if not r.pair.endswith("jac"))
    assert report.refusals_checked > 0 and not report.refusal_failures


def test_compare_catches_a_wrong_backend(
    backends: dict[str, Compiled], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Not vacuous: a reference off by 1e-9 in one component fails."""
    real = reference.rhs

    def off(x: np.ndarray, p: np.ndarray) -> np.ndarray:
        out = real(x, p)
        out[..., 8] *= 1 + 1e-9
        return out

    monkeypatch.setattr(reference, "rhs", off)
    report = compare([backends["c"]], default(), n_states=200, n_params=3, n_ill=1, seed=1)
    assert not report.passed


@pytest.mark.parametrize("language", ["c", "fortran"])
def test_setup_codes_match_python_checks(backends: dict[str, Compiled], language: str) -> None:
    b = backends[language]
    rng = np.random.default_rng(11)
    for base in sampling.random_parameters(rng, 5):
        for what, p, expected in sampling.invalid_parameters(base):
            code, _ = b.setup_code(p)
            assert code == expected == sampling.setup_code(p), what


@pytest.mark.parametrize("language", ["c", "fortran"])
def test_boundary_cases_are_accepted(backends: dict[str, Compiled], language: str) -> None:
    """A lamina carrier (I22 = I11 + I33) and a thin-disc rotor (J = 2 I)."""
    p = np.array([10.0, 2.0, 3.0, 5.0, 2.0, 0.0, 0.5, 1.0, 0.2, -0.1, 9.81, 0.5])
    code, _ = backends[language].setup_code(p)
    assert code == 0


def test_refused_setup_raises_in_python(backends: dict[str, Compiled]) -> None:
    p = sampling.random_parameters(np.random.default_rng(0), 1)[0]
    p[0] = -1.0
    with pytest.raises(ValueError, match=r"code 2\): a mass"):
        backends["c"].setup(p)


def test_single_state_matches_reference(backends: dict[str, Compiled]) -> None:
    rng = np.random.default_rng(5)
    p = sampling.random_parameters(rng, 1, max_condition=100)[0]
    x = sampling.random_states(rng, 1)[0]
    for b in backends.values():
        assert scaled_error(b.rhs(x, b.setup(p)), reference.rhs(x, p)) < TOLERANCE


@pytest.mark.slow
@pytest.mark.parametrize("name", builtin_names())
@WIDE
def test_verify_command_passes_on_every_builtin_scene(name: str, cli) -> None:
    """`gyrogen verify SCENE` as a user runs it (default counts): exit 0."""
    code, out, err = cli(["verify", name])
    assert code == 0, out + err
    assert "FAIL" not in out and " ok" in out


@pytest.mark.slow
def test_verify_counts_the_scenes_own_parameters_apart(cli, tmp_path) -> None:
    """--params 1 on a scene with [simulate] parameters compares 2 sets: the
    line says which is the scene's own (it said "2 well-conditioned" with
    no word of where the second came from)."""
    code, out, err = cli(["verify", "dual_spin", "--states", "1", "--params", "1",
                          "--out", str(tmp_path / "v")])  # fmt: skip
    assert code == 0, out + err
    assert "x 2 well-conditioned (1 random, 1 the scene's own) and" in out
