"""The rules a scene's values follow beyond their types: names and
descriptions that are data in every target, folded values of a size setup
can multiply, unit quaternions, a sane output grid, and setup's own checks
(gyrogen.setup_checks) on the values known at generation. Each raises
ValueError with the one line pydantic shows under the key."""

from __future__ import annotations

import itertools
import math
import sys
from collections.abc import Mapping
from typing import Annotated

from pydantic import BeforeValidator, StrictFloat

from gyrogen.abi import (
    DESCRIPTION_MAX_LENGTH,
    FOLDED_MAX,
    FOLDED_MIN,
    NAME_MAX_LENGTH,
    QUATERNION_NORM_SLACK,
)
from gyrogen.abi_groups import MAX_START_ANGLE, state_kind
from gyrogen.limits import MAX_OUTPUT_POINTS, MIN_OUTPUT_STEP
from gyrogen.methods import STEP_UNDERFLOW
from gyrogen.setup_checks import first_failure

_C_KEYWORDS = frozenset(
    "auto break case char const continue default do double else enum extern float for goto if "
    "inline int long register restrict return short signed sizeof static struct switch typedef "
    "union unsigned void volatile while _Bool _Complex _Imaginary".split()
)

C_HEADERS = frozenset(
    "assert complex ctype errno fenv float inttypes iso646 limits locale math setjmp signal "
    "stdalign stdarg stdatomic stdbool stddef stdint stdio stdlib stdnoreturn string tgmath "
    "threads time uchar wchar wctype omp alloca malloc memory strings unistd pthread fcntl "
    "dirent dlfcn sched termios poll".split()
)
"""Headers a C program includes as <NAME.h> (C11's, OpenMP's, and POSIX's
and glibc's most common): a scene's <name>.h sits in the include directory
of its build and package, where it would hide the system's (a scene named
math broke the package's own math.h include). Compared without case, for
case-insensitive file systems."""

FMI_HEADERS = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")
"""The FMI headers an FMU's wrapper includes (codegen/fmu.py): a scene named
as one would shadow it with its own header, in the FMU's sources and beside
any FMU a user builds with the scene's package (compared without case too)."""


def shown(v: object) -> str:
    """A value as a message quotes it: its repr, a text's first 40
    characters and its length, anything else's repr cut after 40."""
    if isinstance(v, str):
        return repr(v) if len(v) <= 40 else repr(v[:40]) + f"... ({len(v)} characters)"
    text = repr(v)
    return text if len(text) <= 40 else text[:40] + "..."


def shown_integer(v: int) -> str:
    """A long integer as its first digits and their count."""
    digits = str(abs(v))
    return f"{'-' * (v < 0)}{digits[:6]}... ({len(digits)} digits)"


def number(v: object) -> object:
    """A TOML integer too large for a double is out of range, in a line of
    its own (pydantic said only "Input should be a valid number")."""
    if isinstance(v, int) and not isinstance(v, bool) and abs(v) > sys.float_info.max:
        raise ValueError(f"{shown_integer(v)} is out of range: a double holds at most 1.8e308")
    return v


Number = Annotated[StrictFloat, BeforeValidator(number)]
"""A TOML integer or float, never a boolean or a string."""


def parameter_value(v: object) -> object:
    """A parameter is a number (folded into the code) or "runtime"; a TOML
    boolean or a quoted number is neither (pydantic would take true as 1.0)."""
    if v == "runtime":
        return v
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise ValueError(f'expected a number or "runtime", not {v!r}')
    try:
        x = float(v)
    except OverflowError as exc:  # an integer past a double's range (TOML's have no other)
        line = f"{shown_integer(int(v))} is out of range: {folded_size(math.inf)}"
        raise ValueError(line) from exc
    if not math.isfinite(x):
        raise ValueError(f"{v!r} is not a finite number")
    if why := folded_size(x):
        raise ValueError(f'{x!r}: {why}; make it "runtime"')
    return x


def folded_size(x: float) -> str | None:
    """Why x cannot be a number folded into the code (a parameter, a torque
    table's value), or None: it is 0 or of magnitude FOLDED_MIN to FOLDED_MAX."""
    if x != 0.0 and not FOLDED_MIN <= abs(x) <= FOLDED_MAX:
        return (
            f"a folded value must be 0 or of magnitude {FOLDED_MIN:g} to {FOLDED_MAX:g} "
            "(its products must stay doubles)"
        )
    return None


