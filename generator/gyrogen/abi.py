"""The interface every generated file shares, in one registry: the names,
units and order of states and parameters, the return codes of setup and of
the integrators, the fields of the step statistics, and the thresholds and
limits the generated code, the scene validator and the command line apply.

Plain Python, no sympy: the numpy reference and the tests read these too, and
they must not depend on the symbolic model they are meant to check. The
templates read them through the render context (codegen.context).
"""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import dataclass, replace

from gyrogen.abi_rotors import AXIS_NORM_SLACK, GIMBAL_PERP_SLACK, ON_GIMBAL, ROTOR_KEYS

STATES: tuple[str, ...] = tuple(f"q{i}" for i in range(1, 8)) + tuple(f"u{i}" for i in range(1, 8))
"""q1..q3: 3-1-2 Euler angles of the carrier A in N; q4: rotor angle about a2
relative to A; q5..q7: position of the mass center AB* in N; u1..u3: angular
velocity of A (A-components); u4: a2 component of the rotor's absolute angular
velocity; u5..u7: velocity of AB* (N-components)."""

PARAMETERS: tuple[str, ...] = (
    "m_a",
    "m_b",
    "I11",
    "I22",
    "I33",
    "I13",
    "I",
    "J",
    "l1",
    "l3",
    "g",
    "T",
)

UNITS: dict[str, tuple[str, str]] = {
    # parameters, in p[] order (PARAMETERS, then CONTROLLER_PARAMETERS)
    "m_a": ("kg", "mass of the carrier A"),
    "m_b": ("kg", "mass of the rotor B"),
    "I11": ("kg m^2", "carrier inertia about A*, a1a1"),
    "I22": ("kg m^2", "carrier inertia about A*, a2a2"),
    "I33": ("kg m^2", "carrier inertia about A*, a3a3"),
    "I13": ("kg m^2", "carrier product of inertia about A*, a1a3"),
    "I12": ("kg m^2", "carrier product of inertia about A*, a1a2 (clusters)"),
    "I23": ("kg m^2", "carrier product of inertia about A*, a2a3 (clusters)"),
    "I": ("kg m^2", "rotor transverse inertia about B*"),
    "J": ("kg m^2", "rotor axial inertia about B* (axis a2)"),
    "l1": ("m", "B* from A* along a1"),
    "l3": ("m", "B* from A* along a3"),
    "g": ("m/s^2", "gravity along +n3"),
    "T": ("N m", "motor torque on B about a2 (minus on A)"),
    "k": ("N m s", "speed controller gain: T = -k (u4 - u2 - w_ref)"),
    "w_ref": ("rad/s", "speed controller: commanded rate of B relative to A"),
    # states, in x[] order (STATES, with e0..e3 for a quaternion attitude)
    "q1": ("rad", "3-1-2 Euler angle 1 of A in N (about n3)"),
    "q2": ("rad", "3-1-2 Euler angle 2 of A in N (about a1')"),
    "q3": ("rad", "3-1-2 Euler angle 3 of A in N (about a2)"),
    "q4": ("rad", "rotor angle about a2 relative to A"),
    "e0": ("-", "Euler parameter (quaternion) of A in N, scalar part"),
    "e1": ("-", "Euler parameter of A in N, vector part along a1"),
    "e2": ("-", "Euler parameter of A in N, vector part along a2"),
    "e3": ("-", "Euler parameter of A in N, vector part along a3"),
    "q5": ("m", "AB* position, n1"),
    "q6": ("m", "AB* position, n2"),
    "q7": ("m", "AB* position, n3"),
    "u1": ("rad/s", "angular velocity of A, a1"),
    "u2": ("rad/s", "angular velocity of A, a2"),
    "u3": ("rad/s", "angular velocity of A, a3"),
    "u4": ("rad/s", "absolute angular velocity of B, a2"),
    "u5": ("m/s", "velocity of AB*, n1"),
    "u6": ("m/s", "velocity of AB*, n2"),
    "u7": ("m/s", "velocity of AB*, n3"),
}
"""Every parameter's and state's unit and meaning, as the headers document them."""


