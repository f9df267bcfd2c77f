"""Sensitivities: the [sensitivities] table, the generated variational
system (Phi' = J_x Phi, S' = J_x S + J_p) and Compiled.integrate_var."""

from __future__ import annotations

import itertools
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
import sympy as sm
from hypothesis import HealthCheck, Phase, assume, given, settings
from hypothesis import strategies as st
from scene_space import scenes
from scipy import integrate
from sources import write_sources
from wide import WIDE

from gyrogen.codegen.context import make_context
from gyrogen.codegen.generate import unit_of
from gyrogen.codegen.manifest import manifest, sizes
from gyrogen.errors import SceneError, SetupRefused
from gyrogen.runtime import build
from gyrogen.runtime.compiled import Compiled
from gyrogen.scene import builtin_text, parse, validate


def scene_with(name: str, table: str):
    return parse(builtin_text(name) + "\n[sensitivities]\n" + table + "\n", f"{name}.toml")


def test_wrt_accepted():
    s = scene_with("gyrostat", 'wrt = ["state", "T"]')
    assert s.sensitivities is not None
    assert s.sensitivities.wrt == ["state", "T"]
    assert s.sensitivities.error == "all"


@pytest.mark.parametrize(
    ("name", "table", "message"),
    [
        ("gyrostat", 'wrt = ["state", "state"]', "sensitivities.wrt: 'state' is listed twice"),
        ("gyrostat", 'wrt = ["T", "g", "T"]', "sensitivities.wrt: 'T' is listed twice"),
        (
            "gyrostat",
            'wrt = ["state", "bogus"]',
            "sensitivities.wrt[1]: 'bogus' is neither \"state\" nor a runtime parameter",
        ),
        ("dual_spin", 'wrt = ["J"]', "sensitivities.wrt[0]: 'J' is folded to a number"),
        ("gyrostat", "wrt = []", "sensitivities.wrt: List should have at least 1 item"),
        ("gyrostat", 'wrt = ["T"]\nerror = "phi"', "sensitivities.error: Input should be"),
        ("gyrostat", 'wrt = ["T"]\nstep = 1', "sensitivities.step: unknown key"),
    ],
)
def test_wrt_refused_in_one_line(name, table, message):
    with pytest.raises(SceneError) as info:
        scene_with(name, table)
    text = str(info.value)
    assert message in text
    assert "\n" not in text


def test_build_id_unchanged_without_the_table():
    """A scene without [sensitivities] dumps as before (its build id)."""
    s = parse(builtin_text("gyrostat"), "g.toml")
    assert "sensitivities" not in s.model_dump(mode="json")


# --- the generated system, symbolically -------------------------------------------------


@pytest.fixture(scope="module")
def derived():
    """The default scene's unit with wrt = ["T", "state", "l1"]."""
    s = scene_with("gyrostat", 'wrt = ["T", "state", "l1"]')
    return s, make_context(s)


def test_layout_state_first_sparse_and_counted(derived):
    """wrt's "state" gives the first nx columns wherever it stands; an entry no
    path of J's pattern reaches is not integrated; the manifest counts the
    augmented rhs's ops beside the rhs's."""
    s, unit = derived
    var = unit.optimized.variational
    names = [x.name for x in unit.states]
    assert var.columns == (*names, "T", "l1")
    assert var.state_columns == 14
    entries = set(var.entries)
    u1, q1 = names.index("u1"), names.index("q1")
    assert (u1, q1) not in entries  # the rates never read the attitude
    assert (q1, u1) in entries and (u1, u1) in entries
    assert len(entries) < 14 * 16 // 2
    data = manifest(unit, sizes(unit))
    assert data["variational"]["columns"] == [*names, "T", "l1"]
    assert data["variational"]["nx"] == 14 + len(entries)
    assert data["ops"]["var_rhs"] == unit.optimized.augmented.ops > data["ops"]["rhs"]
    assert data["variational"]["integrators"] == list(s.integrators)


