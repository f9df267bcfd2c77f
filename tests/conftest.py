"""Shared fixtures: one generated copy of the default scene per session,
the compiled backends built from it (in a per-session cache directory), and
the command line as a test calls it (`cli`)."""

from __future__ import annotations

import contextlib
import io
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import pytest

from gyrogen.cli import main
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


class Outcome(NamedTuple):
    code: int
    """The exit code: 0, 1 for a failure, 2 for a usage or scene error."""
    out: str
    err: str


def run_cli(argv: list[str]) -> Outcome:
    """gyrogen's main() on argv, with what it wrote to stdout and stderr
    captured here: usable in fixtures of any scope, unlike capsys."""
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        try:
            main(argv)
            code = 0
        except SystemExit as exc:
            code = int(exc.code or 0)
    return Outcome(code, stdout.getvalue(), stderr.getvalue())


@pytest.fixture(scope="session")
def cli() -> Callable[[list[str]], Outcome]:
    """cli(argv) -> (code, out, err): the command line, run in this process."""
    return run_cli


@pytest.fixture(scope="session")
def check_builds(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Compiled]:
    """The C build of each scene the `gyrogen check` cases use, by scene name."""
    from gyrogen.analysis.check_cases import cases

    out = {}
    for case in cases():
        if case.scene.name not in out:
            src = tmp_path_factory.mktemp(case.scene.name)
            generate(case.scene, src)
            out[case.scene.name] = build.build(src, "c")
    return out
