"""The generated sources compile clean under the strict flags, as C and as
C++, and the build cache and its errors behave."""

from __future__ import annotations

import hashlib
import importlib.machinery
import json
import os
import shutil
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from wide import WIDE

from gyrogen.abi import COMPILER_LOG_LINES
from gyrogen.errors import BuildError
from gyrogen.runtime import build, cache
from gyrogen.runtime.compiled import Compiled
from gyrogen.runtime.flags import C_WARNINGS, FORTRAN_STRICT


def _compile(cmd: list[str], cwd: Path) -> None:
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == "", proc.stderr


def test_c99_strict(source_dir: Path, tmp_path: Path) -> None:
    _compile(
        ["gcc", "-std=c99", *C_WARNINGS, "-c",
         str(source_dir / "gyrostat.c"), "-o", str(tmp_path / "g.o")],
        source_dir,
    )  # fmt: skip


def test_source_compiles_as_cxx(source_dir: Path, tmp_path: Path) -> None:
    _compile(
        ["g++", "-x", "c++", "-std=c++17", *C_WARNINGS, "-c",
         str(source_dir / "gyrostat.c"), "-o", str(tmp_path / "g.o")],
        source_dir,
    )  # fmt: skip


def test_fortran_2008_strict(source_dir: Path, tmp_path: Path) -> None:
    _compile(
        ["gfortran", *FORTRAN_STRICT, "-J", str(tmp_path), "-c", str(source_dir / "gyrostat.f90"),
         "-o", str(tmp_path / "f.o")],
        source_dir,
    )  # fmt: skip


def _fresh(source_dir: Path, tmp_path: Path, tag: str) -> Path:
    """A copy of the sources with a comment of its own: a cache key no
    other test (and nothing loaded in this process) has."""
    src = tmp_path / f"src-{tag}"
    shutil.copytree(source_dir, src)
    with open(src / "gyrostat.c", "a") as fh:
        fh.write(f"/* {tag} */\n")
    return src


def _break(src: Path, extra: str = "") -> None:
    text = (src / "gyrostat.c").read_text().replace("return GYROSTAT_OK;", "return GYROSTAT_OK")
    (src / "gyrostat.c").write_text(text + extra)