def test_parameter_work_in_setup(derived):
    """d c / d p is computed once, by setup: the augmented rhs reads no
    parameter, and the scene's constants keep their values (the variational
    system's come after them, before the condition number)."""
    plain = unit_of(parse(builtin_text("gyrostat"), "g.toml"))  # the full model, built once
    unit = derived[1]
    params = set(unit.params)
    assert not unit.optimized.augmented.free_symbols & params
    assert unit.nc > plain.nc
    p = dict(parse(builtin_text("gyrostat"), "g.toml").simulate.parameters)
    assert [float(v) for v in setup_values(plain, p)[:-1]] == pytest.approx(
        [float(v) for v in setup_values(unit, p)[: plain.nc - 1]], rel=1e-14
    )


def setup_values(unit, p):
    """setup's constants from its block, in sympy at the parameters p."""
    values = {s: sm.Float(p[s.name], 30) for s in unit.params}
    for a in unit.optimized.setup.temporaries:
        values[a.lhs] = sm.sympify(a.rhs).xreplace(values).evalf(30)
    return [sm.sympify(e).xreplace(values).evalf(30) for e in unit.optimized.setup.outputs]


# --- the compiled flow -------------------------------------------------------------------

METHODS = ("dopri5", "dop853", "rodas4", "radau5", "taylor")
"""Every adaptive method (rk4 too is offered, at fixed steps)."""
TOL = 1e-13
"""The tolerance of the flow and of its finite differences."""


def built(tmp: Path, cache: Path, text: str, languages=("c", "fortran")) -> dict[str, Compiled]:
    """The scene's sources generated into tmp and built per language."""
    scene = parse(text, "scene.toml")
    write_sources(scene, tmp)
    mp = pytest.MonkeyPatch()
    mp.setenv("GYROGEN_CACHE", str(cache))
    try:
        return {lang: build.build(tmp, lang) for lang in languages}
    finally:
        mp.undo()


def start(text: str) -> tuple[np.ndarray, np.ndarray]:
    """The scene's initial state and runtime parameters (simulate's)."""
    s = parse(text, "scene.toml")
    return np.array(s.initial_state()), np.array([s.simulate.parameters[n] for n in s.runtime])


def finite_differences(
    m: Compiled,
    method: str,
    x0: np.ndarray,
    p: np.ndarray,
    t1: float,
    rel: float = 1e-3,
    tol: float = TOL,
) -> np.ndarray:
    """Phi by central differences of the compiled flow, Richardson-extrapolated
    (4 D(h) - D(2h)) / 3: truncation h^4, the flow's own error over h; a
    column NaN where a parameter sits within 2 h of a bound setup refuses."""
    var = m.manifest["variational"]
    runtime = m.manifest["parameters"]
    out = np.zeros((len(x0), len(var["columns"])))
    for k, name in enumerate(var["columns"]):
        state = k < var["state_columns"]
        base = x0[k] if state else p[runtime.index(name)]
        unit = np.zeros(len(x0) if state else len(p))
        unit[k if state else runtime.index(name)] = 1.0

        def flow(d: float, state=state, unit=unit) -> np.ndarray:
            if state:
                return m.integrate(method, x0 + d * unit, m.setup(p), 0.0, t1, rtol=TOL, atol=TOL)[
                    0
                ]
            return m.integrate(method, x0, m.setup(p + d * unit), 0.0, t1, rtol=TOL, atol=TOL)[0]

        h = rel * (max(1.0, abs(base)) if state else abs(base) or 1.0)
        try:
            d1 = (flow(h) - flow(-h)) / (2 * h)
            d2 = (flow(2 * h) - flow(-2 * h)) / (4 * h)
        except SetupRefused:  # within 2 h of a bound setup checks: no differences
            out[:, k] = np.nan
            continue
        out[:, k] = (4 * d1 - d2) / 3
    return out


def parameter_error(s: np.ndarray, ref: np.ndarray, p: np.ndarray, x: np.ndarray) -> float:
    """The largest difference of S from ref as a change of x per relative
    change of each parameter, against x's size: a tiny parameter's column,
    relative to itself, is the flow's noise over a tiny step."""
    size = np.maximum(1.0, np.abs(p)) / np.maximum(1.0, np.abs(x))[:, None]
    return float((np.abs(s - ref) * size).max()) if s.size else 0.0


