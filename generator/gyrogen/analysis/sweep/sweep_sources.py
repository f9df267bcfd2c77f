"""A sweep's generated sources, on the client and on the workers.

The client renders the scene's sources in memory (kept in the build cache
under sources/, keyed by the scene, the sympy version and a digest of
gyrogen's own code and templates, so a rerun skips the derivation) and ships them to the workers
through the task graph: a worker needs gyrogen installed, not a checkout or
a shared file system. A worker process writes them once into its build
cache and builds them there (runtime/build.py: a cache hit costs nothing),
once per process and build id, never per task.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
import threading
from dataclasses import dataclass
from functools import cache
from importlib.metadata import version
from pathlib import Path

import gyrogen
from gyrogen.runtime.build import build
from gyrogen.runtime.cache import cache_dir
from gyrogen.runtime.compiled import Compiled, Language
from gyrogen.scene import Scene


@dataclass(frozen=True)
class Sources:
    """What a worker builds: the files by name, their build id and language."""

    build_id: str
    language: Language
    files: dict[str, str]


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
    h = hashlib.sha256()
    for path in digested(root):
        h.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes())
    return h.hexdigest()[:16]


def scene_sources(scene: Scene) -> Sources:
    """The scene's rendered sources (C when it has a C target, else Fortran):
    from the cache when this gyrogen and sympy rendered them before (then
    sympy is not even imported), else derived and rendered, and kept."""
    language: Language = "c" if "c" in scene.targets else "fortran"
    text = json.dumps([scene.model_dump(mode="json"), code_digest(), version("sympy")])
    key = hashlib.sha256(text.encode()).hexdigest()[:24]
    stored = cache_dir() / "sources" / f"{key}.json"
    try:
        held = json.loads(stored.read_text(encoding="utf-8"))
        return Sources(str(held["build_id"]), language, dict(held["files"]))
    except (OSError, ValueError, KeyError, TypeError):
        pass
    from gyrogen.codegen.context import build_id  # sympy: only when rendering
    from gyrogen.codegen.generate import render_all, unit_of

    files = render_all(unit_of(scene))
    _store(stored, json.dumps({"build_id": build_id(scene), "files": files}))
    return Sources(build_id(scene), language, files)


def _store(path: Path, text: str) -> None:
    """text into path through a temporary file and a rename (best effort: a
    cache that cannot be written costs only the next derivation)."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except OSError:
        pass


_BUILT: dict[str, Compiled] = {}
_BUILDS: list[str] = []
"""The build ids this process has built, one entry per build (a test reads it)."""
_LOCK = threading.Lock()


def compiled(sources: Sources) -> Compiled:
    """The sources built in this process: once per build id (threads wait
    for the first)."""
    key = f"{sources.build_id}-{sources_digest(sources)}"
    with _LOCK:
        if key not in _BUILT:
            directory = cache_dir() / "sweep-sources" / key
            if not (directory / "manifest.json").is_file():
                _write_dir(directory, sources.files)
            _BUILT[key] = build(directory, sources.language)
            _BUILDS.append(sources.build_id)
        return _BUILT[key]


def builds() -> list[str]:
    """The build ids built in this process so far."""
    return list(_BUILDS)


def sources_digest(sources: Sources) -> str:
    text = json.dumps(sources.files, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _write_dir(directory: Path, files: dict[str, str]) -> None:
    """files into a new directory beside directory, renamed into place whole
    (another process may have done it first: then that one stays)."""
    directory.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=".sources-", dir=directory.parent))
    try:
        for name, text in files.items():
            (work / name).write_text(text, encoding="utf-8")
        try:
            work.rename(directory)
        except OSError:
            if not (directory / "manifest.json").is_file():
                raise
    finally:
        shutil.rmtree(work, ignore_errors=True)
