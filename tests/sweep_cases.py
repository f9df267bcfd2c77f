"""What the sweep tests share: small sweep files, a free port, and a
sweep's rows read back."""

from __future__ import annotations

import socket
from pathlib import Path

import pandas as pd

from gyrogen import api

SMALL = """
scene = "gyrostat"
method = "dop853"
t_end = {t_end}
rtol = 1e-9
atol = 1e-9
chunk = {chunk}
[grid]
I22 = {{ list = [8.0, 9.0, 10.0] }}
u4 = {{ linspace = [0.0, 100.0, 5] }}
[draws]
seed = 11
count = {count}
u1 = {{ normal = [0.2, 0.05] }}
u3 = {{ uniform = [-0.2, 0.2] }}
m_a = {{ normal = [100.0, 5.0], truncate = [90.0, 110.0] }}
[metrics]
keep = ["final_state", "max_nutation", "max_rate", "invariant_drift", "stats", "time_to"]
samples = 10
time_to = {{ nutation = 0.3, u1 = 0.25 }}
"""
"""Grid x draws over the default scene: a drawn mass makes every trajectory
its own parameter set, the grid's I22 and u4 a parameter and a state."""


def small(path: Path, t_end: float = 2.0, chunk: int = 25, count: int = 4) -> Path:
    path.write_text(SMALL.format(t_end=t_end, chunk=chunk, count=count))
    return path


def long(path: Path) -> Path:
    """41 chunks of 100 trajectories, ~0.1 s each: long enough to stop or
    kill something in the middle of it even when the machine is busy (at
    ~0.03 s each a loaded machine's test process, waking late, found the
    sweep done)."""
    return small(path, t_end=100.0, chunk=100, count=4000 // 15 + 1)


def rows(out: Path) -> pd.DataFrame:
    return api.read(out)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


OBSTACLES = [
    ("parts", "mine", "{out}/parts: not a directory"),
    ("sweep.json", "[1, 2]", "{out}/sweep.json: not a gyrogen sweep state (not a JSON object)"),
    # valid JSON, not a sweep's state: was "holds another sweep (None, None trajectories)"
    ("sweep.json", '{"a": 1}', "{out}/sweep.json: not a gyrogen sweep state (no sweep, "
     "fingerprint, trajectories, scene): remove it or use another --out"),
    ("sweep.json", '{"sweep": 1, "fingerprint": 1, "trajectories": 1, "scene": 1, "identity": [1]}',
     "{out}/sweep.json: not a gyrogen sweep state (its identity is not a JSON object)"),
    ("sweep.json", '{"sweep": 1, "fingerprint": 1, "trajectories": "60", "scene": 1}',
     "{out}/sweep.json: not a gyrogen sweep state (its trajectories is not a count)"),
    ("sweep.json", "[" * 10**5, "{out}/sweep.json: unreadable (maximum recursion depth"),
    # a directory where the sweep writes a file: every part was computed first, then exit 1
    *((name, None, f"{{out}}/{name}: not a file, and the sweep writes one there")
      for name in ("sweep.json", "sweep.lock", "summary.json", "summary.md", "histograms.png",
                   "map.png")),
]  # fmt: skip
"""(name, a file's text or None for a directory, the message's start)"""


def put(out: Path, name: str, text: str | None) -> dict[str, bytes | None]:
    """The obstacle name in out; what out holds (to compare after)."""
    out.mkdir()
    (out / name).write_text(text) if text is not None else (out / name).mkdir()
    return {p.name: p.read_bytes() if p.is_file() else None for p in out.rglob("*")}