def column_error(phi: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Each column's largest difference relative to the column's largest entry."""
    scale = np.abs(ref).max(axis=0)
    return np.abs(phi - ref).max(axis=0) / np.where(scale > 0, scale, 1.0)


DEFAULT_VAR = builtin_text("gyrostat") + '\n[sensitivities]\nwrt = ["state", "T"]\n'


@pytest.fixture(scope="module")
def default_var(tmp_path_factory: pytest.TempPathFactory, cache_dir: Path) -> dict[str, Compiled]:
    return built(tmp_path_factory.mktemp("var") / "gyrostat", cache_dir, DEFAULT_VAR)


@pytest.mark.slow
@pytest.mark.parametrize("method", METHODS)
def test_phi_against_finite_differences(default_var, method):
    """Phi (14 x 15: the state's columns, then T's) agrees with central
    differences of the compiled flow to 1e-7 relative, column by column."""
    m = default_var["c"]
    x0, p = start(DEFAULT_VAR)
    _, phi, _, code = m.integrate_var(method, x0, m.setup(p), 0.0, 10.0, rtol=TOL, atol=TOL)
    assert code == 0 and phi.shape == (14, 15)
    np.testing.assert_array_equal(phi.shape, (m.nx, 15))
    assert column_error(phi, finite_differences(m, method, x0, p, 10.0)).max() < 1e-7


@pytest.mark.slow
def test_c_fortran_and_lanes_agree_bit_for_bit(default_var):
    """C = Fortran = the SIMD lanes of a batch, every entry of Phi."""
    c_build, f_build = default_var["c"], default_var["fortran"]
    x0, p = start(DEFAULT_VAR)
    c = c_build.setup(p)
    rng = np.random.default_rng(3)
    starts = x0 + 0.01 * rng.standard_normal((5, len(x0)))
    for method in METHODS:
        one = [
            c_build.integrate_var(method, s, c, 0.0, 2.0, rtol=1e-10, atol=1e-10) for s in starts
        ]
        xs, phis, _, codes = c_build.integrate_var_batch(
            method, starts, c, 0.0, 2.0, rtol=1e-10, atol=1e-10
        )
        assert not codes.any()
        np.testing.assert_array_equal(phis, np.array([o[1] for o in one]))
        np.testing.assert_array_equal(xs, np.array([o[0] for o in one]))
        fortran = f_build.integrate_var(method, starts[0], c, 0.0, 2.0, rtol=1e-10, atol=1e-10)
        np.testing.assert_array_equal(fortran[1], one[0][1])
        assert fortran[2]["accepted"] == one[0][2]["accepted"]


@pytest.mark.slow
def test_liouville(default_var):
    """det Phi(t) = exp(integral of tr J_x along the trajectory)."""
    m = default_var["c"]
    x0, p = start(DEFAULT_VAR)
    c = m.setup(p)
    t1 = 4.0
    _, phi, _, code = m.integrate_var("dop853", x0, c, 0.0, t1, rtol=TOL, atol=TOL)
    assert code == 0
    ts = np.linspace(0.0, t1, 401)
    xs = [x0] + [m.integrate("dop853", x0, c, 0.0, t, rtol=TOL, atol=TOL)[0] for t in ts[1:]]
    trace = np.array([np.trace(m.jacobian(x, c)) for x in xs])
    integral = integrate.simpson(trace, x=ts)
    assert abs(integral) > 0.01  # the test would hold trivially at tr J = 0
    assert np.linalg.det(phi[:, :14]) == pytest.approx(np.exp(integral), rel=1e-8)


TORQUE_FREE = """
name = "free_var"
description = "torque-free, asymmetric, quaternion attitude"
attitude = "quaternion"
integrators = ["dopri5", "dop853", "rodas4", "radau5", "taylor"]

[parameters]
m_a = 10.0
m_b = 2.0
I11 = 3.0
I22 = 4.0
I33 = 5.0
I13 = 0.2
I = 0.05
J = 0.08
l1 = 0.1
l3 = -0.05

[effects]
translation = false
rotor_angle = false
torque = "none"

[outputs]
angular_momentum = true

[simulate]
initial = { e0 = 0.7, e1 = 0.1, e2 = -0.5, e3 = 0.5, u1 = 0.3, u2 = 1.0, u3 = -0.2, u4 = 40.0 }

[sensitivities]
wrt = ["state"]
"""


@pytest.mark.slow
@WIDE
def test_gradient_of_momentum_conserved(tmp_path, cache_dir):
    """Torque-free, |H|^2 is a first integral: its gradient is carried by
    Phi, dH2(x(t))/dx . Phi(t) = dH2(x0)/dx."""
    m = built(tmp_path / "free", cache_dir, TORQUE_FREE, ("c",))["c"]
    x0, p = start(TORQUE_FREE)
    c = m.setup(p)

    def h2(x: np.ndarray) -> float:
        h = np.ravel(m.output("angular_momentum", x, c))
        return float(h @ h)

    def gradient(x: np.ndarray) -> np.ndarray:
        out = np.zeros(len(x))
        for i in range(len(x)):
            d = np.zeros(len(x))
            d[i] = 1e-4 * max(1.0, abs(x[i]))
            one = (h2(x + d) - h2(x - d)) / (2 * d[i])
            two = (h2(x + 2 * d) - h2(x - 2 * d)) / (4 * d[i])
            out[i] = (4 * one - two) / 3
        return out

    g0 = gradient(x0)
    for method in METHODS:
        x, phi, _, code = m.integrate_var(method, x0, c, 0.0, 20.0, rtol=TOL, atol=TOL)
        assert code == 0
        np.testing.assert_allclose(gradient(x) @ phi, g0, rtol=0, atol=1e-8 * np.abs(g0).max())


@pytest.mark.slow
def test_against_heyoka(default_var):
    """The state's columns of Phi agree with heyoka's var_ode_sys on the same
    system (gyrogen's rhs block as heyoka expressions) to 1e-11."""
    hy = pytest.importorskip("heyoka")
    from gyrogen.analysis.bench.heyoka_peer import system

    unit = unit_of(parse(DEFAULT_VAR, "scene.toml"))
    sys_ = system(hy, unit)
    m = default_var["c"]
    x0, p = start(DEFAULT_VAR)
    c = m.setup(p)
    ta = hy.taylor_adaptive(
        hy.var_ode_sys(sys_.pairs, hy.var_args.vars, order=1),
        x0,
        tol=1e-15,
        pars=c[: sys_.npars],
        compact_mode=True,
    )
    ta.propagate_until(10.0)
    nx = len(x0)
    theirs = ta.state[nx:].reshape(nx, nx)
    for method in METHODS:
        _, phi, _, code = m.integrate_var(method, x0, c, 0.0, 10.0, rtol=1e-14, atol=1e-14)
        assert code == 0
        assert column_error(phi[:, :nx], theirs).max() < 1e-11


@pytest.mark.slow
@WIDE
def test_error_measured_on_the_state_alone(tmp_path, cache_dir):
    """sensitivities.error = "state": the step control measures x alone (Phi
    rides on its steps, fewer of them), and Phi still agrees with the
    differences of the flow."""
    text = DEFAULT_VAR + 'error = "state"\n'
    alone = built(tmp_path / "gyrostat", cache_dir, text, ("c",))["c"]
    x0, p = start(text)
    c = alone.setup(p)
    for method in METHODS:
        _, phi, stats, code = alone.integrate_var(method, x0, c, 0.0, 10.0, rtol=TOL, atol=TOL)
        assert code == 0
        if method == "dop853":
            assert column_error(phi, finite_differences(alone, method, x0, p, 10.0)).max() < 1e-7
        plain = alone.integrate(method, x0, c, 0.0, 10.0, rtol=TOL, atol=TOL)[1]
        assert stats["accepted"] <= plain["accepted"] * 1.1 + 2


# --- hostile -------------------------------------------------------------------------------

FLAT_SPIN = """
name = "flat_spin"
description = "spin about the intermediate axis, exactly: an unstable equilibrium"
attitude = "quaternion"
integrators = ["dopri5", "dop853", "taylor"]

[parameters]
m_a = 10.0
m_b = 2.0
I11 = 12.0
I22 = 9.0
I33 = 15.0
I13 = 0.0
I = 0.05
J = 0.08
l1 = 0.0
l3 = 0.0

[effects]
translation = false
rotor_angle = false
torque = "none"

[simulate]
initial = { u1 = 20.0 }

[sensitivities]
wrt = ["state"]
"""


@pytest.mark.slow
@WIDE
def test_phi_overflowing_is_a_code(tmp_path, cache_dir):
    """On an unstable equilibrium x stays put while Phi grows as e^(5 t):
    past t = 135 s it overflows. The run stops with a code (non-finite for
    the pairs; step size underflow for taylor, whose coefficients overflow
    first) and returns its last finite state and Phi, where the plain run
    goes on."""
    m = built(tmp_path / "spin", cache_dir, FLAT_SPIN, ("c",))["c"]
    x0, _ = start(FLAT_SPIN)
    c = m.setup([])
    codes = {"dopri5": 3, "dop853": 3, "taylor": 1}
    for method, expected in codes.items():
        assert m.integrate(method, x0, c, 0.0, 400.0, rtol=1e-10, atol=1e-10)[2] == 0
        x, phi, stats, code = m.integrate_var(method, x0, c, 0.0, 400.0, rtol=1e-10, atol=1e-10)
        assert code == expected
        assert 100.0 < stats["t"] < 400.0
        assert np.isfinite(x).all() and np.isfinite(phi).all()
        assert np.abs(phi).max() > 1e300


@pytest.mark.slow
def test_nan_parameters_refused(default_var):
    """A NaN parameter is refused by setup (its code 1), and NaN constants
    by integrate_var in one line, and a NaN start ends with the code of a
    non-finite state."""
    m = default_var["c"]
    x0, p = start(DEFAULT_VAR)
    bad = p.copy()
    bad[-1] = np.nan
    with pytest.raises(SetupRefused, match=r"code 1\)"):
        m.setup(bad)
    c = m.setup(p)
    with pytest.raises(ValueError, match="the constants c are not all finite"):
        m.integrate_var("dop853", x0, np.where(np.arange(len(c)) == 3, np.nan, c), 0.0, 1.0)
    x_bad = x0.copy()
    x_bad[2] = np.nan
    assert m.integrate_var("dop853", x_bad, c, 0.0, 1.0)[3] == 3  # a non-finite state


def test_no_sensitivities_declared(backends):
    """integrate_var on a scene without [sensitivities]: one line saying what to add."""
    with pytest.raises(ValueError, match=r"declares no sensitivities: add a \[sensitivities\]"):
        backends["c"].integrate_var("dop853", np.zeros(14), np.zeros(12), 0.0, 1.0)


def normalization(x0: np.ndarray, quaternion: bool) -> np.ndarray:
    """d(start)/d(x0) of the integrators' start: the Euler parameters
    normalized (I - e e^T at |e| = 1), the rest as given."""
    out = np.eye(len(x0))
    if quaternion:
        e = x0[:4]
        out[:4, :4] -= np.outer(e, e)
    return out


VAR_EXAMPLES = int(os.environ.get("GYROGEN_VAR_EXAMPLES", "2"))
"""Drawn scenes whose Phi and S meet the flow's differences: the suite's
fixed two (about 30 s each), `make fuzz` FUZZ_VAR."""


@pytest.mark.slow
@settings(max_examples=VAR_EXAMPLES, deadline=None, derandomize=True, database=None,
          phases=[Phase.generate], suppress_health_check=list(HealthCheck))  # fmt: skip
@given(drawn=scenes(), pick=st.randoms(use_true_random=False))
@WIDE
def test_drawn_scenes_against_finite_differences(drawn, pick, tmp_path_factory, cache_dir):
    """Drawn scenes (tests/scene_space.py), wrt the state and a draw of their
    runtime parameters: Phi agrees with the differences of the flow column by
    column (a quaternion start's normalization applied to it, as the flow
    applies it), S as parameter_error measures."""
    assume(drawn.valid)
    data = tomllib.loads(drawn.text)
    scene = parse(drawn.text, "drawn.toml")
    params = [n for n in scene.runtime if pick.random() < 0.5]
    data["integrators"], data["targets"] = ["dop853"], ["c"]  # a drawn scene may be Fortran's alone
    data["sensitivities"] = {"wrt": ["state", *params]}
    scene = validate(data, "drawn.toml")
    out = tmp_path_factory.mktemp("drawn") / scene.name
    write_sources(scene, out)
    mp = pytest.MonkeyPatch()
    mp.setenv("GYROGEN_CACHE", str(cache_dir))
    try:
        m = build.build(out, "c")
    finally:
        mp.undo()
    x0 = np.array(scene.initial_state())
    p = np.array([scene.simulate.parameters[n] for n in scene.runtime], dtype=float)
    t1 = scene.simulate.t_end
    tol = 1e-14  # drawn states and parameters span decades: the differences' noise is tol / h
    x, phi, _, code = m.integrate_var("dop853", x0, m.setup(p), 0.0, t1, rtol=tol, atol=tol)
    assume(code == 0 and m.integrate("dop853", x0, m.setup(p), 0.0, t1, rtol=tol, atol=tol)[2] == 0)
    nx = len(x0)
    phi[:, :nx] = phi[:, :nx] @ normalization(x0, scene.attitude == "quaternion")
    cols = m.manifest["variational"]["columns"][nx:]
    values = np.array([p[scene.runtime.index(n)] for n in cols])

    def errors(rel: float) -> tuple[float, float]:
        fd = finite_differences(m, "dop853", x0, p, t1, rel=rel, tol=tol)
        known = ~np.isnan(fd[:, nx:]).any(axis=0)
        s, ref = phi[:, nx:][:, known], fd[:, nx:][:, known]
        col = column_error(phi[:, :nx], fd[:, :nx]).max()
        return col, parameter_error(s, ref, values[known], x)

    # differences err by their truncation at a large step and by the flow's noise over a small
    # one (a drawn J of 5.6e-5 moved by 1e-5 of itself: 2.5e-7 of noise, by 1e-3: 2e-9; another
    # scene's J column 1.9e-6 at 1e-5 and 1e-3, 1e-9 at 1e-2): Phi and S must agree with them
    # at one of three steps
    found = errors(1e-5)
    for rel in (1e-3, 1e-2):
        if max(found) >= 1e-7:
            found = tuple(min(a, b) for a, b in zip(found, errors(rel), strict=True))
    assert found[0] < 1e-7 and found[1] < 1e-7, (found, drawn.text)


@pytest.mark.slow
@WIDE
def test_every_parameter_of_a_cluster(tmp_path, cache_dir):
    """rw4_hardware with wrt naming the state and all 47 of its runtime
    parameters (a clamped motor among them): Phi is 10 x 57 and agrees with
    the differences of the flow, each parameter's column as the change of x
    per relative change of the parameter against x's size (a mass's
    sensitivity is 1e-11 of a wheel's speed: relative to itself it is noise)."""
    runtime = parse(builtin_text("rw4_hardware"), "rw4.toml").runtime
    assert len(runtime) == 47
    wrt = ", ".join(f'"{n}"' for n in ("state", *runtime))
    text = builtin_text("rw4_hardware") + f"\n[sensitivities]\nwrt = [{wrt}]\n"
    m = built(tmp_path / "rw4", cache_dir, text, ("c",))["c"]
    x0, p = start(text)
    c = m.setup(p)
    x, phi, _, code = m.integrate_var("dop853", x0, c, 0.0, 0.5, rtol=TOL, atol=TOL)
    assert code == 0 and phi.shape == (10, 57)
    fd = finite_differences(m, "dop853", x0, p, 0.5, rel=1e-4)
    assert column_error(phi[:, :10], fd[:, :10]).max() < 1e-7
    known = ~np.isnan(fd[:, 10:]).any(axis=0)
    assert known.sum() > 40
    assert parameter_error(phi[:, 10:][:, known], fd[:, 10:][:, known], p[known], x) < 1e-7


@pytest.mark.slow
def test_the_shooting_example_converges_quadratically():
    """examples/shooting.py: Newton on Phi reaches the start that nulls the
    nutation, each residual at most a constant times the square of the last."""
    run = subprocess.run(
        [sys.executable, str(Path(__file__).resolve().parents[1] / "examples" / "shooting.py")],
        capture_output=True,
        text=True,
        check=True,
    )
    assert run.stdout.rstrip().endswith("converged")
    rows = [line.split() for line in run.stdout.splitlines() if line.split()[0].isdigit()]
    residuals = [float(r[-1]) for r in rows]
    assert len(residuals) >= 3
    for before, after in itertools.pairwise(residuals):
        assert after <= 100 * before**2 + 1e-14