def unit_and_doc(name: str, gimbals: Collection[int] = ()) -> tuple[str, str]:
    """A state's or parameter's unit and meaning: UNITS, or a cluster's derived
    name (gimbals: the k of the rotors on gimbals, whose keys ON_GIMBAL reads)."""
    if name in UNITS:
        return UNITS[name]
    if name.startswith("th") and name[2:].isdigit():
        return ("rad", f"angle of rotor B{name[2:]} about g{name[2:]} relative to A")
    if name.startswith("gam") and name[3:].isdigit():
        return ("rad", f"angle of gimbal G{name[3:]} about its axis relative to A")
    if name.startswith("gd") and name[2:].isdigit():
        return ("rad/s", f"rate of gimbal G{name[2:]} about its axis relative to A")
    if name.startswith("w") and name[1:].isdigit():
        return ("rad/s", f"absolute angular velocity of rotor B{name[1:]}, along g{name[1:]}")
    key, _, k = name.rpartition("_")
    unit, doc = (
        ON_GIMBAL if key in ON_GIMBAL and k.isdigit() and int(k) in gimbals else ROTOR_KEYS
    )[key]
    return unit, doc.format(k=k)


CONTROLLER_PARAMETERS = ("k", "w_ref")
"""Speed controller T = -k (u4 - u2 - w_ref): gain (N m s) and reference rate (rad/s);
runtime ones follow PARAMETERS in p[]."""

OUTPUT_DOC: dict[str, tuple[str, str]] = {
    "kinetic_energy": ("J", "kinetic energy of the system"),
    "angular_momentum": ("kg m^2/s", "angular momentum about AB*, N components h[0..2]"),
    "power": ("W", "power of the motor torque, T (u4 - u2)"),
}
"""The optional output functions: unit and what they compute."""
CLUSTER_OUTPUT_DOC: dict[str, tuple[str, str]] = {
    **OUTPUT_DOC,
    "angular_momentum": (
        "kg m^2/s",
        "angular momentum about the mass center, N components h[0..2]",
    ),
    "power": ("W", "power of each motor, T_k (w_k - g_k.w_A), out[k-1]"),
}
"""The output functions of a rotor cluster."""


def output_doc(cluster: bool) -> dict[str, tuple[str, str]]:
    """The output functions' units and docs, in the order every model gives
    them (out[] laid end to end): a rotor cluster's (the scene's [[rotors]])
    or the paper's one rotor's."""
    return CLUSTER_OUTPUT_DOC if cluster else OUTPUT_DOC


@dataclass(frozen=True)
class Code:
    """A return code: its value, the macro suffix (<PREFIX>_<name>), the one
    line Python says, and the comment the headers give it."""

    value: int
    name: str
    message: str
    note: tuple[str, ...] = ()
    """Lines of a comment above the macro; {macro} is the scene's prefix."""
    doc: str = ""
    """A comment after the macro (C), when there is no note."""
    cluster: str = ""
    """The message in a cluster scene, where the keys it names differ (a
    rotor's are <key>_<k>); empty: the same message."""


