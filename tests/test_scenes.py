"""Scenes: the file format, its errors, specialization, and every built-in
scene checked against the numpy reference in C and Fortran."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from sources import write_sources
from wide import WIDE

from gyrogen.abi_groups import MAX_START_ANGLE
from gyrogen.codegen.generate import generate
from gyrogen.commands import scenes as scenes_command
from gyrogen.errors import BuildError, SceneError
from gyrogen.limits import MAX_OUTPUT_POINTS, MAX_SCENE_BYTES
from gyrogen.oracle import scene_view
from gyrogen.oracle.compare import compare
from gyrogen.runtime import build
from gyrogen.scene import builtin_names, builtin_text, load, parse

GOOD = builtin_text("wheel_spinup")


def edit(old: str, new: str, text: str = GOOD) -> str:
    assert old in text, old
    return text.replace(old, new, 1)


def named(value: str) -> str:
    return edit('name = "wheel_spinup"', f'name = "{value}"')


def described(start: str) -> str:
    return edit('description = "', f'description = "{start}')


def simulating(line: str) -> str:
    return edit("[simulate]", f"[simulate]\n{line}")


def laned(value: str) -> str:
    return edit("[parameters]", f"lanes = {value}\n\n[parameters]")


FOLDED_SINGULAR = edit("I11 = ", "I11 = 1e-15 #")
for _old, _new in [
    ("I22 = 25.0", "I22 = 1e-15"), ("I33 = 18.0", "I33 = 1e-15"), ("I13 = 0.5", "I13 = 0.0"),
    ("I   = 0.01", "I = 1e-15"), ("J   = 0.015", "J = 1e-15"), ("l3  = 0.1", "l3 = 1.0"),
    ("l1  = 0.3", "l1 = 1.0"),
]:  # fmt: skip
    FOLDED_SINGULAR = FOLDED_SINGULAR.replace(_old, _new)
HUGE_MOMENTS = edit(
    "parameters = { T = 0.02 }",
    "parameters = { T = 0.02, I11 = 1.7e308, I33 = 1.7e308 }",
    edit("I11 = 20.0", 'I11 = "runtime"', edit("I33 = 18.0", 'I33 = "runtime"')),
)
NESTED = "a = " + "[" * 5000 + "]" * 5000
CONTROLLED = edit('torque = "constant"', 'torque = "speed_controller"')
TABLED = edit('T   = "runtime"   # N m\n', "", edit('torque = "constant"', 'torque = "table"'))
# Expected messages too long for a row of BAD:
HUGE_INT = "100000... (401 digits) is out of range"  # not "not a finite number", every digit
DOUBLE = "a double holds at most 1.8e308"
DIGITS_4300 = "invalid TOML: an integer of more than 4300 digits"  # a ValueError traceback
NOT_DEFINITE = "carrier inertia is not positive definite"
NUL_AT_1 = "description: control character U+0000 at position 1"
NOT_A_NUMBER = 'parameters.m_a: expected a number or "runtime", not True'
NOT_A_FLAG = "effects.rotor_angle: Input should be a valid boolean"
STEPS = "simulate.dt: t_end/dt = "
LIMIT = "more than the limit of 1,000,000: raise dt or lower t_end"
TINY_DT = f"{STEPS}60 s/1e-300 s is 6e+301 output steps, {LIMIT}"
HUGE_T_END = f"{STEPS}1e+300 s/0.05 s is 2e+301 output steps"
JUST_OVER = f"{STEPS}50000.1 s/0.05 s is 1000001 output steps, more than the limit"
LONGER = "simulate.dt: output step 61 s is longer than the span 60 s"
SUBNORMAL_DT = edit("t_end = 60.0", "t_end = 5e-324", edit("dt = 0.05", "dt = 5e-324"))
SHORTER = "simulate.dt: output step 4.94066e-324 s is shorter than 1e-300 s"
# the generated setup's arithmetic overflows to a NaN condition number: code 7
OVERFLOW = "parameters: the mass matrix's coupled block has condition number nan > 1e+13"
FOLDED_RANGE = "a folded value must be 0 or of magnitude 1e-50 to 1e+50"

BAD = [
    # (case, scene text, a part of the message), rows of one form kept together
    ("unknown key", edit("[effects]", "[effects]\nwobble = true"), "effects.wobble: unknown key"),
    ("wrong type", edit("m_a = 150.0", 'm_a = "heavy"'), "parameters.m_a"),
    ("missing value", edit("I33 = 18.0\n", ""), "parameters: missing I33"),
    ("non-finite", edit("I22 = 25.0", "I22 = inf"), "parameters.I22"),
    ("nan", edit("l1  = 0.3", "l1 = nan"), "parameters.l1"),
    ("negative mass", edit("m_b = 3.0", "m_b = -3.0"), "parameters.m_b: must be positive"),
    ("zero J", edit("J   = 0.015", "J = 0.0"), "parameters.J: must be positive"),
    ("triangle", edit("I22 = 25.0", "I22 = 45.0"), "violate the triangle inequality"),
    ("rotor 2I < J", edit("J   = 0.015", "J = 0.05"), "parameters.J: rotor needs J <= 2 I"),
    ("number quoted", edit("m_a = 150.0", 'm_a = "150"'), "parameters.m_a: expected a number"),
    ("folded 1e308", edit("m_a = 150.0", "m_a = 1e308"), "parameters.m_a: 1e+308: a folded value"),
    ("folded 1e-60", edit("l1  = 0.3", "l1 = 1e-60"), "parameters.l1: 1e-60: a folded value"),
    ("flag as string", edit("rotor_angle = true", 'rotor_angle = "false"'), "effects.rotor_angle"),
    ("t_end as string", edit("t_end = ", 't_end = "5" #'), "simulate.t_end"),
    ("g unused", edit("T   = ", "g = 9.81\nT   = "), "parameters.g: gravity has no effect"),
    ("T unused", edit('torque = "constant"', 'torque = "none"'), "parameters.T: only used"),
    ("bad target", edit('targets = ["c", "fortran"]', 'targets = ["rust"]'), "targets.0"),
    ("no target", edit('targets = ["c", "fortran"]', "targets = []"), "targets"),
    ("attitude", edit('targets = ["c"', 'attitude = "rodrigues"\ntargets = ["c"'), "attitude"),
    ("initial", edit("initial = { u1", "initial = { u9 = 1.0, u1"), "u9 is not a state"),
    (
        "wound rotor angle",
        edit("initial = { u1", "initial = { q4 = 1e5, u1"),
        "simulate.initial.q4 = 100000 rad: more than 2607 turns (16384 rad), where a double "
        "holds the angle only to 7.3e-12 rad; give it modulo 2 pi",
    ),
    ("wound attitude", edit("initial = { u1", "initial = { q1 = -16385.0, u1"), "q1 = -16385 rad"),
    (
        "table T 1e300",
        edit('"table"', '"table"\ntorque_table = [[0, 0], [1, 1e300]]', TABLED),
        "effects: torque_table[1]: T = 1e+300 at t = 1: a folded value must be 0 or of magnitude",
    ),
    (
        "table T -1e-60",
        edit('"table"', '"table"\ntorque_table = [[0, 0], [2, -1e-60]]', TABLED),
        f"effects: torque_table[1]: T = -1e-60 at t = 2: {FOLDED_RANGE}",
    ),
    (
        "integer 10**400",
        edit("m_a = 150.0", f"m_a = {10**400}"),
        f"m_a: {HUGE_INT}: {FOLDED_RANGE}",
    ),
    ("integer t_end", edit("t_end = 60.0", f"t_end = {10**400}"), f"t_end: {HUGE_INT}: {DOUBLE}"),
    ("integer u1", edit("{ u1 = 0.01", f"{{ u1 = {-(10**400)}"), f"u1: -{HUGE_INT}: {DOUBLE}"),
    ("integer of 5001 digits", edit("m_a = 150.0", "m_a = 1" + "0" * 5000), DIGITS_4300),
    ("huge I11", edit("I11 = 20.0", "I11 = 1e308"), f"parameters.I11: 1e+308: {FOLDED_RANGE}"),
    ("not positive definite", edit("I13 = 0.5", "I13 = 30.0"), NOT_DEFINITE),
    ("number true", edit("m_a = 150.0", "m_a = true"), NOT_A_NUMBER),
    ("flag as number", edit("rotor_angle = true", "rotor_angle = 1"), NOT_A_FLAG),
    ("tiny dt", edit("dt = 0.05", "dt = 1e-300"), TINY_DT),
    ("dt longer than t_end", edit("dt = 0.05", "dt = 61.0"), LONGER),
    ("dt subnormal", SUBNORMAL_DT, SHORTER),
    (
        "dt just under 1e-300",
        edit("t_end = 60.0", "t_end = 1e-300", edit("dt = 0.05", "dt = 9e-301")),
        "shorter than 1e-300 s",
    ),
    ("huge t_end", edit("t_end = 60.0", "t_end = 1e300"), HUGE_T_END),
    ("just over the point limit", edit("t_end = 60.0", "t_end = 50000.05"), JUST_OVER),
    ("folded singular", FOLDED_SINGULAR, "condition number"),
    ("controller needs k", CONTROLLED, "parameters: missing k, w_ref"),
    ("nested too deeply", NESTED, "invalid TOML: arrays or tables nested too deeply"),
    ("moments overflow", HUGE_MOMENTS, OVERFLOW),
    ("bad toml", "name = ", "invalid TOML"),
    ("bad name", named("2fast"), "name: '2fast' is not an identifier in C and Fortran"),
    ("name _x", named("_x"), "name: '_x' is not an identifier"),
    ("name a__b", named("a__b"), "double or trailing underscore"),
    ("name a_", named("a_"), "double or trailing underscore"),
    ("name empty", named(""), "name: must not be empty"),
    ("name non-ASCII", named("r\u00f6tor"), "not an identifier"),
    ("C keyword", named("double"), "is a C keyword"),
    ("C header", named("math"), "names a C library header (<math.h>)"),
    ("C header, case", named("StdInt"), "names a C library header (<stdint.h>)"),
    ("OpenMP header", named("omp"), "the scene's omp.h would hide it"),
    ("FMI header", named("fmi2Functions"), "names an FMI header (fmi2Functions.h)"),
    ("FMI header, case", named("FMI2typesplatform"), "an FMI header (fmi2TypesPlatform.h)"),
    ("description escape", described("\\u001b[31m"), "description: control character U+001B"),
    ("rtol no double meets", simulating("rtol = 1e-20"), "simulate.rtol: must be above 2.22e-15"),
    ("rtol at the bound", simulating("rtol = 2.220446049250313e-15"), "simulate.rtol"),
    ("name 33 characters", named("a" * 33), "is longer than 32 characters"),
    ("name 300 characters", named("b" * 300), "... (300 characters) is longer than 32"),
    ("description too long", described("x" * 2001), "description: 2"),
    ("description NUL", described("a\\u0000b "), NUL_AT_1),
    (
        "description bidi",
        described("\\u202e hostile */"),
        "description: bidirectional control U+202E",
    ),
    ("description isolate", described("ok \\u2066x"), "description: bidirectional control U+2066"),
    ("lanes always", laned('["dop853"]'), "lanes: [0] 'dop853': its batch always runs over lanes"),
    ("lanes none", laned('["rk4"]'), "lanes: [0] 'rk4': its batch has no lanes; only radau5 can"),
    ("lanes unknown", laned('["radau6"]'), "lanes: [0] 'radau6': not one of rk4, dopri5"),
    ("lanes twice", laned('["radau5", "radau5"]'), "lanes: list each integrator once"),
    ("lanes not a list", laned('"radau5"'), "lanes: Input should be a valid list"),
    (
        "lanes not integrated",
        laned('["radau5"]\nintegrators = ["dop853"]'),
        "lanes: radau5 is not among this scene's integrators",
    ),
]


@pytest.mark.parametrize(("case", "text", "message"), BAD, ids=[b[0] for b in BAD])
def test_bad_scene_is_one_line_exit_2_nothing_written(
    case: str, text: str, message: str, tmp_path: Path, cli
) -> None:
    path = tmp_path / "scene.toml"
    path.write_text(text)
    out = tmp_path / "out"
    code, stdout, err = cli(["generate", str(path), "--out", str(out)])
    assert code == 2, (case, err)
    assert err.count("\n") == 1 and err.startswith(f"gyrogen: error: {path}: ")
    assert message in err, err
    assert not out.exists() and stdout == ""


def test_lanes_asked_for_are_kept_and_none_leave_the_dump_as_before() -> None:
    """radau5's lanes asked for: in the scene and its dump (its build id);
    not asked for: no `lanes` key in the dump, the build id of before."""
    scene = parse(laned('["radau5"]'), "laned")
    assert scene.lanes == ["radau5"] and scene.model_dump()["lanes"] == ["radau5"]
    assert "lanes" not in parse(GOOD, "plain").model_dump()


def test_a_start_angle_at_the_bound_is_accepted() -> None:
    """abi_groups.MAX_START_ANGLE itself, either way."""
    text = edit("initial = { u1", "initial = { q4 = 16384.0, q3 = -16384.0, u1")
    assert parse(text, "x.toml").simulate.initial["q4"] == MAX_START_ANGLE


def test_output_points_at_the_limit_are_accepted() -> None:
    scene = parse(edit("t_end = 60.0", "t_end = 50000.0"), "x.toml")
    assert scene.simulate.t_end / scene.simulate.dt == MAX_OUTPUT_POINTS


def _directory(path: Path) -> None:
    path.mkdir()


def _fifo(path: Path) -> None:
    os.mkfifo(path)


def _huge(path: Path) -> None:
    path.write_text(GOOD + "#" * MAX_SCENE_BYTES)


def _latin1(path: Path) -> None:
    path.write_bytes(GOOD.replace("reaction wheel", "r\u00e9action wheel").encode("latin-1"))


UNREADABLE = [
    (_directory, "is a directory, not a scene file"),
    (_fifo, "is a device, FIFO or socket, not a scene file"),  # refused, not waited on
    (_huge, "more than 1,048,576 bytes, the limit for a scene file"),
    (_latin1, "cannot read: not UTF-8 (invalid continuation byte at byte 5)"),
]


@pytest.mark.parametrize(("make", "why"), UNREADABLE, ids=[u[0].__name__ for u in UNREADABLE])
def test_unreadable_scene_file_is_one_line_exit_2(
    make: Callable[[Path], None], why: str, tmp_path: Path, cli
) -> None:
    path = tmp_path / "scene.toml"
    make(path)
    code, out, err = cli(["generate", str(path), "--out", str(tmp_path / "out")])
    assert (code, out, err) == (2, "", f"gyrogen: error: {path}: {why}\n")
    assert not (tmp_path / "out").exists()


def test_scene_of_exactly_the_size_limit_is_read(tmp_path: Path) -> None:
    path = tmp_path / "scene.toml"
    path.write_text(GOOD + "#" * (MAX_SCENE_BYTES - len(GOOD.encode()) - 1) + "\n")
    assert path.stat().st_size == MAX_SCENE_BYTES
    assert load(str(path)).name == "wheel_spinup"


def test_a_byte_order_mark_is_dropped(tmp_path: Path, cli) -> None:
    """A scene (and a sweep file, read the same way) saved with a UTF-8 BOM is
    read (tomllib said "Invalid statement (at line 1, column 1)")."""
    path = tmp_path / "scene.toml"
    path.write_bytes(b"\xef\xbb\xbf" + GOOD.encode())
    assert load(str(path)) == parse(GOOD, "x.toml")
    code, _, err = cli(["generate", str(path), "--no-check", "--out", str(tmp_path / "o")])
    assert code == 0, err


def test_table_torque_needs_increasing_times() -> None:
    text = edit('torque = "constant"', 'torque = "table"\ntorque_table = [[0.0, 1.0], [0.0, 2.0]]')
    with pytest.raises(SceneError, match="torque_table times must increase"):
        parse(edit('T   = "runtime"   # N m\n', "", text), "x.toml")


def test_unknown_scene_name_lists_the_builtins(cli) -> None:
    code, _, err = cli(["generate", "no_such_scene"])
    assert code == 2 and "no such file, and no built-in scene" in err and "dual_spin" in err


def test_builtin_scenes_listed(cli) -> None:
    code, out, _ = cli(["scenes"])
    assert code == 0
    for name in builtin_names():
        assert name in out
    assert set(builtin_names()) >= {
        "gyrostat", "dual_spin", "torque_free", "wheel_spinup", "speed_controlled"
    }  # fmt: skip
    assert "runtime m_a, m_b, I11" in out and "integrators rk4, dopri5, dop853, rodas4" in out
    assert "ops setup" not in out  # listing does not derive


@pytest.mark.slow
@pytest.mark.parametrize("every", [False, pytest.param(True, marks=WIDE)], ids=["two", "every"])
def test_builtin_scenes_with_their_op_counts(
    every: bool, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`scenes --ops` derives each listed scene for its counts: the suite
    lists torque_free and gyrostat, `make test-wide` every built-in scene."""
    if not every:
        monkeypatch.setattr(scenes_command, "builtin_names", lambda: ("gyrostat", "torque_free"))
    code, out, _ = cli(["scenes", "--ops"])
    listed = builtin_names() if every else ("gyrostat", "torque_free")
    assert code == 0 and out.count("ops setup") == len(listed)
    assert "torque_free" in out and "ops setup 0, rhs 19" in out


