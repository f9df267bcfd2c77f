"""The documentation: README.md and the site under docs/.

The site builds with warnings as errors (broken links and anchors among
them), fetches nothing from elsewhere, and its reference pages hold what the
code registers. Every shell and Python snippet is run, page by page in a
fresh directory, each page's snippets in order; a block preceded by
`<!-- docs-test: skip (reason) -->` is not, and those are few and counted.
Every TOML block is a scene or a sweep file that gyrogen accepts. No page
tells the project's history.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest
from wide import WIDE

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted([ROOT / "README.md", *(ROOT / "docs").rglob("*.md")])
SKIP = re.compile(r"<!-- docs-test: skip \((.+?)\) -->")
RUNS = {"sh": "sh", "bash": "sh", "python": "python"}
MAX_SKIPPED = 4
"""Blocks that set up a machine, run the whole suite or a long job."""


@dataclass(frozen=True)
class Block:
    page: Path
    line: int
    lang: str
    code: str
    skipped: str
    """The reason given in the skip marker above the block, or ''."""


def blocks(page: Path) -> list[Block]:
    """The fenced code blocks of a page, with their language and skip marker."""
    lines = page.read_text(encoding="utf-8").splitlines()
    out, i = [], 0
    while i < len(lines):
        m = re.match(r"^```(\w*)", lines[i])
        if not m:
            i += 1
            continue
        start, body = i, []
        i += 1
        while lines[i] != "```":
            body.append(lines[i])
            i += 1
        marker = SKIP.fullmatch(lines[start - 1].strip()) if start else None
        out.append(
            Block(page, start + 1, m[1], "\n".join(body) + "\n", marker[1] if marker else "")
        )
        i += 1
    return out


def env() -> dict[str, str]:
    """This checkout's gyrogen first: its sources, then the venv's scripts.
    A CMake build the page does not give a type (the README's package) is
    a Debug one (CMAKE_BUILD_TYPE, read by CMake 3.22 and later), as the
    suite's own builds are at GYROGEN_OPT_LEVEL: what is checked is that the
    commands run; test_cmake_package builds the package as Release."""
    e = dict(os.environ)
    e.setdefault("CMAKE_BUILD_TYPE", "Debug")
    e["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{e.get('PATH', '')}"
    e["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT / "generator"), e.get("PYTHONPATH")]))
    e["NO_MKDOCS_2_WARNING"] = "1"
    return e


def runnable(page: Path) -> list[Block]:
    return [b for b in blocks(page) if b.lang in RUNS and not b.skipped]


def where(b: Block) -> str:
    return f"{b.page.relative_to(ROOT)}:{b.line}"


@pytest.mark.slow
@pytest.mark.parametrize(
    "page",
    [p if p.name == "README.md" else pytest.param(p, marks=WIDE) for p in PAGES if runnable(p)],
    ids=lambda p: str(p.relative_to(ROOT)),
)
def test_every_snippet_runs(page: Path, tmp_path: Path) -> None:
    """The page's shell and Python blocks, in order, in one fresh directory
    (the README's in the suite; the guides' in `make test-wide`)."""
    for b in runnable(page):
        if RUNS[b.lang] == "python":
            cmd = [sys.executable, "-c", b.code]
        else:
            cmd = ["bash", "-euo", "pipefail", "-c", b.code]
        proc = subprocess.run(
            cmd, cwd=tmp_path, env=env(), capture_output=True, text=True, timeout=900
        )
        assert proc.returncode == 0, f"{where(b)} exit {proc.returncode}:\n{proc.stderr[-3000:]}"


def test_few_snippets_are_skipped_and_each_says_why() -> None:
    skipped = [b for p in PAGES for b in blocks(p) if b.skipped]
    assert len(skipped) <= MAX_SKIPPED, [where(b) for b in skipped]
    assert all(b.lang in RUNS for b in skipped), "a skip marker above a block that never runs"
    stray = [
        f"{p.relative_to(ROOT)}"
        for p in PAGES
        for text in [p.read_text(encoding="utf-8")]
        if len(SKIP.findall(text)) != len([b for b in blocks(p) if b.skipped])
    ]
    assert not stray, f"a skip marker not right above a code block: {stray}"


def test_every_toml_block_is_a_scene_or_a_sweep_gyrogen_accepts() -> None:
    from gyrogen.analysis.sweep.spec import parse as parse_sweep
    from gyrogen.scene import parse as parse_scene

    checked = 0
    for b in (b for p in PAGES for b in blocks(p) if b.lang == "toml"):
        data = tomllib.loads(b.code)
        if "scene" in data:
            parse_sweep(b.code, where(b), "docs", ROOT)
        else:
            parse_scene(b.code, where(b))
        checked += 1
    assert checked >= 3


HISTORY = re.compile(
    r"this round|last round|round before|this session|in an earlier round"
    r"|\bissue \d+|(?<![\w&/])#\d+\b|\b\d{1,2}:\d{2}(:\d{2})? ?UTC\b|\b20\d\d-\d\d-\d\d\b",
    re.IGNORECASE,
)


def test_no_page_tells_the_projects_history() -> None:
    found = [
        f"{page.relative_to(ROOT)}:{n}: {m[0]!r}"
        for page in PAGES
        for n, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1)
        for m in HISTORY.finditer(line)
    ]
    assert not found, "history belongs in CHANGELOG.md:\n" + "\n".join(found)


def test_the_history_check_finds_history() -> None:
    for text in ("measured this round", "see issue 22", "fixed in #22", "at 02:36 UTC",
                 "on 2026-11-27"):  # fmt: skip
        assert HISTORY.search(text), text
    for text in ("#include <math.h>", "[x](#names-and-units)", "&#8212;", "q2 = pi/2"):
        assert not HISTORY.search(text), text


def mkdocs(docs: Path, site: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--clean",
         "-f", str(docs.parent / "mkdocs.yml"), "-d", str(site)],
        env=env(), capture_output=True, text=True, timeout=600,
    )  # fmt: skip


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The site, built from this checkout with warnings as errors."""
    out = tmp_path_factory.mktemp("site")
    proc = mkdocs(ROOT / "docs", out)
    assert proc.returncode == 0, proc.stderr[-5000:]
    return out


@pytest.mark.slow  # MkDocs builds the whole site
def test_the_site_builds_with_warnings_as_errors_and_fetches_nothing(site: Path) -> None:
    pages = list(site.rglob("*.html"))
    assert len(pages) >= 15
    external = re.compile(r"<(script|link|img)\b[^>]*\b(src|href)=\"(https?:)?//", re.IGNORECASE)
    fetched = [
        f"{p.relative_to(site)}: {m[0]}" for p in pages for m in external.finditer(p.read_text())
    ]
    assert not fetched, fetched
    assert "<math" in (site / "gyrostat-eom.html").read_text()


def text_of(site: Path, page: str) -> str:
    return (site / page).read_text(encoding="utf-8")


@pytest.mark.slow  # MkDocs builds the whole site
def test_the_reference_holds_what_the_code_registers(site: Path) -> None:
    from gyrogen import abi, api, methods
    from gyrogen.commands.group import cli
    from gyrogen.runtime.compiled import Compiled
    from gyrogen.scene import Effects, Outputs, Scene, Simulate
    from gyrogen.scene.rotors import Rotor

    scene, abi_page = text_of(site, "reference/scene.html"), text_of(site, "reference/abi.html")
    for model in (Scene, Effects, Outputs, Simulate, Rotor):
        assert all(f"<code>{name}</code>" in scene for name in model.model_fields), model
    for code in (*abi.SETUP_CODES, *abi.ODE_CODES):
        assert f"&lt;PREFIX&gt;_{code.name}" in abi_page, code.name
    assert all(f"<code>{f.name}</code>" in abi_page for f in abi.STATS_FIELDS)
    assert all(f"<code>{m}</code>" in abi_page for m in methods.NAMES)
    cli_page = text_of(site, "reference/cli.html")
    assert all(f"gyrogen {name}" in cli_page for name in cli.commands)  # type: ignore[attr-defined]
    api_page = text_of(site, "reference/api.html")
    public = [
        n
        for n in vars(api)
        if callable(getattr(api, n))
        and getattr(api, n).__module__ == api.__name__
        and not n.startswith("_")
    ]
    assert all(f'id="gyrogen.api.{n}"' in api_page for n in public), public
    assert all(f'id="gyrogen.runtime.compiled.Compiled.{n}"' in api_page
               for n in ("setup", "rhs", "jacobian", "integrate", "integrate_batch"))  # fmt: skip
    assert Compiled.__doc__


@pytest.mark.slow
def test_a_broken_anchor_fails_the_build(tmp_path: Path) -> None:
    """The strict build checks links and anchors: one that points nowhere fails it."""
    shutil.copytree(ROOT / "docs", tmp_path / "docs")
    shutil.copy(ROOT / "mkdocs.yml", tmp_path / "mkdocs.yml")
    (tmp_path / "tools").symlink_to(ROOT / "tools")  # the benchmarks page's renderer
    page = tmp_path / "docs" / "guide" / "fmu.md"
    page.write_text(page.read_text() + "\nSee [the codes](../reference/abi.md#no-such-section).\n")
    proc = mkdocs(tmp_path / "docs", tmp_path / "site")
    assert proc.returncode != 0
    assert "no-such-section" in proc.stderr


def test_each_benchmark_record_names_its_machine() -> None:
    import json

    records = sorted((ROOT / "docs" / "benchmarks").glob("*.json"))
    assert records
    for path in records:
        r = json.loads(path.read_text())
        m = r["machine"]
        for key in ("cpu", "cores", "load_before", "load_after", "gcc", "gfortran", "libraries"):
            assert m[key], (path.name, key)
        assert r["date"] and r["command"] and r["measurements"]


@pytest.mark.slow
@pytest.mark.parametrize("module", ["api.py", "runtime/compiled.py"])
def test_the_docstrings_examples_run(module: str, tmp_path: Path) -> None:
    """The Examples sections of the Python API's reference, run by doctest."""
    path = ROOT / "generator" / "gyrogen" / module
    proc = subprocess.run(
        [sys.executable, "-m", "doctest", str(path)],
        cwd=tmp_path, env=env(), capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]
