"""`gyrogen fmu`: the FMU passes FMPy's checks, FMPy simulates it
in both modes in agreement with `gyrogen simulate` (on a 1 s slice here;
`make fmu-agreement` runs the whole t_end), bad parameter values through
the FMI setters are FMI errors with a logged reason, its sources compile
under the strict flags, and the command's refusals are one line each."""

from __future__ import annotations

import ctypes
import math
import subprocess
import sys
import zipfile
from collections.abc import Callable
from functools import cache
from pathlib import Path
from typing import Any

import fmpy
import numpy as np
import pytest
from conftest import built_once
from fmpy.build import build_platform_binary
from fmpy.fmi1 import FMICallException
from fmpy.simulation import instantiate_fmu
from fmpy.validation import validate_fmu
from fmu_cases import BAR, MODES, build, build_model, by_fmpy, cases, differences, reference
from wide import WIDE

from gyrogen import abi, api, methods
from gyrogen.runtime.flags import C_STRICT, C_WARNINGS
from gyrogen.runtime.fmu_build import fmi_headers
from gyrogen.scene import builtin_text, load, parse

pytestmark = pytest.mark.slow  # FMUs built and simulated with FMPy

SLICE = 1.0
"""Seconds simulated here; `make fmu-agreement` runs each scene's t_end."""
CASES = {case.label: case for case in cases()}
SCENES = Path(__file__).resolve().parents[1] / "generator" / "gyrogen" / "scenes"


@pytest.fixture(scope="module")
def fmus(tmp_path_factory: pytest.TempPathFactory, cli) -> dict[str, Path]:
    """The four FMUs, built once per run: the default and the stiff scene's
    through the command line, the quaternion scene's (no built-in) and the
    CMG pyramid's through the API."""

    def make(root: Path) -> None:
        code, out, err = cli(["fmu", "gyrostat", "--out", str(root / "default")])
        assert code == 0, err
        assert "wrote" in out and "FMI 2.0" in out and "(taylor)" in out  # auto: smooth
        code, _, err = cli(
            ["fmu", "stiff_wheel", "--method", "rodas4", "--out", str(root / "stiff")]
        )
        assert code == 0, err
        build(CASES["quaternion"], root / "quaternion")
        build(CASES["cmg"], root / "cmg")

    root = built_once(tmp_path_factory, "fmus", make)
    return {
        "default": root / "default" / "gyrostat.fmu",
        "stiff": root / "stiff" / "stiff_wheel.fmu",
        "quaternion": root / "quaternion" / "gyrostat_quat.fmu",
        "cmg": root / "cmg" / "cmg4_pyramid.fmu",
    }


@cache
def simulated(label: str, root: Path) -> Any:
    """`gyrogen simulate`'s trajectory over SLICE, once per case."""
    return reference(CASES[label], SLICE, root / f"simulate-{label}")


@pytest.mark.parametrize("label", list(CASES))
@WIDE
def test_fmpy_finds_no_problem(fmus: dict[str, Path], label: str) -> None:
    assert validate_fmu(str(fmus[label])) == []


def test_contents(fmus: dict[str, Path]) -> None:
    """Model description, the binary for this machine, and the sources;
    variables with units, parameters tunable, starts from the scene."""
    with zipfile.ZipFile(fmus["stiff"]) as zf:
        names = set(zf.namelist())
    assert names == {
        "modelDescription.xml",
        f"binaries/{fmpy.platform}/stiff_wheel.so",
        *(f"sources/stiff_wheel{s}" for s in (".c", ".h", "_ode.c", "_ode.h", "_fmi2.c")),
    }
    md = fmpy.read_model_description(str(fmus["stiff"]))
    assert md.modelExchange is not None and md.coSimulation is not None
    by_name = {v.name: v for v in md.modelVariables}
    scene = CASES["stiff"].scene
    assert by_name["k"].causality == "parameter" and by_name["k"].variability == "tunable"
    assert float(by_name["k"].start) == scene.simulate.parameters["k"]
    assert (by_name["k"].unit, by_name["u2"].unit, by_name["der(u2)"].unit) == (
        abi.UNITS["k"][0], "rad/s", "rad/s^2")  # fmt: skip
    assert by_name["angular_momentum[3]"].unit == abi.OUTPUT_DOC["angular_momentum"][0]
    assert float(by_name["u1"].start) == scene.simulate.initial["u1"]
    assert md.defaultExperiment.stopTime == str(scene.simulate.t_end)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("label", list(CASES))
def test_agrees_with_simulate(
    fmus: dict[str, Path], label: str, mode: str, tmp_path_factory: pytest.TempPathFactory
) -> None:
    ref = simulated(label, tmp_path_factory.getbasetemp())
    scaled, absolute = differences(by_fmpy(CASES[label], fmus[label], mode, SLICE), ref)
    assert scaled <= BAR and absolute <= BAR