def test_new_writes_a_valid_commented_scene(tmp_path: Path, cli) -> None:
    target = tmp_path / "my_sat.toml"
    code, out, _ = cli(["new", "my_sat", "--out", str(target)])
    assert code == 0 and "wrote" in out
    text = target.read_text()
    assert text.count("#") > 20
    assert load(str(target)).name == "my_sat"
    code, _, err = cli(["new", "my_sat", "--out", str(target)])
    assert code == 1 and "exists" in err
    code, _, err = cli(["new", "2bad", "--out", str(tmp_path / "x.toml")])
    assert code == 2 and "not a valid scene name" in err
    for bad, why in (("x" * 300, "longer than 32 characters"), ("a__b", "double or trailing")):
        code, out, err = cli(["new", bad, "--out", str(tmp_path / "y.toml")])
        assert (code, out) == (2, "") and err.count("\n") == 1 and why in err, err
    code, out, err = cli(["new", "ok", "--out", str(tmp_path / ("y" * 300 + ".toml"))])
    assert (code, out) == (1, "") and err.endswith(": File name too long\n"), err


def test_specialization_drops_states_and_parameters(tmp_path: Path) -> None:
    unit = generate(load("torque_free"), tmp_path)
    m = json.loads((tmp_path / "manifest.json").read_text())
    assert m["states"] == ["q1", "q2", "q3", "u1", "u2", "u3", "u4"]
    assert m["parameters"] == [] and m["nc"] == 1  # the condition number only
    assert m["full_model"]["nx"] == 14 and m["full_model"]["ops"]["rhs"] == unit.ops["rhs"] + 21
    h = (tmp_path / "torque_free.h").read_text()
    assert "#define TORQUE_FREE_NX 7" in h and "#define TORQUE_FREE_NP 0" in h


