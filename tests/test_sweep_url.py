"""--out as an fsspec URL: file:// runs a sweep, resumes it and summarizes it
through fsspec (the same rows as a local directory); every hostile URL is
refused in one line naming it and why, before any work, with nothing
written; an unwritable place is one line, exit 1, nothing half-written; a
write cut short leaves no temporary behind. (The real scheduler and
workers writing to a file:// URL: tests/test_sweep_cluster.py.)"""

from __future__ import annotations

import importlib.util
import json
import os
import socket
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sweep_cases import OBSTACLES, free_port, put, rows, small

from gyrogen.analysis.sweep.store import Store, store, url_store
from gyrogen.errors import GyrogenError


@pytest.fixture
def cache(cache_dir: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("GYROGEN_CACHE", str(cache_dir))
    return cache_dir


def _listing(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


HOSTILE = [
    ("file://relative/o", "a file URL names an absolute path on this machine: file:///PATH"),
    ("file://", "a file URL names an absolute path on this machine"),
    ("file:///", "names no path (PROTOCOL://PATH)"),
    ("nope://bucket/o", "unknown protocol 'nope': fsspec has no file system of that name"),
    ("memory://o", "memory:// is each process's own memory: workers would not share it"),
    ("file:///{dir}/o?x=1", "a query or fragment (? or #) is not supported"),
    ("file:///{dir}/o#top", "a query or fragment (? or #) is not supported"),
    ("simplecache::file:///{dir}/o", "a chained URL (::) is not supported"),
    ("zip://a::file:///{dir}/o.zip", "a chained URL (::) is not supported"),  # was exit 1
    ("file:///{dir}/o::x", "a chained URL (::) is not supported"),
    ("://{dir}/o", "not a URL (PROTOCOL://PATH"),
    ("file:///{dir}/o\nx", "a URL with a character that is not printable"),
    ("file:///{dir}/o\x00", "a URL with a character that is not printable"),
    ("", "'': an empty path: name a directory or a URL"),  # was the current directory
    ("  ", "'  ': an empty path: name a directory or a URL"),  # was a directory named '  '
    ("\t", "'\\t': an empty path"),
    ("file:relative/o", "a file URL names an absolute path on this machine: file:///PATH"),
    ("LOCAL:", "a file URL names an absolute path on this machine: file:///PATH"),
    # the URL's host was not given to the file system: a 49-line traceback
    ("ftp:///{dir}/o", "the ftp file system can be made for (missing a required argument: 'host')"),
    ("ftp://127.0.0.1:99999/o", "the ftp file system can be made for (Port out of range 0-65535)"),
    ("zip:///{dir}/o", "zip:// is no directory to write in"),  # wrappers: exit 1 or tracebacks
    ("simplecache:///{dir}/o", "simplecache:// is no directory to write in"),
    ("data:///{dir}/o", "data:// is no directory to write in"),
    ("generic:///{dir}/o", "generic:// is no directory to write in"),
]


@pytest.mark.parametrize(("url", "message"), HOSTILE, ids=[h[0] for h in HOSTILE])
def test_a_hostile_url_is_one_line_exit_2_nothing_written(
    url: str, message: str, tmp_path: Path, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)  # a URL read as a relative path would write here
    sweep = small(tmp_path / "s.toml")
    before = _listing(tmp_path)
    code, stdout, err = cli(["sweep", str(sweep), "--out", url.format(dir=tmp_path)])
    assert (code, stdout) == (2, "") and err.count("\n") == 1, err
    assert err.startswith("gyrogen sweep: error: Invalid value for '--out': "), err
    assert message in err, err
    assert _listing(tmp_path) == before


@pytest.mark.parametrize(
    "form", ["file:{dir}/o", "FILE://{dir}/o", "local:{dir}/o", "LOCAL://{dir}/o"]
)
def test_a_file_url_of_any_spelling_is_its_absolute_path(form: str, tmp_path: Path) -> None:
    """file:/PATH is file:///PATH, as fsspec and pyarrow read it (it was a
    relative directory ./file:/PATH that the summary then missed), and the
    protocol's case is not the path's (FILE:///PATH was ./FILE:/PATH)."""
    url = form.format(dir=tmp_path)
    found = store(url)
    assert (found.where, found.protocol, found.root) == (url, form[:5].lower().rstrip(":"),
                                                         str(tmp_path / "o"))  # fmt: skip


def test_a_url_gives_its_host_to_the_file_system() -> None:
    """ftp://USER:PASS@HOST:PORT/PATH: the file system is made with its host
    and port (they were dropped: no ftp:// or sftp:// could be made)."""
    found = url_store("ftp://me:pw@example.org:2121/o")
    assert found.root == "/o" and dict(found.options) == {
        "host": "example.org", "port": 2121, "username": "me", "password": "pw"
    }  # fmt: skip


@pytest.mark.parametrize(
    ("url", "options"),
    [
        ("ftp://[::1]/o", {"host": "::1"}),  # fsspec's own reading: host "[:"
        ("ftp://me@[::1]:2121/o", {"host": "::1", "port": 2121, "username": "me"}),
        ("ftp://[fe80::1%25eth0]:21/o", {"host": "fe80::1%eth0", "port": 21}),
    ],
)
def test_an_ipv6_host_is_no_chain_and_the_file_system_gets_it(
    url: str, options: dict[str, object]
) -> None:
    """sftp://[::1]/x was refused as a chained URL (its ::): an IPv6 host is
    given to the file system without its brackets (fsspec kept them, or cut
    the host at its last colon)."""
    found = url_store(url)
    assert found.root == "/o" and dict(found.options) == options


def test_an_ipv6_host_is_reached(tmp_path: Path, cli) -> None:
    """The real FTP client reaches [::1] (with the brackets it could not
    resolve the name): nothing listens there, one line, exit 1."""
    with socket.socket(socket.AF_INET6) as s:
        s.bind(("::1", 0))
        port = s.getsockname()[1]
    url = f"ftp://[::1]:{port}/o"
    code, stdout, err = cli(["sweep", str(small(tmp_path / "s.toml")), "--out", url])
    assert (code, stdout, err) == (
        1,
        "",
        f"gyrogen: error: cannot open {url}: Connection refused\n",
    )


@pytest.mark.parametrize(
    ("out", "place"), [("file:{tmp}/there", "{tmp}/there"), ("s3:b/o", "{tmp}/here/s3:b/o")]
)
def test_a_short_file_url_sweeps_there_and_summarizes(
    out: str, place: str, tmp_path: Path, cache: Path, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    """--out file:/PATH: everything under /PATH (before: the parts under
    ./file:/PATH, then the summary's traceback); a relative directory that
    pyarrow would read as a URI (s3:b/o) is that directory, read back too."""
    here, out, place = tmp_path / "here", out.format(tmp=tmp_path), place.format(tmp=tmp_path)
    here.mkdir()
    monkeypatch.chdir(here)
    code, stdout, err = cli(["sweep", str(small(tmp_path / "s.toml", count=1)), "--out", out,
                             "--quiet", "--no-plots"])  # fmt: skip
    assert code == 0 and f"wrote {out}/ (summary.json" in stdout, err
    assert list(tmp_path.rglob("summary.json")) == [Path(place, "summary.json")]
    assert len(rows(out)) == 15


@pytest.mark.skipif(importlib.util.find_spec("s3fs") is not None, reason="s3fs is installed")
def test_a_protocol_without_its_package_says_which(tmp_path: Path, cli) -> None:
    code, _, err = cli(["sweep", str(small(tmp_path / "s.toml")), "--out", "s3://bucket/o"])
    assert code == 2 and err.count("\n") == 1, err
    assert "s3://bucket/o: the s3 protocol needs a package that is not installed" in err, err
    assert "s3fs" in err, err


PROTOCOLS = st.sampled_from(["file", "local", "memory", "s3", "gs", "nope", "FILE", "ftp", "x+y"])
TAILS = st.text(st.characters(codec="utf-8"), max_size=30)


@settings(max_examples=300, deadline=None)
@given(protocol=PROTOCOLS, tail=TAILS, slash=st.sampled_from(["", "/", "//"]))
def test_every_url_is_a_store_or_one_line_naming_it(protocol: str, tail: str, slash: str) -> None:
    """Whatever follows PROTOCOL://: a store of a protocol fsspec has, on the
    path fsspec reads from the URL, or one GyrogenError line that starts
    with the URL (repr when it holds a character that is not printable). Nothing is
    touched: url_store only reads the URL."""
    url = f"{protocol}://{slash}{tail}"
    try:
        found = url_store(url)
    except GyrogenError as exc:
        message = str(exc)
        assert "\n" not in message and message.startswith(f"{url}: " if url.isprintable()
                                                          else repr(url)), message  # fmt: skip
        return
    assert isinstance(found, Store) and found.where == url and found.protocol == protocol.lower()
    assert found.root and "?" not in found.root and "#" not in found.root
    if found.protocol in ("file", "local"):
        assert os.path.isabs(found.root)


@pytest.mark.slow
def test_a_file_url_sweeps_resumes_and_summarizes_as_a_directory(
    tmp_path: Path, cache: Path, cli
) -> None:
    sweep = small(tmp_path / "s.toml")
    local, there = tmp_path / "local", tmp_path / "there"
    url = f"file://{there}"
    assert cli(["sweep", str(sweep), "--out", str(local), "--quiet"]).code == 0
    code, stdout, err = cli(["sweep", str(sweep), "--out", url, "--quiet"])
    assert code == 0, err
    assert f"wrote {url}/ (summary.json" in stdout
    assert rows(url).equals(rows(local))
    summary, mine = (json.loads((d / "summary.json").read_text()) for d in (there, local))
    assert summary["metrics"] == mine["metrics"] and summary["parts"] == mine["parts"] == 3
    # a resume through the URL: one part gone, one cut short, one writer's temporary left
    parts = sorted((there / "parts").glob("part-*.parquet"))
    parts[0].unlink()
    parts[1].write_bytes(parts[1].read_bytes()[:100])
    (there / "parts" / f".{parts[2].name}.0123456789ab.new").write_bytes(b"half")
    code, stdout, err = cli(["sweep", str(sweep), "--out", url, "--quiet"])
    assert code == 0 and "2 chunks computed, 1 already written" in stdout, (stdout, err)
    assert "damaged or cut short" in err and rows(url).equals(rows(local))
    assert sorted(p.name for p in (there / "parts").iterdir()) == sorted(p.name for p in parts)


def test_an_unwritable_url_is_one_line_exit_1_nothing_written(tmp_path: Path, cli) -> None:
    blocker = tmp_path / "afile"
    blocker.write_text("mine")
    sweep = small(tmp_path / "s.toml")
    before = _listing(tmp_path)
    for url, why in [
        (f"file://{blocker}/o", "Not a directory"),  # a file in the way
        ("file:///proc/gyrogen-none/o", "No such file or directory"),  # not even root makes it
        (f"ftp://127.0.0.1:{free_port()}/o", "Connection refused"),  # no server: was a traceback
    ]:
        code, stdout, err = cli(["sweep", str(sweep), "--out", url])
        assert (code, stdout) == (1, "") and err.count("\n") == 1, err
        assert err.startswith("gyrogen: error: cannot ") and url in err and why in err, err
        assert _listing(tmp_path) == before and blocker.read_text() == "mine"


@pytest.mark.parametrize(("name", "text", "message"), OBSTACLES, ids=[o[0] for o in OBSTACLES])
def test_obstacles_at_a_url_are_refused_before_any_work(
    tmp_path: Path, cli, name: str, text: str | None, message: str
) -> None:
    out = tmp_path / "o"
    before = put(out, name, text)
    url = f"file://{out}"
    code, stdout, err = cli(["sweep", str(small(tmp_path / "s.toml")), "--out", url])
    assert (code, stdout) == (1, "") and err.count("\n") == 1
    assert err.startswith("gyrogen: error: " + message.format(out=url)), err
    assert {p.name: p.read_bytes() if p.is_file() else None for p in out.rglob("*")} == before


def test_a_url_write_cut_short_leaves_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The rename that would make a part whole fails: one line naming the
    part, no temporary, no part."""
    where = url_store(f"file://{tmp_path}")
    where.make_dir("parts")

    def refused(*args: object, **kwargs: object) -> None:
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(type(where.fs), "mv", refused)
    with pytest.raises(GyrogenError) as exc:
        where.write({"part-1.parquet": b"rows"}, "parts")
    assert (
        str(exc.value) == f"cannot write file://{tmp_path}/parts/part-1.parquet: Permission denied"
    )
    assert list((tmp_path / "parts").iterdir()) == []


def _memory(name: str) -> Store:
    """An empty memory:// store (this process's own: the lock's URL path,
    testable in one process)."""
    where = Store(f"memory://{name}", "memory", f"/{name}")
    if where.fs.exists(where.root):
        where.fs.rm(where.root, recursive=True)
    return where


@pytest.mark.parametrize("kind", ["dir", "memory"])
def test_a_held_out_is_refused_and_free_once_released(tmp_path: Path, kind: str) -> None:
    """The lock of a local directory (an flock) and of a URL (an exclusively
    created file): a second taker is refused in one line naming the holder;
    released, the lock is gone and the next taker gets it."""
    from gyrogen.analysis.sweep.lock import LOCK, take

    where = Store(str(tmp_path / "o")) if kind == "dir" else _memory("held")
    first = take(where)
    with pytest.raises(GyrogenError) as exc:
        take(where)
    assert str(exc.value) == (
        f"{where.show()} is being written by another sweep (process {os.getpid()} on "
        f"{socket.gethostname()}): wait for it to end, or use another --out"
    )
    first.release()
    assert where.kind(LOCK) == "absent"
    take(where).release()


@pytest.mark.parametrize("first", ["path", "url"])
def test_a_directory_is_one_out_as_a_path_and_as_a_file_url(tmp_path: Path, first: str) -> None:
    """A local directory named by its path and by file:// (or local://) is
    one lock, an flock on the same file, whichever spelling takes it first:
    the other is refused, and no lock file is left once it is released."""
    from gyrogen.analysis.sweep.lock import LOCK, take

    spellings = [store(str(tmp_path / "o")), store(f"file://{tmp_path}/o")]
    taker, other = spellings if first == "path" else spellings[::-1]
    assert [s.on_disk for s in (*spellings, store(f"local://{tmp_path}/o"))] == [True] * 3
    held = take(taker)
    for late in (other, store(f"local://{tmp_path}/o")):
        with pytest.raises(GyrogenError, match="is being written by another sweep"):
            take(late)
    held.release()
    assert not (tmp_path / "o" / LOCK).exists()
    take(other).release()


def _lock_of(holder: dict[str, object]) -> Store:
    from gyrogen.analysis.sweep.lock import LOCK

    where = _memory("stale")
    where.make_dir()
    where.write({LOCK: json.dumps(holder)})
    return where


def _this_host() -> dict[str, object]:
    from gyrogen.analysis.sweep.lock import _namespace

    return {"host": socket.gethostname(), "namespace": _namespace(), "token": "theirs"}


def test_a_lock_left_by_a_process_of_this_host_that_is_gone_is_taken(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Stale: the pid of a process that has ended, or a live pid whose
    process started at another time (reused); a note names it."""
    import subprocess
    import sys

    from gyrogen.analysis.sweep.lock import LOCK, take

    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    for pid, started in [(gone.pid, 1.0), (os.getpid(), 1.0)]:
        where = _lock_of({**_this_host(), "pid": pid, "started": started})
        lock = take(where)
        assert json.loads(where.read_text(LOCK))["pid"] == os.getpid()
        lock.release()
        assert capsys.readouterr().err == (
            f"{where.show(LOCK)}: its sweep (process {pid} on this host) has ended: taking it\n"
        )


def test_a_lock_of_another_host_is_refused_with_how_to_free_it() -> None:
    """A holder on another host cannot be seen from here: refused, and the
    line says which file to remove if it is gone (an unreadable lock too)."""
    from gyrogen.analysis.sweep.lock import LOCK, take

    for holder, who in [
        (
            {**_this_host(), "host": "elsewhere", "pid": 1, "started": 1.0},
            " (process 1 on elsewhere)",
        ),
        ({}, ""),
    ]:
        where = _lock_of(holder)
        with pytest.raises(GyrogenError) as exc:
            take(where)
        assert str(exc.value) == (
            f"{where.show()} is being written by another sweep{who}: wait for it to end, or "
            f"use another --out; if it is gone, remove {where.show(LOCK)}"
        )
        assert json.loads(where.read_text(LOCK)) == holder


def test_a_lock_that_cannot_be_made_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A local file system without flock, a URL whose lock cannot be
    written: one line naming the lock and why."""
    import errno
    import fcntl

    from gyrogen.analysis.sweep.lock import take

    def no_locks(*args: object) -> None:
        raise OSError(errno.ENOLCK, "No locks available")

    with monkeypatch.context() as patch:
        patch.setattr(fcntl, "flock", no_locks)
        with pytest.raises(GyrogenError) as exc:
            take(Store(str(tmp_path / "o")))
    assert str(exc.value) == f"cannot lock {tmp_path}/o/sweep.lock: No locks available"
    where = _memory("unwritable")

    def refused(*args: object, **kwargs: object) -> None:
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(type(where.fs), "open", refused)
    with pytest.raises(GyrogenError) as exc:
        take(where)
    assert str(exc.value) == "cannot write memory://unwritable/sweep.lock: Permission denied"
