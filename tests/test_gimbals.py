"""Control-moment gyros: rotors on gimbals ([rotors.gimbal]), their scene
rules, the proof of their equations and the compiled code's invariants."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import sympy as sm
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from wide import WIDE

from gyrogen import api
from gyrogen.scene import Scene, SceneError, builtin_text, parse
from gyrogen.scene.rotors import exact_perpendicular, exact_unit
from gyrogen.symbolic import cluster, gimbals

REPO = Path(__file__).resolve().parents[1]
GOOD = builtin_text("vscmg3")


def edit(old: str, new: str, text: str = GOOD) -> str:
    assert old in text, old
    return text.replace(old, new, 1)


FIXED = """[[rotors]]
m = 2.0
I = 0.01
J = 0.015
axis = [0.6, 0.8, 0.0]
position = [0.2, 0.2, 0.0]
b = 0.001
torque = "constant"
T = 0.01

[simulate]"""
MIXED = edit(
    "inertia = [0.1, 0.2, 0.3]\nm = 6.0",
    'inertia = [0.3, 0.25, 0.2]\nm = 6.0\ntorque = "constant"\nT = 0.02',
    edit("[simulate]", FIXED, edit("rotor_angle = false", "rotor_angle = true")),
)
"""vscmg3 with a fixed rotor beside its gimbals, a gimbal torque, unequal
gimbal inertias and the fixed rotor's angle kept."""
RUNTIME = edit(
    "initial = {",
    "parameters = { m_1 = 6.0, I_1 = 0.0795, J_1 = 0.159, mG_2 = 6.0, IGs_2 = 0.1, "
    "IGg_2 = 0.3 }\ninitial = {",
    edit("m = 6.0\nI = 0.0795\nJ = 0.159\naxis = [0.0, 1.0, 0.0]",
         'm = "runtime"\nI = "runtime"\nJ = "runtime"\naxis = [0.0, 1.0, 0.0]',
         edit("axis = [0.0, 1.0, 0.0]\ninertia = [0.1, 0.2, 0.3]\nm = 6.0",
              'axis = [0.0, 1.0, 0.0]\ninertia = ["runtime", 0.2, "runtime"]\nm = "runtime"')),
)  # fmt: skip
"""vscmg3 with the first CMG's wheel mass and inertias at run time, and the
second's gimbal frame's mass and two of its inertias (setup checks them:
the compare's refusals)."""

G1 = "axis = [1.0, 0.0, 0.0]      # g_g"


def runtime_axes(gimbal_axis: str) -> str:
    """vscmg3 with its first CMG's spin axis (a2) and gimbal axis at run time."""
    both = edit(G1, 'axis = "runtime"', edit("axis = [0.0, 1.0, 0.0]      # g_s0",
                                             'axis = "runtime"'))  # fmt: skip
    given = f"parameters = {{ g1_1 = 0.0, g2_1 = 1.0, g3_1 = 0.0, {gimbal_axis} }}\ninitial = {{"
    return edit("initial = {", given, both)