SETUP_CODES: tuple[Code, ...] = (
    Code(0, "OK", "parameters accepted"),
    Code(1, "ERR_NONFINITE", "a parameter is NaN or infinite"),
    Code(2, "ERR_MASS", "a mass (m_a or m_b) is not positive",
         cluster="a mass (m_a, a rotor's m_k or a gimbal frame's mG_k) is not positive"),
    Code(3, "ERR_ROTOR_INERTIA", "a rotor inertia (I or J) is not positive",
         cluster="a rotor inertia (I_k, J_k, or a gimbal frame's IGs_k, IGt_k, IGg_k) is not "
         "positive"),
    Code(4, "ERR_CARRIER_NOT_PD", "the carrier inertia is not positive definite"),
    Code(5, "ERR_CARRIER_TRIANGLE",
         "the carrier's principal moments violate the triangle inequality"),
    Code(6, "ERR_ROTOR_TRIANGLE", "the rotor violates the triangle inequality (2 I < J)",
         cluster="a rotor (2 I_k < J_k) or a gimbal frame violates the triangle inequality"),
    Code(7, "ERR_MASS_SINGULAR",
         "the mass matrix is not numerically positive definite (condition number above 1e13)"),
    Code(8, "ERR_AXIS", f"a rotor axis is not of unit length (within {AXIS_NORM_SLACK:g})",
         cluster=f"a rotor's axis or a gimbal axis is not of unit length (within "
         f"{AXIS_NORM_SLACK:g})"),
    Code(9, "ERR_OVERFLOW",
         "a constant derived from the parameters is not finite (together they overflow doubles)"),
    Code(10, "ERR_GIMBAL_PERP",
         f"a gimbal's spin axis is not perpendicular to its gimbal axis (within "
         f"{GIMBAL_PERP_SLACK:g})"),
)  # fmt: skip
"""Return codes of <prefix>_setup, checked in this order (a runtime axis, 8,
and a gimbal's pair, 10, before the condition number, 7, which reads the
axes; the constants, 9, last, once computed); the first failure wins."""


def setup_codes_of(cluster: bool) -> tuple[Code, ...]:
    """SETUP_CODES as a scene's setup says them: a cluster's messages name its keys."""
    if not cluster:
        return SETUP_CODES
    return tuple(replace(c, message=c.cluster) if c.cluster else c for c in SETUP_CODES)


ODE_CODES: tuple[Code, ...] = (
    Code(0, "ODE_OK", "ok"),
    Code(1, "ODE_ERR_STEP_UNDERFLOW", "step size underflow",
         doc="step size fell below 16 eps |t|"),
    Code(2, "ODE_ERR_MAX_STEPS", "max_steps reached", doc="max_steps steps were not enough"),
    Code(3, "ODE_ERR_NONFINITE", "non-finite state or derivative",
         doc="the state or its derivative is NaN or Inf"),
    Code(4, "ODE_ERR_SINGULAR", "singular iteration matrix",
         doc="the iteration matrix is singular"),
    Code(
        5,
        "ODE_ERR_ARGUMENT",
        "bad argument",
        note=(
            "5: t1 < t0, steps or max_steps < 1, rtol <= {macro}_ODE_MIN_RTOL (taylor:",
            "{macro}_ODE_TAYLOR_MIN_RTOL), atol <= 0, or t0, t1, rtol, atol or h0 NaN",
            "or infinite; quaternion scenes: x's Euler parameters e0..e3 of norm 0",
            "(below sqrt(DBL_MIN)) or too large to square (x as given)",
        ),
    ),
    Code(
        6,
        "ODE_ERR_ATTITUDE_SINGULAR",
        'the 3-1-2 attitude reached gimbal lock: use attitude = "quaternion"',
        note=(
            '6: the 3-1-2 attitude reached gimbal lock: use attitude = "quaternion"',
            "(3-1-2 scenes only; see above)",
        ),
    ),
    Code(
        7,
        "ODE_ERR_GRID",
        "bad output grid (times: at least one, finite, strictly increasing)",
        note=(
            "7: a _grid call's times: none (ntimes < 1), or one NaN or infinite, or not",
            "strictly increasing (unsorted or repeated); nothing is integrated or written",
        ),
    ),
    Code(8, "ODE_EVENT", "stopped by a terminal event",
         doc="an _events call: x and stats.t are the state and time of the event, the log's last"),
    Code(9, "ODE_ERR_EVENT_LOG_FULL", "the event log is full",
         doc="an _events call: capacity events logged; x and stats.t are at the next one"),
)  # fmt: skip
"""Return codes of the compiled integrators (<PREFIX>_ODE_* in <prefix>_ode.h);
on failure x holds the last good state."""