class Log:
    """The FMU's logger: what it said, by status."""

    def __init__(self) -> None:
        self.lines: list[tuple[int, str]] = []

    def __call__(self, env: object, name: bytes, status: int, category: bytes, msg: bytes) -> None:
        self.lines.append((status, msg.decode()))


def instantiate(fmu: Path, mode: str, tmp_path: Path) -> tuple[Any, Log]:
    """An instance as FMPy makes one, with Log as its logger."""
    md = fmpy.read_model_description(str(fmu))
    unzipped = fmpy.extract(str(fmu), str(tmp_path / "unzipped"))
    log = Log()
    return instantiate_fmu(unzipped, md, fmi_type=mode, logger=log), log


def refused(call: object, log: Log, message: str) -> None:
    """call() is an FMI error, and the FMU logged message as one."""
    with pytest.raises(FMICallException):
        call()  # type: ignore[operator]
    assert (3, message) in [(s, m[-len(message) :]) for s, m in log.lines]


def initialized(fmu: Path, mode: str, tmp_path: Path, **experiment: float) -> tuple[Any, Log]:
    """An instance through initialization, from t = 0."""
    instance, log = instantiate(fmu, mode, tmp_path)
    instance.setupExperiment(startTime=0.0, **experiment)
    instance.enterInitializationMode()
    instance.exitInitializationMode()
    return instance, log


def vr(fmu: Path, *names: str) -> list[int]:
    md = fmpy.read_model_description(str(fmu))
    refs = {v.name: v.valueReference for v in md.modelVariables}
    return [refs[n] for n in names]


def test_bad_start_parameters_fail_initialization(fmus: dict[str, Path], tmp_path: Path) -> None:
    slave, log = instantiate(fmus["default"], "CoSimulation", tmp_path)
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.setReal(vr(fmus["default"], "m_a"), [-1.0])
    refused(slave.exitInitializationMode, log, abi.message(abi.SETUP_CODES, 2))
    slave.freeInstance()


def test_bad_parameters_between_steps_leave_the_old_ones(
    fmus: dict[str, Path], tmp_path: Path
) -> None:
    """Each refused, logged, and stepping goes on as if nothing was set."""
    fmu = fmus["default"]
    slave, log = initialized(fmu, "CoSimulation", tmp_path / "a")
    refused(lambda: slave.setReal(vr(fmu, "I11"), [math.nan]), log, abi.message(abi.SETUP_CODES, 1))
    refused(lambda: slave.setReal(vr(fmu, "I22"), [1e3]), log, abi.message(abi.SETUP_CODES, 5))
    refused(
        lambda: slave.setReal(vr(fmu, "q1"), [0.5]), log, "q1 is set before initialization only"
    )
    refused(lambda: slave.setReal(vr(fmu, "der(q1)"), [0.5]), log, "der(q1) is computed, not set")
    clean, _ = initialized(fmu, "CoSimulation", tmp_path / "b")
    for instance in (slave, clean):
        instance.doStep(0.0, 0.5)
    assert slave.getReal(vr(fmu, "q1", "u4")) == clean.getReal(vr(fmu, "q1", "u4"))
    for instance in (slave, clean):
        instance.freeInstance()


def test_bad_parameters_in_event_mode(fmus: dict[str, Path], tmp_path: Path) -> None:
    """Model Exchange: refused in event mode, and a good value taken."""
    fmu = fmus["stiff"]
    model, log = initialized(fmu, "ModelExchange", tmp_path)
    refused(lambda: model.setReal(vr(fmu, "k"), [-math.inf]), log, abi.message(abi.SETUP_CODES, 1))
    model.setReal(vr(fmu, "k"), [10.0])
    assert model.getReal(vr(fmu, "k")) == [10.0]
    model.freeInstance()


def test_a_failed_step_is_an_fmi_error(fmus: dict[str, Path], tmp_path: Path) -> None:
    """A step the integrator fails (a torque that overflows the state): the
    step fails with the integrator's code and reason."""
    fmu = fmus["default"]
    slave, log = initialized(fmu, "CoSimulation", tmp_path)
    slave.setReal(vr(fmu, "T"), [1e300])
    refused(
        lambda: slave.doStep(0.0, 0.1),
        log,
        f"gyrostat_taylor failed at t = 0 (code 3): {abi.message(abi.ODE_CODES, 3)}",
    )
    slave.freeInstance()


