"""`gyrogen generate` checks what it hands out: it compiles every target and
compares the rhs, the outputs and the Jacobian with the numpy reference
before writing; a failure names the scene and what differs, exits 1 and
writes nothing. And verify's bars hold correct code and catch wrong code."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from wide import WIDE

from gyrogen.codegen.generate import generate
from gyrogen.codegen.ir.c import CPrinter
from gyrogen.oracle import compare, scene_view
from gyrogen.runtime import build
from gyrogen.runtime.compiled import Compiled
from gyrogen.scene import builtin_text, load


def test_generate_checks_before_it_writes(tmp_path: Path, cli) -> None:
    code, out, _ = cli(["generate", "wheel_spinup", "--out", str(tmp_path / "o")])
    assert code == 0
    assert "checked wheel_spinup: c, fortran compiled and compared with the reference in" in out
    assert (tmp_path / "o" / "manifest.json").is_file()


@pytest.mark.slow  # a second scene derived, compiled twice and checked; generate's check stays fast
@WIDE
def test_given_parameters_setup_refuses_are_left_out_of_the_check(tmp_path: Path, cli) -> None:
    """[simulate] parameters whose constants overflow (setup's code 9, which
    the validator cannot see): the code is still checked and written (at the
    random sets), where the check ended in a ValueError traceback."""
    scene = tmp_path / "overflow.toml"
    text = builtin_text("wheel_spinup")
    scene.write_text(text.replace("parameters = { T = 0.02 }", "parameters = { T = 1e308 }"))
    code, out, err = cli(["generate", str(scene), "--out", str(tmp_path / "o")])
    assert code == 0 and "Traceback" not in err, err
    assert "checked wheel_spinup: c, fortran compiled and compared" in out


def test_no_check_skips_the_check(tmp_path: Path, cli) -> None:
    code, out, _ = cli(["generate", "torque_free", "--no-check", "--out", str(tmp_path)])
    assert code == 0 and "checked" not in out and (tmp_path / "manifest.json").is_file()


@pytest.mark.slow
@WIDE
def test_wrong_code_is_not_written(tmp_path: Path, cli, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every C double one part in 1e9 off: C differs from the reference and
    from the (right) Fortran; nothing is written."""
    real = CPrinter.number

    def off(self: CPrinter, value: float) -> str:
        return real(self, value * (1 + 1e-9))

    monkeypatch.setattr(CPrinter, "number", off)
    out = tmp_path / "o"
    code, _, err = cli(["generate", "wheel_spinup", "--out", str(out)])
    assert code == 1, err
    assert err.startswith("gyrogen: error: wheel_spinup: the generated code differs from the ")
    assert "from the reference: C vs " in err and err.count("\n") == 1
    assert not out.exists()