@pytest.mark.slow
def test_rebuild_hits_the_cache(
    source_dir: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    first = build.build(source_dir, "c")
    entries = sorted((tmp_path / "cache").iterdir())
    assert len(entries) == 1

    def no_compile(*args: object, **kwargs: object) -> None:
        raise AssertionError("unchanged sources were compiled again")

    monkeypatch.setattr(cache, "build_entry", no_compile)
    second = build.build(source_dir, "c")
    assert second.lib is first.lib
    assert sorted((tmp_path / "cache").iterdir()) == entries


@pytest.mark.slow
@WIDE
def test_changed_source_gets_a_new_cache_entry(
    source_dir: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    src = _fresh(source_dir, tmp_path, "changed")
    build.build(src, "c")
    with open(src / "gyrostat.c", "a") as fh:
        fh.write("/* touched */\n")
    build.build(src, "c")
    assert len(list((tmp_path / "cache").iterdir())) == 2


@pytest.mark.parametrize(("tool", "language"), [("gcc", "c"), ("gfortran", "fortran")])
def test_missing_compiler_names_the_package(
    source_dir: Path, monkeypatch: pytest.MonkeyPatch, tool: str, language: str
) -> None:
    real_which = shutil.which
    monkeypatch.setattr(shutil, "which", lambda name: None if name == tool else real_which(name))
    with pytest.raises(
        BuildError, match=rf"^{tool} not found: install it with `apt-get install -y {tool}`$"
    ):
        build.build(source_dir, language)  # type: ignore[arg-type]


def test_compile_error_shows_the_compiler_message(
    source_dir: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    src = _fresh(source_dir, tmp_path, "error")
    _break(src)
    with pytest.raises(BuildError) as info:
        build.build(src, "c")
    first, *rest = str(info.value).splitlines()
    plan = build._plan(src, "c")
    log = tmp_path / "cache" / "logs" / f"{plan.key}-gyrostat.c.log"
    assert first == f"gcc failed on gyrostat.c (exit status 1); full output in {log}:"
    assert "\n".join(rest) == log.read_text().strip()  # short: shown whole
    assert any("error: expected" in line and "before" in line for line in rest)
    assert [p.name for p in (tmp_path / "cache").iterdir()] == ["logs"]  # no entry, no temp


def test_long_compiler_output_shows_its_start_and_keeps_the_log(
    source_dir: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    src = _fresh(source_dir, tmp_path, "long")
    _break(src, "".join(f"int broken_{i} = ;\n" for i in range(200)))
    with pytest.raises(BuildError) as info:
        build.build(src, "c")
    first, *rest = str(info.value).splitlines()
    log = tmp_path / "cache" / "logs" / f"{build._plan(src, 'c').key}-gyrostat.c.log"
    everything = log.read_text().strip().splitlines()
    assert len(everything) > 200
    assert first == (
        f"gcc failed on gyrostat.c (exit status 1); full output in {log}; "
        f"its first {COMPILER_LOG_LINES} of {len(everything)} lines:"
    )
    assert rest == everything[:COMPILER_LOG_LINES]


@pytest.mark.slow
def test_glue_that_does_not_compile_shows_its_start(
    source_dir: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    real_render = build.render

    def broken_glue(name: str, **ctx: object) -> str:
        text = real_render(name, **ctx)
        return text + "\n#error broken glue\n" if name.startswith("cffi/glue") else text

    monkeypatch.setattr(build, "render", broken_glue)
    with pytest.raises(BuildError) as info:
        build.build(source_dir, "c")
    first, *rest = str(info.value).splitlines()
    log = tmp_path / "cache" / "logs" / f"{build._plan(source_dir, 'c').key}-cffi.log"
    assert first.startswith("cffi could not build the glue module (")
    assert f"; full output in {log}" in first and len(rest) <= COMPILER_LOG_LINES
    assert "#error broken glue" in log.read_text()


@pytest.mark.slow
def test_gyrogen_cache_naming_a_file_is_one_line(tmp_path: Path) -> None:
    """From the command line, before anything is compiled: exit 1."""
    blocker = tmp_path / "file"
    blocker.write_text("not a cache")
    env = dict(os.environ, GYROGEN_CACHE=str(blocker))
    proc = subprocess.run(
        [sys.executable, "-m", "gyrogen", "verify", "--states", "10", "--params", "1"],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    assert proc.returncode == 1
    assert proc.stderr == (
        f"gyrogen: error: GYROGEN_CACHE={blocker}: cannot use it as the build cache: "
        "Not a directory\n"
    )
    assert blocker.read_text() == "not a cache"


@pytest.mark.parametrize("value", ["9", "3x", "-O2", "fast"])
def test_an_optimization_level_not_0_to_3_is_one_line(
    value: str, source_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """GYROGEN_OPT_LEVEL other than 0, 1, 2 or 3 is named before anything is
    compiled, and the cache is left untouched."""
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("GYROGEN_OPT_LEVEL", value)
    with pytest.raises(BuildError) as caught:
        build.build(source_dir, "c")
    assert str(caught.value) == (
        f"GYROGEN_OPT_LEVEL={value!r}: not an optimization level (0, 1, 2 or 3)"
    )
    assert not (tmp_path / "cache").exists() or not any((tmp_path / "cache").iterdir())


def test_every_optimization_level_gives_the_same_bits(
    source_dir: Path, backends: dict[str, Compiled], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The default scene built at -O2 (the suite's level) runs every method,
    single and over lanes, to the bits of the -O3 build users run: nothing
    the levels change reassociates or fuses."""
    from gyrogen import methods
    from gyrogen.analysis.simulate.engine import runtime_values
    from gyrogen.scene import default

    monkeypatch.setenv("GYROGEN_OPT_LEVEL", "2")
    assert "-O2" in build._plan(source_dir, "c").flags
    low, high = build.build(source_dir, "c"), backends["c"]
    scene = default()
    x0 = np.array(scene.initial_state())
    c = high.setup(runtime_values(scene))
    x0s = np.tile(x0, (9, 1))
    x0s[:, scene.states.index("u1") :] *= 1.0 + 1e-3 * np.arange(9)[:, None]  # the speeds
    for method in methods.NAMES:
        steps = 50 if methods.get(method).fixed_step else None
        ran = [b.integrate(method, x0, c, 0.0, 5.0, rtol=1e-9, atol=1e-9, steps=steps)
               for b in (low, high)]  # fmt: skip
        assert np.array_equal(ran[0][0], ran[1][0]) and ran[0][2] == ran[1][2], method
        assert ran[0][1]["accepted"] == ran[1][1]["accepted"], method
        batch = [b.integrate_batch(method, x0s, c, 0.0, 5.0, rtol=1e-9, atol=1e-9, steps=steps)
                 for b in (low, high)]  # fmt: skip
        assert np.array_equal(batch[0][0], batch[1][0]), method
        assert np.array_equal(batch[0][2], batch[1][2]) and not batch[1][2].any(), method


@pytest.mark.parametrize(
    ("variable", "value", "root"),
    [("GYROGEN_CACHE", "file/cache", "file/cache"), ("XDG_CACHE_HOME", "file", "file/gyrogen")],
)
def test_cache_below_a_file_is_one_line(
    variable: str,
    value: str,
    root: str,
    source_dir: Path,
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
) -> None:
    """The cache root is a file or below one: one line naming it, and
    GYROGEN_CACHE: either because it chose the root, or as the way out."""
    (tmp_path / "file").write_text("")
    monkeypatch.delenv("GYROGEN_CACHE", raising=False)
    monkeypatch.setenv(variable, str(tmp_path / value))
    with pytest.raises(BuildError) as info:
        build.build(source_dir, "c")
    where, why = tmp_path / root, "Not a directory"
    assert (
        str(info.value)
        == {
            "GYROGEN_CACHE": f"GYROGEN_CACHE={where}: cannot use it as the build cache: {why}",
            "XDG_CACHE_HOME": f"cannot use {where} as the build cache: {why} "
            "(set GYROGEN_CACHE to another directory)",
        }[variable]
    )


def test_unwritable_cache_is_one_line(
    source_dir: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    src = _fresh(source_dir, tmp_path, "unwritable")

    def refuse(*args: object, **kwargs: object) -> str:
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(cache.tempfile, "mkdtemp", refuse)
    with pytest.raises(BuildError) as info:
        build.build(src, "c")
    assert str(info.value) == (
        f"GYROGEN_CACHE={tmp_path / 'cache'}: cannot use it as the build cache: Permission denied"
    )


def test_relative_cache_root_is_made_absolute(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A Fortran module finds its library by the entry's path (rpath): a
    relative one would break from another directory."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("GYROGEN_CACHE", "rel/cache")
    assert cache.cache_root() == tmp_path / "rel" / "cache"
    monkeypatch.delenv("GYROGEN_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", "xdg")
    assert cache.cache_root() == tmp_path / "xdg" / "gyrogen"


@pytest.mark.slow
@WIDE
def test_both_languages_build_at_once_under_a_relative_cache(
    source_dir: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """build_dir builds C and Fortran in threads, each with cffi's compile,
    which changes the working directory: with GYROGEN_CACHE and the sources
    relative, both builds land in that cache and load, and this process's
    working directory never moves."""
    from gyrogen.runtime.scene_build import build_dir

    src = _fresh(source_dir, tmp_path, "relative")
    with open(src / "gyrostat.f90", "a") as fh:
        fh.write("! relative\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("GYROGEN_CACHE", "cache")
    moved: list[object] = []
    real_chdir = os.chdir

    def chdir(path: object) -> None:  # cffi's compile calls it, in whatever process runs it
        moved.append(path)
        real_chdir(path)  # type: ignore[arg-type]

    monkeypatch.setattr(os, "chdir", chdir)
    built = build_dir(Path(src.name), ["c", "fortran"])
    assert {lang: b.language for lang, b in built.items()} == {"c": "c", "fortran": "fortran"}
    assert moved == []
    keys = {build._plan(src, lang).key for lang in ("c", "fortran")}
    assert keys <= {p.name for p in (tmp_path / "cache").iterdir()}
    assert sorted(tmp_path.rglob("cache")) == [tmp_path / "cache"]


FAKE_COMPILER = """#!/bin/sh
case "$*" in
  *{source}*) sleep 600 & echo $! > "{pids}/$(basename "$0")"; wait; exit 1 ;;
esac
exec {real} "$@"
"""


def _gone(pid: int) -> bool:
    """No such process, or one killed and not yet reaped."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] == "Z"
    except OSError:
        return True


@pytest.mark.slow
def test_an_interrupted_build_ends_the_other_languages_compiler(
    source_dir: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """build_dir's main thread interrupted (Ctrl-C) while C and Fortran
    build in threads: each compiler ends at once, with what it started, and
    the cache holds no entry, no half-built directory and no log."""
    import signal
    import threading

    from gyrogen.runtime.scene_build import build_dir

    src = _fresh(source_dir, tmp_path, "interrupted")
    with open(src / "gyrostat.f90", "a") as fh:
        fh.write("! interrupted\n")
    fake, pids = tmp_path / "bin", tmp_path / "pids"
    fake.mkdir(), pids.mkdir()
    for tool, source in (("gcc", "gyrostat.c"), ("gfortran", "gyrostat.f90")):
        real = shutil.which(tool)
        assert real is not None
        (fake / tool).write_text(FAKE_COMPILER.format(source=source, pids=pids, real=real))
        (fake / tool).chmod(0o755)
    monkeypatch.setenv("PATH", f"{fake}{os.pathsep}{os.environ['PATH']}")
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))

    def interrupt_when_both_compile() -> None:
        while len(list(pids.iterdir())) < 2:
            threading.Event().wait(0.05)
        os.kill(os.getpid(), signal.SIGINT)  # as a terminal's Ctrl-C: the main thread's

    threading.Thread(target=interrupt_when_both_compile, daemon=True).start()
    # Ctrl-C as a terminal's process takes it, where this run ignores it (in the background)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            build_dir(src, ["c", "fortran"])
    finally:
        signal.signal(signal.SIGINT, previous)
    sleepers = [int(p.read_text()) for p in pids.iterdir()]
    assert len(sleepers) == 2 and all(_gone(pid) for pid in sleepers)
    assert list((tmp_path / "cache").iterdir()) == []


def test_no_home_directory_asks_for_gyrogen_cache(
    source_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def no_home() -> Path:
        raise RuntimeError("Could not determine home directory.")

    monkeypatch.delenv("GYROGEN_CACHE", raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.setattr(cache.Path, "home", staticmethod(no_home))
    with pytest.raises(
        BuildError, match=r"^no home directory for the build cache: set GYROGEN_CACHE$"
    ):
        build.build(source_dir, "c")


@pytest.fixture(scope="module")
def built(source_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """A cache entry of its own, built once: the tests below damage it."""
    mp = pytest.MonkeyPatch()
    tmp = tmp_path_factory.mktemp("damaged")
    mp.setenv("GYROGEN_CACHE", str(tmp / "cache"))
    src = _fresh(source_dir, tmp, "damaged")
    build.build(src, "c")
    yield src
    mp.undo()


def _module(entry: Path) -> Path:
    return entry / json.loads((entry / cache.MARKER).read_text())["module"]


def _truncate(entry: Path) -> None:
    """The module cut to its first 4 KiB, as a new file put in its place:
    cutting the file itself would pull the pages from under this process
    when the module is the one it has loaded (SIGBUS at the next call)."""
    so = _module(entry)
    cut = so.with_name(so.name + ".cut")
    cut.write_bytes(so.read_bytes()[:4096])
    cut.replace(so)


DAMAGES = [
    (lambda entry: (entry / cache.MARKER).unlink(), "no readable complete.json"),
    (lambda entry: _module(entry).unlink(), "{name} is missing or not as built"),
    (_truncate, "{name} is missing or not as built"),
]


@pytest.mark.slow
@pytest.mark.parametrize(("damage", "why"), DAMAGES, ids=["no marker", "no module", "truncated"])
def test_damaged_entry_is_rebuilt_with_one_warning(
    built: Path,
    damage: Callable[[Path], None],
    why: str,
    backends: dict[str, Compiled],
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("GYROGEN_CACHE", str(built.parent / "cache"))
    entry = cache.cache_dir() / build._plan(built, "c").key
    name = _module(entry).name
    damage(entry)
    comp = build.build(built, "c")
    err = capsys.readouterr().err
    assert err.startswith(f"gyrogen: warning: rebuilding cache entry {entry}: ")
    assert why.format(name=name) in err and err.count("\n") == 1
    assert cache.verified(entry) == entry / name  # whole again
    _agrees(comp, backends["c"])


def _agrees(comp: Compiled, reference: Compiled) -> None:
    p = np.array([10, 2, 3, 4, 5, 0.3, 0.5, 0.8, 0.2, -0.1, 9.81, 0.5])
    x = np.linspace(-0.5, 0.5, 14)
    np.testing.assert_array_equal(comp.rhs(x, comp.setup(p)), reference.rhs(x, reference.setup(p)))


def _garbage_module(entry: Path, module_name: str) -> None:
    """An entry whose marker matches a module that is not a shared object."""
    entry.mkdir(parents=True)
    so = entry / f"{module_name}{importlib.machinery.EXTENSION_SUFFIXES[0]}"
    so.write_bytes(b"not an ELF file")
    digest = hashlib.sha256(so.read_bytes()).hexdigest()
    marker = {"module": so.name, "sha256": {so.name: digest}}
    (entry / cache.MARKER).write_text(json.dumps(marker))


@pytest.mark.slow
@pytest.mark.parametrize(
    ("make", "why"),
    [
        (lambda entry, name: entry.mkdir(parents=True), "no readable complete.json"),
        (_garbage_module, "cannot load"),
    ],
    ids=["empty", "not loadable"],
)
def test_entry_never_loaded_is_checked_too(
    make: Callable[[Path, str], None],
    why: str,
    source_dir: Path,
    tmp_path: Path,
    backends: dict[str, Compiled],
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """An entry left by a build cut short (an empty directory, where the
    old code failed with a traceback), or one that matches its marker but
    does not load: rebuilt, with one warning."""
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    src = _fresh(source_dir, tmp_path, why.replace(" ", "_"))
    plan = build._plan(src, "c")
    entry = tmp_path / "cache" / plan.key
    make(entry, plan.module_name)
    comp = build.build(src, "c")
    err = capsys.readouterr().err
    assert err.startswith(f"gyrogen: warning: rebuilding cache entry {entry}: {why}")
    assert err.count("\n") == 1
    assert cache.verified(entry).name.startswith(plan.module_name)
    _agrees(comp, backends["c"])


def test_missing_manifest(tmp_path: Path) -> None:
    with pytest.raises(BuildError, match=r"no manifest\.json in"):
        build.build(tmp_path, "c")
