"""Shared fixtures: one generated copy of the default scene per session, and
the compiled backends built from it (in a per-session cache directory)."""

from __future__ import annotations

from pathlib import Path

import pytest

from gyrogen.codegen.generate import generate
from gyrogen.runtime import build
from gyrogen.runtime.compiled import Compiled
from gyrogen.scene import default

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def cache_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("cache")


@pytest.fixture(scope="session")
def source_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("generated") / default().name
    generate(default(), out)
    return out


@pytest.fixture(scope="session")
def backends(source_dir: Path, cache_dir: Path) -> dict[str, Compiled]:
    mp = pytest.MonkeyPatch()
    mp.setenv("GYROGEN_CACHE", str(cache_dir))
    try:
        return {lang: build.build(source_dir, lang) for lang in ("c", "fortran")}
    finally:
        mp.undo()
