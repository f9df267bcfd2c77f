"""`gyrogen linearize`: A from the generated Jacobian and B, C, D from the
generated <prefix>_linear agree with central differences of the compiled
rhs, outputs and setup; the eigenvalues agree with NOTES.md's spin-stability
criterion on the stability map's grid; bad points are one line, exit 2."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from wide import WIDE

from gyrogen import api
from gyrogen.analysis.check.engine import spin_stable
from gyrogen.analysis.linearize import engine, files, modes
from gyrogen.analysis.sweep import spec as sweep_spec
from gyrogen.analysis.sweep.draws import grid_values
from gyrogen.analysis.sweep.report import spin_values
from gyrogen.codegen.context import make_context
from gyrogen.errors import GyrogenError
from gyrogen.runtime.compiled import Compiled
from gyrogen.scene import builtin_text, load, parse
from gyrogen.scene.rotors import lumped_inertia

SCENES = ("dual_spin", "rw4_pyramid", "speed_controlled", "wheel_spinup", "rw3_orthogonal")
FD_BAR = 1e-7


@pytest.fixture(scope="module")
def builds() -> dict[str, Compiled]:
    return {name: engine.build(load(name)) for name in SCENES}


def _central(f, v: np.ndarray, j: int) -> np.ndarray:
    """d f / d v_j by central differences (step ~ cbrt(eps) |v_j|)."""
    h = 6e-6 * max(1.0, abs(v[j]))
    up, down = v.copy(), v.copy()
    up[j] += h
    down[j] -= h
    return (f(up) - f(down)) / (up[j] - down[j])


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def _points(name: str, comp: Compiled) -> tuple[np.ndarray, list[np.ndarray]]:
    """The scene's parameters and states around its found equilibrium
    (wheels within 1 rad/s of it: inside every torque clamp)."""
    scene = load(name)
    p = engine.parameters_of(scene, {})
    x0, _ = engine.find_spin(scene, comp, p, None, None)
    rng = np.random.default_rng(7)
    return p, [x0 + rng.normal(0.0, 0.3, x0.size) for _ in range(5)]


@pytest.mark.parametrize("name", SCENES)
def test_a_and_c_agree_with_central_differences(name: str, builds: dict[str, Compiled]) -> None:
    comp = builds[name]
    p, xs = _points(name, comp)
    c = comp.setup(p)
    outputs = comp.manifest["linear"]["from"]
    for x in xs:
        nx = x.size
        a = comp.jacobian(x, c)
        fd = np.column_stack([_central(lambda v: comp.rhs(v, c), x, j) for j in range(nx)])
        assert _relative(a, fd) < FD_BAR, name
        a_lin, _, c_lin, _ = engine.generated(comp, x, c)
        assert _relative(a_lin, a) < 1e-14
        if outputs:
            y = lambda v: np.concatenate([comp.output(o, v, c)[0] for o in outputs])  # noqa: E731
            fd_c = np.column_stack([_central(y, x, j) for j in range(nx)])
            assert _relative(c_lin, fd_c) < FD_BAR, name


@pytest.mark.parametrize("name", [n for n in SCENES if load(n).runtime])
def test_b_and_d_agree_with_central_differences_through_setup(
    name: str, builds: dict[str, Compiled]
) -> None:
    """Each runtime input (T, T_k, w_ref, w_ref_k): B and D are the rhs's
    and the outputs' derivatives along that parameter of setup."""
    comp = builds[name]
    scene = load(name)
    p, xs = _points(name, comp)
    inputs = comp.manifest["linear"]["inputs"]
    outputs = comp.manifest["linear"]["from"]
    x = xs[0]
    _, b, _, d = engine.generated(comp, x, comp.setup(p))
    checked = 0
    for j, u in enumerate(inputs):
        if u not in scene.runtime:
            continue  # folded: checked through its twin scenes below
        k = scene.runtime.index(u)
        fd = _central(lambda q: comp.rhs(x, comp.setup(q)), p, k)
        assert _relative(b[:, j], fd) < FD_BAR, (name, u)
        if outputs:
            y = lambda q: np.concatenate(  # noqa: E731
                [comp.output(o, x, comp.setup(q))[0] for o in outputs]
            )
            assert np.max(np.abs(d[:, j] - _central(y, p, k))) <= FD_BAR * max(
                1.0, float(np.max(np.abs(d)))
            ), (name, u)
        checked += 1
    assert checked >= 1


