"""The command line: outputs, and one clear line per error with its exit code."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import weakref
from pathlib import Path
from typing import Any

import pytest
from ctrl_c import interrupted, tree

from gyrogen import files as files_module
from gyrogen.codegen import generate as generate_module
from gyrogen.errors import GyrogenError
from gyrogen.scene import default


def test_generate_writes_sources_and_manifest(tmp_path: Path, cli) -> None:
    code, out, _ = cli(["generate", "--out", str(tmp_path / "o")])
    assert code == 0
    names = sorted(p.name for p in (tmp_path / "o").iterdir())
    assert names == [
        "gyrostat.c", "gyrostat.f90", "gyrostat.h", "gyrostat_f.h",
        "gyrostat_ode.c", "gyrostat_ode.f90", "gyrostat_ode.h", "manifest.json",
    ]  # fmt: skip
    assert "gyrostat" in out and "(full model)" in out


def test_unknown_option_is_one_line_exit_2(cli) -> None:
    code, out, err = cli(["generate", "--bogus"])
    assert code == 2
    assert err.count("\n") == 1 and "No such option" in err and "--bogus" in err
    assert out == ""


def test_unknown_command_is_one_line_exit_2(cli) -> None:
    code, _, err = cli(["frobnicate"])
    assert code == 2 and err.count("\n") == 1 and "frobnicate" in err


def test_unwritable_out_is_one_line_exit_1(tmp_path: Path, cli) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    code, _, err = cli(["generate", "--out", str(blocker / "sub")])
    assert code == 1
    assert (
        err
        == f"gyrogen: error: cannot create output directory {blocker / 'sub'}: Not a directory\n"
    )
    assert blocker.read_text() == "not a directory"


def test_failed_write_leaves_nothing_half_written(
    tmp_path: Path, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    out_dir = tmp_path / "o"
    out_dir.mkdir()
    (out_dir / "gyrostat.c").write_text("old")
    real_replace = os.replace
    calls = []

    def fail_second(src: str, dst: Path) -> None:
        calls.append(dst)
        if len(calls) == 1:
            raise OSError(28, "No space left on device")
        real_replace(src, dst)

    monkeypatch.setattr(files_module.os, "replace", fail_second)
    code, _, err = cli(["generate", "--no-check", "--out", str(out_dir)])
    assert code == 1
    assert (
        err == f"gyrogen: error: cannot write {out_dir / 'gyrostat.h'}: No space left on device\n"
    )
    assert sorted(p.name for p in out_dir.iterdir()) == ["gyrostat.c"]
    assert (out_dir / "gyrostat.c").read_text() == "old"


def _old_sources(out_dir: Path) -> dict[str, str]:
    """An earlier generation's gyrostat.c and manifest.json in out_dir."""
    out_dir.mkdir()
    old = {"gyrostat.c": "old source", "manifest.json": "old manifest"}
    for name, text in old.items():
        (out_dir / name).write_text(text)
    return old


def _contents(out_dir: Path) -> dict[str, str]:
    return {p.name: p.read_text() for p in out_dir.iterdir() if p.is_file()}


def test_directory_in_the_way_writes_nothing(tmp_path: Path, cli) -> None:
    out_dir = tmp_path / "o"
    old = _old_sources(out_dir)
    (out_dir / "gyrostat_ode.c").mkdir()
    code, out, err = cli(["generate", "--no-check", "--out", str(out_dir)])
    assert code == 1 and out == ""
    assert err == f"gyrogen: error: cannot write {out_dir / 'gyrostat_ode.c'}: Is a directory\n"
    assert _contents(out_dir) == old  # no new file, no temporary, the old ones as they were
    assert (out_dir / "gyrostat_ode.c").is_dir()


def test_fifo_in_the_way_writes_nothing(tmp_path: Path, cli) -> None:
    out_dir = tmp_path / "o"
    old = _old_sources(out_dir)
    os.mkfifo(out_dir / "gyrostat.h")
    code, _, err = cli(["generate", "--no-check", "--out", str(out_dir)])
    assert code == 1
    assert err == f"gyrogen: error: cannot write {out_dir / 'gyrostat.h'}: Not a regular file\n"
    assert _contents(out_dir) == old