def check_output_grid(t_end: float, dt: float) -> None:
    """ValueError unless dt fits in t_end at most MAX_OUTPUT_POINTS times
    (and at least once), and is no shorter than MIN_OUTPUT_STEP."""
    if dt > t_end:
        raise ValueError(f"output step {dt:g} s is longer than the span {t_end:g} s")
    steps = t_end / dt
    if not steps <= MAX_OUTPUT_POINTS:
        raise ValueError(
            f"t_end/dt = {t_end:g} s/{dt:g} s is {steps:.7g} output steps, more than the "
            f"limit of {MAX_OUTPUT_POINTS:,}: raise dt or lower t_end"
        )
    if dt < MIN_OUTPUT_STEP:
        raise ValueError(
            f"output step {dt:g} s is shorter than {MIN_OUTPUT_STEP:g} s: the quadrature "
            "samples inside it would be steps shorter than any integrator resolves"
        )


QUATERNION = ("e0", "e1", "e2", "e3")


def check_name(v: str) -> None:
    """The scene's name prefixes every identifier gyrogen writes, in C (and
    C++, through the header) and Fortran: a letter, then letters, digits and
    single underscores, never ending in one (prefix + "_" would make "__",
    which C++ reserves), at most NAME_MAX_LENGTH characters; not a C keyword,
    nor a header's name (C_HEADERS, FMI_HEADERS) that its <name>.h would hide."""
    quoted = shown(v)
    if not v:
        raise ValueError("must not be empty")
    if len(v) > NAME_MAX_LENGTH:
        raise ValueError(
            f"{quoted} is longer than {NAME_MAX_LENGTH} characters (Fortran identifiers "
            "stop at 63, and gyrogen appends up to 26)"
        )
    if not (v.isascii() and v[0].isalpha() and v.replace("_", "a").isalnum()):
        raise ValueError(
            f"{quoted} is not an identifier in C and Fortran: a letter, then letters, "
            "digits and underscores"
        )
    if "__" in v or v.endswith("_"):
        raise ValueError(f"{quoted} has a double or trailing underscore (C++ reserves '__')")
    if v in _C_KEYWORDS:
        raise ValueError(f"{quoted} is a C keyword")
    if v.lower() in C_HEADERS:
        raise ValueError(
            f"{quoted} names a C library header (<{v.lower()}.h>): the scene's {v}.h would hide it"
        )
    fmi = [h for h in FMI_HEADERS if h[:-2].lower() == v.lower()]
    if fmi:
        raise ValueError(
            f"{quoted} names an FMI header ({fmi[0]}): the scene's {v}.h would hide it"
        )


BIDI_CONTROLS = frozenset((0x061C, 0x200E, 0x200F, *range(0x202A, 0x202F), *range(0x2066, 0x206A)))
"""Unicode's bidirectional controls: in a comment they can make the code read
otherwise than it compiles ("Trojan Source"), and gcc refuses an unpaired
one (-Werror=bidi-chars), so a description with one would not compile."""


def check_description(v: str) -> str:
    """Any text but control characters (newlines and tabs are fine),
    bidirectional controls (BIDI_CONTROLS) and what XML 1.0 cannot hold
    (U+FFFE, U+FFFF, lone surrogates: an FMU's modelDescription.xml carries
    the description), at most DESCRIPTION_MAX_LENGTH characters; CR LF is
    read as a newline."""
    v = v.replace("\r\n", "\n")
    if len(v) > DESCRIPTION_MAX_LENGTH:
        raise ValueError(f"{len(v)} characters; at most {DESCRIPTION_MAX_LENGTH}")
    for i, ch in enumerate(v):
        if ch not in "\n\t" and (ord(ch) < 32 or 127 <= ord(ch) < 160):
            raise ValueError(f"control character U+{ord(ch):04X} at position {i}")
        if ord(ch) in BIDI_CONTROLS:
            raise ValueError(
                f"bidirectional control U+{ord(ch):04X} at position {i}: it would make the "
                "generated code's comments read otherwise than they compile"
            )
        if ord(ch) in (0xFFFE, 0xFFFF) or 0xD800 <= ord(ch) <= 0xDFFF:
            raise ValueError(
                f"U+{ord(ch):04X} at position {i} is not a character: XML (an FMU's "
                "modelDescription.xml) cannot hold it"
            )
    return v