def test_b_of_folded_runtime_and_absent_torques_is_the_inverse_inertia() -> None:
    """rw3_orthogonal: wheel 1's T folded, wheel 2's runtime, wheel 3 without
    a motor. Each T_k enters as I~ u' = ... - T_k g_k and J_k w_k' = T_k, so
    B's columns are -I~^-1 g_k over u and 1/J_k over w_k, whatever the law."""
    scene = load("rw3_orthogonal")
    lin = api.linearize(scene, spin=0.0)
    assert lin.inputs == ("T_1", "T_2", "T_3")
    inverse = np.linalg.inv(np.array(lumped_inertia(scene.parameters, scene.rotors)))
    axes = np.array([[float(g) for g in r.unit_axis] for r in scene.rotors]).T
    u = [lin.states.index(s) for s in ("u1", "u2", "u3")]
    w = [lin.states.index(f"w{k}") for k in (1, 2, 3)]
    assert np.allclose(lin.B[u], -inverse @ axes, rtol=1e-12, atol=0)
    assert np.allclose(lin.B[w], np.diag([1 / r.J for r in scene.rotors]), rtol=1e-14, atol=0)


@pytest.mark.slow
def test_the_linear_model_leaves_the_scene_code_as_it_was() -> None:
    """outputs.linear_model adds <prefix>_linear and constants after the
    rhs's own: rhs, Jacobian and outputs stay the same expressions."""
    scene = load("dual_spin")
    mine = make_context(engine.with_model(scene))
    own = make_context(scene)
    assert mine.optimized.rhs == own.optimized.rhs
    assert mine.optimized.outputs == own.optimized.outputs
    assert mine.optimized.setup.outputs[: own.nc - 1] == own.optimized.setup.outputs[:-1]
    assert engine.with_model(scene).model_dump()["outputs"]["linear_model"] is True
    assert "linear_model" not in scene.model_dump()["outputs"]


def test_eigenvalues_agree_with_the_spin_criterion_on_the_stability_map() -> None:
    """Every cell of the stability map (gyrostat, 41 x 41 over I22 and u4,
    a spin of u2 = 1 rad/s): unstable from the eigenvalues of the rotational
    block (u1..u4; translation is a double integrator of its own) against
    NOTES.md's (H_a - I_t1 Omega)(H_a - I_t3 Omega) > 0. The cells on the
    boundary have a double zero eigenvalue: a Jordan block (unstable, like
    t) where the criterion's product is zero to rounding."""
    spec = sweep_spec.load("stability_map")
    scene = spec.scene
    comp = engine.build(scene)
    n = spec.sweep.grid_size
    grid = grid_values(spec, np.arange(n))
    base, start = spec.base_parameters(), spec.base_state()
    omega = start["u2"]
    agree = 0
    for i in range(n):
        cell = {k: float(v[i]) for k, v in grid.items()}
        p = engine.parameters_of(scene, {**base, "I22": cell["I22"]})
        x = engine.state_of(scene, None, {"u2": omega, "u4": cell["u4"]})
        lin = engine.linearize(scene, comp, p, x, "grid")
        assert lin.residual == 0.0
        rot = [lin.states.index(s) for s in ("u1", "u2", "u3", "u4")]
        unstable = modes.unstable(lin.A[np.ix_(rot, rot)], ("u1", "u2", "u3", "u4"))
        v = spin_values(spec, {k: np.array([cell[k]]) for k in grid})
        stable = bool(spin_stable(v, np.float64(omega), v["u4"])[0])
        agree += stable != unstable
    assert n == 1681 and agree / n >= 0.995, agree


def test_found_spin_of_the_dual_spin_is_an_exact_equilibrium_and_marginal() -> None:
    lin = api.linearize("dual_spin")
    assert lin.residual == 0.0 and lin.dropped == ("q1", "q2", "q3")
    found = modes.modes(lin.A, lin.states)
    assert modes.overall(found) == "marginal"
    nutation = [m for m in found if m.oscillating]
    assert len(nutation) == 1 and set(nutation[0].states) == {"u1", "u3"}
    assert "oscillating at 0.0475" in nutation[0].words()