@pytest.mark.parametrize("h", [-0.1, math.nan, math.inf])
def test_a_step_size_is_refused_by_name(fmus: dict[str, Path], tmp_path: Path, h: float) -> None:
    """A communication step size below 0, NaN, or one that takes t past
    double range: the FMU says so (before: the integrator's "bad argument",
    naming no argument); the state stays."""
    fmu = fmus["default"]
    slave, log = initialized(fmu, "CoSimulation", tmp_path)
    before = slave.getReal(vr(fmu, "q1", "u4"))
    refused(
        lambda: slave.doStep(0.0, h),
        log,
        f"fmi2DoStep: the communication step size {h:g} is not >= 0, or t + h "
        f"({0.0 + h:.17g}) is not finite",
    )
    assert slave.getReal(vr(fmu, "q1", "u4")) == before
    slave.doStep(0.0, 0.1)
    slave.freeInstance()


@pytest.mark.parametrize(("t0", "h"), [(2.0**52, 0.5), (1e17, 0.1), (1e300, 0.1)])
def test_a_step_lost_in_the_rounding_of_t_is_refused(
    fmus: dict[str, Path], tmp_path: Path, t0: float, h: float
) -> None:
    """h > 0 with t + h == t: an FMI error naming h (before: fmi2OK, and the
    time and the state stood still, step after step)."""
    fmu = fmus["default"]
    instance, log = instantiate(fmu, "CoSimulation", tmp_path)
    instance.setupExperiment(startTime=t0)
    instance.enterInitializationMode()
    instance.exitInitializationMode()
    refused(
        lambda: instance.doStep(t0, h),
        log,
        f"fmi2DoStep: the communication step size {h:g} is lost in the rounding of t = {t0:.17g} "
        "(t + h == t)",
    )
    instance.freeInstance()


ATTITUDE = ("e0", "e1", "e2", "e3")


def started(fmu: Path, mode: str, tmp_path: Path, **values: float) -> tuple[Any, Log]:
    """An instance with these start values, through initialization."""
    instance, log = instantiate(fmu, mode, tmp_path)
    instance.setupExperiment(startTime=0.0)
    instance.enterInitializationMode()
    if values:
        instance.setReal(vr(fmu, *values), list(values.values()))
    instance.exitInitializationMode()
    return instance, log


@pytest.mark.parametrize("mode", MODES)
def test_euler_parameters_are_normalized_at_initialization(
    fmus: dict[str, Path], tmp_path: Path, mode: str
) -> None:
    """Start values 2 e: after initialization the state and the outputs are
    those of e, as the C library normalizes a start (before: Model
    Exchange's angular momentum came out 4 times e's)."""
    fmu = fmus["quaternion"]
    md = fmpy.read_model_description(str(fmu))
    start = {v.name: float(v.start) for v in md.modelVariables if v.name in ATTITUDE}
    names = [v.name for v in md.modelVariables if v.causality == "output"]
    clean, _ = started(fmu, mode, tmp_path / "clean")
    doubled, _ = started(fmu, mode, tmp_path / "doubled", **{k: 2 * v for k, v in start.items()})
    assert doubled.getReal(vr(fmu, *names)) == clean.getReal(vr(fmu, *names))
    if mode == "CoSimulation":
        for instance in (clean, doubled):
            instance.doStep(0.0, 0.5)
        assert doubled.getReal(vr(fmu, *names)) == clean.getReal(vr(fmu, *names))
    for instance in (clean, doubled):
        instance.freeInstance()


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("e", [(0.0, 0.0, 0.0, 0.0), (1e-170, 0.0, 0.0, 0.0), (1e200, 1.0, 0, 0)])
def test_euler_parameters_without_a_direction_are_refused(
    fmus: dict[str, Path], tmp_path: Path, mode: str, e: tuple[float, ...]
) -> None:
    """|e| of 0 (or below sqrt(DBL_MIN)) or too large to square: an FMI error
    at the end of initialization naming e0..e3 (before: Co-Simulation's
    first step failed with NaN states, Model Exchange went on with H = 0)."""
    fmu = fmus["quaternion"]
    instance, log = instantiate(fmu, mode, tmp_path)
    instance.setupExperiment(startTime=0.0)
    instance.enterInitializationMode()
    instance.setReal(vr(fmu, *ATTITUDE), list(e))
    refused(
        instance.exitInitializationMode,
        log,
        f"fmi2ExitInitializationMode: the start values of e0, e1, e2, e3 ({e[0]:g}, {e[1]:g}, "
        f"{e[2]:g}, {e[3]:g}) are no attitude: their norm is 0, below sqrt(DBL_MIN) or too large "
        "to square",
    )
    instance.freeInstance()