def test_code_that_does_not_compile_is_not_written(
    tmp_path: Path, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    from gyrogen.codegen.backends import c

    real = c.files

    def broken(unit):  # type: ignore[no-untyped-def]
        files = real(unit)
        files[f"{unit.prefix}.c"] += "\nint broken(void) { return undeclared; }\n"
        return files

    monkeypatch.setattr(c, "files", broken)
    out = tmp_path / "o"
    code, _, err = cli(["generate", "torque_free", "--out", str(out)])
    assert code == 1
    assert err.startswith("gyrogen: error: torque_free: generated code that does not compile:")
    assert "undeclared" in err
    assert not out.exists()


@pytest.fixture(scope="module")
def controlled(tmp_path_factory: pytest.TempPathFactory) -> tuple[Compiled, object]:
    scene = load("speed_controlled")
    src = tmp_path_factory.mktemp("speed_controlled")
    generate(scene, src)
    return build.build(src, "c"), scene


@pytest.mark.slow
def test_size_scaled_bar_holds_correct_code_where_terms_cancel(controlled) -> None:  # type: ignore[no-untyped-def]
    """The speed controller's slip u4 - u2 - w_ref near zero: a plain
    relative error is large for correct code; scaled by the sizes, small."""
    comp, scene = controlled
    p = np.array([8.0, 199.0])  # k, w_ref
    x = np.zeros((50, comp.nx))
    idx = {s: i for i, s in enumerate(scene.states)}
    x[:, idx["u2"]] = np.linspace(-5, 5, 50)
    x[:, idx["u4"]] = 199.0 + x[:, idx["u2"]] + np.linspace(-1e-9, 1e-9, 50)  # slip ~ 1e-9
    ref = scene_view.rhs(scene, x, p)
    got = comp.rhs(x, comp.setup(p))
    f = lambda xs, q: scene_view.rhs(scene, xs, q)  # noqa: E731
    assert compare.size_scaled_error(got, ref, f, x, p) < compare.TOLERANCE
    # and a real error of one part in 1e9 is caught whatever the sizes
    wrong = got.copy()
    wrong[:, idx["u1"]] += 1e-9 * (1 + np.abs(ref[:, idx["u1"]]))
    assert compare.size_scaled_error(wrong, ref, f, x, p) > 100 * compare.TOLERANCE


def test_jacobian_error_catches_a_wrong_entry(controlled) -> None:  # type: ignore[no-untyped-def]
    comp, scene = controlled
    p = np.array([0.5, 30.0])
    rng = np.random.default_rng(2)
    x = scene_view.random_states(scene, rng, 20)
    c = comp.setup(p)
    jac = np.array([comp.jacobian(xi, c) for xi in x])
    assert np.array_equal(comp.jacobians(x, c), jac)  # the check's one call: the same numbers
    with pytest.raises(ValueError, match=r"states must have shape \(n, 8\)"):
        comp.jacobians(x[0], c)
    f = lambda xs, q: scene_view.rhs(scene, xs, q)  # noqa: E731
    assert compare.jacobian_error(jac, f, x, p) < 1e-7
    jac[:, 5, 6] *= 1.001
    assert compare.jacobian_error(jac, f, x, p) > compare.JAC_TOLERANCE


def test_the_pairs_of_a_function_measure_each_rows_term_sizes_once() -> None:
    """TermSizes: a row two comparisons find suspect is measured once (f
    evaluated at it, its nx moved states and np moved parameters: three
    calls), and each comparison's error is what it is measured alone."""
    seen: list[int] = []

    def f(xs: np.ndarray, q: np.ndarray) -> np.ndarray:
        seen.append(len(xs))
        return np.column_stack([xs[:, 0] * q[0] - xs[:, 1], xs[:, 1] ** 2])

    x = np.random.default_rng(3).normal(size=(40, 2))
    p = np.array([1.5])
    ref = f(x, p)
    a, b = ref * (1 + 1e-13), ref * (1 - 1e-13)  # rows suspect in both pairs
    alone = [compare.size_scaled_error(v, ref, f, x, p) for v in (a, b)]
    seen.clear()
    sizes = compare.TermSizes(f, x, p)
    shared = [compare.size_scaled_error(v, ref, f, x, p, sizes) for v in (a, b)]
    k = seen[0]  # the suspect rows: f at them, at each moved state, at each moved parameter
    assert shared == alone and seen == [k, 2 * k, k] and k > 30


def test_term_sizes_read_the_values_the_comparison_has() -> None:
    """Given f's values at every state (a comparison has them), TermSizes
    asks f only at the moved states and parameters, and measures the same S."""
    seen: list[int] = []

    def f(xs: np.ndarray, q: np.ndarray) -> np.ndarray:
        seen.append(len(xs))
        return np.column_stack([xs[:, 0] * q[0] - xs[:, 1], xs[:, 1] ** 2])

    x = np.random.default_rng(4).normal(size=(40, 2))
    p = np.array([1.5])
    ref = f(x, p)
    a = ref * (1 + 1e-13)  # every row suspect
    rows = np.arange(len(x))
    asked = compare.TermSizes(f, x, p).at(rows)
    seen.clear()
    given = compare.TermSizes(f, x, p, ref).at(rows)
    assert seen == [2 * len(x), len(x)]  # the moved states, the moved parameter
    assert np.array_equal(given, asked)
    assert compare.size_scaled_error(a, ref, f, x, p, compare.TermSizes(f, x, p, ref)) == (
        compare.size_scaled_error(a, ref, f, x, p)
    )