def test_state_space_carries_the_names_and_the_poles() -> None:
    control = pytest.importorskip("control")
    lin = api.linearize("rw4_pyramid", spin=0.0)
    sys = api.state_space(lin)
    assert list(sys.state_labels) == list(lin.states)
    assert list(sys.input_labels) == ["w_ref_1", "w_ref_2", "w_ref_3", "w_ref_4"]
    assert len(sys.output_labels) == 8
    poles = control.poles(sys)  # eigvals: the same to rounding, in another order at ties
    gaps = np.abs(poles[:, None] - lin.eigenvalues[None, :])
    assert np.max(gaps.min(axis=0)) <= 1e-12 and np.max(gaps.min(axis=1)) <= 1e-12


def test_command_writes_npz_and_pole_map(tmp_path: Path, cli) -> None:
    code, out, err = cli(["linearize", "dual_spin", "--out", str(tmp_path), "--plot"])
    assert code == 0 and err == "", err
    assert "marginal: 2 modes" in out and "(x2)" in out and "in u1, u3" in out
    data = np.load(tmp_path / files.NPZ)
    assert data["A"].shape == (4, 4) and list(data["states"]) == ["u1", "u2", "u3", "u4"]
    assert list(data["inputs"]) == ["T"] and data["C"].shape == (4, 4)
    png = (tmp_path / files.PLOT).read_bytes()
    assert png.startswith(b"\x89PNG") and len(png) > 10_000


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--state", "0,0,0,0.05"], "the equilibrium has 4 values; dual_spin has 7 states"),
        (["--at", "u2=nan"], "state u2 is nan: not a finite number"),
        (["--at", "u9=1"], "u9 is not a state of dual_spin"),
        (["--at", "u2"], "'u2' is not NAME=NUMBER"),
        (["--at", "u2=1", "--spin", "1"], "give the equilibrium or ask for a spin"),
        (["--param", "k=1"], "k is not a runtime parameter of the scene"),
        (["--at", "u2=1,u2=2"], "u2 is given twice"),
        (["--at", "=1"], "'=1' is not NAME=NUMBER"),
        (["--spin", "1e308"], "a spin of 1e+308 rad/s: beyond 1e+100 rad/s"),
        (["--at", "u4=1e308"], "state u4 = 1e+308: beyond 1e+100 rad/s"),
        (["--at", "q2=1.5707963267948966"], "at gimbal lock (|cos q2| < 1e-09)"),
        (["--at", "q2=-4.71238898038469"], "at gimbal lock"),
        (["--at", "q3=1e7"], "state q3 = 1e+07 rad: more than 2607 turns (16384 rad)"),
        (["--state", "0,0,-20000,0,1,0,0"], "state q3 = -20000 rad: more than 2607 turns"),
    ],
)
def test_bad_points_are_one_line_exit_2(argv: list[str], message: str, tmp_path: Path, cli) -> None:
    code, out, err = cli(["linearize", "dual_spin", "--out", str(tmp_path), *argv])
    assert (code, out) == (2, "") and err.count("\n") == 1 and message in err, err
    assert not any(tmp_path.iterdir())


def test_parameters_whose_constants_overflow_are_one_line_exit_2(tmp_path: Path, cli) -> None:
    """Each value valid, together refused by setup (code 9: T/J past
    DBL_MAX): one line, no traceback, nothing written."""
    argv = ["linearize", "wheel_spinup", "--out", str(tmp_path), "--param", "T=1e308"]
    code, out, err = cli(argv)
    assert (code, out) == (2, "") and err.count("\n") == 1, err
    assert "wheel_spinup: parameters: setup refused the parameters (code 9)" in err
    assert not any(tmp_path.iterdir())


def test_not_an_equilibrium_is_warned_with_its_residual(tmp_path: Path, cli) -> None:
    code, _, err = cli(
        ["linearize", "dual_spin", "--out", str(tmp_path), "--at", "u1=0.01,u2=0.05,u4=600"]
    )
    assert code == 0 and err.count("\n") == 1, err
    assert err.startswith("gyrogen: warning: not an equilibrium: max |dx/dt|")
    assert "the model is about a moving point" in err
    assert (tmp_path / files.NPZ).is_file()


def test_the_residual_is_relative_without_overflow() -> None:
    """A row's scale may overflow where the share does not: 1e305 against
    1e300 x 1e10 is 1e-5 (a warning), not 1e305 / inf = 0; each row has its
    own (the second's 1 against 2)."""
    from gyrogen.analysis.linearize.engine import relative

    jac = np.array([[1e300, -1e300], [0.0, 2.0]])
    share = relative(np.array([1e305, 1.0]), jac, np.array([1e10, 0.0]))
    assert share[0] == pytest.approx(1e-5) and share[1] == 0.5
    assert list(relative(np.zeros(2), np.zeros((2, 2)), np.zeros(2))) == [0.0, 0.0]
    assert list(relative(np.ones(2), np.zeros((2, 2)), np.ones(2))) == [np.inf, np.inf]


