"""gyrogen sweep on real engines: a `dask scheduler` and two `dask worker`
processes on 127.0.0.1 give the local run's rows bit for bit, each worker
builds the sources once, and a worker killed mid-sweep loses nothing; a
client interrupted with SIGINT resumes without recomputing what it wrote;
a second sweep into the --out of a running one is refused, and one killed
does not hold its --out."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from ctrl_c import interrupted
from sweep_cases import long, rows
from wide import WIDE

from gyrogen.runtime.scene_build import builds

pytestmark = pytest.mark.slow  # sweeps of a cluster scene on Dask workers

DASK = str(Path(sys.executable).with_name("dask"))
CHUNKS = 41


def _environment(cache_dir: Path) -> dict[str, str]:
    return {**os.environ, "GYROGEN_CACHE": str(cache_dir)}


@pytest.fixture
def cache(cache_dir: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("GYROGEN_CACHE", str(cache_dir))
    return cache_dir


STARTUP = 240
"""Seconds the scheduler and workers get to come up: on a loaded CI machine
each `dask` process imports distributed while the suite compiles beside it."""


def _wait(what: str, ready, procs: list[subprocess.Popen], log: Path) -> None:
    """Poll ready() until it holds; fail with the processes' log when one of
    them exits first or STARTUP passes."""
    deadline = time.monotonic() + STARTUP
    while not ready():
        dead = [p.args[1] for p in procs if p.poll() is not None]
        if dead or time.monotonic() > deadline:
            why = f"{dead} exited" if dead else f"not up after {STARTUP} s"
            pytest.fail(f"{what}: {why}; dask log:\n{log.read_text()[-3000:]}")
        time.sleep(0.1)


@pytest.fixture
def cluster(tmp_path: Path, cache: Path) -> Iterator[tuple[str, list[subprocess.Popen]]]:
    """A scheduler and two single-thread workers (no nanny: a killed worker
    stays dead), started here and stopped at the end. The scheduler picks its
    own port and writes it to a scheduler file (a port probed free beforehand
    can be taken by another process before the scheduler binds it)."""
    from distributed import Client

    info, log_path = tmp_path / "scheduler.json", tmp_path / "dask.log"
    env, log = _environment(cache), open(log_path, "w")  # noqa: SIM115
    common = {"env": env, "stdout": log, "stderr": subprocess.STDOUT, "cwd": tmp_path}
    where = ["--scheduler-file", str(info), "--no-dashboard"]
    procs = [
        subprocess.Popen(
            [DASK, "scheduler", "--host", "127.0.0.1", "--port", "0", *where],
            **common,  # type: ignore[call-overload]
        )
    ]
    try:
        _wait("the dask scheduler", info.is_file, procs, log_path)
        for name in ("w1", "w2"):
            cmd = [DASK, "worker", "--name", name, "--nthreads", "1", "--no-nanny", *where]
            cmd += ["--host", "127.0.0.1", "--local-directory", str(tmp_path)]
            procs.append(subprocess.Popen(cmd, **common))  # type: ignore[call-overload]
        with Client(scheduler_file=str(info), timeout=STARTUP) as client:
            address = client.scheduler.address
            _wait("two dask workers", lambda: len(client.scheduler_info()["workers"]) == 2,
                  procs, log_path)  # fmt: skip
        yield address, procs
    finally:
        for proc in reversed(procs):  # the workers first, then the scheduler
            proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        log.close()


def _kill_when(parts: Path, count: int, proc: subprocess.Popen, seen: list[int]) -> None:
    """SIGKILL proc once parts holds count files; seen gets how many it held."""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        written = len(list(parts.glob("part-*.parquet"))) if parts.is_dir() else 0
        if written >= count:
            proc.send_signal(signal.SIGKILL)
            seen.append(written)
            return
        time.sleep(0.01)


@WIDE
def test_cluster_gives_the_local_rows_and_survives_a_killed_worker(
    tmp_path: Path, cluster: tuple[str, list[subprocess.Popen]], cli
) -> None:
    from distributed import Client

    address, procs = cluster
    sweep = long(tmp_path / "long.toml")
    local, remote, killed = (tmp_path / n for n in ("local", "remote", "killed"))
    assert cli(["sweep", str(sweep), "--out", str(local), "--no-plots", "--quiet"]).code == 0
    code, stdout, err = cli(["sweep", str(sweep), "--out", str(remote), "--scheduler", address])
    assert code == 0, err
    assert f"dask.distributed at {address} (2 worker threads); {CHUNKS} chunks computed" in stdout
    assert rows(remote).equals(rows(local))

    seen: list[int] = []
    watcher = threading.Thread(target=_kill_when, args=(killed / "parts", 3, procs[2], seen))
    watcher.start()
    code, _, err = cli(["sweep", str(sweep), "--out", str(killed), "--scheduler", address])
    watcher.join()
    assert code == 0, err
    assert procs[2].wait(timeout=10) == -signal.SIGKILL and seen and seen[0] < CHUNKS
    assert rows(killed).equals(rows(local))
    with Client(address) as client:  # the survivor built once for three sweeps
        assert list(client.run(builds).values()) == [[_build_id(local)]]


@WIDE
def test_two_clients_at_once_share_no_task(
    tmp_path: Path, cluster: tuple[str, list[subprocess.Popen]], cli
) -> None:
    """The same sweep from two clients on one scheduler: task keys are unique
    to a run (they were the sweep's fingerprint and chunk, and the
    scheduler warned of different run_specs under one key), so each gets its
    own rows, equal to a local run's."""
    address, _ = cluster
    sweep = long(tmp_path / "long.toml")
    local = tmp_path / "local"
    assert cli(["sweep", str(sweep), "--out", str(local), "--no-plots", "--quiet"]).code == 0
    cmd = [sys.executable, "-m", "gyrogen", "sweep", str(sweep), "--scheduler", address]
    env = _environment(Path(os.environ["GYROGEN_CACHE"]))
    runs = [
        subprocess.Popen(
            [*cmd, "--out", str(tmp_path / n), "--quiet", "--no-plots"],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for n in ("a", "b")
    ]
    for proc in runs:
        _, err = proc.communicate(timeout=300)
        assert proc.returncode == 0, err
    for n in ("a", "b"):
        assert rows(tmp_path / n).equals(rows(local))
    assert "Detected different `run_spec`" not in (tmp_path / "dask.log").read_text()


def _build_id(out: Path) -> str:
    return str(json.loads((out / "summary.json").read_text())["build_id"])


def test_interrupted_client_resumes_without_recomputing(tmp_path: Path, cache: Path, cli) -> None:
    """Ctrl-C as the sweep stages its third part (a moment chosen inside the
    process: one timed from outside came after the sweep's end under load):
    exit 130; a rerun computes only the chunks not written, and its rows are
    a fresh run's."""
    sweep = long(tmp_path / "long.toml")
    out, parts = tmp_path / "out", tmp_path / "out" / "parts"
    cmd = [sys.executable, "-m", "gyrogen", "sweep", str(sweep), "--out", str(out)]
    code, err = interrupted(parts, [*cmd[3:], "--workers", "1", "--quiet", "--no-plots"], cache, 2)
    assert code == 130, err
    assert err.rstrip().endswith("gyrogen: aborted")
    before = {p.name: p.stat().st_mtime_ns for p in parts.glob("part-*.parquet")}
    assert 2 <= len(before) < CHUNKS
    code, stdout, err = cli([*cmd[3:], "--quiet", "--no-plots"])
    assert code == 0, err
    assert f"{CHUNKS - len(before)} chunks computed, {len(before)} already written" in stdout
    after = {p.name: p.stat().st_mtime_ns for p in parts.glob("part-*.parquet")}
    assert len(after) == CHUNKS and all(after[n] == ns for n, ns in before.items())
    fresh = tmp_path / "fresh"
    assert cli([*cmd[3:5], "--out", str(fresh), "--quiet", "--no-plots"]).code == 0
    assert rows(out).equals(rows(fresh))


def _sweeping(cmd: list[str], cache: Path, parts: Path) -> subprocess.Popen:
    """cmd started, returned once it has written a part (it holds its --out)."""
    proc = subprocess.Popen(
        cmd, env=_environment(cache), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not list(parts.glob("part-*.parquet")):
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.01)
    return proc


def _held(out: Path) -> dict[str, bytes | None]:
    return {str(p): p.read_bytes() if p.is_file() else None for p in sorted(out.rglob("*"))}


@pytest.mark.parametrize(
    ("form", "other"),
    [("dir", "dir"), ("file-url", "file-url"), ("file-url", "dir"), ("dir", "file-url")],
)
@WIDE
def test_a_second_sweep_into_a_busy_out_is_refused(
    tmp_path: Path, cache: Path, form: str, other: str
) -> None:
    """Two `gyrogen sweep` processes into one --out, each naming it as a
    path or as a file:// URL: the first, stopped (SIGSTOP) once it has
    written a part, holds it; the second is refused in one line, exit 1,
    and changes nothing there; the first, continued, computes every chunk
    once (before: both ran to the end, computing the same chunks twice)."""
    import socket

    sweep, out = long(tmp_path / "long.toml"), tmp_path / "out"
    where, second_where = (str(out) if f == "dir" else f"file://{out}" for f in (form, other))
    cmd = [sys.executable, "-m", "gyrogen", "sweep", str(sweep), "--out", where, "--quiet",
           "--no-plots", "--workers", "1"]  # fmt: skip
    first = _sweeping(cmd, cache, out / "parts")
    first.send_signal(signal.SIGSTOP)
    try:
        before = _held(out)
        second = subprocess.run(
            [*cmd[:6], second_where, *cmd[7:]],
            env=_environment(cache),
            capture_output=True,
            text=True,
            timeout=120,
        )
        after = _held(out)
    finally:
        first.send_signal(signal.SIGCONT)
    stdout, err = first.communicate(timeout=120)
    assert first.returncode == 0, err
    assert (second.returncode, second.stdout) == (1, "") and after == before
    assert second.stderr == (
        f"gyrogen: error: {second_where} is being written by another sweep (process "
        f"{first.pid} on {socket.gethostname()}): wait for it to end, or use another --out\n"
    )
    assert f"{CHUNKS} chunks computed, 0 already written" in stdout
    assert list(rows(where)["sample"]) == list(range(CHUNKS * 100 - 95))


@pytest.mark.parametrize("form", ["dir", "file-url"])
@WIDE
def test_a_killed_sweep_does_not_hold_its_out(tmp_path: Path, cache: Path, form: str) -> None:
    """The first sweep SIGKILLed once it has written a part: its lock is no
    one's (a directory's flock, a file:// URL's too, ends with its process),
    and the rerun resumes without a word."""
    sweep, out = long(tmp_path / "long.toml"), tmp_path / "out"
    where = str(out) if form == "dir" else f"file://{out}"
    cmd = [sys.executable, "-m", "gyrogen", "sweep", str(sweep), "--out", where, "--quiet",
           "--no-plots", "--workers", "1"]  # fmt: skip
    first = _sweeping(cmd, cache, out / "parts")
    first.send_signal(signal.SIGKILL)
    first.communicate(timeout=60)
    kept = len(list((out / "parts").glob("part-*.parquet")))
    second = subprocess.run(cmd, env=_environment(cache), capture_output=True, text=True,
                            timeout=120)  # fmt: skip
    assert second.returncode == 0, second.stderr
    assert second.stderr == ""
    assert f"{CHUNKS - kept} chunks computed, {kept} already written" in second.stdout
    assert list(rows(where)["sample"]) == list(range(CHUNKS * 100 - 95))


def test_memory_does_not_grow_with_the_number_of_chunks(tmp_path: Path, cache: Path) -> None:
    """A 1000 x 1000 x 1000 grid in chunks of 1 (10^9 tasks): the client
    once listed every chunk index, 3 GB within 15 s before the first part.
    After 20 parts its peak resident memory is that of a small sweep."""
    sweep = tmp_path / "big.toml"
    sweep.write_text(
        'scene = "gyrostat"\nt_end = 0.01\n[grid]\n'
        + "".join(f"{n} = {{ linspace = [0.0, 1.0, 1000] }}\n" for n in ("u1", "u3", "u4"))
    )
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [sys.executable, "-m", "gyrogen", "sweep", str(sweep), "--out", str(out), "--chunk", "1",
         "--quiet"], env=_environment(cache), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and len(list(out.glob("parts/part-*"))) < 20:
            time.sleep(0.05)
        status = Path(f"/proc/{proc.pid}/status").read_text()
    finally:
        proc.kill()
        proc.communicate(timeout=60)
    peak_kb = int(next(line for line in status.splitlines() if line.startswith("VmHWM")).split()[1])
    assert len(list(out.glob("parts/part-*"))) >= 20
    assert peak_kb < 600_000, peak_kb  # 185 MB measured; a list of 10^9 indices is 3 GB and more


@WIDE
def test_workers_write_their_parts_to_the_shared_path(
    tmp_path: Path,
    cluster: tuple[str, list[subprocess.Popen]],
    cli,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """--shared: each worker process writes the parts it computes into --out
    (here a directory both reach), and the client writes none, receiving
    only each chunk's figures; a worker SIGKILLed once 3 parts are there
    loses nothing, and no temporary of a write it cut short stays behind."""
    from gyrogen.analysis.sweep import engine

    address, procs = cluster
    sweep = long(tmp_path / "long.toml")
    local, shared = tmp_path / "local", tmp_path / "shared"
    assert cli(["sweep", str(sweep), "--out", str(local), "--no-plots", "--quiet"]).code == 0
    by_client: list[tuple[int, int]] = []
    real = engine.write_part

    def counted(parts: Path, start: int, stop: int, data: bytes) -> None:
        by_client.append((start, stop))
        real(parts, start, stop, data)

    monkeypatch.setattr(engine, "write_part", counted)
    seen: list[int] = []
    watcher = threading.Thread(target=_kill_when, args=(shared / "parts", 3, procs[1], seen))
    watcher.start()
    code, stdout, err = cli(["sweep", str(sweep), "--out", str(shared), "--scheduler", address,
                             "--shared", "--quiet"])  # fmt: skip
    watcher.join()
    assert code == 0, err
    assert procs[1].wait(timeout=10) == -signal.SIGKILL and seen and seen[0] < CHUNKS
    assert f"{CHUNKS} chunks computed" in stdout and by_client == []
    assert rows(shared).equals(rows(local))
    assert (
        sorted(p.name for p in (shared / "parts").iterdir() if not p.name.startswith("part-")) == []
    )


def test_shared_is_for_a_scheduler(tmp_path: Path, cli) -> None:
    code, _, err = cli(["sweep", "monte_carlo", "--out", str(tmp_path / "o"), "--shared"])
    assert code == 2 and "--shared is for --scheduler" in err and not (tmp_path / "o").exists()


@WIDE
def test_workers_write_their_parts_to_a_file_url(
    tmp_path: Path,
    cluster: tuple[str, list[subprocess.Popen]],
    cli,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """--out file:///... --shared: the workers write every part through
    fsspec (the client none), the rows are the local run's, the summary is
    read back from the URL and written there, and a rerun after two parts
    are lost computes only those two (the resume lists and reads the URL)."""
    from gyrogen.analysis.sweep import engine

    address, _ = cluster
    sweep = long(tmp_path / "long.toml")
    local, there = tmp_path / "local", tmp_path / "there"
    url = f"file://{there}"
    assert cli(["sweep", str(sweep), "--out", str(local), "--no-plots", "--quiet"]).code == 0
    by_client: list[tuple[int, int]] = []
    real = engine.write_part

    def counted(where: object, start: int, stop: int, data: bytes) -> None:
        by_client.append((start, stop))
        real(where, start, stop, data)  # type: ignore[arg-type]

    monkeypatch.setattr(engine, "write_part", counted)
    run = ["sweep", str(sweep), "--out", url, "--scheduler", address, "--shared", "--quiet"]
    code, stdout, err = cli(run)
    assert code == 0, err
    assert f"{CHUNKS} chunks computed" in stdout and by_client == []
    assert rows(url).equals(rows(local))
    summary, mine = (json.loads((d / "summary.json").read_text()) for d in (there, local))
    assert summary["parts"] == CHUNKS and summary["metrics"] == mine["metrics"]
    assert summary["integrator_codes"] == mine["integrator_codes"]
    lost = sorted((there / "parts").iterdir())[3:5]
    for part in lost:
        part.unlink()
    code, stdout, err = cli(run)
    assert code == 0 and "2 chunks computed, 39 already written" in stdout, (stdout, err)
    assert rows(url).equals(rows(local)) and by_client == []
    assert all(p.name.startswith("part-") for p in (there / "parts").iterdir())
