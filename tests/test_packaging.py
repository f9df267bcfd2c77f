"""The wheel is the package: every module, template and scene of
generator/gyrogen ships in it (the build backend finds them; nothing is
listed by hand), and installed into a fresh venv outside the source tree the
command line starts and does the main job."""

from __future__ import annotations

import fcntl
import os
import site
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from wide import WIDE

pytestmark = pytest.mark.slow  # a wheel built and installed into a fresh venv

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "generator" / "gyrogen"


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    # one build at a time: setuptools builds in the checkout's build/, which
    # two pytest-xdist workers would share
    lock = (tmp_path_factory.getbasetemp().parent / "gyrogen-wheel.lock").open("w")
    fcntl.flock(lock, fcntl.LOCK_EX)
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation",
         "-w", str(out), str(REPO)],
        check=True, capture_output=True,
    )  # fmt: skip
    fcntl.flock(lock, fcntl.LOCK_UN)
    lock.close()
    (path,) = out.glob("gyrogen-*.whl")
    return path


def test_wheel_holds_every_file_of_the_package(wheel: Path) -> None:
    """The package's files, and the templates: at the top level of the
    checkout, in the package as gyrogen/templates (a link to them)."""
    tracked = subprocess.run(
        ["git", "ls-files", "generator/gyrogen", "templates"], cwd=REPO, capture_output=True,
        text=True, check=True,
    ).stdout.split()  # fmt: skip
    assert (PACKAGE / "templates").is_symlink()
    expected = {f.removeprefix("generator/") for f in tracked if f.startswith("generator/")}
    expected -= {"gyrogen/templates"}  # the link itself
    expected |= {"gyrogen/" + f for f in tracked if f.startswith("templates/")}
    assert any(f.startswith("gyrogen/commands/") for f in expected)
    assert any(f.endswith(".jinja") for f in expected)
    assert any(f.endswith(".toml") for f in expected)
    names = set(zipfile.ZipFile(wheel).namelist())
    assert expected <= names, sorted(expected - names)


@pytest.fixture(scope="module")
def fresh(wheel: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A new venv with the wheel installed (no editable link to this tree).
    Its dependencies come from this test run's environment through a plain
    path entry, so no download is needed and no .pth of that environment (the
    editable install of gyrogen among them) is read."""
    venv = tmp_path_factory.mktemp("venv") / "fresh"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    py = venv / "bin" / "python"
    subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps", str(wheel)], check=True,
                   capture_output=True)  # fmt: skip
    purelib = subprocess.run(
        [str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True, text=True, check=True,
    ).stdout.strip()  # fmt: skip
    deps = "\n".join(site.getsitepackages())
    (Path(purelib) / "zz_test_dependencies.pth").write_text(deps + "\n")
    return venv


def run(venv: Path, *args: str, cwd: Path) -> str:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    proc = subprocess.run([str(venv / "bin" / "gyrogen"), *args], cwd=cwd, env=env,
                          capture_output=True, text=True, check=False)  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


@WIDE
def test_installed_wheel_runs_the_command_line(fresh: Path, tmp_path: Path) -> None:
    where = subprocess.run(
        [str(fresh / "bin" / "python"), "-c", "import gyrogen; print(gyrogen.__file__)"],
        cwd=tmp_path, capture_output=True, text=True, check=True,
    ).stdout  # fmt: skip
    assert where.startswith(str(fresh)), where  # the wheel's copy, not this tree
    assert "generate" in run(fresh, "--help", cwd=tmp_path)
    out = run(fresh, "run", "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert "all checks passed" in out and (tmp_path / "out" / "gyrostat.c").is_file()
    out = run(fresh, "verify", "dual_spin", cwd=tmp_path)
    assert "FAIL" not in out and "refused with the documented code" in out


def test_the_code_digest_reads_every_template() -> None:
    """A sweep's identity hashes gyrogen's modules and templates, the
    templates through the package's link to them."""
    from gyrogen.runtime.scene_build import digested

    templates = {p.name for p in (REPO / "templates").rglob("*.jinja")}
    read = {p.name for p in digested(PACKAGE) if p.suffix == ".jinja"}
    assert templates and templates <= read