@pytest.mark.parametrize("w_ref", [2e2, 1e6, 1e10, 1e12, 1e15, 1e40])
def test_the_attitude_turns_whatever_the_wheel_speed(w_ref: float) -> None:
    """speed_controlled's spin of 0.102 rad/s about a2 turns the attitude
    at that rate whatever w_ref: its angles are left out, as at w_ref = 200.
    At w_ref = 1e12 their 0.102 rad/s passed the still test against 1e-12 of
    the wheel's speed: kept, linearized as a Jordan block, "unstable ...
    grows like t", with no warning (the residual against ||A|| ||x||)."""
    lin = api.linearize("speed_controlled", parameters={"w_ref": w_ref})
    assert lin.dropped == ("q1", "q2", "q3", "q4") and files.warning(lin) is None
    assert not any(m.secular for m in modes.modes(lin.A, lin.states))


def test_a_turning_quaternion_beside_a_fast_wheel_is_left_out(tmp_path: Path, cli) -> None:
    """dual_spin with Euler parameters at u2 = 0.05 and a wheel at 1e100
    rad/s: e turns at 0.025 /s, left out (it was kept: 0.025 <= 1e-12 of
    1e100); the speeds are still, no warning."""
    path = tmp_path / "dual_spin_e.toml"
    path.write_text(QUATERNION_DUAL_SPIN)
    argv = ["linearize", str(path), "--out", str(tmp_path / "out"), "--at", "u2=0.05,u4=1e100"]
    code, out, err = cli(argv)
    assert code == 0 and err == "", err
    assert "left out (their rates do not vanish): e0, e1, e2, e3\n" in out, out
    assert "grows like t" not in out


QUATERNION_SPINUP = builtin_text("wheel_spinup").replace(
    'name = "wheel_spinup"', 'name = "wheel_spinup_e"\nattitude = "quaternion"'
)


@pytest.mark.parametrize("u4", ["600", "1e12", "1e100"])
def test_a_wheel_still_spun_up_is_warned_at_any_speed(u4: str, tmp_path: Path, cli) -> None:
    """wheel_spinup (T = 0.02 N m speeds the wheel up at 1.33 rad/s^2) with
    Euler parameters: at u4 = 1e100 rad/s it was no warning (1.33 against
    ||A|| ||x|| ~ 1e197); each kept rate is measured against its own row,
    and u4's row of A is 0 (no state moves it): a warning at every speed."""
    path = tmp_path / "spinup_e.toml"
    path.write_text(QUATERNION_SPINUP)
    argv = ["linearize", str(path), "--out", str(tmp_path / "out"), "--at", f"u2=0.5,u4={u4}"]
    code, out, err = cli(argv)
    assert code == 0 and err.count("\n") == 1, err
    assert err.startswith("gyrogen: warning: not an equilibrium: max |dx/dt|"), err
    assert "u4' = 1.33, which no state moves" in err, err
    assert "left out (their rates do not vanish): e0, e1, e2, e3, q4\n" in out, out
    assert (tmp_path / "out" / files.NPZ).is_file()


def test_a_subnormal_spin_is_linearized_quietly(tmp_path: Path, cli) -> None:
    code, out, err = cli(["linearize", "dual_spin", "--out", str(tmp_path), "--spin", "1e-320"])
    assert code == 0 and err == "", err
    assert "found: a steady spin of 9.99989e-321 rad/s" in out


@pytest.mark.parametrize(
    ("axis", "verdict", "growth"),
    [("2", "marginal: 3 modes", None), ("1", "unstable: 4 modes", "unstable: +0.145233+0i, ")],
)
def test_a_stiff_wheel_does_not_merge_the_slow_modes(
    axis: str, verdict: str, growth: str | None, tmp_path: Path, cli
) -> None:
    """stiff_wheel with k = 3e6: a wheel mode at -1e8 beside the nutation
    (+-0.38i about a2, a saddle +-0.145 about a1) and a zero. Measured
    against -1e8, the slow three merged into one Jordan block ("grows like
    t", x3) about a2 and hid the saddle's exponential growth about a1."""
    argv = ["linearize", "stiff_wheel", "--out", str(tmp_path), "--spin", "1", "--axis", axis]
    code, out, err = cli([*argv, "--param", "k=3e6,w_ref=150"])
    assert code == 0 and err == "", err
    assert f"\n{verdict} (eigenvalues" in out and "grows like t" not in out, out
    assert "stable: -1.0004e+08+0i, not oscillating" in out
    if growth is None:
        assert "marginal: +0+0.381246i, oscillating at 0.381246 rad/s" in out, out
    else:
        assert f"{growth}not oscillating, growing: doubles every 4.773 s" in out, out


