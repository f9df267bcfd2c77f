"""The scene space under property tests (tests/scene_space.py): in CI a
derandomized slice of SHARDS x EXAMPLES drawn scenes, each generated,
compiled by gcc, clang and gfortran with -Werror and compared with the
reference; `make fuzz` (tools/fuzz_scenes.py) runs thousands with a fresh
seed."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, seed, settings
from scene_space import Draw, check, run_shard, scenes
from scene_space_clusters import clusters

pytestmark = pytest.mark.slow  # hundreds of drawn scenes, each generated, compiled and compared

SHARDS = 4
EXAMPLES = 16
"""SHARDS x EXAMPLES drawn scenes in CI (pytest-xdist spreads the shards)."""


@pytest.mark.parametrize("shard", range(SHARDS))
def test_every_drawn_scene_keeps_the_promise(
    shard: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    counts, failures = run_shard(1000 + shard, EXAMPLES, tmp_path / "failures")
    assert not failures, "\n\n".join(failures)
    assert counts["examples"] == EXAMPLES and counts["checked"] >= EXAMPLES // 2, counts


CLUSTER_EXAMPLES = 4
"""Drawn cluster scenes in CI (N = 1..6 rotors: each derived with KanesMethod)."""


def test_every_drawn_cluster_keeps_the_promise(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    counts, failures = run_shard(2000, CLUSTER_EXAMPLES, tmp_path / "failures", clusters())
    assert not failures, "\n\n".join(failures)
    assert counts["examples"] == CLUSTER_EXAMPLES and counts["checked"] >= 1, counts


CMG_EXAMPLES = 2
"""Drawn clusters of control-moment gyros in CI (1 to 3 rotors, at least one
on a gimbal: each derived with KanesMethod and proven equal to the momentum
form, the slowest draws)."""


def test_every_drawn_cmg_cluster_keeps_the_promise(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    drawn = clusters(gimbals=True)
    counts, failures = run_shard(3000, CMG_EXAMPLES, tmp_path / "failures", drawn)
    assert not failures, "\n\n".join(failures)
    assert counts["examples"] == CMG_EXAMPLES and counts["checked"] >= 1, counts


REGRESSIONS = sorted((Path(__file__).parent / "regressions").glob("*.toml"))


@pytest.mark.parametrize("path", REGRESSIONS, ids=[p.stem for p in REGRESSIONS])
def test_scenes_the_fuzzing_broke_keep_the_promise(
    path: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Each failure `make fuzz` found, as a scene file (its first lines say
    what broke and what fixed it)."""
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    assert check(Draw(path.read_text(encoding="utf-8"), True, "")) == "checked"


def radau5_steps(path: Path | str, work: Path, tols: tuple[float, ...]) -> dict[str, list[tuple]]:
    """Per language, radau5's (code, accepted, rejected) on the scene at
    path (or the built-in scene of that name) from its start to its t_end,
    at rtol = atol = each of tols."""
    runs = method_runs(path, work, [("radau5", {"rtol": tol, "atol": tol}) for tol in tols])
    return {language: [run[1:4] for run in out] for language, out in runs.items()}


def method_runs(
    path: Path | str, work: Path, plan: list[tuple[str, dict]]
) -> dict[str, list[tuple]]:
    """Per language and (method, controls) of plan: the method, code,
    accepted and rejected steps and the final state, from the scene's start
    to its t_end."""
    from gyrogen.analysis.simulate.engine import runtime_values
    from gyrogen.codegen.generate import generate
    from gyrogen.runtime.build import build
    from gyrogen.scene import load

    scene = load(str(path))
    generate(scene, work / "src")
    x0, p = np.array(scene.initial_state()), runtime_values(scene)
    runs: dict[str, list[tuple]] = {}
    for language in ("c", "fortran"):
        b = build(work / "src", language)
        c, t1 = b.setup(p), scene.simulate.t_end
        runs[language] = []
        for method, controls in plan:
            x, stats, code = b.integrate(method, x0, c, 0.0, t1, **controls)
            runs[language].append((method, code, stats["accepted"], stats["rejected"], x))
    return runs