BAD = [
    ("parallel axes", edit(G1, "axis = [0.0, 1.0, 0.0]"),
     "rotors.0: gimbal.axis: not perpendicular to the spin axis (|g_s0 . g_g| = 1 > 0.001)"),
    ("zero inertia", edit("inertia = [0.1, 0.2, 0.3]", "inertia = [0.0, 0.1, 0.1]"),
     "rotors.0.gimbal: inertia: IGs must be positive (got 0.0)"),
    ("huge inertia", edit("inertia = [0.1, 0.2, 0.3]", "inertia = [1e49, 0.1, 0.1]"),
     "violate the triangle inequality"),
    ("huge inertias", edit("inertia = [0.1, 0.2, 0.3]", "inertia = [1e49, 1e49, 1e49]"),
     "rotors: the lumped inertia has condition number"),
    ("past a double", edit("inertia = [0.1, 0.2, 0.3]", "inertia = [1e51, 1e51, 1e51]"),
     "a folded value must be 0 or of magnitude 1e-50 to 1e+50"),
    ("triangle", edit("inertia = [0.1, 0.2, 0.3]", "inertia = [0.1, 0.1, 0.3]"),
     "principal inertias (0.1, 0.1, 0.3) violate the triangle inequality"),
    ("nan inertia", edit("inertia = [0.1, 0.2, 0.3]", "inertia = [0.1, nan, 0.1]"),
     "nan is not a finite number"),
    ("six inertias", edit("inertia = [0.1, 0.2, 0.3]", "inertia = [0.1, 0.1, 0.1, 0, 0, 0]"),
     "6 values, not 3: give the principal inertias [IGs, IGt, IGg]"),
    ("no mass", edit("inertia = [0.1, 0.2, 0.3]   # [IGs, IGt, IGg]\nm = 6.0",
                     "inertia = [0.1, 0.2, 0.3]\nm = 0.0"),
     "rotors.0.gimbal: m: must be positive (got 0.0)"),
    ("runtime frame", edit("inertia = [0.1, 0.2, 0.3]", 'inertia = ["runtime", -0.2, 0.3]'),
     "rotors.0.gimbal: inertia: IGt must be positive (got -0.2)"),
    ("runtime axes off", runtime_axes("gg1_1 = 1.01, gg2_1 = 0.0, gg3_1 = 0.0"),
     "simulate.parameters.gg1_1..gg3_1: length 1.01 is not 1 (within 0.001)"),
    ("runtime axes parallel", runtime_axes("gg1_1 = 0.0, gg2_1 = 1.0, gg3_1 = 0.0"),
     "simulate.parameters.gg1_1..gg3_1: not perpendicular to the spin axis (|g_s0 . g_g| = 1"),
    ("servo without rate", edit("m = 6.0\n\n[[rotors]]", 'm = 6.0\ntorque = "rate_servo"\n'
                                "k = 1.0\n\n[[rotors]]"),
     "torque = 'rate_servo' needs rate_ref"),
    ("unknown law", edit("m = 6.0\n\n[[rotors]]", 'm = 6.0\ntorque = "pid"\n\n[[rotors]]'),
     "'pid': not one of 'none', 'constant', 'rate_servo', 'table'"),
    ("unknown key", edit("m = 6.0\n\n[[rotors]]", "m = 6.0\nIGs = 1.0\n\n[[rotors]]"),
     "rotors.0.gimbal.IGs: unknown key"),
    ("wound gimbal", edit("initial = { u1 = 0.08,", "initial = { gam1 = 6.3e6, u1 = 0.08,"),
     "simulate.initial.gam1 = 6.3e+06 rad: more than 2607 turns (16384 rad), where a double"
     " holds the angle only to 4.7e-10 rad; give it modulo 2 pi"),
]  # fmt: skip


@pytest.mark.parametrize(("case", "text", "message"), BAD, ids=[b[0] for b in BAD])
def test_a_bad_gimbal_is_one_line_exit_2(
    case: str, text: str, message: str, tmp_path: Path, cli
) -> None:
    path = tmp_path / "scene.toml"
    path.write_text(text)
    code, stdout, err = cli(["generate", str(path), "--out", str(tmp_path / "out")])
    assert code == 2, (case, err)
    assert err.count("\n") == 1 and err.startswith(f"gyrogen: error: {path}: "), err
    assert message in err, err
    assert not (tmp_path / "out").exists() and stdout == ""


def test_the_states_are_the_gimbals_angles_and_rates() -> None:
    scene = parse(MIXED, "mixed.toml")
    assert scene.states == (
        *("q1", "q2", "q3", "th4", "gam1", "gam2", "gam3", "u1", "u2", "u3"),
        *("gd1", "gd2", "gd3", "w1", "w2", "w3", "w4"),
    )


