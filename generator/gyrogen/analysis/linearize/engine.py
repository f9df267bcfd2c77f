"""gyrogen linearize: the linear model x' = A x + B u, y = C x + D u of a
scene about an equilibrium.

The scene is built with its linear model (outputs.linear_model, C, with the
Jacobian): A is the generated Jacobian, B, C and D come from the generated
<prefix>_linear. The equilibrium is given (a full state, or states by name,
on the command line or as the scene's `equilibrium`) or found: a steady spin
about a principal axis of the inertia with the wheels locked, each wheel at
the rate its torque law holds, polished by Gauss-Newton on the compiled rhs.

About a spin the attitude and the rotor angles keep turning: they are no
equilibrium coordinates, and they drive nothing (no torque depends on
them), so the model keeps the states whose rates vanish there and leaves
those out (Linear.dropped); each rate against its own row's scale (relative:
an attitude angle's against the body rates, not a wheel's 1e12 rad/s). A
point that is no equilibrium of the kept states is linearized all the same,
with a warning stating the residual.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gyrogen import methods, physics
from gyrogen.abi import GIMBAL_LOCK_COS
from gyrogen.analysis.linearize import modes
from gyrogen.errors import SceneError
from gyrogen.limits import MAX_SPIN
from gyrogen.runtime.compiled import Compiled
from gyrogen.runtime.scene_build import compiled, scene_sources
from gyrogen.scene import Scene, validate
from gyrogen.scene.rotors import lumped_inertia, resolved, unit_axes
from gyrogen.scene.rules import QUATERNION, check_angles, check_quaternion

RESIDUAL_BAR = 1e-9
"""A point is an equilibrium when each kept state's rate is at most this
share of its row's scale (relative)."""
DRIFT_BAR = 1e-12
"""A coordinate whose rate is at most this share of its row's scale stays put."""
NEWTON_STEPS = 30
ATTITUDE = ("q1", "q2", "q3", "e0", "e1", "e2", "e3")
"""The attitude's coordinates: kept together or left out together (about a
spin, its kinematics depend on where it has turned to)."""


@dataclass(frozen=True)
class Linear:
    """The linear model about x (the full state) with the runtime
    parameters p: matrices over the kept states."""

    scene: Scene
    states: tuple[str, ...]
    """The kept states: A's rows and columns."""
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    x: np.ndarray
    p: np.ndarray
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    dropped: tuple[str, ...]
    """Coordinates left out: their rates do not vanish at x (a spin)."""
    residual: float
    """max |dx/dt| over the kept states at x."""
    relative_residual: float
    """The largest kept rate's share of its row's scale (relative): above
    RESIDUAL_BAR, x is no equilibrium."""
    worst: str
    """The kept state whose rate has that share ("" if none is kept)."""
    worst_rate: float
    found: str
    """How x was chosen: given, the scene's, or found (and how)."""

    @property
    def eigenvalues(self) -> np.ndarray:
        """A's, as the modes read them (the words print these)."""
        return modes.eigenvalues(self.A)


def with_model(scene: Scene) -> Scene:
    """The scene built for linearize: C, its linear model, the Jacobian (one
    implicit method), no other integrator."""
    data = scene.model_dump(mode="json")
    data["outputs"]["linear_model"] = True
    data["targets"] = ["c"]
    data["integrators"] = [methods.STIFF_CHOICE[0]]
    return validate(data, scene.name)


def build(scene: Scene) -> Compiled:
    return compiled(scene_sources(with_model(scene)))


def parameters_of(scene: Scene, given: dict[str, float]) -> np.ndarray:
    """p[] from given, else simulate.parameters; every runtime one needed."""
    bad = sorted(set(given) - set(scene.runtime))
    if bad:
        raise SceneError(f"{scene.name}: {bad[0]} is not a runtime parameter of the scene "
                         f"({', '.join(scene.runtime) or 'it has none'})")  # fmt: skip
    values = {**scene.simulate.parameters, **given}
    missing = [n for n in scene.runtime if n not in values]
    if missing:
        raise SceneError(f"{scene.name}: no value for the runtime parameter {missing[0]} "
                         "(give it with --param NAME=VALUE or in simulate.parameters)")  # fmt: skip
    p = np.array([float(values[n]) for n in scene.runtime])
    _finite(p, scene.runtime, "parameter")
    return p


def _finite(v: np.ndarray, names: tuple[str, ...], what: str) -> None:
    bad = [n for n, x in zip(names, v, strict=True) if not math.isfinite(x)]
    if bad:
        raise SceneError(f"{what} {bad[0]} is {v[names.index(bad[0])]}: not a finite number")