def test_torque_free_principal_scene_meets_the_op_goal() -> None:
    """Torque-free, no translation, principal axes, every value folded: at
    most 20 ops in rhs (trig calls included here, so stricter than asked)."""
    from gyrogen.codegen.context import make_context

    assert make_context(load("torque_free")).ops["rhs"] <= 20


@pytest.mark.slow
def test_c_only_scene_builds_no_fortran(tmp_path: Path) -> None:
    scene = parse(edit('targets = ["c", "fortran"]', 'targets = ["c"]'), "c_only.toml")
    write_sources(scene, tmp_path)
    assert not list(tmp_path.glob("*.f90"))
    with pytest.raises(BuildError, match="has no fortran target"):
        build.build(tmp_path, "fortran")


@pytest.mark.slow
@pytest.mark.parametrize("name", builtin_names())
@WIDE
def test_builtin_scene_matches_the_reference(name: str, tmp_path: Path) -> None:
    scene = load(name)
    write_sources(scene, tmp_path)
    backends = [build.build(tmp_path, lang) for lang in scene.targets]
    report = compare(backends, scene, n_states=500, n_params=5, n_ill=2, seed=3)
    assert report.passed, [r for r in report.rows if not r.passed] + report.refusal_failures
    pairs = {r.pair for r in report.rows}
    assert "C vs reference" in pairs and "Fortran vs reference" in pairs
    for out in ("kinetic_energy", "angular_momentum", "power"):
        if getattr(scene.outputs, out):
            assert f"C vs reference {out}" in pairs