def check_quaternion(initial: dict[str, float], key: str = "simulate.initial") -> None:
    """Euler parameters start on |e| = 1 (e0 = 1 when not given); key: where
    the start state was given (a scene's simulate.initial, a sweep's initial)."""
    e = [initial.get(n, 1.0 if n == "e0" else 0.0) for n in QUATERNION]
    norm = math.hypot(*e)  # the squares of 1e-200 or 1e200 underflow or overflow
    if norm == 0.0:
        raise ValueError(f"{key}: e0..e3 are all zero: not an attitude")
    if abs(norm - 1.0) > QUATERNION_NORM_SLACK:
        raise ValueError(
            f"{key}: e0..e3 = ({', '.join(f'{x:g}' for x in e)}) has norm "
            f"{norm:.9g}, not 1 (within {QUATERNION_NORM_SLACK:g}): give a unit quaternion"
        )


def check_angles(point: Mapping[str, float], key: str, relation: str = "=") -> None:
    """Every angle of a start state (or an equilibrium, or how far a sweep's
    values of it reach: relation "reaches") given within MAX_START_ANGLE,
    where a double still holds it to verify's bar; point's names are the
    scene's states (checked before), named in the error as key.name (name
    alone for an empty key)."""
    for name, v in point.items():
        if state_kind(name) == "angle" and not abs(v) <= MAX_START_ANGLE:
            raise ValueError(
                f"{f'{key}.' if key else ''}{name} {relation} {v:.6g} rad: more than "
                f"{int(MAX_START_ANGLE / (2 * math.pi))} "
                f"turns ({MAX_START_ANGLE:g} rad), where a double holds the angle only to "
                f"{math.ulp(v) / 2:.2g} rad; give it modulo 2 pi"
            )


def check_physics(p: Mapping[str, float | str]) -> None:
    """The generated setup's checks (gyrogen.setup_checks), made on the
    values known at generation: the folded ones, and the [simulate]
    parameters with them."""
    failed = first_failure({k: x for k, x in p.items() if not isinstance(x, str)})
    if failed is not None:
        raise ValueError(failed[1])


def check_table(torque: str, table: list[tuple[float, float]] | None) -> None:
    """A torque table goes with torque = 'table', and only with it: at least
    2 (t, T) points, the times increasing strictly, each T a folded value's
    size (folded_size: the code multiplies them)."""
    if torque != "table":
        if table is not None:
            raise ValueError("torque_table is only used with torque = 'table'")
        return
    if table is None or len(table) < 2:
        raise ValueError("torque = 'table' needs torque_table with at least 2 (t, T) points")
    if any(b[0] <= a[0] for a, b in itertools.pairwise(table)):
        raise ValueError("torque_table times must increase strictly")
    for (a, _), (b, _) in itertools.pairwise(table):
        if b - a <= 2 * STEP_UNDERFLOW * sys.float_info.epsilon * max(abs(a), abs(b)):
            raise ValueError(
                f"torque_table times {a!r} and {b!r} lie within the rounding of t: a step "
                f"cannot end on each (they must differ by more than "
                f"{2 * STEP_UNDERFLOW:g} DBL_EPSILON |t|)"
            )
    for i, (t, torque_value) in enumerate(table):
        if why := folded_size(torque_value):
            raise ValueError(f"torque_table[{i}]: T = {torque_value!r} at t = {t:g}: {why}")


WRT_STATE = "state"
"""[sensitivities] wrt's name for the initial state (nx columns of Phi)."""


def check_wrt(wrt: list[str], runtime: tuple[str, ...], folded: set[str]) -> None:
    """[sensitivities] wrt: "state" or runtime parameters, each once (the
    duplicate is the field's own check)."""
    for i, name in enumerate(wrt):
        if name == WRT_STATE or name in runtime:
            continue
        where = f"sensitivities.wrt[{i}]: {shown(name)}"
        if name in folded:
            raise ValueError(
                f'{where} is folded to a number in this scene: make it "runtime" to '
                "differentiate with respect to it"
            )
        raise ValueError(f'{where} is neither "state" nor a runtime parameter of this scene')