def state_of(
    scene: Scene, vector: list[float] | None, named: dict[str, float] | None
) -> np.ndarray:
    """A full state from a vector (all nx values) or by name (others 0, e0 1)."""
    if vector is not None:
        if len(vector) != len(scene.states):
            raise SceneError(
                f"the equilibrium has {len(vector)} values; {scene.name} has "
                f"{len(scene.states)} states ({', '.join(scene.states)})"
            )
        x = np.array(vector, dtype=float)
    else:
        named = named or {}
        bad = sorted(set(named) - set(scene.states))
        if bad:
            raise SceneError(f"{bad[0]} is not a state of {scene.name} "
                             f"({', '.join(scene.states)})")  # fmt: skip
        start = {"e0": 1.0, **named}
        x = np.array([float(start.get(s, 0.0)) for s in scene.states])
    _finite(x, scene.states, "state")
    try:  # as a scene's start: each angle within MAX_START_ANGLE
        check_angles(dict(zip(scene.states, x, strict=True)), "")
    except ValueError as exc:
        raise SceneError(f"state {exc}") from None
    if scene.attitude == "quaternion":  # as a scene's start: |e| within the slack, normalized
        e = [scene.states.index(n) for n in QUATERNION]
        try:
            check_quaternion(dict(zip(QUATERNION, x[e], strict=True)), "the equilibrium")
        except ValueError as exc:
            raise SceneError(str(exc)) from None
        x[e] /= math.hypot(*x[e])
    _within_spin(scene, x, "state")
    return x


def _within_spin(scene: Scene, x: np.ndarray, what: str) -> None:
    """Every speed of x finite and at most MAX_SPIN."""
    fast = [i for i in _speeds(scene) if not abs(x[i]) <= MAX_SPIN]
    if fast:
        raise SceneError(
            f"{what} {scene.states[fast[0]]} = {x[fast[0]]:g}: beyond {MAX_SPIN:g} rad/s, the "
            "rates' squares times the inertias overflow double arithmetic"
        )


def _speeds(scene: Scene) -> list[int]:
    """The speeds (u, w): the states with a dynamic equation."""
    return [i for i, s in enumerate(scene.states) if s[0] in "uw"]


