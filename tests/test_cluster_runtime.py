"""Runtime cluster properties, the part built: the carrier's mass and
tensor and each wheel's mass, transverse and axial inertia and position may
be "runtime" (the axes stay folded). The lumped inertia I~ is then
named scalars of setup, inverted there; setup checks the values (masses
and inertias positive, the carrier positive definite and meeting the
triangle inequality, J_k <= 2 I_k, I~'s condition number); the
Newton-Euler reference reads them from p[]."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from wide import WIDE

from gyrogen.analysis.linearize import engine
from gyrogen.codegen.context import make_context
from gyrogen.errors import SceneError, SetupRefused
from gyrogen.oracle.compare import compare
from gyrogen.runtime.compiled import Compiled, Language
from gyrogen.runtime.scene_build import build_scene
from gyrogen.scene import Scene, builtin_text, load, parse

CARRIER = {"m_a": 800.0, "I11": 420.0, "I22": 380.0, "I33": 300.0, "I12": -4.0, "I13": 6.0,
           "I23": 2.5}  # fmt: skip
WHEEL = {"m": 5.0, "I": 0.025, "J": 0.045}
POSITIONS = [(0.3, 0.0, -0.2), (0.0, 0.3, -0.2), (-0.3, 0.0, -0.2), (0.0, -0.3, -0.2)]
PLACES = {f"r{i}_{k}": x for k, at in enumerate(POSITIONS, 1) for i, x in enumerate(at, 1)}
W_REF = {"w_ref_1": 100.0, "w_ref_2": -50.0, "w_ref_3": 80.0, "w_ref_4": 30.0}


def _runtime_text() -> str:
    text = builtin_text("rw4_pyramid").replace('name = "rw4_pyramid"', 'name = "rw4_runtime"')
    for name, value in CARRIER.items():
        text = text.replace(f"{name} = {value}", f'{name} = "runtime"', 1)
    for key, value in WHEEL.items():
        text = text.replace(f"\n{key} = {value}\n", f'\n{key} = "runtime"\n')
    for at in POSITIONS:
        text = text.replace(f"position = {list(at)}", 'position = "runtime"')
    given = {**CARRIER, **{f"{key}_{k}": v for k in range(1, 5) for key, v in WHEEL.items()},
             **PLACES}  # fmt: skip
    extra = ", ".join(f"{n} = {v!r}" for n, v in given.items())
    return text.replace("w_ref_4 = 30.0 }", f"w_ref_4 = 30.0, {extra} }}")


TEXT = _runtime_text()
NOMINAL = {**CARRIER, **{f"{key}_{k}": v for k in range(1, 5) for key, v in WHEEL.items()},
           **PLACES, **W_REF}  # fmt: skip


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> tuple[Scene, dict[Language, Compiled]]:
    scene = parse(TEXT, "rw4_runtime.toml")
    backends = build_scene(scene, tmp_path_factory.mktemp("runtime"), ["c", "fortran"])
    return scene, backends


def _p(scene: Scene, **change: float) -> np.ndarray:
    return np.array([{**NOMINAL, **change}[n] for n in scene.runtime])


def test_p_holds_the_carrier_then_each_rotor(built) -> None:
    scene, backends = built
    assert scene.runtime[:7] == tuple(CARRIER)
    assert scene.runtime[7:14] == ("m_1", "I_1", "J_1", "r1_1", "r2_1", "r3_1", "w_ref_1")
    assert len(scene.runtime) == 7 + 4 * 7
    assert backends["c"].manifest["parameters"] == list(scene.runtime)


def test_c_and_fortran_match_the_reference_and_refuse_what_setup_must(built) -> None:
    """Random states and parameter sets (oracle.scene_view: tensors kept
    within the triangle inequality), and the refusals of every inertial
    value made unphysical (oracle.sampling.invalid_cluster) and NaN."""
    scene, backends = built
    report = compare(list(backends.values()), scene, n_states=2000, n_params=20, n_ill=0)
    assert report.passed, [r for r in report.rows if not r.passed]
    assert not report.refusal_failures and report.refusals_checked >= 100


@pytest.mark.parametrize(
    "language", ["c", pytest.param("fortran", marks=pytest.mark.slow)]
)  # C in the fast loop: each builds rw4_pyramid; Fortran's runtime cluster is checked there too
def test_at_the_folded_values_it_is_the_folded_scene(
    language: Language, built, tmp_path: Path
) -> None:
    """With p at rw4_pyramid's values, rhs and outputs equal its own build's
    to rounding (that build, folded, keeps its bytes: make check-generated)."""
    scene, backends = built
    theirs = build_scene(load("rw4_pyramid"), tmp_path / "folded", [language])
    rng = np.random.default_rng(3)
    xs = rng.normal(size=(200, len(scene.states)))
    xs[:, -4:] = rng.uniform(-300, 300, (200, 4))
    mine = backends[language].setup(_p(scene))
    own = theirs[language].setup(np.array(list(W_REF.values())))
    a, b = backends[language].rhs(xs, mine), theirs[language].rhs(xs, own)
    assert np.max(np.abs(a - b) / (1 + np.abs(b))) < 1e-13
    for name in ("kinetic_energy", "angular_momentum", "power"):
        a = backends[language].output(name, xs, mine)
        b = theirs[language].output(name, xs, own)
        assert np.max(np.abs(a - b) / (1 + np.abs(b))) < 1e-13, name


@pytest.mark.parametrize(
    ("change", "code"),
    [
        ({}, 0),
        ({"m_a": 0.0}, 2),
        ({"m_3": -1.0}, 2),
        ({"I_2": 0.0}, 3),
        ({"J_4": -1e-3}, 3),
        ({"I11": -420.0}, 4),
        ({"I12": 500.0}, 4),
        ({"I33": 900.0}, 5),
        ({"I33": 800.0, "I12": 0.0, "I13": 0.0, "I23": 0.0}, 0),  # a lamina: on the boundary
        ({"J_1": 0.0501}, 6),
        ({"I_1": 0.0224}, 6),
    ],
)
def test_setup_codes(change: dict[str, float], code: int, built) -> None:
    scene, backends = built
    for comp in backends.values():
        assert comp.setup_code(_p(scene, **change))[0] == code, (comp.language, change)


def test_a_refused_mass_is_named_as_a_cluster_names_it(built) -> None:
    """Code 2 in a cluster is m_a, a rotor's m_k or a gimbal's mG_k (not m_b, which a
    cluster does not have): setup's refusal, and the manifest the C and
    Fortran strerror print from."""
    scene, backends = built
    why = "a mass (m_a, a rotor's m_k or a gimbal frame's mG_k) is not positive"
    for comp in backends.values():
        assert comp.manifest["setup_codes"]["2"] == why
        with pytest.raises(SetupRefused) as err:
            comp.setup(_p(scene, m_3=-1.0))
        assert str(err.value) == f"setup refused the parameters (code 2): {why}"


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (
            "I33 = 300.0,",
            "simulate.parameters.I11..I23: principal moments (379.586, 420.328, 900.087)",
        ),
        ("J_2 = 0.045", "simulate.parameters.J_2: rotor needs J <= 2 I (I = 0.025, J = 0.06)"),
        ("m_4 = 5.0", "simulate.parameters.m_4: must be positive (got -5.0)"),
    ],
)
def test_the_scene_checks_the_runtime_values_it_gives(edit: str, message: str) -> None:
    bad = {"I33 = 300.0,": "I33 = 900.0,", "J_2 = 0.045": "J_2 = 0.06",
           "m_4 = 5.0": "m_4 = -5.0"}[edit]  # fmt: skip
    assert edit in TEXT
    with pytest.raises(SceneError) as err:
        parse(TEXT.replace(edit, bad), "bad.toml")
    assert message in str(err.value) and "\n" not in str(err.value)


@pytest.mark.slow
def test_op_counts_before_and_after() -> None:
    """The issue's bar: at most 160 ops in the rhs with every inertial value
    and position runtime (rw4_pyramid folded: 114)."""
    runtime = make_context(parse(TEXT, "rw4_runtime.toml")).ops["rhs"]
    folded = make_context(load("rw4_pyramid")).ops["rhs"]
    assert folded == 114 and runtime <= 160, (folded, runtime)


def test_the_linear_model_reads_them_from_p(built) -> None:
    """B over each wheel rate at a hold is k_k / J_k, J_k from p."""
    scene, _ = built
    j = [0.03, 0.04, 0.045, 0.05]
    lin = engine.model(scene, parameters={f"J_{k}": v for k, v in enumerate(j, 1)}, spin=0.0)
    rows = [lin.states.index(f"w{k}") for k in (1, 2, 3, 4)]
    assert np.allclose(np.diag(lin.B[rows]), [0.05 / v for v in j], rtol=1e-12)


@pytest.mark.slow
@WIDE
def test_random_axes_with_everything_runtime(tmp_path: Path) -> None:
    """Six wheels on axes off the carrier's (exact rationals of denominators
    ~1e9): I~'s entries stay sums as the formulas give them (put over a
    common denominator, these raised LiteralError: coefficients past double
    range), and C matches the reference."""
    rng = np.random.default_rng(5)
    rows, given = [], {**CARRIER}
    for k in range(1, 7):
        g = [float(x) for x in rng.normal(size=3)]
        g = [x / float(np.linalg.norm(g)) for x in g]
        rows.append(
            f'[[rotors]]\nm = "runtime"\nI = "runtime"\nJ = "runtime"\n'
            f'axis = [{g[0]!r}, {g[1]!r}, {g[2]!r}]\nposition = "runtime"\n'
        )
        given.update({f"m_{k}": 4.0, f"I_{k}": 0.02, f"J_{k}": 0.03, f"r1_{k}": 0.1 * k,
                      f"r2_{k}": -0.1, f"r3_{k}": 0.05})  # fmt: skip
    head = "\n".join(f'{n} = "runtime"' for n in CARRIER)
    sim = ", ".join(f"{n} = {v!r}" for n, v in given.items())
    text = (
        f'name = "rw6_random"\ndescription = "random axes"\nintegrators = ["dop853"]\n'
        f"[parameters]\n{head}\n[outputs]\nangular_momentum = true\n" + "".join(rows)
        + f"[simulate]\nparameters = {{ {sim} }}\n"
    )  # fmt: skip
    scene = parse(text, "rw6_random.toml")
    backends = build_scene(scene, tmp_path / "gen", ["c"])
    report = compare([backends["c"]], scene, n_states=500, n_params=5, n_ill=0)
    assert report.passed and not report.refusal_failures, report.rows


@pytest.mark.slow
@WIDE
def test_a_runtime_diagonal_beside_negative_folded_products(tmp_path: Path, cli) -> None:
    """rw4_pyramid with I11 and wheel 1's J at run time, the rest as shipped:
    setup's checks fold I12 = -4.0 beside the runtime I11 (pd2 = I11*380.0
    - (-4.0)*(-4.0)), which Fortran printed as - -4.0*-4.0 and gfortran
    refused. The scene generates and verifies."""
    text = builtin_text("rw4_pyramid").replace('name = "rw4_pyramid"', 'name = "rw4_rt"')
    text = text.replace("I11 = 420.0", 'I11 = "runtime"', 1)
    text = text.replace("J = 0.045", 'J = "runtime"', 1)
    scene = tmp_path / "rw4_rt.toml"
    scene.write_text(text)
    made = cli(["generate", str(scene), "--out", str(tmp_path / "gen")])
    assert made.code == 0, made.err
    verified = cli(["verify", str(scene), "--states", "500", "--params", "10"])
    assert verified.code == 0 and "setup refusals" in verified.out, verified.out + verified.err