def test_a_start_at_gimbal_lock_is_refused(fmus: dict[str, Path], tmp_path: Path) -> None:
    """3-1-2 angles: the integrator's start check, at initialization."""
    fmu = fmus["default"]
    instance, log = instantiate(fmu, "ModelExchange", tmp_path)
    instance.setupExperiment(startTime=0.0)
    instance.enterInitializationMode()
    instance.setReal(vr(fmu, "q2"), [math.pi / 2])
    refused(
        instance.exitInitializationMode,
        log,
        "fmi2ExitInitializationMode: gyrostat_taylor refused the start state (code 6): "
        + abi.message(abi.ODE_CODES, 6),
    )
    instance.freeInstance()


def test_a_failed_initialization_leaves_the_error_state(
    fmus: dict[str, Path], tmp_path: Path
) -> None:
    """After fmi2ExitInitializationMode refused a start at gimbal lock, the
    instance is in FMI 2.0's error state: no continuous-time mode, no new
    start values, until fmi2Reset (before: continuous-time mode was entered
    and the derivatives at the refused state, 8e15, came back fmi2OK)."""
    fmu = fmus["default"]
    model, log = instantiate(fmu, "ModelExchange", tmp_path)
    model.setupExperiment(startTime=0.0)
    model.enterInitializationMode()
    model.setReal(vr(fmu, "q2"), [math.pi / 2])
    with pytest.raises(FMICallException):
        model.exitInitializationMode()
    refused(
        model.enterContinuousTimeMode,
        log,
        "fmi2EnterContinuousTimeMode: not allowed in the error state (only in event mode)",
    )
    refused(
        lambda: model.setReal(vr(fmu, "q2"), [0.0]),
        log,
        "fmi2SetReal: not allowed in the error state (only in the instantiated state, "
        "initialization mode, event mode, continuous-time mode or the step-complete state)",
    )
    refused(
        model.terminate,
        log,
        "fmi2Terminate: not allowed in the error state "
        "(only in event mode, continuous-time mode or the step-complete state)",
    )
    model.reset()
    model.setupExperiment(startTime=0.0)
    model.enterInitializationMode()
    model.exitInitializationMode()
    model.enterContinuousTimeMode()
    n = len(fmpy.read_model_description(str(fmu)).derivatives)
    dx = (ctypes.c_double * n)()
    model.getDerivatives(dx, n)
    assert all(math.isfinite(v) for v in dx)
    model.freeInstance()


def test_model_exchange_refuses_calls_out_of_order(fmus: dict[str, Path], tmp_path: Path) -> None:
    """FMI 2.0's table of the calls each state allows: a call out of order is
    an fmi2Error naming the call and the state, and the state stays (before:
    continuous-time mode and the derivatives right after instantiation,
    fmi2OK)."""
    fmu = fmus["default"]
    model, log = instantiate(fmu, "ModelExchange", tmp_path)
    n = len(fmpy.read_model_description(str(fmu)).derivatives)
    x, dx = (ctypes.c_double * n)(), (ctypes.c_double * n)()
    derivatives = ("fmi2GetDerivatives: not allowed in {} (only in event mode, continuous-time "
                   "mode, the terminated state or the error state)")  # fmt: skip
    model.setupExperiment(startTime=0.0)
    refused(
        model.enterContinuousTimeMode,
        log,
        "fmi2EnterContinuousTimeMode: not allowed in the instantiated state (only in event mode)",
    )
    refused(lambda: model.getDerivatives(dx, n), log, derivatives.format("the instantiated state"))
    refused(
        lambda: model.getReal(vr(fmu, "q1")),
        log,
        "fmi2GetReal: not allowed in the "
        "instantiated state (only in initialization mode, event mode, continuous-time mode, "
        "the step-complete state, the terminated state or the error state)",
    )
    model.enterInitializationMode()
    refused(lambda: model.getDerivatives(dx, n), log, derivatives.format("initialization mode"))
    refused(
        lambda: model.setTime(0.5),
        log,
        "fmi2SetTime: not allowed in initialization mode "
        "(only in event mode or continuous-time mode)",
    )
    model.exitInitializationMode()
    model.getContinuousStates(x, n)
    refused(
        lambda: model.setContinuousStates(x, n),
        log,
        "fmi2SetContinuousStates: not allowed in event mode (only in continuous-time mode)",
    )
    refused(
        lambda: model.completedIntegratorStep(),
        log,
        "fmi2CompletedIntegratorStep: not allowed in event mode (only in continuous-time mode)",
    )
    model.enterContinuousTimeMode()
    refused(
        lambda: model.newDiscreteStates(),
        log,
        "fmi2NewDiscreteStates: not allowed in continuous-time mode (only in event mode)",
    )
    model.setContinuousStates(x, n)
    model.getDerivatives(dx, n)
    model.terminate()
    refused(
        model.enterEventMode,
        log,
        "fmi2EnterEventMode: not allowed in the terminated state "
        "(only in event mode or continuous-time mode)",
    )
    model.getDerivatives(dx, n)
    model.freeInstance()


