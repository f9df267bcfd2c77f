"""The scene space under property tests (tests/scene_space.py): in CI a
derandomized slice of SHARDS x EXAMPLES drawn scenes, each generated,
compiled by gcc, clang and gfortran with -Werror and compared with the
reference; `make fuzz` (tests/fuzz_scenes.py) runs thousands with a fresh
seed."""

from __future__ import annotations

from pathlib import Path

import pytest
from scene_space import Draw, check, run_shard
from scene_space_clusters import clusters

SHARDS = 4
EXAMPLES = 25
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


REGRESSIONS = sorted((Path(__file__).parent / "regressions").glob("*.toml"))


@pytest.mark.parametrize("path", REGRESSIONS, ids=[p.stem for p in REGRESSIONS])
def test_scenes_the_fuzzing_broke_keep_the_promise(
    path: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Each failure `make fuzz` found, as a scene file (its first lines say
    what broke and what fixed it)."""
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    assert check(Draw(path.read_text(encoding="utf-8"), True, "")) == "checked"