ODE_ATTITUDE_SINGULAR = next(c.value for c in ODE_CODES if c.name == "ODE_ERR_ATTITUDE_SINGULAR")
"""<PREFIX>_ODE_ERR_ATTITUDE_SINGULAR: 3-1-2 angles at gimbal lock (GIMBAL_LOCK_COS)."""
ODE_EVENT = next(c.value for c in ODE_CODES if c.name == "ODE_EVENT")
"""<PREFIX>_ODE_EVENT: an _events call stopped at a terminal event."""
ODE_LOG_FULL = next(c.value for c in ODE_CODES if c.name == "ODE_ERR_EVENT_LOG_FULL")
"""<PREFIX>_ODE_ERR_EVENT_LOG_FULL: an _events call's log had no room for a crossing."""


UNKNOWN_CODE = "unknown return code"
"""What <prefix>_strerror and <prefix>_ode_strerror say for a code not listed."""


def message(codes: tuple[Code, ...], value: int) -> str:
    """The one line a code means, or 'code N' for one not in the registry."""
    return next((c.message for c in codes if c.value == value), f"code {value}")


@dataclass(frozen=True)
class Arg:
    """One argument of a generated function."""

    ctype: str
    """Its C type; {prefix} is the scene's prefix (the stats struct)."""
    name: str
    length: tuple[str, ...] = ()
    """A pointer's element count, as factors: "nx", "np", "nc", "out" (the
    output's size), "n" (a batch's count of states); () for a scalar."""


@dataclass(frozen=True)
class Signature:
    """A generated function's C signature (the Fortran bind(C) one takes the
    same arguments under the same names)."""

    returns: str
    args: tuple[Arg, ...]

    def c(self, name: str, prefix: str = "") -> str:
        """'void name(double t, const double *x, ...)'."""
        args = ", ".join(
            a.ctype.format(prefix=prefix) + ("" if a.ctype.endswith("*") else " ") + a.name
            for a in self.args
        )
        lead = self.returns + ("" if self.returns.endswith("*") else " ")
        return f"{lead}{name}({args})"

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(a.name for a in self.args)


def _args(*specs: str) -> tuple[Arg, ...]:
    """Args from 'ctype name[:factor*factor]' specs, e.g. 'double *x:n*nx'."""
    out = []
    for spec in specs:
        decl, _, length = spec.partition(":")
        ctype, name = decl.rsplit(" ", 1)
        pointer = name.startswith("*")
        out.append(
            Arg(
                ctype + " *" if pointer else ctype,
                name.lstrip("*"),
                tuple(length.split("*")) if length else (),
            )
        )
    return tuple(out)


