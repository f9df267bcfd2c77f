"""One sweep writes an --out at a time: it holds the out's lock (LOCK) from
before it claims the parts until its summary is written, and a second
sweep into the same out is refused in one line, having changed nothing.

- A local directory, named by its path or by a URL of the local file
  system (file:///PATH: Store.on_disk): an flock on LOCK, the same file
  whichever the spelling, so that each excludes the other. The kernel
  drops it when its process ends, however it ends (a crash, SIGKILL): a
  local lock is never stale. Its holder (host and pid) is written into it
  for the refusal's words; it is removed when released.
- Any other URL (analysis/sweep/store.py): LOCK created exclusively
  (fsspec's mode "xb": O_CREAT | O_EXCL, or a conditional PUT on an
  object store that has one), naming its holder: host, pid, the process's start
  time and a token read back once written. A lock whose holder is a process
  of this host (the same host name and process namespace) that is gone (no
  such pid, or the pid reused by a process started at another time) is
  stale: a note says so and the lock is taken. A holder on another host
  cannot be seen from here: the refusal says to remove LOCK if it is gone.
  A file system whose "xb" does not exclude (FTP, say) still refuses a
  sweep that comes once the lock is written; two starting at the same
  instant may both pass there.
"""

from __future__ import annotations

import json
import os
import socket
import sys
import uuid
from contextlib import suppress
from dataclasses import dataclass
from typing import Any

from gyrogen.analysis.sweep.store import Store
from gyrogen.errors import GyrogenError

LOCK = "sweep.lock"


@dataclass
class Lock:
    """out's lock, held by this process until released."""

    out: Store
    token: str
    fd: int | None = None
    """The flocked file's descriptor (a local directory)."""

    def release(self) -> None:
        if self.fd is not None:
            with suppress(OSError):  # removed while held: the flock goes with the descriptor
                os.unlink(self.out.path(LOCK))
            os.close(self.fd)
            self.fd = None
        elif self.token:
            with suppress(OSError, ValueError, GyrogenError):
                if json.loads(self.out.read_text(LOCK)).get("token") == self.token:
                    self.out.remove(LOCK)
            self.token = ""


def take(out: Store) -> Lock:
    """out's lock for this process (out made first), or a one-line
    GyrogenError naming the sweep that holds it."""
    out.make_dir()
    return _flock(out) if out.on_disk else _create(out)


def _holder() -> dict[str, Any]:
    """Who takes a lock: this process, its host and start time, a token."""
    import psutil

    me = os.getpid()
    return {"host": socket.gethostname(), "namespace": _namespace(), "pid": me,
            "started": psutil.Process(me).create_time(), "token": uuid.uuid4().hex}  # fmt: skip


def _namespace() -> str:
    """This process's pid namespace (Linux; "" elsewhere): two containers
    of one host name see each other's pids only when it is the same."""
    try:
        return os.readlink("/proc/self/ns/pid")
    except OSError:
        return ""


def _flock(out: Store) -> Lock:
    import fcntl

    path = out.path(LOCK)
    me = _holder()
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        except OSError as exc:
            raise out.failure("cannot write", (LOCK,), exc) from exc
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            held = _parse(os.pread(fd, 4096, 0))
            os.close(fd)
            raise _busy(out, held) from None
        except OSError as exc:  # a file system without flock (ENOLCK)
            os.close(fd)
            raise out.failure("cannot lock", (LOCK,), exc) from exc
        with suppress(FileNotFoundError):
            if os.stat(path).st_ino == os.fstat(fd).st_ino:
                break
        os.close(fd)  # its holder removed it as this process opened it: take the new one
    os.ftruncate(fd, 0)
    os.write(fd, json.dumps(me).encode())
    return Lock(out, me["token"], fd)


def _create(out: Store) -> Lock:
    me = _holder()
    data = json.dumps(me).encode()
    for _ in range(3):
        if out.kind(LOCK) == "absent":
            try:
                with out.fs.open(out.path(LOCK), "xb") as fh:
                    fh.write(data)
            except FileExistsError:
                pass
            except OSError as exc:
                raise out.failure("cannot write", (LOCK,), exc) from exc
        try:
            held = _parse(out.read_text(LOCK).encode())
        except FileNotFoundError:  # released meanwhile
            continue
        except OSError as exc:
            raise out.failure("cannot read", (LOCK,), exc) from exc
        if held.get("token") == me["token"]:
            return Lock(out, me["token"])
        if not _gone(held):
            raise _busy(out, held)
        print(f"{out.show(LOCK)}: its sweep (process {held['pid']} on this host) has ended: "
              "taking it", file=sys.stderr)  # fmt: skip
        out.remove(LOCK)
    raise _busy(out, {})


def _parse(data: bytes) -> dict[str, Any]:
    """A lock's holder ({} when it is not written yet, or unreadable)."""
    try:
        held = json.loads(data)
    except ValueError:
        return {}
    return held if isinstance(held, dict) else {}


def _here(held: dict[str, Any]) -> bool:
    return bool(held.get("host") == socket.gethostname() and held.get("namespace") == _namespace())


def _gone(held: dict[str, Any]) -> bool:
    """Whether held names a process of this host that has ended."""
    import psutil

    if not _here(held) or not isinstance(held.get("pid"), int):
        return False
    try:
        return bool(psutil.Process(held["pid"]).create_time() != held.get("started"))
    except psutil.NoSuchProcess:
        return True


def _busy(out: Store, held: dict[str, Any]) -> GyrogenError:
    who = f" (process {held['pid']} on {held['host']})" if {"pid", "host"} <= set(held) else ""
    hint = "" if out.on_disk or _here(held) else f"; if it is gone, remove {out.show(LOCK)}"
    return GyrogenError(
        f"{out.show()} is being written by another sweep{who}: wait for it to end, or use "
        f"another --out{hint}"
    )