WHEEL_AGAINST_FRICTION = """
name = "wheel_against_friction"
description = "one wheel driven by a runtime torque against its bearing friction"
targets = ["c"]
[parameters]
m_a = 800.0
I11 = 420.0
I22 = 380.0
I33 = 300.0
[effects]
rotor_angle = false
[outputs]
kinetic_energy = true
[[rotors]]
m = 5.0
I = 0.025
J = 0.045
axis = [1.0, 0.0, 0.0]
position = [0.3, 0.0, -0.2]
b = 2e-05
torque = "constant"
T = "runtime"
[simulate]
t_end = 1.0
dt = 0.1
initial = { u1 = 0.01 }
parameters = { T_1 = 0.1 }
"""


@pytest.mark.parametrize("spin", [[], ["--spin", "0"]])
def test_a_found_spin_whose_wheel_rate_overflows_is_one_line_exit_2(
    spin: list[str], tmp_path: Path, cli
) -> None:
    """A wheel held by T_1 = 1e300 against b = 2e-5 turns at T / b = 5e304
    rad/s: the spin found was that point (|dx/dt| 1e281), exit 0. Now the
    same limit as a given state's (MAX_SPIN), one line, nothing written."""
    path = tmp_path / "wheel.toml"
    path.write_text(WHEEL_AGAINST_FRICTION)
    out_dir = tmp_path / "out"
    code, out, err = cli(
        ["linearize", str(path), "--out", str(out_dir), "--param", "T_1=1e300", *spin]
    )
    assert (code, out) == (2, "") and err.count("\n") == 1, err
    assert (
        "at the steady spin asked for (each wheel at the rate its law holds), w1 = 5e+304: "
        "beyond 1e+100 rad/s" in err
    ), err
    assert not out_dir.exists()
    code, out, err = cli(["linearize", str(path), "--out", str(out_dir), "--param", "T_1=1e-3"])
    assert code == 0 and err == "" and "w1 = 50" in out, err


QUATERNION_DUAL_SPIN = builtin_text("dual_spin").replace(
    'name = "dual_spin"', 'name = "dual_spin_e"\nattitude = "quaternion"'
)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--at", "e0=0"], "the equilibrium: e0..e3 are all zero: not an attitude"),
        (["--state", "0,0,0,0,0,0.05,0,600"], "the equilibrium: e0..e3 are all zero"),
        (["--at", "e0=2"], "the equilibrium: e0..e3 = (2, 0, 0, 0) has norm 2, not 1 (within"),
        (["--at", "e0=0.5,e1=0.5"], "has norm 0.707106781, not 1 (within 1e-06)"),
        (["--at", "e0=1e-200"], "has norm 1e-200, not 1"),
        (["--at", "e1=nan"], "state e1 is nan: not a finite number"),
    ],
)
def test_a_point_off_the_unit_quaternions_is_one_line_exit_2(
    argv: list[str], message: str, tmp_path: Path, cli
) -> None:
    """As a scene's start: e0..e3 all zero, or |e| off 1 by more than
    QUATERNION_NORM_SLACK, is refused (they were linearized about, exit 0)."""
    path = tmp_path / "dual_spin_e.toml"
    path.write_text(QUATERNION_DUAL_SPIN)
    out_dir = tmp_path / "out"
    code, out, err = cli(["linearize", str(path), "--out", str(out_dir), *argv])
    assert (code, out) == (2, "") and err.count("\n") == 1 and message in err, err
    assert not out_dir.exists()


def test_a_nearly_unit_quaternion_point_is_normalized() -> None:
    """Within QUATERNION_NORM_SLACK, the point's e is made a unit quaternion
    (as a scene's start is), in the model and the point it reports."""
    scene = parse(QUATERNION_DUAL_SPIN, "dual_spin_e.toml")
    lin = api.linearize(scene, at={"e0": 0.70710678, "e1": 0.70710678, "u2": 0.05, "u4": 600})
    e = lin.x[[scene.states.index(n) for n in ("e0", "e1", "e2", "e3")]]
    assert abs(float(np.sum(e * e)) - 1.0) <= 4.5e-16 and e[0] == e[1]


