"""Writing files: all or nothing, with the modes open() would give them.

Every command that writes (generate, simulate, bench, check --plots, new)
goes through write_atomic; can_write checks the way is clear first. Inside
a transaction (cli.main holds one around each command) what write_atomic
replaced stays undoable until the transaction ends: a Ctrl-C at any moment
of a command puts back every file and removes every directory it wrote.
"""

from __future__ import annotations

import itertools
import json
import os
import signal
import stat
import tempfile
import threading
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

from gyrogen.errors import GyrogenError, SceneError

NEW_FILE_MODE = 0o666
"""What open(path, "w") asks for a new file; the umask takes its bits away."""
_PROC_STATUS = Path("/proc/self/status")


def umask() -> int:
    """The process's umask, read without changing it: the Umask line of
    /proc/self/status (Linux 4.7 and later), read anew each time. Elsewhere
    os.umask is the only way, and it sets the mask while reading it: done
    once per process (_umask_once), so the window where another thread
    could create a file under the wrong mask opens only once."""
    try:
        with _PROC_STATUS.open() as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    return _umask_once()


@cache
def _umask_once() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@dataclass
class _Written:
    """What writes placed, undoable: the files new where there was none, the
    old version of each replaced one (its temporary name beside it), and the
    directories made (outermost first)."""

    placed: list[Path] = field(default_factory=list)
    saved: dict[Path, Path] = field(default_factory=dict)
    made: list[Path] = field(default_factory=list)

    def add(self, other: _Written) -> None:
        """other's writes, later than these: a file both wrote keeps the
        oldest version (other's is a version written since, dropped)."""
        for target in other.placed:
            if target not in self.saved and target not in self.placed:
                self.placed.append(target)
        for target, old in other.saved.items():
            if target in self.saved or target in self.placed:
                _remove([old])
            else:
                self.saved[target] = old
        self.made += [d for d in other.made if d not in self.made]

    def roll_back(self) -> None:
        """Best effort: each file and directory as it was before."""
        _roll_back(self.placed, self.saved)
        for made in reversed(self.made):
            with suppress(OSError):
                made.rmdir()  # only when empty: what another wrote there stays
        self._forget()

    def commit(self) -> None:
        """The files kept: the old versions removed."""
        _remove(self.saved.values())
        self._forget()

    def _forget(self) -> None:
        self.placed, self.saved, self.made = [], {}, []


_open: list[_Written] = []
"""The transactions open, innermost last (one process, one command: a
Ctrl-C stops all of its threads)."""
_lock = threading.Lock()


@contextmanager
def transaction() -> Iterator[None]:
    """What write_atomic and make_dir do inside the block is one write, all
    or nothing: an exception out of the block (Ctrl-C, a failure) puts back
    every file replaced and removes every file and directory made; a
    SystemExit (a command's end, whatever its code) keeps them. The old
    versions stay aside until the outermost transaction keeps the files;
    an inner one hands its writes to the one around it."""
    written = _Written()
    with _lock:
        _open.append(written)
    try:
        yield
    except BaseException as exc:
        with interrupts_held(), _lock:
            _open.remove(written)
            if not isinstance(exc, SystemExit):
                written.roll_back()
            elif _open:
                _open[-1].add(written)
            else:
                written.commit()
        raise
    with interrupts_held(), _lock:
        _open.remove(written)
        if _open:
            _open[-1].add(written)
        else:
            written.commit()


def _record(written: _Written) -> bool:
    """written joins the innermost open transaction; False with none open."""
    with _lock:
        if not _open:
            return False
        _open[-1].add(written)
        return True


def make_dir(out: Path, keep: bool = False) -> None:
    """out and its missing parents; inside a transaction (and not keep) the
    ones made are removed again when it rolls back."""
    made = _make_dir(out)
    if made and not keep:
        _record(_Written(made=made))


def _make_dir(out: Path) -> list[Path]:
    """out and its missing parents made; the ones made, outermost first."""
    missing = itertools.takewhile(lambda d: not os.path.lexists(d), (out, *out.parents))
    made = list(missing)[::-1]
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise GyrogenError(f"cannot create output directory {out}: {exc.strerror}") from exc
    return made


def write_atomic(out: Path, files: Mapping[str, str | bytes], keep: bool = False) -> None:
    """Write every file into out, or none. A target that is not a regular
    file (a directory, a FIFO) is refused before anything is written. Each
    file goes to a temporary name in out first, with the mode open() would
    give it (NEW_FILE_MODE less the umask); then each target's old version is
    moved aside to a temporary name and the new one renamed in. A failure
    anywhere (a full disk, a refused rename, an exception) puts every old
    version back and removes the new files. Text is UTF-8 as written.
    Ctrl-C waits until the files are placed, then puts the old versions back
    and is raised: a SIGINT between two statements could otherwise leave a
    temporary file no roll-back knows of, and an interrupted write never
    stays written. Inside a transaction the old versions stay aside until it
    ends; keep: outside it, the files stay whatever follows (a sweep's
    parts, which a rerun resumes from; a cache's entries)."""
    with interrupts_held() as caught:
        written = _write_atomic(out, files)
        if caught:
            written.roll_back()
        elif keep or not _record(written):
            written.commit()