def test_a_runtime_gimbal_frame_takes_its_place_in_p_and_its_values_are_checked() -> None:
    """mG_k, IGs_k, IGt_k, IGg_k follow the rotor's own keys in p[];
    simulate.parameters' values meet the rules folded ones meet."""
    assert parse(RUNTIME, "r.toml").runtime == ("m_1", "I_1", "J_1", "mG_2", "IGs_2", "IGg_2")
    for old, new in [
        ("IGs_2 = 0.1", "IGs_2 = 1.0"),
        ("mG_2 = 6.0", "mG_2 = -6.0"),
    ]:
        with pytest.raises(SceneError) as err:
            parse(RUNTIME.replace(old, new), "r.toml")
        text = str(err.value)
        assert ("simulate.parameters.IGs_2, IGt_2, IGg_2: principal inertias (1, 0.2, 0.3) "
                "violate the triangle inequality" in text) if "IGs" in old else (
                "simulate.parameters.mG_2: must be positive (got -6.0)" in text), text  # fmt: skip


def test_runtime_gimbal_axes_take_their_place_in_p() -> None:
    """A runtime spin axis g1_k..g3_k where a fixed rotor's is; a runtime
    gimbal axis gg1_k..gg3_k first among its gimbal's keys."""
    scene = parse(runtime_axes("gg1_1 = 1.0, gg2_1 = 0.0, gg3_1 = 0.0"), "r.toml")
    assert scene.runtime == ("g1_1", "g2_1", "g3_1", "gg1_1", "gg2_1", "gg3_1")


def one_cmg(text: str) -> str:
    """text (vscmg3 edited) with its first CMG alone."""
    first = text.index("[[rotors]]", text.index("[[rotors]]") + 1)
    out = text[:first] + text[text.index("[simulate]") :]
    return out.replace(", gd2 = 0.011, gd3 = -0.003", "").replace(
        ", w2 = 36.651914291880914, w3 = -94.16777960769379", "")  # fmt: skip


RUNTIME_AXES = one_cmg(runtime_axes("gg1_1 = 1.0, gg2_1 = 0.0, gg3_1 = 0.0"))
"""One CMG, its spin axis and gimbal axis at run time (the proof on the
orthonormal pairs: minutes to derive)."""


def test_runtime_gimbal_axes_are_refused_by_setup_when_not_unit_or_not_perpendicular() -> None:
    """verify's refusals: each runtime axis too long, too short or 0 (8), the
    spin axis turned toward the gimbal axis past the slack (10)."""
    from gyrogen.oracle import sampling, scene_view

    scene = parse(RUNTIME_AXES, "r.toml")
    base = scene_view.random_runtime(scene, np.random.default_rng(1), 1)[0]
    g_g, g_s = base[3:], base[:3]
    assert abs(g_g @ g_s) <= 1e-3 * np.linalg.norm(g_g) * np.linalg.norm(g_s)
    cases = sampling.invalid_cluster(scene, base)
    assert [code for _, _, code in cases] == [8] * 6 + [10]
    _, turned, _ = cases[-1]
    cosine = abs(turned[3:] @ turned[:3]) / np.linalg.norm(turned[3:]) / np.linalg.norm(turned[:3])
    assert 2e-3 < cosine < 4e-3


def _units(scene: Scene) -> tuple[list[gimbals.Unit], sm.Matrix]:
    units = [gimbals._unit(r, k) for k, r in enumerate(scene.rotors, 1)]
    return units, cluster.lumped_inertia(scene)


def test_kane_equals_the_momentum_form_with_a_fixed_rotor_beside() -> None:
    units, lumped = _units(parse(MIXED, "mixed.toml"))
    qdot = gimbals._prove(units, lumped, gimbals._carrier(units, lumped))
    assert qdot.shape == (3, 1)


def test_a_wrong_momentum_form_is_caught(monkeypatch: pytest.MonkeyPatch) -> None:
    units, lumped = _units(parse(MIXED, "mixed.toml"))
    right = gimbals._nd
    # the gyroscopic term J w at with its sign turned
    monkeypatch.setattr(gimbals, "_nd", lambda x, ug, w, sa, ta: right(x, ug, -w, sa, ta))
    with pytest.raises(AssertionError, match="internal: Kane's gimbal equations differ"):
        gimbals._prove(units, lumped, gimbals._carrier(units, lumped))


