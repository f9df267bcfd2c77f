"""The one generate-and-build path: a scene's sources rendered (and kept in
the build cache), written into a directory all or nothing, and built per
language. Every command that runs generated code, a sweep's workers and
generate's check before it writes come through here.

Rendering derives the equations (sympy), so it is imported only when a
scene is rendered: a process that builds sources it was handed (a sweep's
worker) or found in the cache never imports sympy.

The rendered sources are cached under the build cache's sources/, keyed by
the scene, the sympy version and a digest of the code that renders it (the
modules rendering imports, and the templates), so a rerun skips the
derivation, and so does a run after an edit to the rest of gyrogen. Built
sources are written into a directory of their own first (runtime/build.py
copies them into its cache entry, keyed by their bytes and the flags), so
two processes building the same sources never share a half-written
directory.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import tempfile
import threading
from collections.abc import Iterable, Mapping
from concurrent.futures import ThreadPoolExecutor
from contextlib import suppress
from dataclasses import dataclass
from functools import cache, cached_property
from importlib.metadata import version
from pathlib import Path
from typing import Any

import gyrogen
from gyrogen.errors import GyrogenError
from gyrogen.files import claim, write_atomic
from gyrogen.runtime.build import Halt, build
from gyrogen.runtime.cache import cache_dir
from gyrogen.runtime.compiled import Compiled, Language
from gyrogen.scene import Scene, default


@dataclass(frozen=True)
class Sources:
    """A scene's rendered files by name, their build id, the language a
    sweep builds, and whether it builds them portable (runtime/flags.py)."""

    build_id: str
    language: Language
    files: dict[str, str]
    portable: bool = False

    @cached_property
    def digest(self) -> str:
        """Of the files (once per instance: a sweep's every task asks, 0.7 ms each)."""
        text = json.dumps(self.files, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


def digested(root: Path) -> list[Path]:
    """gyrogen's modules and templates below root. os.walk follows the link
    to the templates (in a checkout, gyrogen/templates -> ../../templates),
    which Path.rglob does not."""
    found = [Path(d) / f for d, _, files in os.walk(root, followlinks=True) for f in files]
    return sorted(
        p for p in found if p.suffix in (".py", ".jinja") and "__pycache__" not in p.parts
    )


@cache
def code_digest() -> str:
    """A digest of gyrogen's own modules and templates: rendered sources
    cached by an older generator are never reused."""
    root = Path(gyrogen.__file__).parent
    return _digest(root, digested(root))


def _digest(root: Path, paths: Iterable[Path]) -> str:
    """Of each file's name below root and its bytes, in the order given."""
    h = hashlib.sha256()
    for path in paths:
        h.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes())
    return h.hexdigest()[:16]


RENDERING = ("gyrogen.codegen.generate", "gyrogen.codegen.context")
"""Where rendering starts (scene_sources imports these two)."""

_IMPORT = re.compile(
    r"^[ \t]*(?:from[ \t]+(gyrogen[\w.]*)[ \t]+import[ \t]+(\([^)]*\)|[^\n]*)"
    r"|import[ \t]+(gyrogen[\w.]*))",
    re.MULTILINE,
)


def _module_file(root: Path, module: str) -> Path | None:
    path = root.joinpath(*module.split(".")[1:])
    for candidate in (path / "__init__.py", path.with_suffix(".py")):
        if candidate.is_file():
            return candidate
    return None


def imported(root: Path, start: Iterable[str]) -> list[Path]:
    """The files of gyrogen's modules that start imports, at any depth
    (each module's package too, and a module named in `from P import M`),
    read from every import statement of each file, in a function or not:
    what can run when start runs."""
    seen: set[Path] = set()
    todo = list(start)
    while todo:
        parts = todo.pop().split(".")
        for i in range(1, len(parts) + 1):
            path = _module_file(root, ".".join(parts[:i]))
            if path is None or path in seen:
                continue
            seen.add(path)
            for found in _IMPORT.finditer(path.read_text(encoding="utf-8")):
                if found[3]:
                    todo.append(found[3])
                    continue
                todo.append(found[1])
                names = re.findall(r"\w+", re.sub(r"#[^\n]*", "", found[2]))
                todo.extend(f"{found[1]}.{name}" for name in names if name != "as")
    return sorted(seen)


@cache
def rendering_digest() -> str:
    """A digest of the modules rendering can run (imported from RENDERING)
    and of every template: an edit anywhere else in gyrogen (the command
    line, the analyses, the runtime) keeps the rendered sources cached."""
    root = Path(gyrogen.__file__).parent
    kept = {*imported(root, RENDERING), *(p for p in digested(root) if p.suffix == ".jinja")}
    return _digest(root, sorted(kept))


def rendered_by(scenes: Iterable[Scene]) -> str:
    """What scenes' sources are rendered from: the code rendering runs
    (rendering_digest), sympy's version and the scenes themselves.
    generated/RENDERED_BY holds the built-in scenes' (`make generate` writes
    it): while it equals this, generated/ is what a rendering would write,
    and the suite knows so without rendering every scene."""
    dumped = [scene.model_dump(mode="json") for scene in scenes]
    text = json.dumps([dumped, rendering_digest(), version("sympy")], sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def _stored(scene: Scene) -> Path:
    """Where the scene's rendered sources are kept: the build cache's
    sources/, keyed by the scene, the code that renders it and sympy's version."""
    text = json.dumps([scene.model_dump(mode="json"), rendering_digest(), version("sympy")])
    key = hashlib.sha256(text.encode()).hexdigest()[:24]
    return cache_dir() / "sources" / f"{key}.json"


def keep_sources(scene: Scene, build_id: str, files: Mapping[str, str]) -> None:
    """Keep a scene's rendered sources (render_all's, without --lib's build
    files) for the next scene_sources (a cache not written costs only the
    next derivation)."""
    held = json.dumps({"build_id": build_id, "files": dict(files)})
    path = _stored(scene)
    with suppress(GyrogenError):
        write_atomic(path.parent, {path.name: held}, keep=True)


def scene_sources(scene: Scene, portable: bool = False) -> Sources:
    """The scene's rendered sources (built as C when it has a C target, else
    Fortran): from the cache when this gyrogen and sympy rendered them
    before (then sympy is not even imported), else rendered and kept."""
    language: Language = "c" if "c" in scene.targets else "fortran"
    try:
        held = json.loads(_stored(scene).read_text(encoding="utf-8"))
        return Sources(str(held["build_id"]), language, dict(held["files"]), portable)
    except (OSError, ValueError, KeyError, TypeError):
        pass
    full = full_model_manifest() if scene != default() else None  # the default: the full model
    from gyrogen.codegen.context import build_id  # sympy: only when rendering
    from gyrogen.codegen.generate import render_all, unit_of

    files = render_all(unit_of(scene), full=full)
    keep_sources(scene, build_id(scene), files)
    return Sources(build_id(scene), language, files, portable)


def full_model_manifest() -> dict[str, Any]:
    """The full model's (the default scene's) manifest, among its kept
    sources: what every other scene's manifest and `gyrogen generate`'s
    table compare with (its nx, np, nc and ops), so that a process rendering
    another scene derives no full model (3 s of CPU) when the cache holds
    it. It is keyed as every scene's sources are, by the scene, the code
    that renders it and sympy's version: all its sizes depend on. Not kept,
    the default scene is rendered and kept (scene_sources)."""
    held: dict[str, Any] = json.loads(scene_sources(default()).files["manifest.json"])
    return held


def build_dir(
    directory: Path, languages: Iterable[Language], portable: bool = False
) -> dict[Language, Compiled]:
    """The sources in directory built (or fetched from the cache), by
    language: the languages at once, each in a thread (their compilers are
    other processes, and so is cffi's compile: runtime/build.py)."""
    wanted = list(dict.fromkeys(languages))
    if len(wanted) < 2:
        return {language: build(directory, language, portable) for language in wanted}
    halt = Halt()  # set when this thread is interrupted: the others' compilers end too
    with ThreadPoolExecutor(len(wanted)) as pool:
        futures = {lang: pool.submit(build, directory, lang, portable, halt) for lang in wanted}
        try:
            return {language: future.result() for language, future in futures.items()}
        except BaseException:
            halt.set()
            raise


def build_files(
    files: Mapping[str, str], languages: Iterable[Language], portable: bool = False
) -> dict[Language, Compiled]:
    """files built by language, from a directory of their own that is gone
    afterwards (the builds live in the cache): private, so written plainly."""
    with tempfile.TemporaryDirectory(prefix="gyrogen-sources-") as tmp:
        for name, text in files.items():
            path = Path(tmp) / name
            try:
                path.write_text(text, encoding="utf-8")
            except OSError as exc:
                raise GyrogenError(f"cannot write {path}: {exc.strerror or exc}") from exc
        return build_dir(Path(tmp), languages, portable)


def write_scene(scene: Scene, directory: Path) -> None:
    """The scene's sources (scene_sources: from the cache when rendered
    before, so a scene is derived once) written into directory, all or
    nothing; a directory that holds another scene's sources is refused
    (files.claim)."""
    claim(directory, scene.name)
    write_atomic(directory, scene_sources(scene).files)


def build_scene(
    scene: Scene, directory: Path, languages: Iterable[Language]
) -> dict[Language, Compiled]:
    """write_scene, then the sources built per language (or fetched from
    the cache): the backends by language."""
    write_scene(scene, directory)
    return build_dir(directory, languages)


_BUILT: dict[str, Compiled] = {}
_BUILDS: list[str] = []
"""The build ids this process has built, one entry per build (a test reads it)."""
_LOCK = threading.Lock()


def compiled(sources: Sources) -> Compiled:
    """The sources built in this process: once per build id, sources and
    flags (threads wait for the first)."""
    key = f"{sources.build_id}-{sources.digest}-{sources.portable}"
    with _LOCK:
        if key not in _BUILT:
            built = build_files(sources.files, [sources.language], sources.portable)
            _BUILT[key] = built[sources.language]
            _BUILDS.append(sources.build_id)
        return _BUILT[key]


def builds() -> list[str]:
    """The build ids built in this process so far."""
    return list(_BUILDS)