def test_outputs_that_are_not_finite_are_refused(fmus: dict[str, Path], tmp_path: Path) -> None:
    """States the FMU takes (finite) whose outputs are not: fmi2GetReal of the
    outputs is an fmi2Error naming the first that is not finite, as for the
    derivatives (before: fmi2OK with an infinite kinetic energy)."""
    fmu = fmus["stiff"]
    model, log = initialized(fmu, "ModelExchange", tmp_path)
    model.enterContinuousTimeMode()
    md = fmpy.read_model_description(str(fmu))
    n = len(md.derivatives)
    x = (ctypes.c_double * n)()
    model.getContinuousStates(x, n)
    names = [v.name for v in md.modelVariables]
    x[names.index("u1")] = 1e300
    model.setContinuousStates(x, n)
    assert math.isfinite(model.getReal(vr(fmu, "angular_momentum[1]"))[0])
    refused(lambda: model.getReal(vr(fmu, "angular_momentum[1]", "kinetic_energy")), log,
            "fmi2GetReal: kinetic_energy = inf is not finite")  # fmt: skip
    model.freeInstance()


def test_the_help_names_the_default_method(cli) -> None:
    """The --method default as methods.pick applies it (before: "dop853",
    while the default scene's FMU steps with taylor)."""
    code, out, _ = cli(["fmu", "--help"])
    assert code == 0
    text = " ".join(out.split())
    assert f"else of {', '.join(methods.EXPLICIT_CHOICE)}," in text
    assert f"of {', '.join(methods.STIFF_CHOICE)} for a stiff scene" in text


def test_a_start_time_that_is_not_finite_is_refused(fmus: dict[str, Path], tmp_path: Path) -> None:
    """Before: fmi2OK, and every later step refused as from another time."""
    slave, log = instantiate(fmus["default"], "CoSimulation", tmp_path)
    refused(
        lambda: slave.setupExperiment(startTime=math.nan),
        log,
        "fmi2SetupExperiment: the start time nan is not finite",
    )
    slave.setupExperiment(startTime=0.0)
    slave.freeInstance()


@pytest.mark.parametrize("names", [("T", "T"), ("u4", "q1", "u4")])
def test_a_variable_given_twice_is_refused(
    fmus: dict[str, Path], tmp_path: Path, names: tuple[str, ...]
) -> None:
    """One fmi2SetReal that gives a variable twice sets nothing (before: the
    last value silently won)."""
    fmu = fmus["default"]
    slave, log = instantiate(fmu, "CoSimulation", tmp_path)
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    before = slave.getReal(vr(fmu, *names))
    refused(
        lambda: slave.setReal(vr(fmu, *names), [1.0 + k for k in range(len(names))]),
        log,
        f"fmi2SetReal: {names[0]} is given more than once",
    )
    assert slave.getReal(vr(fmu, *names)) == before
    slave.freeInstance()


@pytest.mark.parametrize("tolerance", [math.nan, -1.0, 0.0, 1e-20, 1.0, math.inf])
def test_a_tolerance_the_integrator_cannot_meet_is_refused(
    fmus: dict[str, Path], tmp_path: Path, tolerance: float
) -> None:
    """fmi2SetupExperiment checks the tolerance and says why (before: fmi2OK,
    then every doStep failed with "bad argument")."""
    slave, log = instantiate(fmus["default"], "CoSimulation", tmp_path)
    refused(
        lambda: slave.setupExperiment(tolerance=tolerance, startTime=0.0),
        log,
        f"fmi2SetupExperiment: tolerance {tolerance:g} is not a relative tolerance the "
        f"integrator can meet (above {abi.MIN_RTOL:g} and below 1)".replace("inf", "inf"),
    )
    slave.freeInstance()


@pytest.mark.parametrize(("t", "h"), [(0.0, 0.1), (5.0, 0.1), (0.1 + 1e-9, 0.1)])
def test_a_step_from_another_time_is_refused(
    fmus: dict[str, Path], tmp_path: Path, t: float, h: float
) -> None:
    """FMI 2.0: doStep's communication point is the FMU's time (where the
    last step ended). After one step to 0.1, a step from t is refused, the
    state untouched; the step from 0.1 is taken."""
    fmu = fmus["default"]
    slave, log = initialized(fmu, "CoSimulation", tmp_path)
    slave.doStep(0.0, 0.1)
    before = slave.getReal(vr(fmu, "q1", "u4"))
    refused(
        lambda: slave.doStep(t, h),
        log,
        f"fmi2DoStep: the communication point {t:.17g} is not the FMU's time 0.10000000000000001",
    )
    assert slave.getReal(vr(fmu, "q1", "u4")) == before
    slave.doStep(0.1, 0.1)
    slave.freeInstance()