def locked_inertia(scene: Scene, p: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """The inertia with the wheels locked (A-components), and each wheel's
    axial momentum direction J g (the rate it multiplies: its w or u4)."""
    if scene.rotors:
        known = resolved(scene.parameters, scene.rotors, dict(zip(scene.runtime, p, strict=True)))
        assert known is not None  # p holds every runtime value
        values, rotors = known
        lumped = np.array(lumped_inertia(values, rotors))
        axes = list(unit_axes(rotors, {}))
        js = [float(r.J) * g for r, g in zip(rotors, axes, strict=True)]
        return lumped + sum(np.outer(j, g) for j, g in zip(js, axes, strict=True)), js
    v = {**scene.folded(), **dict(zip(scene.runtime, p, strict=True))}
    a11, a22, a33, a13 = physics.lumped_inertias(*(v[n] for n in physics.LUMPED_FROM))
    inertia = np.array([[a11, 0.0, a13], [0.0, a22 + v["J"], 0.0], [a13, 0.0, a33]])
    return inertia, [np.array([0.0, v["J"], 0.0])]


def wheel_rates(scene: Scene, p: np.ndarray, start: np.ndarray) -> list[float]:
    """Each wheel's rate relative to the carrier that its law holds steady
    (a speed controller's w_ref, less what friction takes; a free wheel's
    rate from the start state); Newton makes them exact."""
    v = dict(zip(scene.runtime, p, strict=True))
    idx = {s: i for i, s in enumerate(scene.states)}
    if not scene.rotors:
        law = {**scene.folded(), **v}
        if scene.effects.torque == "speed_controller":
            return [float(law["w_ref"])]
        return [float(start[idx["u4"]] - start[idx["u2"]])]
    out = []
    for k, r in enumerate(scene.rotors, 1):
        law = {key: v.get(f"{key}_{k}", val) for key, val in r.law().items()}
        if r.torque == "speed_controller":
            gain = float(law["k"])
            out.append(gain * float(law["w_ref"]) / (gain + r.b))
        elif r.torque == "constant" and r.b > 0:
            out.append(float(law["T"]) / r.b)
        else:
            g = unit_axes(scene.rotors, v)[k - 1]
            out.append(float(start[idx[f"w{k}"]] - g @ start[[idx[f"u{i}"] for i in (1, 2, 3)]]))
    return out


def find_spin(
    scene: Scene, comp: Compiled, p: np.ndarray, rate: float | None, axis: int | None
) -> tuple[np.ndarray, str]:
    """The steady spin nearest the one asked: rate (rad/s; default the
    scene's start |w_A|) about the principal axis of the locked inertia
    nearest a_axis (default: nearest the start's w_A), each wheel at the
    rate its law holds; Gauss-Newton on the speeds' rates then makes it an
    equilibrium (with wheel momentum off the axis, the spin axis moves)."""
    start = np.array(scene.initial_state())
    idx = {s: i for i, s in enumerate(scene.states)}
    body = [idx[f"u{i}"] for i in (1, 2, 3)]
    w0 = start[body]
    inertia, _ = locked_inertia(scene, p)
    _, vectors = np.linalg.eigh(inertia)
    toward = np.eye(3)[axis - 1] if axis is not None else w0
    if not np.any(toward):
        toward = np.eye(3)[1]  # a hold: the direction does not matter
    e = vectors[:, int(np.argmax(np.abs(vectors.T @ toward)))]
    e = e if e @ toward >= 0 else -e
    omega = float(np.linalg.norm(w0)) if rate is None else rate
    if not abs(omega) <= MAX_SPIN:
        raise SceneError(
            f"a spin of {omega:g} rad/s: beyond {MAX_SPIN:g} rad/s, the rates' squares times "
            "the inertias overflow double arithmetic"
        )
    x = start.copy()
    x[[i for i, s in enumerate(scene.states) if s[0] == "u"]] = 0.0
    x[body] = omega * e
    rel = wheel_rates(scene, p, start)
    if scene.rotors:
        axes = unit_axes(scene.rotors, dict(zip(scene.runtime, p, strict=True)))
        for k, (g, w) in enumerate(zip(axes, rel, strict=True), 1):
            x[idx[f"w{k}"]] = w + g @ x[body]
    else:
        x[idx["u4"]] = rel[0] + x[idx["u2"]]
    _within_spin(scene, x, "at the steady spin asked for (each wheel at the rate its law holds),")
    x = _newton(comp, comp.setup(p), x, e, omega, body)
    where = f"a{axis}" if axis is not None else "the start's rate"
    how = f"found: a steady spin of {omega:g} rad/s about the principal axis nearest {where}"
    if omega == 0:
        return x, "found: at rest (a hold), each wheel at the rate its law holds"
    w = x[body] / np.max(np.abs(x[body]))  # scaled first: a subnormal spin's squares underflow
    off = math.degrees(math.acos(min(1.0, abs(e @ w) / np.linalg.norm(w))))
    if off > 1e-6:
        how += f" (the wheels' momentum tilts it: it turns {off:.3g} deg off that axis)"
    return x, how


def _newton(
    comp: Compiled, c: np.ndarray, x: np.ndarray, e: np.ndarray, omega: float, body: list[int]
) -> np.ndarray:
    """Zero the speeds' rates over the speeds, holding e . w_A = omega."""
    speeds = [i for i in range(comp.nx) if comp.manifest["states"][i][0] in "uw"]
    scale = max(1.0, float(np.max(np.abs(x[speeds]))))
    for _ in range(NEWTON_STEPS):
        f = comp.rhs(x, c)[speeds]
        jac = comp.jacobian(x, c)[np.ix_(speeds, speeds)]
        if not (np.all(np.isfinite(f)) and np.all(np.isfinite(jac))):
            raise SceneError(
                f"a spin of {omega:g} rad/s: the rates' derivatives overflow double arithmetic "
                "(ask for a slower spin)"
            )
        row = np.zeros(len(speeds))
        row[[speeds.index(i) for i in body]] = e
        system = np.vstack([jac, row])
        residual = np.concatenate([f, [e @ x[body] - omega]])
        step = np.linalg.lstsq(system, -residual, rcond=None)[0]
        x = x.copy()
        x[speeds] += step
        if np.max(np.abs(step)) <= 1e-15 * scale:
            break
    return x


def linearize(
    scene: Scene,
    comp: Compiled,
    p: np.ndarray,
    x: np.ndarray,
    found: str,
) -> Linear:
    """The linear model about x: the kept states (rates that vanish, and
    every speed), A from the Jacobian, B, C, D from <prefix>_linear."""
    if scene.attitude == "euler312":
        q2 = float(x[scene.states.index("q2")])
        if abs(math.cos(q2)) < GIMBAL_LOCK_COS:
            raise SceneError(
                f"q2 = {q2:.17g}: at gimbal lock (|cos q2| < {GIMBAL_LOCK_COS:g}), where the "
                "3-1-2 angles' rates divide by cos q2: take another point, or Euler parameters"
            )
    c = comp.setup(p)
    f = comp.rhs(x, c)
    full_a = comp.jacobian(x, c)
    nx = comp.nx
    _, b, cm, d = generated(comp, x, c)
    if not all(np.all(np.isfinite(m)) for m in (f, full_a, b, cm, d)):
        raise SceneError(
            f"{scene.name}: the model at this point is not finite: its values overflow "
            "double arithmetic (a state or parameter too large)"
        )
    speeds = _speeds(scene)
    share = relative(f, full_a, x)
    still = [i in speeds or share[i] <= DRIFT_BAR for i in range(nx)]
    attitude = [i for i, s in enumerate(scene.states) if s in ATTITUDE]
    if not all(still[i] for i in attitude):  # the attitude turns: all of it goes
        for i in attitude:
            still[i] = False
    kept = [i for i in range(nx) if still[i]]
    dropped = [i for i in range(nx) if i not in kept]
    coupling = full_a[np.ix_(kept, dropped)]
    if coupling.size and np.any(coupling != 0):
        i, j = np.argwhere(coupling != 0)[0]
        raise SceneError(
            f"no steady point: {scene.states[dropped[j]]} moves "
            f"({scene.states[dropped[j]]}' = {f[dropped[j]]:.3g}) and "
            f"{scene.states[kept[i]]}' depends on it"
        )
    a = full_a[np.ix_(kept, kept)]
    residual = float(np.max(np.abs(f[kept]))) if kept else 0.0
    worst = max(kept, key=lambda i: (share[i], abs(f[i])), default=None)
    return Linear(
        scene=scene,
        states=tuple(scene.states[i] for i in kept),
        inputs=tuple(comp.manifest["linear"]["inputs"]),
        outputs=tuple(comp.manifest["linear"]["outputs"]),
        x=x,
        p=p,
        A=a,
        B=b[kept],
        C=cm[:, kept],
        D=d,
        dropped=tuple(scene.states[i] for i in dropped),
        residual=residual,
        relative_residual=float(share[worst]) if worst is not None else 0.0,
        worst=scene.states[worst] if worst is not None else "",
        worst_rate=float(f[worst]) if worst is not None else 0.0,
        found=found,
    )


def relative(f: np.ndarray, jac: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Each rate's share of its own row's scale, |f_i| / (|J| max(|x|, 1))_i:
    of the rates that changing each state by itself (at least by 1, in its
    unit) gives row i. An attitude angle's row reads the body rates (and the
    angles), not a wheel's speed; a rate no state moves (a constant torque)
    has an infinite share. Without overflow: each row over its largest
    entry, max(|x|, 1) over its largest."""
    size = np.maximum(np.abs(x), 1.0)
    top = float(np.max(size, initial=1.0))
    big = np.max(np.abs(jac), axis=1, initial=0.0)
    rows = np.abs(jac) / np.where(big > 0, big, 1.0)[:, None]
    with np.errstate(all="ignore"):  # a rate far beyond its scale: inf, as its share is
        out = np.abs(f) / big / top / (rows @ (size / top))
    return np.where(f == 0, 0.0, out)


def generated(comp: Compiled, x: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, ...]:
    """A, B, C, D as <prefix>_linear computes them at x, over all states."""
    nx, nu, ny = comp.nx, *(len(comp.manifest["linear"][k]) for k in ("inputs", "outputs"))
    shapes = ((nx, nx), (nx, nu), (ny, nx), (ny, nu))
    out = [np.zeros(max(1, r * k)) for r, k in shapes]  # never an empty buffer
    comp.function("linear")(0.0, comp.doubles(x), comp.doubles(c), *map(comp.doubles, out))
    return tuple(o[: r * k].reshape(r, k) for o, (r, k) in zip(out, shapes, strict=True))


def model(
    scene: Scene,
    *,
    state: list[float] | None = None,
    at: dict[str, float] | None = None,
    parameters: dict[str, float] | None = None,
    spin: float | None = None,
    axis: int | None = None,
) -> Linear:
    """The linear model about the point given (state: every value; at: by
    name), else the scene's equilibrium, else the spin found (spin, axis)."""
    if state is not None and at is not None:
        raise SceneError("give the equilibrium as a whole state or by name, not both")
    if (state is not None or at is not None) and (spin is not None or axis is not None):
        raise SceneError("give the equilibrium or ask for a spin to be found, not both")
    p = parameters_of(scene, parameters or {})
    given: tuple[np.ndarray, str] | None = None
    if state is not None or at is not None:
        given = state_of(scene, state, at), "given"
    elif scene.equilibrium is not None and spin is None and axis is None:
        given = state_of(scene, None, scene.equilibrium), "the scene's equilibrium"
    comp = build(scene)
    try:
        comp.setup(p)
    except ValueError as exc:  # each value valid, yet setup refuses them together
        raise SceneError(f"{scene.name}: parameters: {exc}") from exc
    x, how = given if given is not None else find_spin(scene, comp, p, spin, axis)
    return linearize(scene, comp, p, x, how)