def test_the_spin_axis_is_made_exactly_perpendicular() -> None:
    text = edit("axis = [0.0, 1.0, 0.0]      # g_s0", "axis = [0.0004, 0.9999999, 0.0]")
    (unit, *_), _ = _units(parse(text, "near.toml"))
    assert unit.g_g is not None and unit.g_t0 is not None
    assert unit.axis.dot(unit.g_g) == 0 and sm.simplify(unit.axis.dot(unit.axis)) == 1


@settings(max_examples=300, deadline=None)
@given(
    st.lists(st.floats(-1, 1), min_size=3, max_size=3),
    st.lists(st.floats(-1, 1), min_size=3, max_size=3),
)
def test_a_spin_axis_is_exactly_unit_and_perpendicular_near_the_one_given(
    a: list[float], b: list[float]
) -> None:
    """exact_perpendicular: rational, |g_s0| = 1 and g_s0 . g_g = 0 exactly,
    within 1e-15 of the given axis's part perpendicular to g_g (as far as
    floats know that part)."""
    g, v = np.array(a), np.array(b)
    assume(min(np.linalg.norm(g), np.linalg.norm(v)) > 1e-3)
    g, v = g / np.linalg.norm(g), v / np.linalg.norm(v)  # a scene's axes are of unit length
    assume(np.linalg.norm(np.cross(g, v)) > 1e-3)
    g_g = exact_unit(tuple(g))  # type: ignore[arg-type]
    out = exact_perpendicular(tuple(v), g_g)  # type: ignore[arg-type]
    assert sum(x * x for x in out) == 1 and sum(x * y for x, y in zip(out, g_g, strict=True)) == 0
    unit = np.array([float(x) for x in g_g])
    want = v - (v @ unit) * unit
    off = np.abs(np.array([float(x) for x in out]) - want / np.linalg.norm(want)).max()
    assert off < 1e-15 * np.linalg.norm(v) / np.linalg.norm(want)  # the projection's cancellation


def _energy_rate_and_power(scene: Scene, rng: np.random.Generator) -> list[tuple[float, float]]:
    """dK/dt at random states (central differences along f, Richardson) and
    the motors' power less the friction's b Omega^2."""
    compiled = api.compile(scene)
    c = compiled.setup(np.array([scene.simulate.parameters[n] for n in scene.runtime]))
    idx = {s: i for i, s in enumerate(scene.states)}
    out = []
    for _ in range(4):
        x = np.array(scene.initial_state()) + rng.normal(size=len(scene.states)) * 0.3
        f = compiled.rhs(x, c)
        h = 1e-3

        def energy(y: np.ndarray) -> float:
            return float(compiled.output("kinetic_energy", y, c).ravel()[0])

        def central(h: float, x: np.ndarray = x, f: np.ndarray = f) -> float:
            return (energy(x + h * f) - energy(x - h * f)) / (2 * h)

        rate = (4 * central(h / 2) - central(h)) / 3
        w_a = x[[idx["u1"], idx["u2"], idx["u3"]]]
        friction = 0.0
        for k, r in enumerate(scene.rotors, 1):
            g = np.array([float(v) for v in exact_unit(r.axis)])  # type: ignore[arg-type]
            if r.gimbal is not None:
                g_g = np.array([float(v) for v in r.gimbal.unit_axis])
                gam = x[idx[f"gam{k}"]]
                g = np.cos(gam) * g + np.sin(gam) * np.cross(g_g, g)
            friction += r.b * (x[idx[f"w{k}"]] - g @ w_a) ** 2
        power = float(compiled.output("power", x, c).sum())
        out.append((rate, power - friction))
    return out


@pytest.mark.slow
@pytest.mark.parametrize("text", [builtin_text("cmg4_pyramid"), MIXED], ids=["pyramid", "mixed"])
@WIDE
def test_the_energy_changes_by_the_motors_power(text: str) -> None:
    """dK/dt = sum_k (u_s Omega + u_g gd) - b Omega^2, the power output's sum."""
    for rate, power in _energy_rate_and_power(parse(text, "s.toml"), np.random.default_rng(3)):
        # the central differences of K (~4300 J, mostly the wheels') round to ~1e-9 J/s
        assert rate == pytest.approx(power, rel=1e-5, abs=1e-12), (rate, power)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["taylor", "dop853"])