def test_model_exchange_refuses_non_finite_states(fmus: dict[str, Path], tmp_path: Path) -> None:
    fmu = fmus["default"]
    model, log = initialized(fmu, "ModelExchange", tmp_path)
    model.enterContinuousTimeMode()
    n = len(fmpy.read_model_description(str(fmu)).derivatives)
    x, after = (ctypes.c_double * n)(), (ctypes.c_double * n)()
    model.getContinuousStates(x, n)
    bad = (ctypes.c_double * n)(*x)
    bad[1] = math.nan
    refused(lambda: model.setContinuousStates(bad, n), log,
            "fmi2SetContinuousStates: q2 = nan is not finite")  # fmt: skip
    model.getContinuousStates(after, n)
    assert list(after) == list(x)
    model.freeInstance()


def test_model_exchange_refuses_derivatives_that_are_not_finite(
    fmus: dict[str, Path], tmp_path: Path
) -> None:
    """u1 = 1e308 is finite, its products are not: fmi2GetDerivatives (and
    fmi2GetReal of a derivative) is an fmi2Error naming the first derivative
    that is not finite (before: fmi2OK with an infinity)."""
    fmu = fmus["default"]
    model, log = initialized(fmu, "ModelExchange", tmp_path)
    model.enterContinuousTimeMode()
    md = fmpy.read_model_description(str(fmu))
    n = len(md.derivatives)
    x, dx = (ctypes.c_double * n)(), (ctypes.c_double * n)()
    model.getContinuousStates(x, n)
    names = [v.name for v in md.modelVariables]
    x[names.index("u1")] = 1e308
    model.setContinuousStates(x, n)
    with pytest.raises(FMICallException):
        model.getDerivatives(dx, n)
    first = next(i for i in range(n) if not math.isfinite(dx[i]))
    said = f"fmi2GetDerivatives: der({names[first]}) = {dx[first]:g} is not finite"
    assert (3, said) in [(s, m[-len(said) :]) for s, m in log.lines], log.lines
    refused(lambda: model.getReal(vr(fmu, f"der({names[first]})")), log,
            f"fmi2GetReal: der({names[first]}) = {dx[first]:g} is not finite")  # fmt: skip
    model.freeInstance()


@pytest.mark.parametrize("time", [math.nan, -math.inf, math.inf])
def test_a_time_that_is_not_finite_is_refused(
    fmus: dict[str, Path], tmp_path: Path, time: float
) -> None:
    """fmi2SetTime checks its time as fmi2SetupExperiment does its start
    (before: fmi2OK, and the derivatives at t = nan); the time stays."""
    fmu = fmus["default"]
    model, log = initialized(fmu, "ModelExchange", tmp_path)
    model.enterContinuousTimeMode()
    model.setTime(0.5)
    refused(lambda: model.setTime(time), log, f"fmi2SetTime: the time {time:g} is not finite")
    n = len(fmpy.read_model_description(str(fmu)).derivatives)
    dx = (ctypes.c_double * n)()
    model.getDerivatives(dx, n)
    assert all(math.isfinite(v) for v in dx)
    model.freeInstance()


def test_co_simulation_steps_a_stiff_scene_implicitly(
    tmp_path: Path, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    """As `simulate --method auto`: radau5 for stiff_wheel (was dop853). Its
    sources kept in the build cache, the FMU is made from them: the scene
    is not derived."""
    from gyrogen.codegen import generate
    from gyrogen.runtime.scene_build import scene_sources

    scene_sources(load("stiff_wheel"))  # kept (the run's cache is seeded from generated/)
    monkeypatch.setattr(generate, "_UNITS", {})  # this process's units: gone
    monkeypatch.setattr(generate, "make_context", lambda scene: pytest.fail("derived"))
    code, out, err = cli(["fmu", "stiff_wheel", "--out", str(tmp_path)])
    assert code == 0, err
    assert "Co-Simulation (radau5)" in out


@pytest.mark.parametrize("compiler", ["gcc", "clang", "g++"])
def test_sources_compile_strictly(fmus: dict[str, Path], tmp_path: Path, compiler: str) -> None:
    """The FMI wrapper holds to the generated code's flags, and compiles as C++."""
    with zipfile.ZipFile(fmus["default"]) as zf:
        zf.extractall(tmp_path)
    language = ["-x", "c++"] if compiler == "g++" else ["-std=c99"]
    strict = list(C_STRICT[1:])
    cmd = [compiler, *language, *strict, f"-I{fmi_headers()}", "-c", "sources/gyrostat_fmi2.c"]
    proc = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, check=False)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr


DRIVER = Path(__file__).resolve().parent / "consumers" / "fmi2_driver.c"
MISUSE = {
    "wrong_guid", "step_before_initialization", "start_nan", "set_nowhere", "set_twice",
    "exit_refused", "set_in_error", "step_in_error", "set_refused",
    "get_nowhere", "unknown_category", "step_nan", "step_backwards", "other_status",
    "step_after_terminate", "states_too_many", "set_states_too_few", "derivatives_too_many",
    "fmu_state", "set_nan_states", "time_nan", "time_minus_inf", "derivatives_of_1e308",
    "continuous_time_before_initialization", "derivatives_before_initialization",
    "continuous_time_in_error", "states_in_error",
}  # fmt: skip
"""What tests/consumers/fmi2_driver.c does wrong: each an fmi2Error (3) with
a logged line; every other call is fmi2OK (0)."""


def test_the_wrapper_under_sanitizers(fmus: dict[str, Path], tmp_path: Path) -> None:
    """The FMU's sources and a driver that misuses them, under ASan and
    UBSan: each misuse an error with its reason logged, never a crash."""
    with zipfile.ZipFile(fmus["default"]) as zf:
        zf.extractall(tmp_path)
    md = fmpy.read_model_description(str(fmus["default"]))
    p0 = next(v.valueReference for v in md.modelVariables if v.causality == "parameter")
    sanitize = [*C_WARNINGS, "-fsanitize=address,undefined",
                "-fno-sanitize-recover=all", "-g"]  # fmt: skip
    sources = sorted(str(f) for f in (tmp_path / "sources").glob("*.c"))
    subprocess.run(
        ["gcc", "-std=c99", *sanitize, f"-I{fmi_headers()}", "-Isources", *sources, str(DRIVER),
         "-o", "driver", "-lm"], cwd=tmp_path, check=True)  # fmt: skip
    proc = subprocess.run(
        [str(tmp_path / "driver"), md.guid, str(p0), str(md.numberOfContinuousStates),
         str(next(v.valueReference for v in md.modelVariables if v.name == "u1"))],
        capture_output=True, text=True, check=False)  # fmt: skip
    assert (proc.returncode, proc.stderr) == (0, "")
    lines = proc.stdout.splitlines()
    calls = [(i, *line.split()) for i, line in enumerate(lines) if not line.startswith("log ")]
    assert len(calls) == 55 and {what for _, what, _ in calls} >= MISUSE
    for i, what, status in calls:
        assert status == ("3" if what in MISUSE else "0"), what
        assert lines[i - 1].startswith("log 3 ") == (what in MISUSE), what
    refused = "log 3 gyrostat_setup refused the parameters (code 2): "
    assert refused + abi.message(abi.SETUP_CODES, 2) in lines
    step = "log 3 fmi2DoStep: the communication step size "
    assert step + "nan is not >= 0, or t + h (nan) is not finite" in lines
    assert step + "-1 is not >= 0, or t + h (-0.90000000000000002) is not finite" in lines
    assert "log 3 fmi2SetTime: the time -inf is not finite" in lines
    order = "log 3 {}: not allowed in {} (only in {})"
    assert order.format("fmi2DoStep", "the error state", "the step-complete state") in lines
    early = order.format("fmi2EnterContinuousTimeMode", "the instantiated state", "event mode")
    assert early in lines
    assert any(line.startswith("log 3 fmi2GetDerivatives: der(") for line in lines)


def test_fmpy_rebuilds_the_binary_from_the_sources(fmus: dict[str, Path], tmp_path: Path) -> None:
    """The sources inside are enough: FMPy's own build (CMake, its headers)
    makes a new binary from them, which runs as the shipped one (other flags:
    FMPy builds Release; so to 1e-12, not to the bit, though it is equal here)."""
    unzipped = Path(fmpy.extract(str(fmus["stiff"]), str(tmp_path / "unzipped")))
    binary = unzipped / "binaries" / fmpy.platform / "stiff_wheel.so"
    binary.unlink()
    (tmp_path / "build").mkdir()
    build_platform_binary(unzipped, build_dir=tmp_path / "build")
    assert binary.is_file()
    rebuilt = fmpy.simulate_fmu(str(unzipped), fmi_type="CoSimulation", stop_time=SLICE)
    original = fmpy.simulate_fmu(str(fmus["stiff"]), fmi_type="CoSimulation", stop_time=SLICE)
    assert rebuilt.dtype.names == original.dtype.names and len(rebuilt) > 10
    for name in original.dtype.names:
        np.testing.assert_allclose(rebuilt[name], original[name], rtol=1e-12, atol=1e-12)


def scene_file(tmp_path: Path, edit: Callable[[str], str]) -> str:
    """gyrostat.toml, edited."""
    path = tmp_path / "edited.toml"
    path.write_text(edit((SCENES / "gyrostat.toml").read_text()))
    return str(path)