def test_table_torque_scene_matches_the_reference(tmp_path: Path) -> None:
    text = edit(
        'torque = "constant"',
        'torque = "table"\ntorque_table = [[0.0, 0.0], [1.0, 0.05], [4.0, 0.05], [5.0, -0.02]]',
    )
    scene = parse(
        edit('T   = "runtime"   # N m\n', "", text).replace("parameters = { T = 0.02 }", ""), "t"
    )
    write_sources(scene, tmp_path)
    backends = [build.build(tmp_path, lang) for lang in scene.targets]
    report = compare(backends, scene, n_states=300, n_params=1, n_ill=0, seed=4)
    assert report.passed, report.rows
    c = backends[0]
    k = c.setup(np.zeros(0))  # the constants (none at run time: the parameters are empty)
    x = np.zeros((1, len(scene.states)))
    x[0, scene.states.index("u4")] = 1.0
    for t, torque in [(-1.0, 0.0), (0.5, 0.025), (2.0, 0.05), (4.5, 0.015), (9.0, -0.02)]:
        du4 = c.rhs(x, k, t)[0, scene.states.index("u4")]
        assert du4 == pytest.approx(torque / 0.015, rel=1e-12, abs=1e-15)
    np.testing.assert_allclose(
        c.rhs(x, k, 2.5), scene_view.rhs(scene, x, np.zeros(0), 2.5), rtol=1e-13
    )


FOLDED_MASSES = """
name = "folded_masses"
description = "masses and rotor folded, carrier inertias and l3 at run time"
[parameters]
m_a = 100.0
m_b = 5.0
I11 = "runtime"
I22 = "runtime"
I33 = "runtime"
I13 = "runtime"
I   = 0.02
J   = 0.03
l1  = 0.2
l3  = "runtime"
T = 0.01
[effects]
translation = false
[simulate]
parameters = { I11 = 12.0, I22 = 9.0, I33 = 15.0, I13 = 0.8, l3 = -0.1 }
"""


def test_folded_masses_scene_matches_the_reference(tmp_path: Path) -> None:
    """The reduced mass is a number here: setup multiplies the lumped sums out
    in exact rationals, and both languages take the literals."""
    scene = parse(FOLDED_MASSES, "folded_masses.toml")
    write_sources(scene, tmp_path)
    backends = [build.build(tmp_path, lang) for lang in scene.targets]
    report = compare(backends, scene, n_states=300, n_params=3, n_ill=1, seed=5)
    assert report.passed, [r for r in report.rows if not r.passed] + report.refusal_failures