@WIDE
def test_vscmg3_conserves_energy_and_momentum_over_60_s(method: str) -> None:
    scene = parse(GOOD, "vscmg3.toml")
    compiled = api.compile(scene)
    c = compiled.setup(np.zeros(0))
    x0 = np.array(scene.initial_state())
    x1, _, code = compiled.integrate(method, x0, c, 0.0, 60.0, rtol=1e-13, atol=1e-13)
    assert code == 0
    h0, h1 = (compiled.output("angular_momentum", x, c).ravel() for x in (x0, x1))
    k0, k1 = (float(compiled.output("kinetic_energy", x, c).ravel()[0]) for x in (x0, x1))
    assert abs(np.linalg.norm(h1) / np.linalg.norm(h0) - 1) < 1e-13
    # the wheels' J w^2 / 2 is constant (w' = 0): the balance of the rest
    wheels = sum(0.5 * r.J * x0[scene.states.index(f"w{k}")] ** 2  # type: ignore[operator]
                 for k, r in enumerate(scene.rotors, 1))  # fmt: skip
    assert abs(k1 - k0) / k0 < 1e-14  # the issue's 1e-13 relative, over 60 s
    assert abs(k1 - k0) / (k0 - wheels) < 1e-11  # a few ulps of K, of the moving part's 3 J
    assert np.abs(x1 - x0).max() > 1e-3  # the gimbals and the carrier have moved


@pytest.mark.slow
def test_a_nan_gimbal_rate_and_a_far_gimbal_angle_at_the_start() -> None:
    """A NaN rate is the integrators' non-finite start (code 3); an angle of
    a million turns is integrated as the same angle near 0 (sin and cos
    reduce it exactly): the carrier's and the wheels' rates agree."""
    scene = parse(GOOD, "vscmg3.toml")
    compiled = api.compile(scene)
    c = compiled.setup(np.zeros(0))
    x0 = np.array(scene.initial_state())
    bad = x0.copy()
    bad[scene.states.index("gd1")] = np.nan
    for method in ("dop853", "taylor", "radau5"):
        assert compiled.integrate(method, bad, c, 0.0, 1.0)[2] == 3
    gam, turns = scene.states.index("gam1"), 1e6 * 2 * np.pi
    near = x0.copy()
    near[gam] = 0.3
    far = near.copy()
    far[gam] += turns
    a, _, code_a = compiled.integrate("dop853", near, c, 0.0, 5.0, rtol=1e-12, atol=1e-12)
    b, _, code_b = compiled.integrate("dop853", far, c, 0.0, 5.0, rtol=1e-12, atol=1e-12)
    assert code_a == code_b == 0
    rates = [scene.states.index(s) for s in ("u1", "u2", "u3", "gd1", "gd2", "w1")]
    # far's angle itself holds only |gam| eps ~ 1e-9 rad: the rates follow it
    assert np.abs(a[rates] - b[rates]).max() < 1e-6 * np.abs(a[rates]).max()


AXES_AT_RUN_TIME = pytest.mark.skipif(
    not os.environ.get("GYROGEN_VERIFY_AXES"),
    reason="runtime gimbal axes take minutes to derive: make verify-axes",
)


@pytest.mark.slow
@pytest.mark.parametrize(
    "text", [builtin_text("vscmg3"), builtin_text("cmg4_pyramid"), MIXED, RUNTIME,
             pytest.param(RUNTIME_AXES, marks=AXES_AT_RUN_TIME)],
    ids=["vscmg3", "cmg4_pyramid", "mixed", "runtime", "runtime axes"],
)  # fmt: skip
@WIDE
def test_cmg_scenes_match_the_gimbal_reference(text: str, tmp_path: Path) -> None:
    from gyrogen.oracle.compare import compare
    from gyrogen.runtime.scene_build import build_scene

    scene = parse(text, "scene.toml")
    backends = build_scene(scene, tmp_path, scene.targets)
    report = compare(list(backends.values()), scene, n_states=500, n_params=5, n_ill=0, seed=5)
    assert report.passed, [r for r in report.rows if not r.passed] + report.refusal_failures
    assert {"C vs reference", "Fortran vs reference", "C vs reference power"} <= {
        r.pair for r in report.rows
    }