def targets(line: str) -> Callable[[str], str]:
    return lambda text: text.replace('targets = ["c", "fortran"]', line)


@pytest.mark.parametrize(
    ("edit", "args", "message"),
    [
        (targets('targets = ["fortran"]'), [],
         'an FMU is built from the C sources: add "c" to targets'),
        (targets('targets = ["c"]\nintegrators = ["rk4"]'), [],
         "the scene has none (integrators: rk4)"),
        (lambda text: text.split("[simulate.parameters]")[0], [],
         "no value for runtime parameter m_a, m_b"),
        (None, ["gyrostat", "--method", "rk4"], "'rk4' is not one of"),
        (targets('targets = ["c"]\nintegrators = ["dop853"]'), ["--method", "rodas4"],
         "rodas4 is not among the scene's integrators (dop853)"),
        (lambda text: text.replace('name = "gyrostat"', 'name = "fmi2Functions"'), [],
         "name: 'fmi2Functions' names an FMI header (fmi2Functions.h)"),
        (lambda text: text.replace("the paper's full model", "the paper's \ufffe model"), [],
         "U+FFFE at position 12 is not a character: XML (an FMU's modelDescription.xml)"),
    ],
)  # fmt: skip
def test_refusals(
    tmp_path: Path, cli, edit: Callable[[str], str] | None, args: list[str], message: str
) -> None:
    """A scene or an option that cannot make an FMU: one line, exit 2, nothing written."""
    scene = [scene_file(tmp_path, edit)] if edit else []
    code, out, err = cli(["fmu", *scene, *args, "--out", str(tmp_path / "out")])
    assert (code, out) == (2, "") and message in err and err.count("\n") == 1
    assert not (tmp_path / "out").exists()


def test_unwritable_out(tmp_path: Path, cli) -> None:
    (tmp_path / "file").write_text("mine")
    code, _, err = cli(["fmu", "torque_free", "--out", str(tmp_path / "file" / "sub")])
    assert code == 1 and err.count("\n") == 1
    assert err.startswith("gyrogen: error: cannot create output directory")
    assert (tmp_path / "file").read_text() == "mine"


def test_without_fmpy_there_are_no_headers(tmp_path: Path) -> None:
    """Python with FMPy unimportable (as where it is not installed)."""
    run = ("import sys; sys.modules['fmpy'] = None; from gyrogen.cli import main; "
           f"main(['fmu', 'torque_free', '--out', {str(tmp_path)!r}])")  # fmt: skip
    proc = subprocess.run([sys.executable, "-c", run], capture_output=True, text=True, check=False)
    assert proc.returncode == 1
    assert proc.stderr == (
        "gyrogen: error: building an FMU needs the FMI headers, taken from FMPy, which is "
        "not installed: pip install fmpy (or gyrogen's fmu extra)\n"
    )
    assert list(tmp_path.iterdir()) == []


def test_the_same_scene_makes_the_same_bytes(fmus: dict[str, Path], tmp_path: Path, cli) -> None:
    assert cli(["fmu", "gyrostat", "--out", str(tmp_path)]).code == 0
    assert (tmp_path / "gyrostat.fmu").read_bytes() == fmus["default"].read_bytes()


@WIDE
def test_the_scenes_events_end_both_kinds_of_simulation(tmp_path: Path) -> None:
    """dual_spin with sin(3 t) events and a terminal one where q3 passes
    0.3 rad (near 6 s): Model Exchange exposes them as event indicators and
    ends at the terminal one (FMPy's CVODE finds the crossing); Co-Simulation
    ends the step there with fmi2Discard and fmi2Terminated, at the time the
    _events call located."""
    events = """
[[events]]
name = "third"
expr = "sin(3*t)"

[[events]]
name = "spun"
expr = "q3 - 0.3"
direction = "up"
terminal = true
"""
    scene = parse(builtin_text("dual_spin") + events, "events")
    fmu = build_model(scene, "dop853", tmp_path / "fmu")
    md = fmpy.read_model_description(str(fmu))
    assert md.numberOfEventIndicators == 2
    comp = api.compile(scene)
    x0 = np.array(scene.initial_state())
    _, log, _, code = comp.integrate_events("dop853", x0, comp.setup([]), [0.0, 20.0],
                                            rtol=1e-10, atol=1e-10)  # fmt: skip
    assert code == 8
    t_event = log.times[-1]
    for mode, close in (("CoSimulation", 1e-9), ("ModelExchange", 1e-5)):
        out = fmpy.simulate_fmu(str(fmu), fmi_type=mode, stop_time=20.0, output_interval=0.5)
        assert abs(out["time"][-1] - t_event) <= close * t_event, (mode, out["time"][-1], t_event)