def _fail_on(monkeypatch: pytest.MonkeyPatch, target: Path, exc: BaseException) -> None:
    """os.replace raises exc the first time it would put a file at target."""
    real_replace = os.replace
    raised = []

    def replace(src: str, dst: str | Path) -> None:
        if Path(dst) == target and not raised:
            raised.append(exc)
            raise exc
        real_replace(src, dst)

    monkeypatch.setattr(files_module.os, "replace", replace)


def test_failed_rename_puts_every_old_file_back(
    tmp_path: Path, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The rename of the sixth of seven files fails: the five already in
    place are taken back, the old gyrostat.c comes back from its temporary
    name, and manifest.json (renamed last) was never touched."""
    out_dir = tmp_path / "o"
    old = _old_sources(out_dir)
    failing = out_dir / "gyrostat_ode.f90"
    _fail_on(monkeypatch, failing, PermissionError(13, "Permission denied"))
    code, _, err = cli(["generate", "--no-check", "--out", str(out_dir)])
    assert code == 1
    assert err == f"gyrogen: error: cannot write {failing}: Permission denied\n"
    assert _contents(out_dir) == old
    assert sorted(p.name for p in out_dir.iterdir()) == sorted(old)


def test_interrupt_while_writing_puts_every_old_file_back(
    tmp_path: Path, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Ctrl-C (KeyboardInterrupt) in the middle of the renames: exit 130,
    the old files as they were, no temporary file left."""
    out_dir = tmp_path / "o"
    old = _old_sources(out_dir)
    _fail_on(monkeypatch, out_dir / "manifest.json", KeyboardInterrupt())
    code, out, err = cli(["generate", "--no-check", "--out", str(out_dir)])
    assert code == 130 and out == ""
    assert err.endswith("gyrogen: aborted\n") and "Traceback" not in err
    assert _contents(out_dir) == old
    assert sorted(p.name for p in out_dir.iterdir()) == sorted(old)


def test_ctrl_c_while_writing_puts_the_old_files_back_once_they_are_placed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A SIGINT between two statements of write_atomic (here: as the second
    file is staged) is held until every file is placed, then the old
    versions are put back and it is raised: an interrupted write never
    stays written, and no temporary file is left."""
    out_dir = tmp_path / "o"
    old = _old_sources(out_dir)
    real_stage = files_module._stage
    staged = []

    def stage(target: Path, data: str | bytes) -> Path:
        staged.append(target)
        if len(staged) == 2:
            signal.raise_signal(signal.SIGINT)
        return real_stage(target, data)

    monkeypatch.setattr(files_module, "_stage", stage)
    new = {name: f"new {name}" for name in [*old, "gyrostat.h"]}
    # Python's own handler, as a terminal's process has it: a run in the
    # background inherits SIGINT ignored, and nothing would be raised
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            files_module.write_atomic(out_dir, new)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert len(staged) == 3  # every file was staged (and placed) before the roll-back
    assert _contents(out_dir) == old
    assert sorted(p.name for p in out_dir.iterdir()) == sorted(old)


def test_transaction_puts_back_what_each_write_in_it_did(tmp_path: Path) -> None:
    """Two writes into two directories (one made by them, one file written
    twice): an exception out of the transaction puts every file back as it
    was and removes the directories made; a SystemExit keeps them all."""
    old_dir, new_dir = tmp_path / "o", tmp_path / "new" / "deep"
    old = _old_sources(old_dir)
    with pytest.raises(RuntimeError), files_module.transaction():
        files_module.write_atomic(old_dir, {"gyrostat.c": "one", "gyrostat.h": "one"})
        files_module.write_atomic(old_dir, {"gyrostat.c": "two", "gyrostat.h": "two"})
        files_module.write_atomic(new_dir, {"a.c": "a"})
        raise RuntimeError
    assert _contents(old_dir) == old and sorted(p.name for p in old_dir.iterdir()) == sorted(old)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o"]
    with pytest.raises(SystemExit), files_module.transaction():
        files_module.write_atomic(old_dir, {"gyrostat.c": "one"})
        with files_module.transaction():
            files_module.write_atomic(new_dir, {"a.c": "a"})
        raise SystemExit(1)
    assert _contents(old_dir) == {**old, "gyrostat.c": "one"}
    assert sorted(p.name for p in old_dir.iterdir()) == sorted(old)  # the old version removed
    assert _contents(new_dir) == {"a.c": "a"}


def _old_scenes(out: Path, names: list[str]) -> dict[str, bytes]:
    """An earlier generation's files in each scene's directory under out."""
    for name in names:
        (out / name).mkdir(parents=True)
        (out / name / f"{name}.c").write_text(f"old {name}")
        (out / name / "manifest.json").write_text(f'{{"prefix": "{name}", "old": true}}')
    return tree(out)


@pytest.mark.slow  # three scenes rendered in a process of its own
def test_ctrl_c_during_a_multi_scene_generate_writes_no_scene(tmp_path: Path) -> None:
    """A real SIGINT as the second of three scenes is written: before, the
    first scene stayed written, and the second (its Ctrl-C held until its
    files were placed) too, beside exit 130. Now every scene's files are as
    they were (old ones back, no new one, no temporary)."""
    names = ["torque_free", "dual_spin", "wheel_spinup"]
    out = tmp_path / "out"
    old = _old_scenes(out, names)
    argv = ["generate", *names, "--no-check", "--out", str(out)]
    code, err = interrupted(out / names[1], argv, tmp_path / "cache")
    assert code == 130 and err.endswith("gyrogen: aborted\n") and "Traceback" not in err
    assert tree(out) == old


@pytest.mark.slow  # a child interpreter derives a scene, then a real SIGINT (in-process: fast)
def test_ctrl_c_while_a_scene_is_placed_leaves_nothing_written(tmp_path: Path) -> None:
    """A real SIGINT as the one scene's files are being placed: before, exit
    130 "aborted" beside the whole output, written. Now exit 130 and the
    output directory it made is gone."""
    out = tmp_path / "new" / "torque_free"
    argv = ["generate", "torque_free", "--no-check", "--out", str(out)]
    code, err = interrupted(out, argv, tmp_path / "cache")
    assert code == 130 and err.endswith("gyrogen: aborted\n") and "Traceback" not in err
    assert not (tmp_path / "new").exists()


def _default_sigint() -> None:
    """In the child: SIGINT as a terminal's process gets it, where this run
    ignores it (in the background) and the child would inherit that."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_ctrl_c_python_cannot_raise_aborts_after_the_command(
    tmp_path: Path, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A SIGINT whose handler runs where Python cannot propagate what it
    raises (an import lock's weakref callback: the first-second test met it
    in CI): before, Python printed "Exception ignored in ... Interrupted", the
    command ran on and exited 0. Now nothing is printed but the one line,
    exit 130, and what the command wrote is put back."""
    from gyrogen.commands import group

    command = group.run

    def run(argv: list[str] | None) -> None:
        class Box:
            pass

        box = Box()
        ref = weakref.ref(box, lambda _: signal.raise_signal(signal.SIGINT))
        del box  # the callback runs here, and the handler inside it
        assert ref() is None
        command(argv)

    monkeypatch.setattr(group, "run", run)
    target = tmp_path / "new" / "my_sat.toml"
    code, _, err = cli(["new", "my_sat", "--out", str(target)])
    assert (code, err) == (130, "gyrogen: aborted\n")
    assert not (tmp_path / "new").exists()


@pytest.mark.slow
def test_ctrl_c_at_any_moment_of_the_first_second(tmp_path: Path) -> None:
    """SIGINT at 20 moments 0.05 s apart over a command's first second (the
    imports: they take 2 s and more): each is `gyrogen: aborted`, exit 130
    and nothing written (or, done already, exit 0 and the output); never a
    KeyboardInterrupt traceback from inside an import. The second is counted
    from when the interpreter runs the console script: before that no code
    of the program runs and SIGINT is Python's own, so the moments start at
    twice the start-up of five interpreters at once that import what the
    console script imports first, measured here (the load moves it). Five
    run at once; the console script where there is one."""
    script = Path(sys.executable).with_name("gyrogen")
    gyrogen = [str(script)] if script.is_file() else [sys.executable, "-m", "gyrogen"]
    env = {**os.environ, "GYROGEN_CACHE": str(tmp_path / "cache")}
    reset = _default_sigint if signal.getsignal(signal.SIGINT) is signal.SIG_IGN else None
    commands = [["generate", "--out"], ["--help"], ["scenes"], ["generate", "--no-check", "--out"]]
    floor = 2 * _started_in(sys.executable, 5)
    codes = []
    for batch in range(4):
        runs = []
        for k in range(5 * batch, 5 * batch + 5):
            argv = [*gyrogen, *commands[k % 4]]
            argv += [str(tmp_path / f"out{k}")] if argv[-1] == "--out" else []
            pipe = subprocess.PIPE
            proc = subprocess.Popen(
                argv, env=env, stdout=pipe, stderr=pipe, text=True, preexec_fn=reset
            )
            runs.append((k, time.monotonic(), proc))
        for k, start, proc in runs:
            time.sleep(max(0.0, start + floor + 0.05 * k - time.monotonic()))
            proc.send_signal(signal.SIGINT)
        for k, _, proc in runs:
            _, err = proc.communicate(timeout=120)
            codes.append(proc.returncode)
            assert (proc.returncode, err) in ((130, "gyrogen: aborted\n"), (0, "")), (k, err)
            out = tmp_path / f"out{k}"
            if proc.returncode == 130:  # exit 0: the command ended first, its output stands
                assert not out.exists() or not any(out.iterdir()), (k, list(out.iterdir()))
    assert codes.count(130) >= 10, codes


def _started_in(python: str, n: int) -> float:
    """Seconds from starting n pythons at once to the last one's end, each
    running what a console script runs before the program's own code (its
    imports of re and sys): the start-up under this moment's load."""
    start = time.monotonic()
    procs = [subprocess.Popen([python, "-c", "import re, sys"]) for _ in range(n)]
    assert all(p.wait() == 0 for p in procs)
    return time.monotonic() - start