def test_the_printed_eigenvalues_are_the_stored_ones(tmp_path: Path, cli) -> None:
    """stiff_wheel's zero (momentum about a2) printed as -1.45519e-11 while
    linear.npz stored +1.45519e-11 (the words read the Schur form, the file
    numpy's eigvals): each mode of one eigenvalue prints a stored value."""
    code, out, err = cli(["linearize", "stiff_wheel", "--out", str(tmp_path)])
    assert code == 0 and err == "", err
    stored = np.load(tmp_path / files.NPZ)["eigenvalues"]
    lin = api.linearize("stiff_wheel")
    found = modes.modes(lin.A, lin.states)
    assert np.array_equal(stored, lin.eigenvalues)
    for m in (m for m in found if m.multiplicity == 1):
        lam = m.eigenvalue
        assert any(v.real == lam.real and lam.imag in (0.0, abs(v.imag)) for v in stored), m
        assert f"{m.verdict}: {lam.real:+.6g}{lam.imag:+.6g}i" in out


@pytest.mark.parametrize(("param", "times"), [("w_ref=1e90", "(x2)"), ("k=1e40", "(x3)")])
def test_modes_lost_in_rounding_are_one_eigenvalue(
    param: str, times: str, tmp_path: Path, cli
) -> None:
    """speed_controlled at w_ref = 1e90 (||A|| 7e86) or k = 1e40 (4.7e41):
    the speed loop (-10) and the zero, or the nutation (+-0.135i) and the
    zero, lie within A's rounding error (1e73, 6e27) of each other, where a
    backward-stable solver may return them in any order: one eigenvalue to
    A's precision, marginal against that error on every CPU."""
    argv = ["linearize", "speed_controlled", "--out", str(tmp_path), "--param", param]
    code, out, err = cli(argv)
    assert code == 0 and err == "", err
    assert "\nmarginal: 2 modes (eigenvalues" in out, out
    assert f"+0i {times}, not oscillating, at rest (zero)" in out, out


@pytest.mark.parametrize(
    "kw, message",
    [
        ({"axis": 0}, r"axis: 0 is not 1, 2 or 3"),  # read a3 through np.eye(3)[-1]
        ({"axis": -2}, r"axis: -2 is not 1, 2 or 3"),
        ({"axis": 5}, r"axis: 5 is not"),  # numpy's IndexError
        ({"axis": True}, r"axis: True is not"),
        ({"spin": float("nan")}, r"spin: nan is not a finite number"),  # "beyond 1e+100"
        ({"parameters": {"T": "abc"}}, r"parameters: T is 'abc', not a real number"),
        ({"parameters": {"T": None}}, r"parameters: T is None"),
        ({"parameters": [("T", 1.0)]}, r"parameters: give a dict of names to numbers, not list"),
        ({"at": {"u1": "x"}}, r"at: u1 is 'x'"),
        ({"state": [0, 0, 0, 1j, 0, 0, 0]}, r"state: x\[3\] is 1j"),
    ],
)
def test_api_linearize_refuses_what_the_cli_cannot_be_given(kw: dict, message: str) -> None:
    """api.linearize's arguments, which click checks for the CLI: one-line
    GyrogenErrors, before anything is built (axis 0 was taken as a3)."""
    with pytest.raises(GyrogenError, match=message) as info:
        api.linearize("dual_spin", **kw)
    assert "\n" not in str(info.value)


@pytest.mark.slow  # two compilers
@WIDE
def test_verify_takes_a_scene_with_its_linear_model(tmp_path: Path, cli) -> None:
    """outputs.linear_model = true in a scene file: verify compares the
    rhs, the output functions and the Jacobian (before: KeyError
    'linear_model', the linear model taken for an output function)."""
    text = builtin_text("dual_spin").replace("[outputs]", "[outputs]\nlinear_model = true", 1)
    (tmp_path / "lm.toml").write_text(text.replace('name = "dual_spin"', 'name = "lm"'))
    code, out, err = cli(["verify", str(tmp_path / "lm.toml")])
    assert code == 0 and "C vs reference kinetic_energy" in out and "linear" not in out, err
