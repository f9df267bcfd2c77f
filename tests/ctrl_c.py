"""gyrogen in a process of its own, sent a real SIGINT (a terminal's Ctrl-C)
at a moment chosen inside it: when the first file into a given directory
(or the first after a given number) is about to be written, or when a
sweep's first task has begun. A moment no
timing from outside hits every time."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

CHILD = """
import os, signal, sys, time
from pathlib import Path

from gyrogen import files
from gyrogen.cli import main

signal.signal(signal.SIGINT, signal.default_int_handler)  # as a terminal's process has it
at, after, sent, seen = sys.argv[1], int(sys.argv[2]), [], []


def ctrl_c():
    if not sent:
        sent.append(os.kill(os.getpid(), signal.SIGINT))


stage = files._stage


def staged(target, data):
    if str(target.parent) == at:
        seen.append(target)
        if len(seen) > after:
            ctrl_c()
    return stage(target, data)


def task(*args):  # in a worker's thread: the main thread gets the SIGINT
    ctrl_c()
    time.sleep(1.0)  # still running when the interrupted client closes the cluster
    return chunk_task(*args)


files._stage = staged
if at == "task":
    from gyrogen.analysis.sweep import engine

    chunk_task, engine.chunk_task = engine.chunk_task, task
sys.argv = ["gyrogen", *sys.argv[3:]]
main()
"""


def interrupted(at: Path | str, argv: list[str], cache: Path, after: int = 0) -> tuple[int, str]:
    """gyrogen argv in a new process, interrupted as the first file into the
    directory at after `after` of them is staged (at "task": as a sweep's
    first task begins); its exit code and stderr."""
    env = {**os.environ, "GYROGEN_CACHE": str(cache)}
    proc = subprocess.run([sys.executable, "-c", CHILD, str(at), str(after), *argv], env=env,
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    return proc.returncode, proc.stderr


def tree(root: Path) -> dict[str, bytes]:
    """Every file under root (hidden ones too) by its path from root."""
    return {
        str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()
    }
