"""The scene space: a hypothesis strategy that draws whole scene files as a
user could write them, and the check every drawn scene must pass.

A draw is TOML text: any split of the parameters into folded and runtime
(folded values as 0, 1, 0.5, short or long decimals, integers, across about
1e-6..1e6 through a random unit scale; one draw in four a runtime diagonal
moment beside a negative folded product of inertia and position), every
effect and torque law (tables of random points), both attitudes, any
outputs, integrators and targets, and names and descriptions of any length
and character. Some draws are invalid on purpose (a bad name or
description, a non-physical parameter set).

The check: the scene validator accepts exactly the valid draws (its verdict
is predicted independently: a regular expression for names, the numpy
mirror of setup's checks, sampling.setup_code, for the parameters). Each
valid scene is generated and compiled by gcc and clang (C99, -Werror) and
gfortran (-std=f2008 -Werror), its rhs, outputs and Jacobian are compared
with the numpy reference (compare.compare, setup's refusal codes included),
every Fortran line fits in 132 columns, and each of its integrators follows
scipy's DOP853 on the reference for a short span.
"""

from __future__ import annotations

import hashlib
import itertools
import math
import re
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, Phase, given, seed, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from gyrogen import methods
from gyrogen.abi import DESCRIPTION_MAX_LENGTH, NAME_MAX_LENGTH, PARAMETERS
from gyrogen.codegen.generate import render_all, unit_of
from gyrogen.errors import SceneError
from gyrogen.files import write_atomic
from gyrogen.oracle import compare, sampling, scene_view
from gyrogen.runtime import build
from gyrogen.runtime.compiled import Compiled
from gyrogen.runtime.flags import C_WARNINGS
from gyrogen.scene import Scene, parse

INTEGRATORS = methods.NAMES
TORQUES = ("none", "constant", "speed_controller", "table")
C_KEYWORDS = {"auto", "break", "case", "char", "const", "continue", "default", "do", "double",
              "else", "enum", "extern", "float", "for", "goto", "if", "inline", "int", "long",
              "register", "restrict", "return", "short", "signed", "sizeof", "static", "struct",
              "switch", "typedef", "union", "unsigned", "void", "volatile", "while"}  # fmt: skip
NAME = re.compile(r"[A-Za-z](?:[A-Za-z0-9]|_(?=[A-Za-z0-9]))*")
"""A valid scene name, written independently of scene.check_name."""
C_STRICT = ["-std=c99", "-O2", *C_WARNINGS, "-fsyntax-only"]
"""clang's warnings come from its front end: checked without its code
generation (-O2 kept for what the headers see: __OPTIMIZE__), 0.1 s a file
instead of 8 s for the default scene's integrators."""


@dataclass(frozen=True)
class Draw:
    text: str
    valid: bool
    """What the validator must say."""
    why: str
    """Why it is invalid (for a failure message)."""