def test_fortran_radau5_steps_as_c_radau5_on_the_scene_of_issue_19(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 19: on an Intel CPU Fortran radau5 stopped with code 1 (step
    size underflow) within 0.26 s at every tolerance, C radau5 did not
    (tests/regressions/fortran_radau5_quaternion.toml says why)."""
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    path = Path(__file__).parent / "regressions" / "fortran_radau5_quaternion.toml"
    steps = radau5_steps(path, tmp_path, (1e-6, 1e-8, 1e-9, 1e-10))
    assert [code for code, _, _ in steps["c"]] == [0, 0, 0, 0], steps
    assert steps["fortran"] == steps["c"], steps


def drawn_scenes(attitude: str, n: int, seed_: int, integrators: str = '["radau5"]') -> list[str]:
    """The first n valid scenes of that attitude scene_space draws from
    seed_, each made a C and Fortran scene of those integrators."""
    texts: list[str] = []

    @seed(seed_)
    @settings(
        max_examples=max(300, 40 * n),
        deadline=None,
        database=None,
        phases=[Phase.generate],
        suppress_health_check=list(HealthCheck),
    )
    @given(scenes())
    def one(drawn: Draw) -> None:
        if len(texts) < n and drawn.valid and f'attitude = "{attitude}"' in drawn.text:
            text = re.sub(r"(?m)^targets = .*$", 'targets = ["c", "fortran"]', drawn.text)
            texts.append(re.sub(r"(?m)^integrators = .*$", f"integrators = {integrators}", text))

    one()
    assert len(texts) == n, f"{len(texts)} {attitude} scenes drawn from seed {seed_}"
    return texts


@pytest.mark.parametrize("attitude", ["quaternion", "euler312"])
def test_c_and_fortran_radau5_take_the_same_steps_on_drawn_scenes(
    attitude: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    for k, text in enumerate(drawn_scenes(attitude, 3, 19)):
        path = tmp_path / f"drawn{k}.toml"
        path.write_text(text, encoding="utf-8")
        steps = radau5_steps(path, tmp_path / f"drawn{k}", (1e-6, 1e-9))
        assert steps["fortran"] == steps["c"], (text, steps)


@pytest.mark.parametrize("name", ["gyrostat", "stiff_wheel", "torque_free"])
def test_c_and_fortran_radau5_take_the_same_steps_on_builtin_scenes(
    name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The built-in scenes are 3-1-2 ones."""
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    steps = radau5_steps(name, tmp_path, (1e-6, 1e-9))
    assert [code for code, _, _ in steps["c"]] == [0, 0], steps
    assert steps["fortran"] == steps["c"], steps


AGREE = int(os.environ.get("GYROGEN_AGREE_SCENES", "2"))
"""Drawn scenes per attitude on which C and Fortran run every method alike
(`make fuzz`: 250 of each, 500 in all)."""
AGREE_SEED = int(os.environ.get("GYROGEN_AGREE_SEED", "20"))
EVERY = ("rk4", "dopri5", "dop853", "rodas4", "radau5")


def every_method(
    path: Path, work: Path, methods: tuple[str, ...] = EVERY
) -> dict[str, list[tuple]]:
    """method_runs with every method at rtol = atol = 1e-8 (rk4: 200 steps)."""
    plan = [(m, {"steps": 200} if m == "rk4" else {"rtol": 1e-8, "atol": 1e-8}) for m in methods]
    return method_runs(path, work, plan)


@pytest.mark.parametrize("portable", [False, True], ids=["native", "portable"])
@pytest.mark.parametrize("attitude", ["quaternion", "euler312"])
def test_c_and_fortran_run_every_method_alike_on_drawn_scenes(
    attitude: str, portable: bool, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 20: both languages print every integrator from one description,
    so on drawn scenes they take the same accepted and rejected steps with
    every method (the Taylor method too where the scene is smooth) and end
    within 1e-14 (scaled by max(1, |x|)) of each other:
    built with -march=native and without (GYROGEN_PORTABLE)."""
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    if portable:
        monkeypatch.setenv("GYROGEN_PORTABLE", "1")
    from gyrogen.scene import parse

    methods = "[" + ", ".join(f'"{m}"' for m in EVERY) + "]"
    for k, text in enumerate(drawn_scenes(attitude, AGREE, AGREE_SEED, methods)):
        every = EVERY if parse(text, "drawn").not_smooth else (*EVERY, "taylor")
        text = text.replace(f"integrators = {methods}", "integrators = [" + ", ".join(
            f'"{m}"' for m in every) + "]")  # fmt: skip
        path = tmp_path / f"drawn{k}.toml"
        path.write_text(text, encoding="utf-8")
        runs = every_method(path, tmp_path / f"drawn{k}", every)
        for c_run, f_run in zip(runs["c"], runs["fortran"], strict=True):
            assert c_run[:4] == f_run[:4], (text, c_run[:4], f_run[:4])
            xc, xf = c_run[4], f_run[4]
            if c_run[1] == 0:
                gap = np.abs(xc - xf) / np.maximum(1.0, np.abs(xc))
                assert gap.max() <= 1e-14, (text, c_run[0], gap.max())
