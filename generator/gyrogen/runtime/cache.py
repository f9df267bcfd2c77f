"""The build cache: where it lives, the key that names an entry, the entries
and their completion markers, and the logs of failed builds.

An entry is a directory named by its key, filled in a temporary directory
beside it and renamed into place. It is trusted only when its completion
marker (MARKER, written last) matches its files; anything else is rebuilt,
with a warning. A failed step's whole output is kept under logs/.
"""

from __future__ import annotations

import errno
import hashlib
import importlib.util
import json
import os
import shutil
import sys
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from types import ModuleType

import cffi

from gyrogen.abi import COMPILER_LOG_LINES
from gyrogen.errors import BuildError

CACHE_FORMAT = "2"
"""Part of every cache key. 2: entries carry MARKER, so the entries of
earlier versions are never looked at (neither trusted nor warned about)."""
MARKER = "complete.json"
"""Written last into a cache entry: the SHA-256 of each shared object in it.
An entry without it, or whose files do not match it, is rebuilt."""

Fill = Callable[[Path, Path], None]
"""(work, entry): compile into the directory work, which becomes entry."""


def cache_root() -> Path:
    """$GYROGEN_CACHE, else $XDG_CACHE_HOME/gyrogen, else ~/.cache/gyrogen;
    made absolute (a Fortran module finds its library by this path)."""
    if env := os.environ.get("GYROGEN_CACHE"):
        return Path(env).absolute()
    if base := os.environ.get("XDG_CACHE_HOME"):
        return (Path(base) / "gyrogen").absolute()
    try:
        home = Path.home()
    except RuntimeError as exc:  # no HOME and no entry in the password database
        raise BuildError("no home directory for the build cache: set GYROGEN_CACHE") from exc
    return (home / ".cache" / "gyrogen").absolute()


def cache_dir() -> Path:
    """cache_root(), created if need be: one line naming it (and
    GYROGEN_CACHE when that chose it) when it cannot be."""
    root = cache_root()
    try:
        if root.exists() and not root.is_dir():
            raise NotADirectoryError(errno.ENOTDIR, os.strerror(errno.ENOTDIR))
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _cache_error(root, exc) from exc
    return root


def _cache_error(root: Path, exc: OSError) -> BuildError:
    why = exc.strerror or str(exc)
    if os.environ.get("GYROGEN_CACHE"):
        return BuildError(f"GYROGEN_CACHE={root}: cannot use it as the build cache: {why}")
    return BuildError(
        f"cannot use {root} as the build cache: {why} (set GYROGEN_CACHE to another directory)"
    )


def entry_key(parts: Sequence[str], sources: Sequence[Path]) -> str:
    """The name of the entry built from parts (language, tool version, flags,
    glue, ...) and the sources, with the cache format, Python and cffi."""
    h = hashlib.sha256()
    for part in (CACHE_FORMAT, *parts, sys.version):
        h.update(part.encode() + b"\0")
    h.update(cffi.__version__.encode())
    for src in sources:
        h.update(src.name.encode() + b"\0" + src.read_bytes() + b"\0")
    return h.hexdigest()[:20]


class Damaged(BuildError):
    """A cache entry that is not whole or does not load: why."""


_LOADED: dict[str, ModuleType] = {}


def fetch(module_name: str, entry: Path, fill: Fill) -> ModuleType:
    """The module module_name from its cache entry, which fill builds first
    if it is missing. A damaged entry (a build cut short, a file truncated or
    removed since, a module that does not load) is rebuilt, with a warning."""
    if not os.path.lexists(entry):
        build_entry(entry, module_name, fill)
    try:
        return load(module_name, entry)
    except Damaged as exc:
        print(f"gyrogen: warning: rebuilding cache entry {entry}: {exc}", file=sys.stderr)
    _discard(entry)
    build_entry(entry, module_name, fill)
    return load(module_name, entry)


def load(module_name: str, entry: Path) -> ModuleType:
    """The module from a whole entry (loaded once per process)."""
    so = verified(entry)
    if module_name in _LOADED:
        return _LOADED[module_name]
    try:
        spec = importlib.util.spec_from_file_location(module_name, so)
        if spec is None or spec.loader is None:
            raise ImportError("not a Python extension module")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    except ImportError as exc:
        raise Damaged(f"cannot load {so.name}: {exc}") from exc
    _LOADED[module_name] = module
    return module


def verified(entry: Path) -> Path:
    """The module's shared object in a whole entry: its MARKER is there and
    every shared object it lists has the SHA-256 it lists."""
    try:
        marker = json.loads((entry / MARKER).read_text())
        hashes, module = dict(marker["sha256"]), str(marker["module"])
        if module not in hashes:
            raise ValueError(f"{module} is not hashed")
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise Damaged(f"no readable {MARKER}: its build did not finish") from exc
    for name, digest in hashes.items():
        if _sha256(entry / name) != digest:
            raise Damaged(f"{name} is missing or not as built")
    return entry / module


def _sha256(path: Path) -> str | None:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return None


def _seal(work: Path, module_name: str) -> None:
    """Write MARKER, last: the hash of every shared object of the build."""
    modules = list(work.glob(f"{module_name}*.so"))
    if len(modules) != 1:
        raise BuildError(f"cffi left {len(modules)} modules {module_name}*.so in {work}")
    hashes = {p.name: _sha256(p) for p in sorted(work.glob("*.so"))}
    marker = {"module": modules[0].name, "sha256": hashes}
    (work / MARKER).write_text(json.dumps(marker, indent=1) + "\n")


def _discard(entry: Path) -> None:
    try:
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry)
        else:
            entry.unlink()
    except FileNotFoundError:
        pass  # another process took it away first
    except OSError as exc:
        raise BuildError(f"cannot remove the damaged cache entry {entry}: {exc.strerror}") from exc


def build_entry(entry: Path, module_name: str, fill: Fill) -> None:
    """fill a temporary directory beside entry, seal it and rename it entry."""
    try:
        work = Path(tempfile.mkdtemp(prefix=".build-", dir=entry.parent))
    except OSError as exc:
        raise _cache_error(entry.parent, exc) from exc
    try:
        fill(work, entry)
        _seal(work, module_name)
        try:
            work.rename(entry)
        except OSError:  # another process built the same key first
            if not entry.is_dir():
                raise
    except OSError as exc:
        raise BuildError(f"cannot build in the cache {entry.parent}: {exc.strerror}") from exc
    finally:
        shutil.rmtree(work, ignore_errors=True)


def log_path(entry: Path, what: str) -> Path:
    """Where the whole output of a failed step of the build of entry is kept."""
    return entry.parent / "logs" / f"{entry.name}-{what}.log"


def failure(what: str, output: str, log: Path) -> BuildError:
    """what failed, then the first COMPILER_LOG_LINES lines of its output;
    the whole output is kept in log."""
    lines = output.strip().splitlines()
    head = lines[:COMPILER_LOG_LINES]
    try:
        log.parent.mkdir(parents=True, exist_ok=True)
        log.write_text(output, encoding="utf-8")
        where = f"full output in {log}"
    except OSError as exc:
        where = f"output not kept ({log}: {exc.strerror})"
    if len(lines) > len(head):
        where += f"; its first {len(head)} of {len(lines)} lines"
    return BuildError("\n".join([f"{what}; {where}:", *head]))