@contextmanager
def interrupts_held() -> Iterator[list[int]]:
    """A SIGINT inside the block is delivered when it ends (to the handler
    there was before); in the main thread only (Python runs its handlers
    there), elsewhere the block runs as it is. The block gets the list of
    the SIGINTs held so far."""
    caught: list[int] = []
    main = threading.current_thread() is threading.main_thread()
    if not main or signal.getsignal(signal.SIGINT) is None:  # None: not Python's to put back
        yield caught
        return
    previous = signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield caught
    finally:
        signal.signal(signal.SIGINT, previous)
        if caught:
            signal.raise_signal(signal.SIGINT)


def _write_atomic(out: Path, files: Mapping[str, str | bytes]) -> _Written:
    """The files placed; the old versions still aside (in what it returns)."""
    written = _Written(made=_make_dir(out))
    staged: dict[Path, Path] = {}
    current = out
    try:
        targets = can_write(out, files)
        for name, data in files.items():
            current = targets[name]
            staged[current] = _stage(current, data)
        for target, tmp in staged.items():
            current = target
            if os.path.lexists(target):
                written.saved[target] = _move_aside(target)
            os.replace(tmp, target)
            if target not in written.saved:
                written.placed.append(target)
    except BaseException as exc:
        written.roll_back()
        _remove(staged.values())
        if isinstance(exc, OSError):
            raise GyrogenError(f"cannot write {current}: {exc.strerror or exc}") from exc
        raise
    _sync_dir(out)
    return written


def _sync_dir(out: Path) -> None:
    """The renames on disk too (best effort: some file systems refuse)."""
    with suppress(OSError):
        fd = os.open(out, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def can_write(out: Path, names: Iterable[str]) -> dict[str, Path]:
    """Check that each named file can be put in out (nothing in the way that
    a file cannot replace); the target paths by name."""
    existing = next(d for d in (out, *out.parents) if os.path.lexists(d))
    if not existing.is_dir():
        raise GyrogenError(f"cannot create output directory {out}: Not a directory")
    targets = {name: out / name for name in names}
    for target in targets.values():
        if why := _obstacle(target):
            raise GyrogenError(f"cannot write {target}: {why}")
    return targets


def _obstacle(target: Path) -> str | None:
    """Why target cannot be replaced by a file, or None (absent, a regular
    file, or a symbolic link, which is replaced itself)."""
    try:
        mode = os.lstat(target).st_mode
    except FileNotFoundError:
        return None
    except OSError as exc:
        return exc.strerror
    if stat.S_ISREG(mode) or stat.S_ISLNK(mode):
        return None
    return "Is a directory" if stat.S_ISDIR(mode) else "Not a regular file"


def _stage(target: Path, data: str | bytes) -> Path:
    """data in a new temporary file beside target, with the mode of a new file."""
    fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".new", dir=target.parent)
    tmp = Path(name)
    try:
        with os.fdopen(fd, "wb") as fh:
            os.fchmod(fh.fileno(), NEW_FILE_MODE & ~umask())
            fh.write(data.encode("utf-8") if isinstance(data, str) else data)
            fh.flush()
            os.fsync(fh.fileno())  # on disk before the rename makes it the file
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return tmp


def _move_aside(target: Path) -> Path:
    """Rename target to a fresh temporary name beside it; that name."""
    fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".old", dir=target.parent)
    os.close(fd)
    try:
        os.replace(target, name)
    except BaseException:
        os.unlink(name)
        raise
    return Path(name)


def _roll_back(placed: list[Path], saved: dict[Path, Path]) -> None:
    """Best effort: each target as it was before write_atomic began."""
    for target in placed:
        if target not in saved:
            with suppress(OSError):
                target.unlink()
    for target, old in saved.items():
        with suppress(OSError):
            os.replace(old, target)


def _remove(paths: Iterable[Path]) -> None:
    for path in paths:
        with suppress(OSError):
            path.unlink(missing_ok=True)


def claim(out: Path, prefix: str) -> None:
    """Refuse out when it holds another scene's sources (its manifest.json
    names another prefix): two scenes' files never mix in one directory."""
    try:
        held = json.loads((out / "manifest.json").read_text(encoding="utf-8")).get("prefix")
    except (OSError, ValueError, AttributeError):
        return  # no manifest (or none of gyrogen's): nothing to mix with
    if isinstance(held, str) and held != prefix:
        raise SceneError(
            f"{out} holds the sources of scene {held!r} (its manifest.json): writing {prefix!r} "
            "there would mix two scenes' files; give another --out"
        )
