"""The Taylor series integrator: the scene's rhs as elementary
operations (gyrogen.symbolic.jet), its coefficients by the recurrences of
automatic differentiation, printed once to C and Fortran
(gyrogen.codegen.integrators.taylor). Against sympy's own series, a
tight reference, C against Fortran, and where it is not offered."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import sympy as sm
from sources import write_sources
from test_integrators import tabled  # the wheel under a tabled torque
from wide import WIDE

from gyrogen import abi, methods
from gyrogen.errors import GyrogenError, SceneError
from gyrogen.runtime import build
from gyrogen.runtime.compiled import Compiled
from gyrogen.scene import Scene, load
from gyrogen.symbolic.jet import Node, NotExpandable, decompose, regroup
from gyrogen.symbolic.optimize import Assignment, Block

REPO = Path(__file__).resolve().parents[1]
SMOOTH = ["gyrostat", "torque_free", "dual_spin", "speed_controlled", "rw3_orthogonal"]
CODES = {c.name.removeprefix("ODE_"): c.value for c in abi.ODE_CODES}


def coefficients(
    jet_nodes: list, outputs: tuple[int, ...], x0: list[float], order: int
) -> np.ndarray:
    """The normalized Taylor coefficients of the states, by the recurrences
    the generated code prints (a plain Python transcription of them)."""
    n = len(jet_nodes)
    t = np.zeros((order + 1, n))
    nx = len(outputs)
    for k in range(order + 1):
        for i, node in enumerate(jet_nodes):
            if node.op == "x":
                t[k, i] = x0[i] if k == 0 else t[k - 1, outputs[i]] / k if k else 0.0
                continue
            if node.op == "num":
                t[k, i] = node.value if k == 0 else 0.0
                continue
            a = node.args[0]
            if node.op == "neg":
                t[k, i] = -t[k, a]
            elif node.op in ("add", "sub"):
                b = node.args[1]
                t[k, i] = t[k, a] + t[k, b] if node.op == "add" else t[k, a] - t[k, b]
            elif node.op == "mul":
                b = node.args[1]
                t[k, i] = sum(t[j, a] * t[k - j, b] for j in range(k + 1))
            elif node.op == "div":
                b = node.args[1]
                t[k, i] = (t[k, a] - sum(t[j, b] * t[k - j, i] for j in range(1, k + 1))) / t[0, b]
            elif node.op in ("sin", "cos") and k == 0:
                t[0, i] = np.sin(t[0, a]) if node.op == "sin" else np.cos(t[0, a])
            elif node.op == "sin":
                t[k, i] = sum(j * t[j, a] * t[k - j, node.index] for j in range(1, k + 1)) / k
            elif node.op == "cos":
                t[k, i] = -sum(j * t[j, a] * t[k - j, node.index] for j in range(1, k + 1)) / k
    assert nx == len(outputs)
    return t[:, :nx]


@pytest.mark.slow
@WIDE
def test_the_recurrences_are_the_series_of_the_solution() -> None:
    """A small system with every operation: the recurrences' coefficients
    equal sympy's Taylor series of the exact solution's derivatives."""
    xs = sm.symbols("x0:3")
    tmp = sm.Symbol("tmp0")
    f = (
        xs[1] * sm.cos(xs[2]) - sm.Rational(3, 10),
        -sm.sin(xs[2]) / (2 + xs[0] ** 2) + tmp,
        xs[0] * xs[1] - tmp**3,
    )
    block = Block((Assignment(tmp, sm.Float(0.25) * xs[2]),), f)
    jet = decompose(block, xs)
    x0 = [0.3, -0.2, 0.7]
    order = 7
    got = coefficients(list(jet.nodes), jet.outputs, x0, order)
    # the exact series: x^(k) = D^(k-1) f along the flow, by sympy
    fx = [e.subs(tmp, sm.Float(0.25) * xs[2]) for e in f]
    derivs = [list(xs)]
    for _ in range(order):
        prev = derivs[-1]
        derivs.append(
            [sum(sm.diff(p, xs[j]) * fx[j] for j in range(3)) for p in prev]
            if len(derivs) > 1
            else list(fx)
        )
    at = dict(zip(xs, x0, strict=True))
    for k in range(order + 1):
        want = [float(d.subs(at)) / float(sm.factorial(k)) for d in derivs[k]]
        np.testing.assert_allclose(got[k], want, rtol=1e-12, atol=1e-14)


def test_degrees_are_where_the_series_ends() -> None:
    """Jet.degrees: a node's degree as a polynomial in t (inf: none), past
    which its coefficients are 0 (what the generated jet leaves out)."""
    xs, c0 = sm.symbols("x0:5"), sm.Symbol("c0")
    f = (c0, xs[0] * xs[0], xs[1] / c0, sm.sin(xs[2]), sm.Integer(0))
    jet = decompose(Block((), f), xs)
    deg = jet.degrees()
    assert deg[: jet.nx] == (1.0, 3.0, 4.0, math.inf, 1.0)
    nodes = [Node("num", value=0.7) if n.op == "c" else n for n in jet.nodes]  # c0 = 0.7
    got = coefficients(nodes, jet.outputs, [0.3, -0.2, 0.5, 0.1, 2.0], 8)
    for i in (0, 1, 2, 4):
        assert np.all(got[int(deg[i]) + 1 :, i] == 0.0), i
        assert got[int(deg[i]), i] != 0.0 or i == 4  # x4' = 0: its degree 1 is a bound
    assert np.all(got[1:, 3] != 0.0)


@pytest.mark.slow
def test_a_quadratic_rhs_is_regrouped_by_its_fixed_state() -> None:
    """jet.regroup: x2 (constant acceleration: fixed) takes its monomials
    first, so one product of the two in x0' has one term; decompose keeps
    the regrouped form because it has fewer full convolutions, and its
    coefficients are still the series (the plain form's, to rounding)."""
    xs, (c0, c1, c2, c3) = sm.symbols("x0:4"), sm.symbols("c0:4")
    f0 = xs[1] * (c0 * xs[3] + c1 * xs[2]) + xs[0] * (c2 * xs[3] + c3 * xs[2])
    f = (f0, -xs[0] * xs[3], c0, xs[1] * xs[1] - xs[0])
    grouped = regroup(f0, xs, {2})
    assert grouped is not None and sm.expand(grouped - f0) == 0
    factors = {a for term in sm.Add.make_args(grouped) for a in sm.Mul.make_args(term)}
    assert xs[2] in factors and xs[3] in factors  # x2 (c1 x1 + c3 x0) + x3 (c0 x1 + c2 x0)
    jet = decompose(Block((), f), xs)
    # as written: x1 (..), x0 (..), x0 x3, x1 x1; regrouped, x2 (..) has one term
    assert jet.full() == 3
    at = {c0: 0.7, c1: -0.4, c2: 1.3, c3: 0.2}
    nodes = [Node("num", value=at[sm.Symbol(f"c{n.index}")]) if n.op == "c" else n
             for n in jet.nodes]  # fmt: skip
    x0 = [0.3, -0.2, 0.5, 0.1]
    got = coefficients(nodes, jet.outputs, x0, 6)
    fx = [e.subs(at) for e in f]
    derivs = [list(xs)]
    for _ in range(6):
        prev = derivs[-1]
        derivs.append([sum(sm.diff(p, xs[j]) * fx[j] for j in range(4)) for p in prev])
    point = dict(zip(xs, x0, strict=True))
    for k in range(7):
        want = [float(d.subs(point)) / math.factorial(k) for d in derivs[k]]
        np.testing.assert_allclose(got[k], want, rtol=1e-12, atol=1e-14)


def test_regrouping_skips_an_output_its_temporaries_would_blow_up() -> None:
    """Temporaries that each read the one before twice: written out, the
    output's tree has 2^60 nodes. decompose counts no further than
    REGROUP_SIZE and keeps the output as it is (a count of the whole tree
    would not finish)."""
    xs, c = sm.symbols("x0:2"), sm.Symbol("c0")
    tmps = sm.symbols("tmp0:60")
    assigns = [Assignment(tmps[0], xs[0] * xs[1])]
    assigns += [Assignment(tmps[k], tmps[k - 1] + c * tmps[k - 1]) for k in range(1, 60)]
    jet = decompose(Block(tuple(assigns), (tmps[-1], xs[0])), xs)
    assert jet.full() == 1


@pytest.mark.parametrize("seed", range(20))
def test_regroup_is_the_same_polynomial(seed: int) -> None:
    """Any quadratic polynomial with symbolic and float coefficients comes
    back as the same polynomial, every quadratic monomial in one product of
    a state and a linear form; a cubic, a sine or a quotient is not tried."""
    rng = np.random.default_rng(seed)
    xs, cs = sm.symbols("x0:5"), sm.symbols("c0:3")
    terms = [float(rng.normal()) * rng.choice(cs) * xs[i] * xs[j]
             for i, j in rng.integers(0, 5, (int(rng.integers(2, 12)), 2))]  # fmt: skip
    e = sm.Add(*terms, rng.choice(cs) * xs[int(rng.integers(0, 5))], sm.Float(rng.normal()))
    fixed = {int(i) for i in rng.integers(0, 5, int(rng.integers(0, 3)))}
    grouped = regroup(e, xs, fixed)
    if sm.Poly(e, *xs).total_degree() != 2:  # the terms cancelled
        assert grouped is None
        return
    assert grouped is not None and sm.expand(grouped - e) == 0
    for term in sm.Add.make_args(grouped):
        assert sm.Poly(term, *xs).total_degree() <= 2
    assert regroup(xs[0] * xs[1] * xs[2], xs, set()) is None
    assert regroup(sm.sin(xs[0]) * xs[1], xs, set()) is None
    assert regroup(xs[0] / xs[1], xs, set()) is None
    assert regroup(cs[0] * cs[1], xs, set()) is None


@pytest.mark.parametrize(
    "expr, why",
    [
        (sm.Max(sm.Symbol("x0"), 1), "not smooth"),
        (sm.Abs(sm.Symbol("x0")), "not smooth"),
        (sm.exp(sm.Symbol("x0")), "does not expand"),
        (sm.sqrt(sm.Symbol("x0")), "power 1/2"),
        (sm.Symbol("t") * sm.Symbol("x0"), "time-dependent"),
    ],
)
def test_what_is_not_expanded_is_refused(expr: sm.Expr, why: str) -> None:
    with pytest.raises(NotExpandable, match=why):
        decompose(Block((), (expr,)), (sm.Symbol("x0"),))
    assert issubclass(NotExpandable, GyrogenError)


def test_taylor_is_offered_only_where_the_rhs_is_smooth() -> None:
    """Left out of a non-smooth scene's default integrators, refused in one
    line when asked for; smooth built-ins have it by default."""
    data = tabled(["dop853"]).model_dump()
    del data["integrators"]
    assert "taylor" not in Scene.model_validate(data).integrators
    with pytest.raises(SceneError, match=r"taylor is not offered for this scene.*torque table"):
        tabled(["taylor"])
    assert "taylor" not in load("rw4_pyramid").integrators  # clamped motors
    for name in SMOOTH:
        assert "taylor" in load(name).integrators, name


@pytest.fixture(scope="module")
def built(cache_dir: Path) -> dict[tuple[str, str], Compiled]:
    mp = pytest.MonkeyPatch()
    mp.setenv("GYROGEN_CACHE", str(cache_dir))
    try:
        return {
            (name, lang): build.build(REPO / "generated" / name, lang)
            for name in SMOOTH
            for lang in ("c", "fortran")
        }
    finally:
        mp.undo()


def problem(name: str) -> tuple[np.ndarray, np.ndarray]:
    scene = load(name)
    x0 = np.array(scene.initial_state())
    p = np.array([scene.simulate.parameters[n] for n in scene.runtime])
    return x0, p


def scaled(x: np.ndarray, ref: np.ndarray) -> float:
    return float(np.max(np.abs(x - ref) / (1.0 + np.abs(ref))))


@pytest.mark.slow
@pytest.mark.parametrize("name", SMOOTH)
def test_taylor_meets_its_tolerance_in_c_and_fortran_alike(
    built: dict[tuple[str, str], Compiled], name: str
) -> None:
    """Against DOP853 at 1e-13: the error falls with rtol and stays within
    100 rtol; C and Fortran take the same steps and agree to 1e-14 scaled."""
    x0, p = problem(name)
    c_b, f_b = built[name, "c"], built[name, "fortran"]
    c = c_b.setup(p)
    t1 = 10.0
    ref, _, code = c_b.integrate("dop853", x0, c, 0.0, t1, rtol=1e-13, atol=1e-13)
    assert code == 0
    last = np.inf
    for tol in (1e-6, 1e-8, 1e-10, 1e-12):
        xc, sc, cc = c_b.integrate("taylor", x0, c, 0.0, t1, rtol=tol, atol=tol)
        xf, sf, cf = f_b.integrate("taylor", x0, c, 0.0, t1, rtol=tol, atol=tol)
        assert cc == cf == 0 and sc["t"] == sf["t"] == t1
        assert sc["accepted"] == sf["accepted"] and sc["rejected"] == sf["rejected"] == 0
        assert scaled(xc, xf) < 1e-14, (tol, scaled(xc, xf))
        err = scaled(xc, ref)
        assert err < max(100 * tol, 1e-11), (tol, err)
        assert err < last * 1.5 or err < 1e-11
        last = err


@pytest.mark.slow
@pytest.mark.parametrize("language", ["c", "fortran"])
def test_polynomial_states_are_exact_at_any_tolerance(
    built: dict[tuple[str, str], Compiled], language: str
) -> None:
    """The default scene's rotor rate u4 (u4' = T/J), the translation rates
    and positions (u7' = g) are polynomials of degree 1 and 2: the step
    evaluates them exactly and they set no bound on h, so at rtol 1e-4 they
    still equal their closed forms to rounding."""
    x0, p = problem("gyrostat")
    b = built["gyrostat", language]
    c = b.setup(p)
    t1 = 10.0
    x, stats, code = b.integrate("taylor", x0, c, 0.0, t1, rtol=1e-4, atol=1e-4)
    assert code == 0 and stats["accepted"] > 1
    want = {10: x0[10] + c[9] * t1, 11: x0[11], 13: x0[13] + c[10] * t1}
    want |= {4: x0[4] + x0[11] * t1, 6: x0[6] + x0[13] * t1 + 0.5 * c[10] * t1**2}
    for i, v in want.items():
        assert abs(x[i] - v) <= 1e-14 * max(1.0, abs(v)), (i, x[i], v)


@pytest.mark.slow
@pytest.mark.parametrize("start", [{4: 7e6}, {4: 1e12}, {3: 1e7}, {0: 1e5, 2: -3e4}])
def test_a_far_position_or_a_wound_up_angle_leaves_the_step_alone(
    built: dict[tuple[str, str], Compiled], start: dict[int, float]
) -> None:
    """A satellite's position (q5 = 7e6 m), a rotor angle wound up by a long
    run (q4 = 1e7 rad) or large Euler angles do not loosen the step
    (taylor.state_scales): the same steps as from the origin (where the
    state does not enter the rhs), and the carrier's angles and rates
    within 20 rtol of DOP853 at 1e-13. Before,
    q5 = 7e6 took 26 steps where 62 were needed and erred by 3.9e-5 at rtol
    1e-10 (1e12: by 58), with code 0."""
    x0, p = problem("gyrostat")
    b = built["gyrostat", "c"]
    c = b.setup(p)
    carrier = [0, 1, 2, 7, 8, 9]
    _, plain, _ = b.integrate("taylor", x0, c, 0.0, 10.0, rtol=1e-10, atol=1e-10)
    x = x0.copy()
    for i, v in start.items():
        x[i] = v
    ref, _, code = b.integrate("dop853", x, c, 0.0, 10.0, rtol=1e-13, atol=1e-13)
    got, stats, code2 = b.integrate("taylor", x, c, 0.0, 10.0, rtol=1e-10, atol=1e-10)
    assert code == code2 == 0
    if set(start) <= {3, 4}:  # neither enters the rhs: the same trajectory, the same steps
        assert stats["accepted"] == plain["accepted"]
    err = np.max(np.abs(got[carrier] - ref[carrier]) / np.maximum(1.0, np.abs(ref[carrier])))
    assert err <= 20 * 1e-10, err


@pytest.mark.slow
@pytest.mark.parametrize("language", ["c", "fortran"])
def test_taylor_codes(built: dict[tuple[str, str], Compiled], language: str) -> None:
    """The codes every adaptive method returns, the same for Taylor."""
    b = built["gyrostat", language]
    x0, p = problem("gyrostat")
    c = b.setup(p)
    _, st, code = b.integrate("taylor", x0, c, 0.0, 0.0, rtol=1e-8, atol=1e-8)
    assert code == CODES["OK"] and st["accepted"] == 0
    _, _, code = b.integrate("taylor", x0, c, 1.0, 0.0, rtol=1e-8, atol=1e-8)
    assert code == CODES["ERR_ARGUMENT"]
    _, _, code = b.integrate("taylor", x0, c, 0.0, 1.0, rtol=1e-20, atol=1e-8)
    assert code == CODES["ERR_ARGUMENT"]
    bad = x0.copy()
    bad[7] = np.nan
    _, _, code = b.integrate("taylor", bad, c, 0.0, 1.0, rtol=1e-8, atol=1e-8)
    assert code == CODES["ERR_NONFINITE"]
    _, st, code = b.integrate("taylor", x0, c, 0.0, 10.0, rtol=1e-8, atol=1e-8, max_steps=3)
    assert code == CODES["ERR_MAX_STEPS"] and st["accepted"] == 3
    x, st, code = b.integrate("taylor", x0, c, 0.0, 1.0, rtol=1e-8, atol=1e-8)
    x2, st2, code2 = b.integrate("taylor", x0, c, 0.0, 1.0, rtol=1e-8, atol=1e-8, h0=1e-3)
    assert code == code2 == 0 and st2["accepted"] > st["accepted"]  # h0 bounds the first step
    assert scaled(x, x2) < 1e-7
    near = x0.copy()
    near[1] = np.pi / 2 - 1e-12  # q2 at gimbal lock
    _, _, code = b.integrate("taylor", near, c, 0.0, 1.0, rtol=1e-8, atol=1e-8)
    assert code == CODES["ERR_ATTITUDE_SINGULAR"]


def test_taylor_is_a_registered_adaptive_method() -> None:
    m = methods.get("taylor")
    assert m.taylor and not m.pair and not m.implicit and not m.fixed_step
    assert "taylor" in methods.ADAPTIVE


@pytest.mark.slow
def test_a_scene_with_only_the_taylor_method(tmp_path: Path, cache_dir: Path) -> None:
    """Its lanes define their own sin and cos (no pair's rhs_lanes brings
    them), it compiles under generate's strict check, its batch equals its
    single calls, and auto picks it rather than scipy."""

    data = load("torque_free").model_dump()
    data.update(name="only_taylor", integrators=["taylor"])
    scene = Scene.model_validate(data)
    write_sources(scene, tmp_path / "src")
    mp = pytest.MonkeyPatch()
    mp.setenv("GYROGEN_CACHE", str(cache_dir))
    try:
        b = build.build(tmp_path / "src", "c")
    finally:
        mp.undo()
    x0 = np.array(scene.initial_state())
    c = b.setup(np.zeros(0))
    xs = x0 + 0.01 * np.arange(3)[:, None]
    xb, _, codes = b.integrate_batch("taylor", xs, c, 0.0, 2.0, rtol=1e-10, atol=1e-10)
    for k in range(3):
        x, _, code = b.integrate("taylor", xs[k], c, 0.0, 2.0, rtol=1e-10, atol=1e-10)
        assert code == codes[k] == 0 and np.array_equal(x, xb[k])
    assert methods.pick(scene.integrators, stiff=False) == "taylor"


@pytest.mark.slow
def test_step_log2_and_exp2_against_glibc(source_dir: Path, tmp_path: Path) -> None:
    """The step size's branch-free log2 and exp2 (codegen/integrators/
    elementary.py) within their documented bounds of glibc's over their
    ranges (log2 5.7e-7 absolute, exact at powers of 2; exp2 1.1e-7
    relative, subnormal results within that plus 2^-1074), the bit helpers
    exact for every exponent, and the special values the step relies on:
    log2 of +inf is +inf, of 0 is -DBL_MAX, NaN stays NaN; exp2 is DBL_MAX
    past 1023, 0 below -1075."""
    import subprocess

    exe = tmp_path / "elementary"
    harness = Path(__file__).parent / "harness" / "elementary.c"
    subprocess.run(["gcc", "-std=c99", "-O2", f"-I{source_dir}", str(harness),
                    str(source_dir / "gyrostat.c"), "-o", str(exe), "-lm"], check=True)  # fmt: skip
    out = subprocess.run([str(exe), "200000"], check=True, capture_output=True, text=True)
    rows = {r[0]: r[1:] for r in map(str.split, out.stdout.splitlines())}
    assert float(rows["log2_abs"][0]) <= 5.7e-7 and float(rows["exp2_rel"][0]) <= 1.1e-7
    assert float(rows["exp2_subnormal"][0]) <= 1.0
    assert rows["bits_bad"] == ["0"] and rows["powers_bad"] == ["0"]
    assert rows["special"] == ["inf", "-1.79769e+308", "nan", "1.79769e+308", "0", "nan",
                               "1.79769e+308", "0"]  # fmt: skip
