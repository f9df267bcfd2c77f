"""Scene text is data: a description reaches the generated files only inside
comments, escaped for each target, and a name is an identifier in every
target with every suffix gyrogen appends; headers say what the scene is."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from wide import WIDE

from gyrogen.abi import NAME_MAX_LENGTH
from gyrogen.codegen.generate import generate
from gyrogen.codegen.render import c_comment, f_comment, hash_comment, sentence
from gyrogen.runtime.flags import C_STRICT, C_WARNINGS, FORTRAN_STRICT
from gyrogen.scene import builtin_text, load, parse

HOSTILE = (
    "ends the comment */\n#error injected\n/* nests ??/\ntrigraphs ??= ??) ??!\n"
    "trailing backslash \\\n\ttab, and a word " + "w" * 150 + "\n\n"
    "add_subdirectory(evil)\nunicode d\u00e9j\u00e0 vu \u6f22\u5b57"
)
C_FLAGS = ["-O2", *C_STRICT]


def hostile_scene(name: str, attitude: str) -> str:
    text = builtin_text("wheel_spinup").replace('name = "wheel_spinup"', f'name = "{name}"')
    text = text.replace(
        'targets = ["c", "fortran"]', f'targets = ["c", "fortran"]\nattitude = "{attitude}"'
    )
    description = HOSTILE.replace("\\", "\\\\").replace("\n", "\\n").replace("\t", "\\t")
    return text.replace(
        'description = "reaction wheel spin-up under a constant motor torque (T at run time)"',
        f'description = "{description}"',
    )


def test_comment_filters_escape_what_each_syntax_reads() -> None:
    c = c_comment(HOSTILE)
    assert "*/" not in c and "/*" not in c and "??" not in c
    assert "\n * #error injected" in c and "\n *\n" in c  # a blank line stays a paragraph break
    assert all(line.startswith(" * ") or line == " *" for line in c.split("\n")[1:])
    f = f_comment(HOSTILE)
    assert all(line.startswith("!") for line in f.split("\n")[1:])
    h = hash_comment(HOSTILE)
    assert all(line.startswith("#") for line in h.split("\n")[1:])
    assert max(len(line) for line in c.split("\n")) <= 80


def test_a_description_ends_in_one_full_stop() -> None:
    """The files' opening sentence: a full stop added unless the text has one."""
    assert sentence("a wheel") == "a wheel." and sentence("a wheel.\n") == "a wheel."
    assert sentence("spins?") == "spins?" and sentence("") == ""


@pytest.mark.slow
@pytest.mark.parametrize("attitude", ["euler312", "quaternion"])
@WIDE
def test_hostile_text_and_longest_name_compile_cleanly(tmp_path: Path, attitude: str) -> None:
    name = "N" + "a1_" * ((NAME_MAX_LENGTH - 1) // 3)
    name = name[:NAME_MAX_LENGTH].rstrip("_")
    scene = parse(hostile_scene(name, attitude), "hostile.toml")
    generate(scene, tmp_path, lib=True)
    for cc in ("gcc", "clang"):
        for src in (f"{name}.c", f"{name}_ode.c"):
            subprocess.run([cc, *C_FLAGS, "-c", src, "-o", "x.o"], cwd=tmp_path,
                           check=True, capture_output=True)  # fmt: skip
    subprocess.run(["g++", "-x", "c++", *C_WARNINGS, "-fsyntax-only",
                    f"{name}_ode.h"], cwd=tmp_path, check=True, capture_output=True)  # fmt: skip
    subprocess.run(["gfortran", *FORTRAN_STRICT, "-c",
                    f"{name}.f90", f"{name}_ode.f90"], cwd=tmp_path, check=True,
                   capture_output=True)  # fmt: skip
    for f in tmp_path.glob("*.f90"):
        assert max(len(line) for line in f.read_text().splitlines()) <= 132, f.name
    header = (tmp_path / f"{name}.h").read_text()
    assert header.count("*/") == header.count("/*")  # no comment ended early
    assert "#error" not in [line.strip() for line in header.splitlines()]
    cmake = (tmp_path / "CMakeLists.txt").read_text()
    assert "\nadd_subdirectory(evil)" not in cmake and "# add_subdirectory(evil)" in cmake


@pytest.mark.slow
def test_headers_say_which_attitude(tmp_path: Path) -> None:
    generate(load("gyrostat"), tmp_path / "angles")
    h = (tmp_path / "angles" / "gyrostat.h").read_text()
    assert "3-1-2 Euler angles x[0..2]: singular at cos(q2) = 0" in h
    assert "Translation: the mass center AB* moves under gravity" in h
    f = (tmp_path / "angles" / "gyrostat.f90").read_text()
    assert "3-1-2 angles x(1:3): singular at" in f
    quat = parse(hostile_scene("quat", "quaternion"), "quat.toml")
    generate(quat, tmp_path / "quat")
    h = (tmp_path / "quat" / "quat.h").read_text()
    assert "Euler parameters x[0..3]: no singularity" in h and "cos(q2)" not in h
    assert "Motor torque T, constant" in h and "No translation" in h
    f = (tmp_path / "quat" / "quat.f90").read_text()
    assert "Euler parameters x(1:4): no" in f and "cos(q2)" not in f


QUATERNION = builtin_text("wheel_spinup").replace(
    'targets = ["c", "fortran"]', 'targets = ["c", "fortran"]\nattitude = "quaternion"'
)


@pytest.mark.parametrize(
    ("start", "message"),
    [
        ("e0 = 0.0, e1 = 0.0, e2 = 0.0, e3 = 0.0", "e0..e3 are all zero"),
        ("e0 = 2.0", "has norm 2, not 1"),
        ("e0 = 0.7071, e1 = 0.7071", "has norm 0.99999"),
        ("e1 = 0.5", "has norm 1.11803399"),
        ("e0 = 1e-200", r"has norm 1e-200, not 1"),  # its square underflowed: "all zero"
        ("e0 = 1e200", r"has norm 1e\+200, not 1"),
    ],
)
def test_quaternion_start_must_be_a_unit_quaternion(start: str, message: str) -> None:
    text = QUATERNION.replace("initial = { u1 = 0.01", f"initial = {{ {start}, u1 = 0.01")
    with pytest.raises(Exception, match=message):
        parse(text, "q.toml")


@pytest.mark.parametrize(
    ("point", "message"),
    [("e0 = 0.0", "equilibrium: e0..e3 are all zero"), ("e0 = 2.0", "equilibrium: e0..e3 = ")],
)
def test_quaternion_equilibrium_must_be_a_unit_quaternion(point: str, message: str) -> None:
    """The point `gyrogen linearize` takes from the scene is held to the
    start's rule (it was linearized about as given)."""
    at = 'attitude = "quaternion"'
    with pytest.raises(Exception, match=message):
        parse(QUATERNION.replace(at, f"{at}\nequilibrium = {{ {point} }}"), "q.toml")
    assert parse(QUATERNION.replace(at, f"{at}\nequilibrium = {{ e0 = 1.0 }}"), "q.toml")


def test_a_nearly_unit_quaternion_start_is_normalized() -> None:
    text = QUATERNION.replace(
        "initial = { u1 = 0.01", "initial = { e0 = 0.70710678, e1 = 0.70710678, u1 = 0.01"
    )
    scene = parse(text, "q.toml")
    e = scene.initial_state()[:4]
    assert sum(v * v for v in e) == pytest.approx(1.0, abs=4.5e-16)
    assert e[0] == e[1] and e[2] == e[3] == 0.0
