"""Random and invalid inputs for the tests, and the Python mirror of the setup checks.

Pure numpy (only :mod:`gyrogen.abi` and a scene's values besides): the tests use it
to drive both the numpy reference and the generated code, so it must not depend on
the symbolic model.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gyrogen import abi
from gyrogen.abi import MAX_CONDITION, TRIANGLE_SLACK
from gyrogen.abi_rotors import (
    AXIS_NORM_SLACK,
    GIMBAL_INERTIA,
    GIMBAL_KEYS,
    GIMBAL_PERP_SLACK,
    rotor_name,
)
from gyrogen.oracle.reference import lumped
from gyrogen.scene import Scene
from gyrogen.scene.rotors import Rotor

__all__ = ["invalid_parameters", "random_parameters", "random_states", "setup_code"]

Array = NDArray[np.float64]

N_STATES = len(abi.STATES)
N_PARAMETERS = len(abi.PARAMETERS)
_P = {name: k for k, name in enumerate(abi.PARAMETERS)}


def setup_code(p: ArrayLike) -> int:
    """Validity code of one parameter vector, as the generated ``<prefix>_setup`` returns it.

    Codes are those of ``abi.SETUP_CODES``, checked in order, the first failure wins:
    1 a parameter is NaN or infinite; 2 ``m_a <= 0`` or ``m_b <= 0``; 3 ``I <= 0`` or
    ``J <= 0``; 4 the carrier inertia ``[[I11, 0, I13], [0, I22, 0], [I13, 0, I33]]`` is not
    positive definite; 5 its principal moments (I22 and the eigenvalues of
    ``[[I11, I13], [I13, I33]]``) violate the triangle inequality by more than
    ``1e-12 * (sum of the three)``; 6 ``J > 2 I`` by more than ``1e-12 * (2 I + J)``;
    7 the mass matrix's coupled block has a condition number above ``MAX_CONDITION``;
    9 each value is valid and yet what the equations derive from them overflows
    (T / J, T / I~22, 1 / det and the lumped inertias: setup's constants, by another
    road). Returns 0 if all checks pass.
    """
    pa = np.asarray(p, dtype=np.float64)
    if pa.shape != (N_PARAMETERS,):
        raise ValueError(f"p must have shape ({N_PARAMETERS},), got {pa.shape}")
    if not np.all(np.isfinite(pa)):
        return 1
    v = {name: float(pa[k]) for name, k in _P.items()}
    if v["m_a"] <= 0.0 or v["m_b"] <= 0.0:
        return 2
    if v["I"] <= 0.0 or v["J"] <= 0.0:
        return 3
    I11, I22, I33, I13 = v["I11"], v["I22"], v["I33"], v["I13"]
    if not (I11 > 0.0 and I22 > 0.0 and I33 > 0.0 and I11 * I33 - I13 * I13 > 0.0):
        return 4
    mean = 0.5 * (I11 + I33)
    radius = math.hypot(0.5 * (I11 - I33), I13)
    moments = (I22, mean + radius, mean - radius)
    total = sum(moments)
    if 2.0 * max(moments) - total > TRIANGLE_SLACK * total:
        return 5
    I, J = v["I"], v["J"]
    if J - 2.0 * I > TRIANGLE_SLACK * (2.0 * I + J):
        return 6
    if not float(lumped_condition(pa)) <= MAX_CONDITION:
        return 7
    with np.errstate(all="ignore"):
        a11, a22, a33, a13, _, _ = lumped(pa)
        det = a11 * a33 - a13 * a13
        derived = (a11, a22, a33, a13, 1.0 / det, J / det, v["T"] / J, v["T"] / a22)
    return 0 if all(math.isfinite(float(d)) for d in derived) else 9


def _log_uniform(rng: np.random.Generator, lo: float, hi: float, n: int) -> Array:
    return np.exp(rng.uniform(math.log(lo), math.log(hi), n))


def _draw_parameters(rng: np.random.Generator, n: int) -> Array:
    """One unchecked batch of parameter rows (see :func:`random_parameters`)."""
    p = np.empty((n, N_PARAMETERS))
    p[:, _P["m_a"]] = _log_uniform(rng, 0.1, 1000.0, n)
    p[:, _P["m_b"]] = _log_uniform(rng, 0.1, 1000.0, n)

    # Carrier: principal moments (y + z, x + z, x + y) of second moments x, y, z >= 0
    # satisfy the triangle inequality by construction; one of x, y, z is sometimes 0
    # (a lamina: equality). Then rotate the a1-a3 pair by a random angle.
    scale = _log_uniform(rng, 1e-3, 1e2, n)
    w = rng.uniform(0.02, 1.0, (n, 3))
    lamina = rng.random(n) < 0.15
    w[lamina, rng.integers(0, 3, int(lamina.sum()))] = 0.0
    x, y, z = (scale * w[:, k] for k in range(3))
    P1, P2, P3 = y + z, x + z, x + y
    theta = rng.uniform(-np.pi, np.pi, n)
    c, s = np.cos(theta), np.sin(theta)
    p[:, _P["I11"]] = P1 * c**2 + P3 * s**2
    p[:, _P["I22"]] = P2
    p[:, _P["I33"]] = P1 * s**2 + P3 * c**2
    p[:, _P["I13"]] = (P1 - P3) * s * c

    # Rotor: transverse I, axial J <= 2 I (sometimes J = 2 I exactly, a thin disc).
    I = _log_uniform(rng, 1e-4, 10.0, n)
    ratio = rng.uniform(0.05, 1.0, n)
    ratio[rng.random(n) < 0.1] = 1.0
    p[:, _P["I"]] = I
    p[:, _P["J"]] = 2.0 * I * ratio

    p[:, _P["l1"]] = rng.uniform(-2.0, 2.0, n)
    p[:, _P["l3"]] = rng.uniform(-2.0, 2.0, n)
    p[:, _P["g"]] = rng.uniform(-20.0, 20.0, n)
    p[:, _P["T"]] = rng.uniform(-10.0, 10.0, n)
    return p


def lumped_condition(p: ArrayLike) -> Array:
    """Condition number of the coupled block [[I~11, I~13], [I~13, I~33]] of the
    mass matrix (the other rows decouple): how much any double-precision solve
    of M u' = F may amplify rounding. Shape: p's batch shape."""
    with np.errstate(all="ignore"):  # extreme vectors give inf or NaN: not conditioned
        return _condition(np.asarray(p, dtype=float))


def _condition(pa: Array) -> Array:
    m_a, m_b = pa[..., _P["m_a"]], pa[..., _P["m_b"]]
    l1, l3 = pa[..., _P["l1"]], pa[..., _P["l3"]]
    mu = m_a * m_b / (m_a + m_b)
    i_rot = pa[..., _P["I"]]
    a11, _, a33, a13, _, _ = lumped(pa)  # the reference's lumped inertias
    half_gap = np.sqrt(0.25 * (a11 - a33) ** 2 + a13**2)
    largest = 0.5 * (a11 + a33) + half_gap
    # largest / smallest with smallest = det / largest (mean - half_gap would
    # cancel). det multiplied out as the generated setup has it: in
    # a11 a33 - a13^2 the mu^2 terms would cancel in rounding.
    i11, i33, i13 = pa[..., _P["I11"]] + i_rot, pa[..., _P["I33"]] + i_rot, pa[..., _P["I13"]]
    det = i11 * i33 - i13**2 + mu * (l1**2 * i11 + l3**2 * i33 + 2 * i13 * l1 * l3)
    return np.asarray(largest**2 / det)


def random_parameters(
    rng: np.random.Generator, n: int, max_condition: float | None = None
) -> Array:
    """``n`` physically valid parameter rows, shape ``(n, 12)``, in ``abi.PARAMETERS`` order.

    Masses log-uniform in [0.1, 1000]; carrier principal moments satisfying the
    triangle inequality (some laminae), rotated in the a1-a3 plane so I13 != 0; rotor
    ``J <= 2 I``; l1, l3 in [-2, 2]; g in [-20, 20]; T in [-10, 10]. Rows failing
    :func:`setup_code` (e.g. by rounding) are redrawn, so every row has code 0.
    With ``max_condition``, rows whose :func:`lumped_condition` exceeds it are
    redrawn too.
    """
    if n < 0:
        raise ValueError("n must be >= 0")
    p = _draw_parameters(rng, n)
    for _ in range(100):
        bad = np.array([setup_code(row) != 0 for row in p], dtype=bool)
        if max_condition is not None:
            bad |= lumped_condition(p) > max_condition
        if not bad.any():
            break
        p[bad] = _draw_parameters(rng, int(bad.sum()))
    else:  # pragma: no cover - practically unreachable
        raise RuntimeError("could not draw valid parameters")
    assert all(setup_code(row) == 0 for row in p)
    return p


def random_states(rng: np.random.Generator, n: int, max_q2: float = 1.2) -> Array:
    """``n`` state rows, shape ``(n, 14)``, in ``abi.STATES`` order.

    Angles uniform in [-pi, pi] except ``|q2| <= max_q2`` (away from gimbal lock);
    positions in [-100, 100]; u1..u3 in [-5, 5]; u4 in [-200, 200]; u5..u7 in [-50, 50].
    """
    if not 0.0 <= max_q2 < np.pi / 2:
        raise ValueError("max_q2 must be in [0, pi/2)")
    x = np.empty((n, N_STATES))
    x[:, 0] = rng.uniform(-np.pi, np.pi, n)
    x[:, 1] = rng.uniform(-max_q2, max_q2, n)
    x[:, 2] = rng.uniform(-np.pi, np.pi, n)
    x[:, 3] = rng.uniform(-np.pi, np.pi, n)
    x[:, 4:7] = rng.uniform(-100.0, 100.0, (n, 3))
    x[:, 7:10] = rng.uniform(-5.0, 5.0, (n, 3))
    x[:, 10] = rng.uniform(-200.0, 200.0, n)
    x[:, 11:14] = rng.uniform(-50.0, 50.0, (n, 3))
    return x


def invalid_parameters(base: ArrayLike) -> list[tuple[str, Array, int]]:
    """Invalid variants of a valid ``base`` vector: ``(description, vector, expected code)``.

    Each vector fails the intended check and none before it (a few deliberately fail
    several checks, to pin the order: the expected code is the first failing one).
    """
    b = np.asarray(base, dtype=np.float64)
    if setup_code(b) != 0:
        raise ValueError("base must be a valid parameter vector (setup_code 0)")

    def variant(**changes: float) -> Array:
        v = b.copy()
        for name, value in changes.items():
            v[_P[name]] = value
        return v

    I11, I22, I33, I13 = (float(b[_P[k]]) for k in ("I11", "I22", "I33", "I13"))
    I = float(b[_P["I"]])
    nan, inf = math.nan, math.inf
    # cond(M) ~ mu / tiny with l1 = l3 = 1: far above MAX_CONDITION whatever the masses
    tiny = 1e-15 * b[_P["m_a"]] * b[_P["m_b"]] / (b[_P["m_a"]] + b[_P["m_b"]])
    sign13 = 1.0 if I13 >= 0.0 else -1.0
    cases: list[tuple[str, Array, int]] = [
        ("m_a is NaN", variant(m_a=nan), 1),
        ("I13 is NaN", variant(I13=nan), 1),
        ("T is NaN", variant(T=nan), 1),
        ("I22 is +Inf", variant(I22=inf), 1),
        ("l1 is +Inf", variant(l1=inf), 1),
        ("g is -Inf", variant(g=-inf), 1),
        ("NaN in l3 and m_b < 0: NaN is checked first", variant(l3=nan, m_b=-1.0), 1),
        ("m_a = 0", variant(m_a=0.0), 2),
        ("m_b < 0", variant(m_b=-0.5), 2),
        ("m_a = 0 and J = 0: masses are checked first", variant(m_a=0.0, J=0.0), 2),
        ("J = 0", variant(J=0.0), 3),
        ("I < 0", variant(I=-I), 3),
        ("I < 0 and I11 < 0: rotor is checked before carrier", variant(I=-I, I11=-I11), 3),
        ("I11 = 0", variant(I11=0.0), 4),
        ("I33 < 0", variant(I33=-I33), 4),
        ("I22 = 0", variant(I22=0.0), 4),
        ("I11*I33 < I13^2", variant(I13=sign13 * 1.01 * math.sqrt(I11 * I33)), 4),
        ("I11*I33 = I13^2 (singular)", variant(I11=1.0, I33=4.0, I13=2.0), 4),
        (
            "carrier triangle violated: I22 > I11 + I33 with I13 = 0",
            variant(I13=0.0, I22=1.5 * (I11 + I33)),
            5,
        ),
        (
            "carrier triangle violated: I11 > I22 + I33 with I13 = 0",
            variant(I13=0.0, I11=1.5 * (I22 + I33)),
            5,
        ),
        (
            "carrier triangle violated in the a1-a3 plane: I22 tiny next to the in-plane pair",
            variant(I11=2.0, I33=2.0, I13=1.0, I22=1e-3),
            5,
        ),
        (
            "carrier triangle and rotor both violated: carrier is checked first",
            variant(I13=0.0, I22=1.5 * (I11 + I33), J=3.0 * I),
            5,
        ),
        ("rotor 2 I < J", variant(J=2.5 * I), 6),
        ("rotor 2 I < J by 1e-9 relative", variant(J=2.0 * I * (1.0 + 1e-9)), 6),
        (
            "mass matrix numerically singular: a carrier and rotor 1e-15 mu tiny, far off A*",
            variant(I11=tiny, I22=tiny, I33=tiny, I13=0.0, I=tiny, J=tiny, l1=1.0, l3=1.0),
            7,
        ),
        ("T = 1e308 and J = 1e-300, each valid: T / J overflows", variant(T=1e308, J=1e-300), 9),
    ]
    if float(b[_P["J"]]) < 0.5:  # T alone (a scene with only T at run time)
        cases.append(("T = DBL_MAX: T / J overflows", variant(T=np.finfo(float).max), 9))
    return cases


def invalid_cluster(scene: Scene, base: np.ndarray) -> list[tuple[str, np.ndarray, int]]:
    """A cluster's runtime inertial values made unphysical, with setup's code:
    a mass at 0 (2); I_k, J_k or a gimbal frame's inertia at 0 or negative
    (3); the carrier not positive definite (4) or past the triangle
    inequality (5); J_k above 2 I_k or a gimbal frame past its triangle
    inequality (6); a
    runtime axis longer or shorter than the slack allows, or 0 (8)."""
    index = {n: j for j, n in enumerate(scene.runtime)}
    known = {**scene.folded(), **dict(zip(scene.runtime, base, strict=True))}
    edits: list[tuple[dict[str, float], int]] = []
    for name in scene.runtime:
        key = name.rpartition("_")[0]
        if name == "m_a" or key in ("m", GIMBAL_KEYS["m"]):
            edits.append(({name: 0.0}, 2))
        elif key in ("I", "J", *GIMBAL_INERTIA):
            edits += [({name: 0.0}, 3), ({name: -1e-3}, 3)]
    if "I11" in index:
        edits.append(({"I11": -float(known["I11"])}, 4))
    if "I33" in index:
        edits.append(({"I33": 3.0 * (float(known["I11"]) + float(known["I22"]))}, 5))
    for k, r in enumerate(scene.rotors, 1):
        if f"J_{k}" in index or f"I_{k}" in index:
            edits.append(({f"J_{k}": 2.01 * float(known[f"I_{k}"] if r.I == "runtime" else r.I)}
                          if f"J_{k}" in index else {f"I_{k}": 0.49 * float(r.J)}, 6))  # fmt: skip
        frame = [rotor_name(n, k) for n in GIMBAL_INERTIA]
        if r.gimbal is not None and (first := next((n for n in frame if n in index), None)):
            values = {n: float(known[n] if n in index else v)
                      for n, v in zip(frame, r.gimbal.inertia, strict=True)}  # fmt: skip
            others = sum(v for n, v in values.items() if n != first)
            edits.append(({first: 1.5 * others}, 6))  # past the sum of the other two
        for key in ("g", "gg"):
            if f"{key}1_{k}" in index:
                axis = {f"{key}{i}_{k}": float(known[f"{key}{i}_{k}"]) for i in (1, 2, 3)}
                norm = math.sqrt(sum(v * v for v in axis.values()))
                for length in (1.0 + 3.0 * AXIS_NORM_SLACK, 1.0 - 3.0 * AXIS_NORM_SLACK, 0.0):
                    edits.append(({n: v * length / norm for n, v in axis.items()}, 8))
        if r.gimbal is not None and (f"g1_{k}" in index or f"gg1_{k}" in index):
            edits.append((_lost_perpendicular(r, k, known, index), 10))
    cases = []
    for edit, code in edits:
        p = base.copy()
        for name, value in edit.items():
            p[index[name]] = value
        what = ", ".join(f"{n} = {v:g}" for n, v in edit.items())
        cases.append((what, p, code))
    return cases


def _lost_perpendicular(
    r: Rotor, k: int, known: dict[str, float | str], index: dict[str, int]
) -> dict[str, float]:
    """Gimbal k's runtime axis (the spin axis if runtime, else the gimbal
    axis) turned toward the other by 3 GIMBAL_PERP_SLACK (a cosine past the
    slack), its length kept."""
    spin = f"g1_{k}" in index
    key, other = ("g", "gg") if spin else ("gg", "g")
    v = np.array([float(known[f"{key}{i}_{k}"]) for i in (1, 2, 3)])
    if f"{other}1_{k}" in index:
        w = np.array([float(known[f"{other}{i}_{k}"]) for i in (1, 2, 3)])
    else:
        assert r.gimbal is not None
        w = np.array(r.gimbal.axis if spin else r.axis, dtype=float)
    w = w / np.linalg.norm(w)
    turned = v + 3.0 * GIMBAL_PERP_SLACK * np.linalg.norm(v) * w
    turned *= np.linalg.norm(v) / np.linalg.norm(turned)
    return {f"{key}{i}_{k}": float(turned[i - 1]) for i in (1, 2, 3)}