def toml_string(s: str) -> str:
    """A TOML basic string holding s exactly."""
    out = []
    for ch in s:
        if ch in '"\\':
            out.append("\\" + ch)
        elif ord(ch) < 32 or ord(ch) == 127:
            out.append(f"\\u{ord(ch):04X}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def toml_value(v: object) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return toml_string(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return "nan" if math.isnan(v) else repr(v)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    raise TypeError(v)


def to_toml(top: dict[str, object], tables: dict[str, dict[str, object]]) -> str:
    lines = [f"{k} = {toml_value(v)}" for k, v in top.items()]
    for name, table in tables.items():
        lines += ["", f"[{name}]"]
        for k, v in table.items():
            if isinstance(v, dict):
                body = ", ".join(f"{kk} = {toml_value(vv)}" for kk, vv in v.items())
                lines.append(f"{k} = {{ {body} }}")
            else:
                lines.append(f"{k} = {toml_value(v)}")
    return "\n".join(lines) + "\n"


def name_is_valid(name: str) -> bool:
    return (
        0 < len(name) <= NAME_MAX_LENGTH
        and name.isascii()
        and NAME.fullmatch(name) is not None
        and name not in C_KEYWORDS
    )


def description_is_valid(text: str) -> bool:
    text = text.replace("\r\n", "\n")
    bad = any(c not in "\n\t" and (ord(c) < 32 or 127 <= ord(c) < 160) for c in text)
    not_xml = any(c in "\ufffe\uffff" or "\ud800" <= c <= "\udfff" for c in text)  # XML 1.0's Char
    return len(text) <= DESCRIPTION_MAX_LENGTH and not bad and not not_xml


def _mostly(
    valid: st.SearchStrategy[str], *others: st.SearchStrategy[str]
) -> st.SearchStrategy[str]:
    """valid about four times in five, else one of the others (mostly invalid)."""
    return st.sampled_from([valid] * 12 + list(others)).flatmap(lambda s: s)


names = _mostly(
    st.from_regex(NAME, fullmatch=True).map(lambda s: s[:NAME_MAX_LENGTH].rstrip("_")),
    st.sampled_from(["gyrogen", "x", "main", "sin", "c", "p", "t", "I", "J", "mod", "MixedCase",
                     "double", "a" * NAME_MAX_LENGTH, "a" * (NAME_MAX_LENGTH + 1)]),
    st.text(max_size=40),
    st.text(alphabet="ab_", min_size=25, max_size=70),
)  # fmt: skip
descriptions = _mostly(
    st.text(
        alphabet=st.characters(exclude_categories=("Cs", "Cc"), include_characters="\n\t"),
        max_size=300,
    ),
    st.sampled_from(
        ["", "*/ #error x", "a\n\nb", "??/\n\\", "/* c */", "\t", "x" * 2001, "a\ufffeb", "\uffff"]
    ),
    st.text(alphabet="*/?\\#!&\n\t $\"'", max_size=300),
    st.text(max_size=200),
)


def _written(v: float, style: str) -> float | int:
    """v as the user writes it: as drawn, rounded to a few or many digits,
    or an integer when it is one."""
    if style == "short":
        return float(f"{v:.3g}")
    if style == "long":
        return float(f"{v:.17g}")
    if style == "int" and math.isfinite(v) and v == int(v) and abs(v) < 2**53:
        return int(v)
    return float(v)


@st.composite
def parameter_values(draw: st.DrawFn, names_: tuple[str, ...]) -> dict[str, float | int]:
    """Values for the named parameters (PARAMETERS order, then k, w_ref): a
    physical set in a random unit scale, and one time in twenty an invalid
    one. Proportions come from a numpy generator seeded by the draw
    (hypothesis's own integers lean to their bounds)."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    p = sampling.random_parameters(rng, 1)[0]
    mass, length = 10.0 ** rng.uniform(-3, 3), 10.0 ** rng.uniform(-2, 2)
    scale = {"m_a": mass, "m_b": mass, "l1": length, "l3": length, "g": length,
             "T": mass * length**2}  # fmt: skip
    for k in ("I11", "I22", "I33", "I13", "I", "J"):
        scale[k] = mass * length**2
    p = np.array([p[i] * scale[n] for i, n in enumerate(PARAMETERS)])
    if rng.random() < 0.05:  # an invalid set, as sampling knows them
        cases = sampling.invalid_parameters(p)
        p = cases[rng.integers(len(cases))][1]
    values = dict(zip(PARAMETERS, map(float, p), strict=True))
    values["k"] = 10.0 ** rng.uniform(-3, 3)
    values["w_ref"] = rng.uniform(-300, 300)
    for n, special in SPECIAL.items():
        if rng.random() < 0.1:
            values[n] = float(rng.choice(special))
    style = str(rng.choice(["as drawn", "short", "long", "int"]))
    return {n: _written(values[n], style) for n in names_}


SPECIAL = {n: [0.0, 1.0, 0.5] for n in ("I13", "l1", "l3", "g", "T", "w_ref")}
SPECIAL.update({n: [1.0, 0.5] for n in ("m_a", "m_b")})
"""Round values a user writes, where they keep the system physical."""


def _split_inertia(
    values: dict[str, float | int], runtime: set[str], diagonal: tuple[str, ...]
) -> None:
    """A runtime diagonal moment beside the folded product of inertia and
    rotor position, made negative (setup's checks then print a negative
    number after an operator). The tensor stays valid: -I13 is the carrier
    turned the other way."""
    runtime |= set(diagonal)
    runtime -= {"I13", "l1", "l3"}
    values.update({n: -values[n] for n in ("I13", "l1", "l3") if values[n] > 0})


TARGET_LISTS = st.permutations(["c", "fortran"]).flatmap(
    lambda t: st.integers(1, 2).map(lambda k: t[:k]))  # fmt: skip
INTEGRATOR_LISTS = st.permutations(INTEGRATORS).flatmap(
    lambda t: st.integers(0, len(t)).map(lambda k: t[:k]))  # fmt: skip


def offered(integrators: list[str], smooth: bool) -> list[str]:
    """A Taylor method only where the rhs is smooth: elsewhere the scene
    refuses it (test_taylor checks that refusal)."""
    return [m for m in integrators if smooth or not methods.get(m).taylor]


@st.composite
def scenes(draw: st.DrawFn) -> Draw:
    name, description = draw(names), draw(descriptions)
    translation, rotor_angle = draw(st.booleans()), draw(st.booleans())
    torque = draw(st.sampled_from(TORQUES))
    attitude = draw(st.sampled_from(["euler312", "quaternion"]))
    needed = ["m_a", "m_b", "I11", "I22", "I33", "I13", "I", "J", "l1", "l3"]
    needed += ["g"] if translation else []
    needed += {"constant": ["T"], "speed_controller": ["k", "w_ref"]}.get(torque, [])
    values = draw(parameter_values(tuple(needed)))
    runtime = {n for n in needed if draw(st.booleans())}
    if draw(st.integers(0, 3)) == 0:
        _split_inertia(values, runtime, draw(st.sampled_from([("I11",), ("I33",), ("I11", "I33")])))
    effects: dict[str, object] = {"translation": translation, "rotor_angle": rotor_angle,
                                  "torque": torque}  # fmt: skip
    if torque == "table":
        n = draw(st.integers(2, 6))
        drawn_times = draw(st.lists(st.floats(-5, 20), min_size=n, max_size=n))
        times = sorted({round(t, 3) for t in drawn_times})  # points 1 ms apart at least
        if len(times) < 2:
            times = [0.0, 1.0]
        torques = [draw(st.floats(-1, 1)) for _ in times]  # a folded value: 0 or >= 1e-50
        effects["torque_table"] = [
            [t, v if abs(v) >= 1e-50 else 0.0] for t, v in zip(times, torques, strict=True)
        ]
    initial: dict[str, float] = {f"u{i}": draw(st.floats(-2, 2)) for i in (1, 2, 3)}
    initial["u4"] = draw(st.floats(-100, 100))
    if attitude == "quaternion":
        e = np.array([draw(st.floats(-1, 1)) for _ in range(4)]) + np.array([1e-3, 0, 0, 0])
        initial.update(
            zip(("e0", "e1", "e2", "e3"), map(float, e / np.linalg.norm(e)), strict=True)
        )
    else:
        initial["q2"] = draw(st.floats(-1.2, 1.2))
    simulate = {
        "t_end": 1.0,
        "initial": initial,
        "parameters": {n: values[n] for n in needed if n in runtime},
    }
    top = {
        "name": name,
        "description": description,
        "attitude": attitude,
        "targets": draw(TARGET_LISTS),
        "integrators": offered(draw(INTEGRATOR_LISTS), effects.get("torque") != "table"),
    }
    tables = {
        "parameters": {n: "runtime" if n in runtime else values[n] for n in needed},
        "effects": effects,
        "outputs": {
            k: draw(st.booleans()) for k in ("kinetic_energy", "angular_momentum", "power")
        },
        "simulate": simulate,
    }
    full = np.array([float(values.get(n, 0.0)) for n in PARAMETERS])
    why = []
    if not name_is_valid(name):
        why.append(f"name {name!r}")
    if not description_is_valid(description):
        why.append("description")
    code = sampling.setup_code(full)
    if code:
        why.append(f"parameters (setup code {code})")
    if any(v != 0.0 and not 1e-50 <= abs(v) <= 1e50 for _, v in effects.get("torque_table", [])):
        why.append("a torque_table value (0 or of magnitude 1e-50 to 1e50)")
    return Draw(to_toml(top, tables), not why, ", ".join(why))


class Failure(AssertionError):
    """A drawn scene broke a promise; its TOML is kept to reproduce it."""


def reproduce(text: str, why: str, where: Path | None) -> Failure:
    """A Failure, with the scene written to where/<hash>.toml when given."""
    if where is not None:
        where.mkdir(parents=True, exist_ok=True)
        path = where / f"scene-{hashlib.sha256(text.encode()).hexdigest()[:12]}.toml"
        path.write_text(f"# {why.splitlines()[0] if why else ''}\n{text}", encoding="utf-8")
        why = f"{why}\n(reproduce with: gyrogen verify {path})"
    return Failure(f"{why}\n--- scene ---\n{text}")


def check(drawn: Draw, failures: Path | None = None) -> str:
    """Run the whole promise on one drawn scene; returns 'refused' or
    'checked', raises Failure (with a reproducing TOML) otherwise."""
    try:
        scene = parse(drawn.text, "drawn.toml")
    except SceneError as exc:
        if drawn.valid:
            raise reproduce(drawn.text, f"a valid scene was refused: {exc}", failures) from exc
        if "\n" in str(exc):
            raise reproduce(drawn.text, f"the refusal is not one line: {exc}", failures) from exc
        return "refused"
    if not drawn.valid:
        raise reproduce(drawn.text, f"accepted, but invalid: {drawn.why}", failures)
    try:
        _pipeline(scene)
    except Exception as exc:
        why = f"{type(exc).__name__}: {exc}"
        raise reproduce(drawn.text, why, failures) from exc
    return "checked"


def _pipeline(scene: Scene) -> None:
    unit = unit_of(scene)
    files = render_all(unit, lib="c" in scene.targets)  # the build files need C
    with tempfile.TemporaryDirectory(prefix="gyrogen-space-") as tmp:
        src = Path(tmp)
        write_atomic(src, files)
        for f in src.glob("*.f90"):
            long = [n for n, line in enumerate(f.read_text().splitlines(), 1) if len(line) > 132]
            assert not long, f"{f.name}: lines {long[:5]} past 132 columns"
        for c_file in src.glob("*.c"):
            _compile(["clang", *C_STRICT, c_file.name], src)
        backends = [build.build(src, lang) for lang in scene.targets]  # gcc, gfortran, -Werror
        given = compare.given_parameters(scene)
        report = compare.compare(backends, scene, 100, 2, 1, seed=0, given=given)
        failed = [r for r in report.rows if not r.passed] + report.refusal_failures
        assert not failed, f"differs from the reference: {failed}"
        if given is not None:
            for b in backends:
                _integrators(scene, b, given[0])


def _compile(cmd: list[str], cwd: Path) -> None:
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, f"{' '.join(cmd)}:\n{proc.stderr[:2000]}"


def _integrators(scene: Scene, comp: Compiled, p: np.ndarray) -> None:
    """Each integrator over a short span against scipy's LSODA on the
    reference, from the scene's start; an explicit method the problem is too
    stiff for (more than 1e4 adaptive or 1e5 fixed steps) is skipped."""
    x0 = np.array(scene.initial_state())
    t1 = 0.05

    def f(t: float, x: np.ndarray) -> np.ndarray:
        return scene_view.rhs(scene, x[None, :], p, t)[0]

    rate = _largest_rate(f, x0)
    steps = max(200, math.ceil(rate * t1 / 0.02))  # rk4 to about 1e-7 where it is stable
    ref = solve_ivp(f, (0.0, t1), x0, method="LSODA", rtol=1e-12, atol=1e-12).y[:, -1]
    c = comp.setup(p)
    for method in scene.integrators:
        if method == "rk4":
            if steps <= 100_000 and not _spiky(scene):
                _rk4_converges(comp, x0, c, t1, steps, ref)
            continue
        if not methods.get(method).implicit and rate * t1 > 1e4:
            continue  # the pairs and the Taylor series alike: explicit
        x, stats, code = comp.integrate(method, x0, c, 0.0, t1, rtol=1e-9, atol=1e-9)
        assert code == 0, f"{comp.language} {method} returned code {code}: {stats}"
        err = float(np.max(np.abs(x - ref) / (1.0 + np.abs(ref))))
        assert err < 1e-5, f"{comp.language} {method} off scipy's LSODA by {err:.2e}"


def _spiky(scene: Scene) -> bool:
    """A torque table with points closer than 1e-6 s: a jump that RK4's
    fixed steps straddle, so its error is no longer its convergence's."""
    tables = [scene.effects.torque_table or [], *(r.torque_table or [] for r in scene.rotors)]
    return any(b[0] - a[0] < 1e-6 for t in tables for a, b in itertools.pairwise(t))


def _rk4_converges(
    comp: Compiled, x0: np.ndarray, c: np.ndarray, t1: float, steps: int, ref: np.ndarray
) -> None:
    """RK4 with n and 2n steps: the finer one is off the reference by no more
    than the two differ (a torque table's kink can cost it its order, not
    its convergence)."""
    coarse, _, code = comp.integrate("rk4", x0, c, 0.0, t1, steps=steps)
    fine, stats, code2 = comp.integrate("rk4", x0, c, 0.0, t1, steps=2 * steps)
    assert code == code2 == 0, f"{comp.language} rk4 returned code {code}, {code2}: {stats}"
    scale = 1.0 + np.abs(ref)
    err, gap = np.abs(fine - ref) / scale, np.abs(coarse - fine) / scale
    assert np.all(err <= 1.5 * gap + 1e-8), (
        f"{comp.language} rk4 off scipy's LSODA by {np.max(err):.2e}, "
        f"more than its own convergence ({np.max(gap):.2e})"
    )


def _largest_rate(f: object, x0: np.ndarray) -> float:
    """The largest |eigenvalue| of the reference's Jacobian at x0."""
    n = len(x0)
    jac = np.empty((n, n))
    for j in range(n):
        h = 1e-6 * (1.0 + abs(x0[j]))
        up, down = x0.copy(), x0.copy()
        up[j] += h
        down[j] -= h
        jac[:, j] = (f(0.0, up) - f(0.0, down)) / (2 * h)  # type: ignore[operator]
    return float(np.max(np.abs(np.linalg.eigvals(jac))))


def run_shard(
    seed_: int, examples: int, failures: Path | None, drawn: object = None
) -> tuple[dict[str, int], list[str]]:
    """Draw (from drawn, else scenes()) and check `examples` scenes from seed_, not stopping
    or shrinking at a failure: every failure is kept (a TOML each in failures).
    Returns the counts (examples, checked, refused, failed) and the messages."""
    counts = {"examples": 0, "checked": 0, "refused": 0, "failed": 0}
    found: list[str] = []

    @seed(seed_)
    @settings(
        max_examples=examples,
        deadline=None,
        database=None,
        phases=[Phase.generate],
        suppress_health_check=list(HealthCheck),
    )
    @given(drawn if drawn is not None else scenes())
    def one(drawn: Draw) -> None:
        counts["examples"] += 1
        try:
            counts[check(drawn, failures)] += 1
        except Failure as exc:
            counts["failed"] += 1
            found.append(str(exc))

    one()
    return counts, found