@pytest.mark.slow
def test_ops_splits_a_cmg_scene_and_refuses_one_without_gimbals(cli) -> None:
    code, out, _ = cli(["ops", "vscmg3"])
    assert code == 0, out
    ops = {line.split()[0]: int(line.split()[1]) for line in out.splitlines()[1:]}
    assert ops["(fixed)"] + ops["(solve)"] + ops["(gimbal)"] == ops["(rhs)"]
    assert 30 <= ops["(solve)"] <= 50  # 6 cofactors, a determinant, 1/det, three rows
    code, out, err = cli(["ops", "rw3_orthogonal"])
    assert (code, out) == (1, "") and "rw3_orthogonal: no rotor on a gimbal" in err


def test_the_header_says_a_gimbals_spin_axis_is_the_one_at_gimbal_angle_0() -> None:
    """The rotor lines and p[]'s g1_k..g3_k of a rotor on a gimbal: the spin
    axis at gimbal angle 0, turned about the gimbal axis (a fixed rotor's
    keep their words)."""
    from gyrogen.codegen.context import SceneContext

    header = (REPO / "generated" / "cmg4_pyramid" / "cmg4_pyramid.h").read_text()
    assert "Rotor B1 on gimbal G1: spin axis g1 = (0, 1, 0) in A at gimbal angle 0," in header
    assert "turned by gam1 about the gimbal axis g_g1 = (0.816541, 0, 0.577288) in A" in header
    scene = parse(RUNTIME_AXES, "r.toml")
    doc = SceneContext(scene, None, None).rotor_doc  # type: ignore[arg-type]  # reads the scene
    assert doc[0] == ("Rotor B1 on gimbal G1: spin axis g1 = (p[g1_1], p[g2_1], p[g3_1]) made "
                      "perpendicular to g_g1, normalized in A at gimbal angle 0,")  # fmt: skip
    assert doc[1] == "  turned by gam1 about the gimbal axis g_g1 = (p[gg1_1], p[gg2_1], " \
        "p[gg3_1]) normalized in A"  # fmt: skip
    assert scene.unit_and_doc("g2_1") == (
        "-", 'spin axis g_s0 of rotor B1 at gimbal angle 0 (g1 turns with gam1), a2 component '
        '(axis = "runtime")')  # fmt: skip
    assert parse(GOOD, "v.toml").unit_and_doc("T_1")[1].endswith("(minus on gimbal G1)")
    fixed = parse(builtin_text("rw4_hardware"), "rw.toml")
    assert (
        fixed.unit_and_doc("g2_1")[1] == 'spin axis g1 of rotor B1, a2 component (axis = "runtime")'
    )


def test_a_polynomial_is_the_rings_own_conversion() -> None:
    """gimbals._polynomial gives what ring.from_expr gives, shared
    subexpressions, powers and rationals included; a symbol in a
    denominator is a ValueError, as there (the proof then takes rational
    functions as coefficients)."""
    from sympy.polys.domains import QQ
    from sympy.polys.orderings import lex
    from sympy.polys.rings import ring

    c, s, m, u = sm.symbols("c s m u")
    shared = (sm.Rational(3, 7) * c - s * u) ** 2 + c * s
    exprs = [shared * (shared - u) + sm.Rational(1, 3), sm.expand(shared**3), u, sm.S(5)]
    r, *_ = ring([s, c, m, u], QQ, lex)
    for e in exprs:
        assert gimbals._polynomial(e, r) == r.from_expr(e)
    with pytest.raises(ValueError):
        gimbals._polynomial(shared / m, r)