_PER_CALL = ("double t", "const double *x:nx", "const double *c:nc")
_SPAN = ("double t0", "double t1")
_TOLERANCES = ("double rtol", "double atol", "double h0", "long max_steps")
SIGNATURES: dict[str, Signature] = {
    "setup": Signature("int", _args("const double *p:np", "double *c:nc")),
    "rhs": Signature("void", _args(*_PER_CALL, "double *dxdt:nx")),
    "output": Signature("void", _args(*_PER_CALL, "double *out:out")),
    "jac": Signature("void", _args(*_PER_CALL, "double *J:nx*nx")),
    "linear": Signature(
        "void",
        _args(*_PER_CALL, "double *A:nx*nx", "double *B:nx*nu", "double *C:ny*nx",
              "double *D:ny*nu"),
    ),
    "strerror": Signature("const char *", _args("int code")),
    "fixed_step": Signature(
        "int",
        _args(*_SPAN, "long steps", "double *x:nx", "const double *c:nc",
              "{prefix}_stats *stats:1"),
    ),
    "fixed_step_batch": Signature(
        "size_t",
        _args("size_t n", *_SPAN, "long steps", "double *x:n*nx", "const double *c:nc",
              "{prefix}_stats *stats:n", "int *codes:n"),
    ),
    "adaptive": Signature(
        "int",
        _args(*_SPAN, "double *x:nx", "const double *c:nc", *_TOLERANCES,
              "{prefix}_stats *stats:1"),
    ),
    "adaptive_batch": Signature(
        "size_t",
        _args("size_t n", *_SPAN, "double *x:n*nx", "const double *c:nc", *_TOLERANCES,
              "{prefix}_stats *stats:n", "int *codes:n"),
    ),
    "grid": Signature(
        "int",
        _args("long ntimes", "const double *times:ntimes", "double *x:nx", "const double *c:nc",
              *_TOLERANCES, "double *out:ntimes*nx", "{prefix}_stats *stats:1"),
    ),
    "grid_batch": Signature(
        "size_t",
        _args("size_t n", "long ntimes", "const double *times:ntimes", "double *x:n*nx",
              "const double *c:nc", *_TOLERANCES, "double *out:n*ntimes*nx",
              "{prefix}_stats *stats:n", "int *codes:n"),
    ),
    "grid_events": Signature(
        "int",
        _args("long ntimes", "const double *times:ntimes", "double *x:nx", "const double *c:nc",
              *_TOLERANCES, "double *out:ntimes*nx", "long capacity",
              "double *log_t:capacity", "int *log_k:capacity", "double *log_x:capacity*nx",
              "long *nlog:1", "{prefix}_stats *stats:1"),
    ),
    "grid_events_batch": Signature(
        "size_t",
        _args("size_t n", "long ntimes", "const double *times:ntimes", "double *x:n*nx",
              "const double *c:nc", *_TOLERANCES, "double *out:n*ntimes*nx", "long capacity",
              "double *log_t:n*capacity", "int *log_k:n*capacity",
              "double *log_x:n*capacity*nx", "long *nlog:n", "{prefix}_stats *stats:n",
              "int *codes:n"),
    ),
}  # fmt: skip
"""setup, rhs, each output function (energy, momentum, power), the Jacobian,
the linear model (outputs.linear_model: nu inputs, ny outputs, C only),
the two strerror functions (setup's codes, the integrators'), and the
integrators: fixed-step (rk4) or adaptive (and those over an output grid,
without and with the scene's events), each with its _batch variant. The
integrators' stats and codes may be NULL."""


@dataclass(frozen=True)
class StatsField:
    """A field of <prefix>_stats (and of the Fortran bind(C) type, and of
    gyrogen_stats in the cffi glue), in order."""

    name: str
    ctype: str
    """double or long"""
    doc: str
    """{prefix} is the scene's prefix."""


STATS_FIELDS: tuple[StatsField, ...] = (
    StatsField("t", "double", "time reached (t1 on success)"),
    StatsField("h", "double", "last step size tried"),
    StatsField("accepted", "long", "accepted steps"),
    StatsField("rejected", "long", "rejected steps (error too large, or non-finite trial)"),
    StatsField("rhs_calls", "long", "calls of {prefix}_rhs"),
    StatsField("jac_calls", "long", "calls of {prefix}_jac"),
    StatsField("decompositions", "long", "LU decompositions of the iteration matrix"),
)

# The condition number of the mass matrix's coupled block [[I~11, I~13],
# [I~13, I~33]] (the other rows are diagonal and solved exactly): setup
# refuses it above MAX_CONDITION, `gyrogen check` warns above WARN_CONDITION.
MAX_CONDITION = 1e13
WARN_CONDITION = 1e8
AXES_SPAN_WARN = 1e-3
"""`gyrogen check` warns when a cluster's axes nearly fail to span space:
the smallest over the largest singular value of G = [g_1 .. g_N] below this
(the wheels cannot then exert torque about some direction; the dynamics is
unaffected unless the carrier's own inertia is small, see MAX_CONDITION)."""

# Relative slack of the triangle-inequality checks: equality is physical (a
# lamina, a thin disc), and rounding must not refuse it.
TRIANGLE_SLACK = 1e-12

