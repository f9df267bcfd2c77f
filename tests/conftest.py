"""Shared fixtures: one generated copy of the default scene per session,
the compiled backends built from it (in a per-session cache directory), and
the command line as a test calls it (`cli`)."""

from __future__ import annotations

import contextlib
import fcntl
import io
import os
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import pytest

from gyrogen.cli import main
from gyrogen.runtime import flags

if TYPE_CHECKING:  # imported in the fixtures: xdist's controller loads conftest, needs no sympy
    from gyrogen.runtime.compiled import Compiled, Language

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def cache_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The run's build cache, one for all its xdist workers (an entry is
    renamed into place whole, so a worker never reads another's half-built
    one): the same sources are compiled once per run. GYROGEN_TEST_CACHE
    names one kept from run to run instead (`make test-fast`'s): an entry's
    name is the hash of what built it, so a run takes from it only what it
    would have built the same. Either way it starts with the built-in
    scenes' sources (seed_sources)."""
    kept = os.environ.get("GYROGEN_TEST_CACHE")
    cache = Path(kept) if kept else shared_dir(tmp_path_factory) / "cache"
    cache.mkdir(parents=True, exist_ok=True)
    built_once(tmp_path_factory, "sources-seeded", lambda _: seed_sources(cache))
    return cache


def seed_sources(cache: Path) -> None:
    """The built-in scenes' rendered sources, from generated/, into cache's
    sources/ (runtime/scene_build.py's keep_sources), when
    generated/RENDERED_BY says they are what a rendering would write today:
    a test or a process it starts that needs a built-in scene's sources
    (scene_sources: linearize, simulate, a sweep, the README's commands)
    builds them without deriving it. Stale, nothing is seeded, and
    test_generated says so."""
    import json

    from gyrogen.codegen.buildfiles import files as lib_files
    from gyrogen.runtime.scene_build import keep_sources, rendered_by
    from gyrogen.scene import builtin_names, load

    scenes = [load(name) for name in builtin_names()]
    stamp = (REPO / "generated" / "RENDERED_BY").read_text(encoding="utf-8").strip()
    if stamp != rendered_by(scenes):
        return
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("GYROGEN_CACHE", str(cache))
        for scene in scenes:
            held = {
                p.name: p.read_text(encoding="utf-8")
                for p in (REPO / "generated" / scene.name).iterdir()
            }
            manifest = json.loads(held["manifest.json"])
            for name in lib_files(manifest):  # --lib's, which render_all leaves out
                held.pop(name)
            keep_sources(scene, manifest["build_id"], held)


BUILD_LEVEL = "0"
"""The optimization level of the suite's builds (GYROGEN_OPT_LEVEL, unless
the run sets it: `make test-fast` at -O3, its cache being kept; `make
test-wide` at -O2): the same bits at every level (test_compile checks).
gcc 12 compiled the default scene's integrators in 1.2 s of CPU at -O0,
4.4 s at -O1 and 7.2 s at -O2 (gfortran 0.9, 2.4 and 4.2 s); the code runs
3-5 times slower at -O0, which the suite's short runs do not feel: the
whole suite took 1,047 s of CPU at -O0 against 1,340 s at -O1. The default
scene's backends are built at -O3, the level users run."""


@pytest.fixture(scope="session", autouse=True)
def _run_builds(cache_dir: Path) -> Iterator[None]:
    """GYROGEN_CACHE is the run's build cache for every test and every
    process a test starts: the suite never builds into the user's own cache
    (~/.cache/gyrogen), and `make test-fast` keeps all it built. The builds
    are at BUILD_LEVEL."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("GYROGEN_CACHE", str(cache_dir))
        patch.setenv(flags.OPT_LEVEL, os.environ.get(flags.OPT_LEVEL, BUILD_LEVEL))
        yield


@pytest.fixture(scope="session")
def source_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The default scene as `make generate` writes it: sources, manifest and
    the --lib build files."""
    from gyrogen.codegen.generate import generate
    from gyrogen.scene import default

    out = tmp_path_factory.mktemp("generated") / default().name
    generate(default(), out, lib=True)
    return out


@pytest.fixture(scope="session")
def backends(
    source_dir: Path, cache_dir: Path, tmp_path_factory: pytest.TempPathFactory
) -> dict[str, Compiled]:
    """The default scene as C and Fortran, at -O3 (the level users run),
    each compiled once per run: the odd-numbered xdist workers start with
    Fortran, so that two workers compile one language each at the same
    time, then load the other's."""
    from gyrogen.runtime import build

    languages: list[Language] = ["c", "fortran"]
    if int(os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw")) % 2:
        languages.reverse()
    mp = pytest.MonkeyPatch()
    mp.setenv("GYROGEN_CACHE", str(cache_dir))
    mp.setenv(flags.OPT_LEVEL, "3")
    try:
        for lang in languages:
            built_once(
                tmp_path_factory,
                f"default-{lang}",
                lambda _, lang=lang: build.build(source_dir, lang),
            )
        return {lang: build.build(source_dir, lang) for lang in ("c", "fortran")}
    finally:
        mp.undo()


def shared_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A directory every xdist worker of this run sees (the run's own when
    there are no workers)."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


def built_once(
    tmp_path_factory: pytest.TempPathFactory, name: str, make: Callable[[Path], None]
) -> Path:
    """shared_dir/name, made by make(it) once per run: the first worker to
    ask makes it, the others wait for it and reuse it."""
    shared = shared_dir(tmp_path_factory)
    out = shared / name
    with open(shared / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (shared / f"{name}.complete").is_file():
            make(out)
            (shared / f"{name}.complete").touch()
    return out


@pytest.fixture(scope="session")
def examples_build(source_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """examples/Makefile's `all` with its own flags (the default scene's
    library configured, built and installed by CMake, then the programs
    through find_package), built once per run. CMake's Debug build type:
    the flags' own -O2 without Release's -O3 after them: the three libraries
    and five programs in 35 s of CPU against Release's 77 s
    (test_cmake_package builds Release)."""

    def make(build: Path) -> None:
        command = ["make", "-C", str(REPO / "examples"), f"BUILD={build}", f"GEN={source_dir}",
                   "BUILD_TYPE=Debug"]  # fmt: skip
        proc = subprocess.run([*command, "all"], capture_output=True, text=True, check=False)
        assert proc.returncode == 0, proc.stdout + proc.stderr

    return built_once(tmp_path_factory, "examples-default", make)


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
    """The C build of each scene the `gyrogen check` cases use, by scene name:
    a built-in scene from its sources in generated/ (which a test holds
    fresh), the cases' own scenes derived."""
    from gyrogen.analysis.check.cases import cases
    from gyrogen.codegen.generate import generate
    from gyrogen.runtime import build
    from gyrogen.scene import builtin_names, load

    out = {}
    for case in cases():
        name = case.scene.name
        if name in out:
            continue
        if name in builtin_names() and load(name) == case.scene:
            src = REPO / "generated" / name
        else:
            src = tmp_path_factory.mktemp(name)
            generate(case.scene, src)
        out[name] = build.build(src, "c")
    return out


LONG_POLES = (
    "test_docs.py::test_every_snippet_runs[README.md]",
    "test_scene_space.py::test_scenes_the_fuzzing_broke_keep_the_promise",
    "test_generated.py::test_checked_in_scene_is_fresh",
)
"""The suite's longest tests (the README's quick starts; the scenes the
fuzzing broke, each compiled by three compilers; every built-in scene derived
against generated/): collected first, so that pytest-xdist starts them at
once instead of leaving one on a worker at the end of the run while the
other waits."""

WIDE_RUN = "GYROGEN_WIDE"
"""Set (`make test-wide`), the cases marked wide (tests/wide.py) are run;
unset, the suite deselects them."""


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if not os.environ.get(WIDE_RUN):
        wide = [item for item in items if item.get_closest_marker("wide")]
        if wide:
            config.hook.pytest_deselected(items=wide)
            items[:] = [item for item in items if not item.get_closest_marker("wide")]

    def rank(item: pytest.Item) -> int:
        for i, pole in enumerate(LONG_POLES):
            if pole in item.nodeid:
                return i
        return len(LONG_POLES)

    items.sort(key=rank)  # stable: the rest keep their order


def pytest_report_header(config: pytest.Config) -> str | None:
    if os.environ.get(WIDE_RUN):
        return None
    return "the cases marked wide are deselected: make test-wide runs them"
