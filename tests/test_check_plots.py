"""`gyrogen check --plots`: one figure per case, of the quantities that case
is about (analysis/check/plots.py), and each case's extreme quantity
(Case.extreme, declared in cases.py)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread
from wide import WIDE

from gyrogen.analysis.check import cases, engine
from gyrogen.analysis.simulate.plots import PIXELS
from gyrogen.runtime.compiled import Compiled

pytestmark = pytest.mark.slow  # every check case integrated and drawn

EVERY = cases.cases()
ONE_OF_EACH_KIND = {
    "nominal": "nominal.png",
    "fast rotor J u4/(I|w|)=10000": "fast_rotor_J_u4__I_w___10000.png",
    "gimbal lock eps=1e-06 (3-1-2": "gimbal_lock_eps_1e_06__3_1_2_angles.png",
    "through q2 = pi/2 (quaternion)": "through_q2___pi_2__quaternion.png",
    "speed controller k/J=1e+06": "speed_controller_k_J_1e_06.png",
    "mass ratio m_b/m_a = 1e9": "mass_ratio_m_b_m_a___1e9.png",
    "negative mass": "negative_mass.png",
    "cluster ~parallel: tilt 1e-8": "cluster__parallel__tilt_1e_8__carrier_x1e_18.png",
}


def _colours(png: Path) -> int:
    pixels = imread(png)
    assert pixels.shape[:2] == PIXELS
    return len(np.unique(pixels.reshape(-1, pixels.shape[-1]), axis=0))


@WIDE
def test_one_figure_per_case_of_each_kind(tmp_path: Path, cli) -> None:
    """The refused cases too (by setup, and by the cluster scene's own rules
    at generation): the figure says why in words, so it is not blank."""
    code, out, err = cli(["check", "--quick", *ONE_OF_EACH_KIND, "--plots", str(tmp_path)])
    assert code == 0, out + err
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(ONE_OF_EACH_KIND.values())
    for name in ONE_OF_EACH_KIND.values():
        assert _colours(tmp_path / name) > 30, name


def test_every_built_in_case_declares_its_extreme_quantity() -> None:
    assert all(case.extreme is not None for case in EVERY)
    assert all(case.extreme.label for case in EVERY if case.extreme is not None)


@pytest.mark.parametrize(
    "case",
    [c for c in EVERY if c.extreme is not None and c.extreme.values is not None],
    ids=lambda c: c.name,
)
@WIDE
def test_extreme_quantity_is_finite_on_a_short_run(
    case: engine.Case, check_builds: dict[str, Compiled]
) -> None:
    short = replace(case, t_end=min(case.t_end, 0.01), samples=4, steps=min(case.steps, 400))
    res = engine.run_case(short, check_builds[case.scene.name])
    assert res.trajectory is not None and case.extreme is not None and case.extreme.values
    values = case.extreme.values(case, res.trajectory)
    assert values.shape == (len(res.trajectory),) and np.all(np.isfinite(values))
    assert len(res.intervals) >= 1 and res.intervals[0]["accepted"] > 0


def test_the_fast_rotor_ratio_is_the_one_the_case_is_named_for() -> None:
    """J u4 / (I~ |w|) was set from I~ ~ 12 and |w| ~ 1: the measured ratio
    at the start agrees within a factor of 2."""
    for case in (c for c in EVERY if c.name.startswith("fast rotor")):
        named = float(case.name.split("=")[-1])
        x0 = np.array([[case.initial.get(s, 0.0) for s in case.scene.states]])
        assert 0.5 < cases.rotor_ratio(case, x0)[0] / named < 2.0, case.name


def test_cos_q2_agrees_between_angles_and_euler_parameters() -> None:
    """The gimbal cases start eps below q2 = pi/2: |cos q2| = sin eps from
    either attitude, the quaternion's down to rounding of its components."""
    gimbal = [c for c in EVERY if c.name.startswith("gimbal lock")]
    for angles, quaternion in zip(gimbal[::2], gimbal[1::2], strict=True):
        eps = float(angles.name.split("=")[1].split()[0])
        got = [
            cases.cos_q2(
                c, np.array([[{"e0": 1.0, **c.initial}.get(s, 0.0) for s in c.scene.states]])
            )[0]
            for c in (angles, quaternion)
        ]
        assert got[0] == pytest.approx(np.sin(eps), rel=1e-9)
        assert got[1] == pytest.approx(np.sin(eps), rel=1e-9, abs=1e-15)