# A scene's name is the prefix of every generated identifier. Fortran allows
# 63 characters in one, and gyrogen appends up to 26 (<NAME>_ODE_ERR_ATTITUDE_SINGULAR):
# 32 leaves room, and keeps every generated Fortran line within 132 columns.
NAME_MAX_LENGTH = 32

# A description is data: it reaches the generated files only inside comments,
# wrapped and escaped for each target, so it may hold any text but control
# characters; this many characters at most.
DESCRIPTION_MAX_LENGTH = 2000

# A folded value is 0 or has a magnitude in [FOLDED_MIN, FOLDED_MAX]: the
# constants of setup multiply up to about six parameters, and must stay
# within double range (runtime values are checked by setup at run time).
FOLDED_MIN = 1e-50
FOLDED_MAX = 1e50

# Euler parameters e0..e3 given as a start state must have |e| within this of
# 1; gyrogen then normalizes them exactly. A larger miss is a typo, refused.
QUATERNION_NORM_SLACK = 1e-6
ATTITUDE_MIN_NORM = 2.0**-511
"""The integrators normalize a start's Euler parameters and refuse one whose |e|
is below this (sqrt(DBL_MIN)) or not finite with <PREFIX>_ODE_ERR_ARGUMENT: no
direction (e = 0 made every state NaN). A step to such an |e| is non-finite."""

# The adaptive integrators refuse rtol <= MIN_RTOL (and atol <= 0) with
# <PREFIX>_ODE_ERR_ARGUMENT, by Hairer's rule (his codes stop with
# "TOLERANCES ARE TOO SMALL" when RTOL <= 10 UROUND): a step's error is
# measured against atol + rtol |x|, and every stage rounds x by up to
# DBL_EPSILON/2 |x|, so a relative tolerance within ten roundings cannot be
# met and the step size shrinks until max_steps or underflow ends the run.
MIN_RTOL = 10 * 2.0**-52
"""10 DBL_EPSILON = 2.220446049250313e-15: rtol must exceed it, in the
integrators and in a scene's simulate.rtol."""
TAYLOR_MIN_RTOL = 2.0**-52
"""DBL_EPSILON: the Taylor method's own bound (<PREFIX>_taylor and its batch).
Hairer's rule is about an error estimate, which it has none of: its order and
step come from its coefficients' decay, and within ten roundings it still steps
(order 20), its error that of the rounding; heyoka's bound is DBL_EPSILON too."""

# The 3-1-2 attitude's kinematics divide by cos(q2): its integrators stop
# with <PREFIX>_ODE_ERR_ATTITUDE_SINGULAR when |cos q2| < GIMBAL_LOCK_COS,
# or when a step's two ends lie on two sides of a point q2 = pi/2 + k pi
# (any integer k: a step of a whole turn or more too), numbered by
# floor(q2 GIMBAL_INTERVALS + 1/2).
GIMBAL_INTERVALS = 1 / math.pi
"""Gimbal-lock intervals per radian of q2: one between each two points
pi/2 + k pi."""
GIMBAL_LOCK_COS = 1e-9
"""Near q2 = pi/2 a double q2 carries a rounding error of about
DBL_EPSILON |q2| = 3.5e-16 rad (one ulp there is 2.2e-16), and cos(q2) moves
by as much: at |cos q2| = 1e-9 the rounding of q2 alone changes 1/cos(q2),
and so the kinematic rates q1' and q3', in the 7th digit (3.5e-7). Closer,
the rates are noise at the tolerances the integrators accept, and the steps
shrink toward underflow; Euler parameters (attitude = "quaternion") have no
such point."""

COMPILER_LOG_LINES = 10  # of a failed compiler's output in its error (all: the cache's logs/)

MAX_STEPS = 10**7
"""Steps (accepted and rejected) an adaptive integration takes by default before
max_steps ends it (the Python API, the benchmarks, an FMU's Co-Simulation step),
and scipy's RHS calls under `simulate --max-nfev`: a bound on a run that blows
up rather than a cost to plan for."""
