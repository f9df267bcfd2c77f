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
from wide import WIDE

pytestmark = pytest.mark.slow  # hundreds of drawn scenes, each generated, compiled and compared

SHARDS = 2
EXAMPLES = 16
"""SHARDS x EXAMPLES drawn scenes in CI (pytest-xdist spreads the shards;
each shard's seed fixed, so the same scenes each run): the slice of `make
fuzz`'s thousands that the suite can afford."""


@pytest.mark.parametrize("shard", range(SHARDS))
@WIDE
def test_every_drawn_scene_keeps_the_promise(
    shard: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    counts, failures = run_shard(1000 + shard, EXAMPLES, tmp_path / "failures")
    assert not failures, "\n\n".join(failures)
    assert counts["examples"] == EXAMPLES and counts["checked"] >= EXAMPLES // 2, counts


CLUSTER_EXAMPLES = 4
"""Drawn cluster scenes in CI (N = 1..6 rotors: each derived with KanesMethod)."""


@WIDE
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


@WIDE
def test_every_drawn_cmg_cluster_keeps_the_promise(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    drawn = clusters(gimbals=True)
    counts, failures = run_shard(3000, CMG_EXAMPLES, tmp_path / "failures", drawn)
    assert not failures, "\n\n".join(failures)
    assert counts["examples"] == CMG_EXAMPLES and counts["checked"] >= 1, counts


REGRESSIONS = sorted((Path(__file__).parent / "regressions").glob("*.toml"))
REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("path", REGRESSIONS, ids=[p.stem for p in REGRESSIONS])
def test_scenes_the_fuzzing_broke_keep_the_promise(
    path: Path, cache_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Each failure `make fuzz` found, as a scene file (its first lines say
    what broke and what fixed it)."""
    monkeypatch.setenv("GYROGEN_CACHE", str(cache_dir))
    assert check(Draw(path.read_text(encoding="utf-8"), True, "")) == "checked"


def method_runs(scene: str, plan: list[tuple[str, dict]]) -> dict[str, list[tuple]]:
    """Per language and (method, controls) of plan: the method, code,
    accepted and rejected steps and the final state, from the start of the
    scene (a built-in name: its sources in generated/, which a test holds
    fresh; or a scene file's text: rendered once per run, in the build
    cache) to its t_end."""
    from gyrogen.analysis.simulate.engine import runtime_values
    from gyrogen.runtime.scene_build import build_dir, build_files, scene_sources
    from gyrogen.scene import builtin_names, load, parse

    languages = ("c", "fortran")
    if scene in builtin_names():
        scene_ = load(scene)
        backends = build_dir(REPO / "generated" / scene, languages)
    else:
        scene_ = parse(scene, "drawn")
        backends = build_files(scene_sources(scene_).files, languages)
    x0, p = np.array(scene_.initial_state()), runtime_values(scene_)
    runs: dict[str, list[tuple]] = {}
    for language, b in backends.items():
        c, t1 = b.setup(p), scene_.simulate.t_end
        runs[language] = []
        for method, controls in plan:
            x, stats, code = b.integrate(method, x0, c, 0.0, t1, **controls)
            runs[language].append((method, code, stats["accepted"], stats["rejected"], x))
    return runs


def radau5_steps(scene: str, tols: tuple[float, ...]) -> dict[str, list[tuple]]:
    """Per language, radau5's (code, accepted, rejected) on the scene (a
    built-in name or a scene file's text) from its start to its t_end, at
    rtol = atol = each of tols."""
    plan = [("radau5", {"rtol": tol, "atol": tol}) for tol in tols]
    runs = method_runs(scene, plan)
    return {language: [run[1:4] for run in out] for language, out in runs.items()}


def test_fortran_radau5_steps_as_c_radau5_on_a_quaternion_scene(
    cache_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """On an Intel CPU, Fortran radau5 once stopped with code 1 (step
    size underflow) within 0.26 s at every tolerance, C radau5 did not
    (tests/regressions/fortran_radau5_quaternion.toml says why)."""
    monkeypatch.setenv("GYROGEN_CACHE", str(cache_dir))
    path = Path(__file__).parent / "regressions" / "fortran_radau5_quaternion.toml"
    text = path.read_text(encoding="utf-8")
    steps = radau5_steps(text, (1e-6, 1e-8, 1e-9, 1e-10))
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


@pytest.mark.parametrize(
    "name",
    [pytest.param("gyrostat", marks=WIDE), "stiff_wheel", pytest.param("torque_free", marks=WIDE)],
)
def test_c_and_fortran_radau5_take_the_same_steps_on_builtin_scenes(
    name: str,
    cache_dir: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The built-in scenes are 3-1-2 ones. The suite runs stiff_wheel, the
    stiff one radau5 is for; `make test-wide` runs gyrostat and torque_free
    too."""
    monkeypatch.setenv("GYROGEN_CACHE", str(cache_dir))
    steps = radau5_steps(name, (1e-6, 1e-9))
    assert [code for code, _, _ in steps["c"]] == [0, 0], steps
    assert steps["fortran"] == steps["c"], steps


AGREE = int(os.environ.get("GYROGEN_AGREE_SCENES", "2"))
"""Drawn scenes per attitude on which C and Fortran run every method alike
(`make fuzz`: 250 of each, 500 in all)."""
AGREE_SEED = int(os.environ.get("GYROGEN_AGREE_SEED", "20"))
EVERY = ("rk4", "dopri5", "dop853", "rodas4", "radau5")


RADAU5_TOLERANCES = (1e-6, 1e-9)
"""radau5 runs at these too: its Newton iteration and step control at a
loose and a tight tolerance (Fortran's once stopped where C's did not)."""


def every_method(scene: str, methods: tuple[str, ...] = EVERY) -> dict[str, list[tuple]]:
    """method_runs with every method at rtol = atol = 1e-8 (rk4: 200 steps),
    then radau5 at each of RADAU5_TOLERANCES."""
    plan = [(m, {"steps": 200} if m == "rk4" else {"rtol": 1e-8, "atol": 1e-8}) for m in methods]
    plan += [("radau5", {"rtol": tol, "atol": tol}) for tol in RADAU5_TOLERANCES]
    return method_runs(scene, plan)


@pytest.mark.parametrize(
    ("attitude", "portable"),
    [
        ("quaternion", False),
        pytest.param("quaternion", True, marks=WIDE),
        ("euler312", False),
        ("euler312", True),
    ],
    ids=["quaternion-native", "quaternion-portable", "euler312-native", "euler312-portable"],
)
@WIDE
def test_c_and_fortran_run_every_method_alike_on_drawn_scenes(
    attitude: str,
    portable: bool,
    cache_dir: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Both languages print every integrator from one description,
    so on drawn scenes they take the same accepted and rejected steps with
    every method (the Taylor method too where the scene is smooth; radau5
    at a loose and a tight tolerance besides) and end within 1e-14 (scaled
    by max(1, |x|)) of each other: built with -march=native and without
    (GYROGEN_PORTABLE), from one generation of each scene. The suite builds
    the quaternion scenes natively only; `make test-wide` builds them
    portably too, and `make fuzz` draws GYROGEN_AGREE_SCENES of each."""
    monkeypatch.setenv("GYROGEN_CACHE", str(cache_dir))
    if portable:
        monkeypatch.setenv("GYROGEN_PORTABLE", "1")
    from gyrogen.scene import parse

    methods = "[" + ", ".join(f'"{m}"' for m in EVERY) + "]"
    for text in drawn_scenes(attitude, AGREE, AGREE_SEED, methods):
        every = EVERY if parse(text, "drawn").not_smooth else (*EVERY, "taylor")
        text = text.replace(f"integrators = {methods}", "integrators = [" + ", ".join(
            f'"{m}"' for m in every) + "]")  # fmt: skip
        runs = every_method(text, every)
        for c_run, f_run in zip(runs["c"], runs["fortran"], strict=True):
            assert c_run[:4] == f_run[:4], (text, c_run[:4], f_run[:4])
            xc, xf = c_run[4], f_run[4]
            if c_run[1] == 0:
                gap = np.abs(xc - xf) / np.maximum(1.0, np.abs(xc))
                assert gap.max() <= 1e-14, (text, c_run[0], gap.max())