def test_full_disk_while_staging_leaves_no_temporary(
    tmp_path: Path, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The third temporary file cannot be created: the two already written
    are removed, and nothing was renamed."""
    out_dir = tmp_path / "o"
    old = _old_sources(out_dir)
    real_mkstemp = files_module.tempfile.mkstemp
    made = []

    def mkstemp(**kwargs: Any) -> tuple[int, str]:
        made.append(kwargs["prefix"])
        if len(made) == 3:
            raise OSError(28, "No space left on device")
        return real_mkstemp(**kwargs)

    monkeypatch.setattr(files_module.tempfile, "mkstemp", mkstemp)
    code, _, err = cli(["generate", "--no-check", "--out", str(out_dir)])
    assert code == 1 and made[2] == ".gyrostat_ode.h."
    assert (
        err
        == f"gyrogen: error: cannot write {out_dir / 'gyrostat_ode.h'}: No space left on device\n"
    )
    assert sorted(p.name for p in out_dir.iterdir()) == sorted(old) and _contents(out_dir) == old


@pytest.mark.parametrize(
    "mask",
    [
        pytest.param(0o022, marks=pytest.mark.slow),
        0o027,
        pytest.param(0o077, marks=pytest.mark.slow),
    ],
)  # one mask in the fast loop: each renders the default scene twice
def test_written_files_have_the_mode_open_gives(
    mask: int, tmp_path: Path, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    """0o666 less the umask, for new and replaced files, generate and new
    alike; also where /proc/self/status does not tell the umask."""
    saved = os.umask(mask)
    try:
        cli(["generate", "--no-check", "--out", str(tmp_path / "o")])
        cli(["generate", "--no-check", "--out", str(tmp_path / "o")])  # replaces each file
        cli(["new", "my_sat", "--out", str(tmp_path / "my_sat.toml")])
        monkeypatch.setattr(files_module, "_PROC_STATUS", tmp_path / "no_such_status")
        files_module._umask_once.cache_clear()
        cli(["new", "my_sat2", "--out", str(tmp_path / "my_sat2.toml")])
    finally:
        os.umask(saved)
        files_module._umask_once.cache_clear()
    written = [*(tmp_path / "o").iterdir(), tmp_path / "my_sat.toml", tmp_path / "my_sat2.toml"]
    assert len(written) == 10
    assert {oct(p.stat().st_mode & 0o777) for p in written} == {oct(0o666 & ~mask)}


def test_umask_is_read_without_changing_it(monkeypatch: pytest.MonkeyPatch) -> None:
    saved = os.umask(0o037)
    try:
        calls = []
        monkeypatch.setattr(files_module.os, "umask", lambda m: calls.append(m) or 0o037)
        assert files_module.umask() == 0o037 and calls == []  # from /proc/self/status
    finally:
        monkeypatch.undo()  # the real os.umask again, to restore the mask
        os.umask(saved)


def test_out_naming_a_file_is_a_usage_error(tmp_path: Path, cli) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("mine")
    code, _, err = cli(["generate", "--out", str(blocker)])
    assert code == 2
    assert err == (
        f"gyrogen generate: error: Invalid value for '--out': Directory '{blocker}' is a file. "
        "(see --help)\n"
    )
    assert blocker.read_text() == "mine"


def test_render_failure_writes_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def broken(unit: object) -> dict[str, str]:
        raise GyrogenError("boom")

    monkeypatch.setattr(generate_module.fortran, "files", broken)
    with pytest.raises(GyrogenError):
        generate_module.generate(default(), tmp_path / "o")
    assert not (tmp_path / "o").exists()


@pytest.mark.slow  # the proof again: test_model proves it in the fast loop
def test_prove(cli) -> None:
    code, out, _ = cli(["prove"])
    assert code == 0
    assert "mass matrix (7x7)" in out and "forcing (7)" in out
    assert "The two formulations are identical." in out


@pytest.mark.slow
def test_equations_text_and_latex(cli) -> None:
    code, out, _ = cli(["equations"])
    assert code == 0
    assert "(a) Separate bodies" in out and "(b) Lumped carrier" in out
    assert "IA11 = I + I11 + l3**2*m_a*m_b/(m_a + m_b)" in out
    code, out, _ = cli(["equations", "--latex"])
    assert code == 0 and r"\begin{align}" in out and r"I_{\tilde{A}11}" in out


def test_ops_table(cli) -> None:
    code, out, _ = cli(["ops"])
    assert code == 0
    assert all(f"({k})" in out for k in ("i", "ii", "iii", "lu", "setup"))


def test_verify_small(tmp_path: Path, cli) -> None:
    code, out, _ = cli(["verify", "--out", str(tmp_path / "v"), "--states", "500", "--params", "5"])
    assert code == 0, out
    assert "C vs reference" in out and "Fortran vs reference" in out and "C vs Fortran" in out
    assert "setup refusals:" in out


def test_run_lists_the_files_it_wrote(tmp_path: Path, cli) -> None:
    """Into a directory that holds an older version: the listing names the
    files written, not the old versions its transaction keeps aside until
    the command ends."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "gyrostat.c").write_text("/* an older version */\n")
    code, text, err = cli(["run", "--out", str(out), "--states", "20", "--params", "1"])
    assert code == 0, err
    listed = next(line for line in text.splitlines() if line.startswith("generated "))
    names = sorted(p.name for p in out.iterdir())
    assert listed == f"generated {out}/ ({', '.join(names)})", listed


@pytest.mark.slow  # a child interpreter derives the default scene (test_compile: fast)
def test_missing_compiler_from_the_command_line(tmp_path: Path) -> None:
    """A PATH without gcc: one line naming the package, exit 1."""
    env = dict(os.environ, PATH=str(tmp_path), GYROGEN_CACHE=str(tmp_path / "cache"))
    proc = subprocess.run(
        [sys.executable, "-m", "gyrogen", "verify", "--out", str(tmp_path / "v"), "--states", "10"],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    assert proc.returncode == 1
    assert (
        proc.stderr == "gyrogen: error: gcc not found: install it with `apt-get install -y gcc`\n"
    )


def test_generate_lib_writes_build_files(tmp_path: Path, cli) -> None:
    code, _, _ = cli(["generate", "--no-check", "--lib", "--out", str(tmp_path / "o")])
    assert code == 0
    names = {p.name for p in (tmp_path / "o").iterdir()}
    assert {"CMakeLists.txt", "gyrostat.mk", "gyrostat.c", "manifest.json"} <= names
    assert "Do not edit" in (tmp_path / "o" / "CMakeLists.txt").read_text()


def test_new_into_a_missing_directory_creates_it(tmp_path: Path, cli) -> None:
    target = tmp_path / "a" / "b" / "my_sat.toml"
    code, out, _ = cli(["new", "my_sat", "--out", str(target)])
    assert code == 0 and out == f"wrote {target}: edit it, then `gyrogen generate {target}`\n"
    assert target.is_file() and sorted(p.name for p in target.parent.iterdir()) == ["my_sat.toml"]


def test_new_over_a_directory_is_one_line(
    tmp_path: Path, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "my_sat.toml").mkdir()
    code, _, err = cli(["new", "my_sat"])
    assert (code, err) == (
        1,
        "gyrogen: error: my_sat.toml exists: choose another name or pass --force\n",
    )
    code, _, err = cli(["new", "my_sat", "--force"])
    assert (code, err) == (1, "gyrogen: error: cannot write my_sat.toml: Is a directory\n")
    code, _, err = cli(["new", "my_sat", "--out", "my_sat.toml"])
    assert code == 2 and err == (
        "gyrogen new: error: Invalid value for '--out': File 'my_sat.toml' is a directory. "
        "(see --help)\n"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["my_sat.toml"]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["my_sat", "--out", ""], "Invalid value for '--out': '' is empty: give the file to write"),
        (["my_sat", "--out", "./sub/"], "'./sub/' names a directory: give the file to write, as"),
        (["my_sat", "--out", "sub/."], "'--out': 'sub/.' names a directory"),
        (["my_sat", "--out", "sub/.."], "'--out': 'sub/..' names a directory"),
        (["fmi2Functions"], "'fmi2Functions' names an FMI header (fmi2Functions.h)"),
    ],
)
def test_new_refuses_a_place_or_name_it_cannot_write_as_asked(
    args: list[str], message: str, tmp_path: Path, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A directory's spelling or nothing as --out (./sub/ wrote a file
    named sub), or a name whose header would hide an FMI header: one line,
    exit 2, nothing written."""
    monkeypatch.chdir(tmp_path)
    code, out, err = cli(["new", *args])
    assert (code, out) == (2, "") and message in err and err.count("\n") == 1, err
    assert list(tmp_path.iterdir()) == []


def test_new_out_dash_is_standard_output(
    tmp_path: Path, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`new --out -` wrote a file named -; now the scene alone goes to
    standard output (to pipe or redirect), and nothing is written."""
    from gyrogen.scene import parse

    monkeypatch.chdir(tmp_path)
    code, out, err = cli(["new", "my_sat", "--out", "-"])
    assert (code, err) == (0, "") and parse(out, "stdin").name == "my_sat"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "argv",
    [["generate"], ["simulate", "gyrostat"], ["linearize", "dual_spin"], ["sweep", "monte_carlo"]],
)
def test_a_directory_out_of_dash_is_one_line(
    argv: list[str], tmp_path: Path, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A directory --out of - made a directory named -: - is standard
    output (as for `new`), which holds no directory; one line, exit 2."""
    monkeypatch.chdir(tmp_path)
    code, out, err = cli([*argv, "--out", "-"])
    assert (code, out) == (2, "") and err.count("\n") == 1, err
    assert "'-' is standard output, which cannot hold a directory" in err
    assert list(tmp_path.iterdir()) == []


NUMBERS = [
    (
        ["verify", "--states", "0"],
        "Invalid value for '--states': 0 is not in the range 1<=x<=1000000.",
    ),
    (["verify", "--states", "1000001"], "'--states': 1000001 is not in the range 1<=x<=1000000."),
    (
        ["verify", "--params", "0"],
        "Invalid value for '--params': 0 is not in the range 1<=x<=10000.",
    ),
    (["verify", "--seed", "-1"], "Invalid value for '--seed': -1 is not in the range x>=0."),
    (
        ["run", "--states", "-5"],
        "Invalid value for '--states': -5 is not in the range 1<=x<=1000000.",
    ),
    (["simulate", "torque_free", "--t-end", "nan"], "'--t-end': 'nan' is not a finite number."),
    (["simulate", "torque_free", "--t-end", "inf"], "'--t-end': 'inf' is not a finite number."),
    (["simulate", "torque_free", "--dt", "nan"], "'--dt': 'nan' is not a finite number."),
    (["simulate", "torque_free", "--dt", "-inf"], "'--dt': -inf is not in the range x>0.0."),
    (["simulate", "torque_free", "--dt", "0"], "'--dt': 0.0 is not in the range x>0.0."),
    (["simulate", "torque_free", "--max-nfev", "0"], "'--max-nfev': 0 is not in the range"),
    (
        ["simulate", "torque_free", "--max-nfev", "10000000000000"],
        "'--max-nfev': 10000000000000 is not in the range 1<=x<=1000000000000.",
    ),
    (
        ["bench-rhs", "--repeats", "0"],
        "Invalid value for '--repeats': 0 is not in the range 1<=x<=1000.",
    ),
    (["bench-rhs", "--repeats", "1001"], "'--repeats': 1001 is not in the range 1<=x<=1000."),
]


@pytest.mark.parametrize(("argv", "message"), NUMBERS, ids=[" ".join(a) for a, _ in NUMBERS])
def test_number_out_of_range_is_one_line_exit_2(
    argv: list[str], message: str, tmp_path: Path, cli
) -> None:
    code, out, err = cli([*argv, "--out", str(tmp_path / "o")])
    assert code == 2 and out == ""
    assert err.startswith(f"gyrogen {argv[0]}: error: ") and err.count("\n") == 1
    assert message in err, err
    assert not (tmp_path / "o").exists()


def test_two_scenes_never_mix_in_one_out(tmp_path: Path, cli) -> None:
    """A second scene into a directory that holds another's sources is one
    line, exit 2, and the first scene's files stay as they were."""
    out = tmp_path / "gen"
    assert cli(["generate", "gyrostat", "--lib", "--no-check", "--out", str(out)]).code == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    for argv in (["generate", "rw4_pyramid", "--lib", "--no-check"], ["verify", "torque_free"]):
        code, _, err = cli([*argv, "--out", str(out)])
        assert code == 2, err
        name = argv[1]
        assert err == (
            f"gyrogen: error: {out} holds the sources of scene 'gyrostat' (its manifest.json): "
            f"writing {name!r} there would mix two scenes' files; give another --out\n"
        )
        assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert cli(["generate", "gyrostat", "--no-check", "--out", str(out)]).code == 0  # itself


def _refuse_dual_spin(monkeypatch: pytest.MonkeyPatch) -> None:
    """generate's check fails for dual_spin (at once, without compiling) and
    passes every other scene."""
    from gyrogen.oracle import compare

    def check(unit: Any, files: Any) -> float:
        if unit.prefix == "dual_spin":
            raise GyrogenError("dual_spin: the generated code differs from the reference")
        return 0.0

    monkeypatch.setattr(compare, "check_rendered", check)


@pytest.mark.parametrize("failure", ["check", "in the way", "another scene's"])
def test_several_scenes_are_all_checked_before_any_is_written(
    failure: str, tmp_path: Path, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The second scene failing its check, or with something in the way of
    its directory, leaves the first unwritten too (it was written, exit 1)."""
    out = tmp_path / "D"
    if failure == "check":
        _refuse_dual_spin(monkeypatch)
    elif failure == "in the way":
        (out / "dual_spin" / "dual_spin.c").mkdir(parents=True)
    else:
        (out / "dual_spin").mkdir(parents=True)
        (out / "dual_spin" / "manifest.json").write_text('{"prefix": "other"}')
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    code, stdout, err = cli(["generate", "torque_free", "dual_spin", "--out", str(out)])
    assert code == (2 if failure == "another scene's" else 1) and "wrote" not in stdout, err
    assert err.count("gyrogen: error: ") == 1 and err.endswith("\n") and "dual_spin" in err
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before


def test_two_scenes_of_one_name_are_refused(tmp_path: Path, cli) -> None:
    """Both would go to D/torque_free: the second overwrote the first."""
    text = (Path(__file__).parents[1] / "generator/gyrogen/scenes/torque_free.toml").read_text()
    copy = tmp_path / "copy.toml"
    copy.write_text(text.replace("description = ", 'description = "another" #', 1))
    code, stdout, err = cli(
        ["generate", "torque_free", str(copy), "--no-check", "--out", str(tmp_path / "D")]
    )
    assert (code, stdout) == (2, "")
    assert err == (
        "gyrogen: error: two scenes named 'torque_free': each writes its own directory named "
        "after the scene, so the second would overwrite the first; give one another name\n"
    )
    assert not (tmp_path / "D").exists()


def test_runtime_masses_that_sum_to_zero_are_one_line(tmp_path: Path, cli) -> None:
    """m_a runtime at -5 beside a folded m_b = 5: setup's positive-mass check
    refuses it before the reduced mass divides by m_a + m_b = 0."""
    text = (Path(__file__).parents[1] / "generator/gyrogen/scenes/gyrostat.toml").read_text()
    head, tail = text.split("[simulate.parameters]")
    head = head.replace('m_b = "runtime"', "m_b = 5.0")
    tail = tail.replace("m_a = 100.0", "m_a = -5.0").replace("m_b = 5.0\n", "")
    path = tmp_path / "neg.toml"
    path.write_text(head + "[simulate.parameters]" + tail)
    code, out, err = cli(["generate", str(path), "--out", str(tmp_path / "out")])
    assert (code, out) == (2, "")
    assert err == f"gyrogen: error: {path}: parameters.m_a: must be positive (got -5.0)\n"
    assert not (tmp_path / "out").exists()


def test_cluster_manifest_records_the_effects_it_has() -> None:
    import json

    manifest = json.loads((Path(__file__).parents[1] / "generated/rw4_pyramid/manifest.json")
                          .read_text())  # fmt: skip
    assert manifest["scene"]["effects"] == {"rotor_angle": False}


def test_a_crlf_description_is_held_with_lf(tmp_path: Path, cli) -> None:
    import json

    text = (Path(__file__).parents[1] / "generator/gyrogen/scenes/torque_free.toml").read_text()
    head, tail = text.split("description = ", 1)
    path = tmp_path / "crlf.toml"
    crlf = head + 'description = """two\r\nlines"""\n' + tail.split("\n", 1)[1]
    path.write_bytes(crlf.encode())
    assert cli(["generate", str(path), "--no-check", "--out", str(tmp_path / "o")]).code == 0
    manifest = json.loads((tmp_path / "o" / "manifest.json").read_text())
    assert manifest["scene"]["description"] == "two\nlines"


@pytest.mark.slow  # a derivation and two cold builds in a cache of its own
def test_verify_after_generate_derives_nothing_again(
    tmp_path: Path, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`gyrogen generate` keeps what it rendered in the build cache's
    sources/: a verify of the scene then writes the same files and builds
    them without deriving the scene again."""
    from gyrogen.codegen import generate

    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    gen, out = tmp_path / "gen", tmp_path / "v"
    assert cli(["generate", "torque_free", "--lib", "--no-check", "--out", str(gen)]).code == 0
    monkeypatch.setattr(generate, "_UNITS", {})  # this process's units: gone
    monkeypatch.setattr(generate, "make_context", lambda scene: pytest.fail("derived again"))
    code, text, err = cli(["verify", "torque_free", "--states", "50", "--params", "2",
                           "--out", str(out)])  # fmt: skip
    assert code == 0, text + err
    written = {p.name: p.read_bytes() for p in out.iterdir()}
    assert written == {p.name: p.read_bytes() for p in gen.iterdir() if p.name in written}
    lib = {"CMakeLists.txt", "torque_free.mk", "torque_freeConfig.cmake.in", "torque_free.pc.in"}
    assert {p.name for p in gen.iterdir()} - set(written) == lib


def test_other_scenes_take_the_full_model_from_the_cache(
    tmp_path: Path, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A scene other than the default one is rendered (by `gyrogen generate`
    and by scene_sources, api.compile's path) with the full model's sizes
    read from the default scene's kept manifest: the full model is not
    derived, and its sizes are those a derivation gives."""
    from gyrogen.codegen.manifest import FULL_MODEL, sizes
    from gyrogen.runtime import scene_build
    from gyrogen.scene import load

    derived = sizes(generate_module.full_model_unit())  # once per process (source_dir's too)
    held = scene_build.scene_sources(default())  # the run's cache: seeded from generated/
    monkeypatch.setenv("GYROGEN_CACHE", str(tmp_path / "cache"))
    scene_build.keep_sources(default(), held.build_id, held.files)
    monkeypatch.setattr(generate_module, "full_model_unit", lambda: pytest.fail("full model"))
    code, text, err = cli(["generate", "torque_free", "--no-check", "--out", str(tmp_path / "o")])
    assert code == 0, text + err
    ops = derived["ops"]
    assert text.splitlines()[-2].split() == [
        "(full", "model)", "14/14", str(derived["np"]), str(derived["nc"]),
        str(ops["setup"]), str(ops["rhs"]),
    ]  # fmt: skip
    rendered = scene_build.scene_sources(load("dual_spin")).files  # not kept: rendered
    for manifest in (tmp_path / "o" / "manifest.json").read_text(), rendered["manifest.json"]:
        full = json.loads(manifest)["full_model"]
        assert full == {key: derived[key] for key in FULL_MODEL}
