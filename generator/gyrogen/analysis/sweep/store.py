"""Where a sweep's files are (its --out): a local directory, or an fsspec URL
(file:///PATH, s3://BUCKET/PATH, gs://, ...) that the client and, with
--shared, every worker reach. Everything the sweep reads and writes there
(sweep.json, the parts, the summary and figures) goes through a Store.

Each file is written atomically, so a reader, a resume or the summary sees
it whole or not at all:

- a local directory: files.write_atomic (a temporary name beside it,
  fsynced, then renamed; several files all or nothing), kept whatever
  follows (a Ctrl-C of the command puts back no part: a rerun resumes);
- an object store (s3, gs, az): one PUT per file, which the store makes
  visible only once whole (an interrupted upload leaves nothing);
- any other protocol (file://, sftp, hdfs, ...): a temporary name beside it
  (.<name>.<random>.new, which a resume removes), then the file system's
  rename: atomic on a POSIX file system and on HDFS. fsspec's local files
  are not fsynced: after a power cut a part may be cut short, and the
  resume, which reads every part's footer, computes it again.

A URL is checked before any work: its form, a protocol fsspec knows and
whose package is installed, and not memory:// (each process has its own).
"""

from __future__ import annotations

import inspect
import os
import posixpath
import re
import stat
import uuid
from collections.abc import Iterator, Mapping
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlsplit

from gyrogen.errors import GyrogenError
from gyrogen.files import can_write, make_dir, write_atomic

URL = re.compile(r"([A-Za-z][A-Za-z0-9+.-]*)://(.*)", re.S)
FILE_URL = re.compile(r"(file|local):(.*)", re.I | re.S)
"""file:/PATH, a file URL's short form: the local path /PATH to fsspec and
pyarrow alike (not a relative directory named "file:")."""
IPV6_HOST = re.compile(r"\[[0-9A-Fa-f:.]*(%25[0-9A-Za-z._~-]+)?\]")
"""A URL's host as an IPv6 literal ([::1], RFC 3986; a zone as %25, RFC
6874): its colons are no chain (::), and the file system gets it without
the brackets (and the zone's % unescaped)."""
OBJECT_STORES = frozenset({"s3", "s3a", "gs", "gcs", "az", "abfs", "abfss"})
"""Protocols whose files are objects, each PUT whole or not at all (no rename)."""
NOT_PLACES = frozenset(
    {"blockcache", "cached", "filecache", "simplecache", "dir", "dask", "generic", "reference",
     "asyncwrapper", "async_wrapper", "zip", "tar", "libarchive", "data", "http", "https",
     "github", "gist", "git"}
)  # fmt: skip
"""fsspec protocols that are no directory to write in: wrappers of another
file system (a chain), an archive's or a repository's files, data:// (the
bytes are the URL), HTTP (read only)."""


@dataclass(frozen=True)
class Store:
    """A sweep's directory: where (the path or URL as given), protocol
    (None: a local directory), root (the path within the file system) and
    options (what the URL gives its file system: ftp's host and port, ...)."""

    where: str
    protocol: str | None = None
    root: str = ""
    options: tuple[tuple[str, Any], ...] = ()

    @property
    def local(self) -> bool:
        return self.protocol is None

    @cached_property
    def on_disk(self) -> bool:
        """Whether its files are this machine's own, at path(): a local
        directory, or a URL of fsspec's local file system (file:///PATH,
        local://PATH). Both spellings of one directory are one --out to
        its lock (analysis/sweep/lock.py)."""
        if self.local:
            return True
        import fsspec
        from fsspec.implementations.local import LocalFileSystem

        return issubclass(fsspec.get_filesystem_class(self.protocol), LocalFileSystem)

    @property
    def has_dirs(self) -> bool:
        """Whether a directory is there before files are (not an object store's prefix)."""
        return self.protocol not in OBJECT_STORES

    @cached_property
    def fs(self) -> Any:
        """The fsspec file system (made in each process that asks; the first
        look, before any work, makes it in the client): a server that does
        not answer is one line."""
        import fsspec

        try:
            return fsspec.filesystem(self.protocol, **dict(self.options))
        except Exception as exc:  # each file system its own: ConnectionRefusedError, gaierror
            why = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
            raise GyrogenError(f"cannot open {self.where}: {why}") from exc

    def __getstate__(self) -> dict[str, Any]:  # the file system is made anew where it goes
        return {k: v for k, v in self.__dict__.items() if k != "fs"}

    def absolute(self) -> Store:
        """The same place named from anywhere (a worker's own directory)."""
        return Store(os.path.abspath(self.where)) if self.local else self

    def path(self, *names: str) -> str:
        """names within the store, as its file system spells them."""
        if self.local:
            return os.path.join(self.where, *names)
        return posixpath.join(self.root, *names)

    def show(self, *names: str) -> str:
        """names within the store as a user would write them (in messages)."""
        if self.local:
            return str(Path(self.where, *names))
        return "/".join([self.where.rstrip("/"), *names])

    def kind(self, *names: str) -> str:
        """What is at names: "absent", "dir", "file" or "other"."""
        if self.local:
            path = self.path(*names)
            try:
                mode = os.lstat(path).st_mode
                if stat.S_ISLNK(mode):  # what it points to; a dangling link is a file
                    mode = os.stat(path).st_mode if os.path.exists(path) else stat.S_IFREG
            except FileNotFoundError:
                return "absent"
            except OSError as exc:
                raise self.failure("cannot look at", names, exc) from exc
            if stat.S_ISDIR(mode):
                return "dir"
            return "file" if stat.S_ISREG(mode) else "other"
        try:
            kind = self.fs.info(self.path(*names)).get("type")
        except FileNotFoundError:
            return "absent"
        except OSError as exc:
            raise self.failure("cannot look at", names, exc) from exc
        return {"directory": "dir", "file": "file"}.get(kind, "other")

    def listdir(self, *names: str) -> list[str]:
        """The names in the directory names ([] when it is not there)."""
        try:
            if self.local:
                return os.listdir(self.path(*names))
            found = self.fs.ls(self.path(*names), detail=False)
        except FileNotFoundError:
            return []
        except OSError as exc:
            raise self.failure("cannot list", names, exc) from exc
        return [posixpath.basename(str(p).rstrip("/")) for p in found]

    def entries(self, *names: str) -> dict[str, str]:
        """What the directory names holds ({} when it is not there): each
        name's kind as kind() says it, from one listing."""
        try:
            if self.local:
                with os.scandir(self.path(*names)) as found:
                    return {e.name: _kind_of(e) for e in found}
            found = self.fs.ls(self.path(*names), detail=True)
        except FileNotFoundError:
            return {}
        except OSError as exc:
            raise self.failure("cannot list", names, exc) from exc
        kinds = {"directory": "dir", "file": "file"}
        return {posixpath.basename(str(e["name"]).rstrip("/")): kinds.get(e.get("type"), "other")
                for e in found}  # fmt: skip

    def read_text(self, *names: str) -> str:
        """The file's text; OSError (FileNotFoundError when absent) as raised."""
        if self.local:
            return Path(self.path(*names)).read_text(encoding="utf-8")
        return bytes(self.fs.cat_file(self.path(*names))).decode("utf-8")

    @contextmanager
    def open(self, *names: str) -> Iterator[Any]:
        """The file to read (a path, or an fsspec file object): what
        pyarrow's ParquetFile takes. A local path is made absolute: pyarrow
        reads a relative one that looks like a URI (s3:x/...) as that URI."""
        if self.local:
            yield os.path.abspath(self.path(*names))
            return
        with self.fs.open(self.path(*names), "rb") as fh:
            yield fh

    def make_dir(self, *names: str) -> None:
        if self.local:
            make_dir(Path(self.path(*names)), keep=True)
            return
        try:
            self.fs.makedirs(self.path(*names), exist_ok=True)
        except OSError as exc:
            raise self.failure("cannot create directory", names, exc) from exc

    def can_write(self, *names: str) -> None:
        """Nothing in the way of writing the file names (checked before any
        work): a local directory's can_write; for a URL, no file where a
        directory of the way should be, and the directory makeable."""
        if self.local:
            can_write(Path(self.where), ["/".join(names)])
            return
        parent = names[:-1]
        for depth in range(len(parent) + 1):
            if self.kind(*parent[:depth]) not in ("dir", "absent"):
                raise GyrogenError(f"cannot write {self.show(*names)}: Not a directory")
        if self.kind(*names) in ("dir", "other"):
            raise GyrogenError(f"cannot write {self.show(*names)}: Is a directory")
        self.make_dir(*parent)

    def write(self, files: Mapping[str, str | bytes], *names: str) -> None:
        """Each file into the directory names, atomically (the module's
        docstring says how, per protocol); locally all or none."""
        if self.local:
            write_atomic(Path(self.path(*names)), files, keep=True)
            return
        for name, data in files.items():
            blob = data.encode("utf-8") if isinstance(data, str) else data
            target = self.path(*names, name)
            try:
                if self.protocol in OBJECT_STORES:
                    self.fs.pipe_file(target, blob)
                    continue
                tmp = self.path(*names, f".{name}.{uuid.uuid4().hex[:12]}.new")
                try:
                    self.fs.pipe_file(tmp, blob)
                    self.fs.mv(tmp, target)
                except BaseException:
                    with suppress(OSError):
                        self.fs.rm_file(tmp)
                    raise
            except OSError as exc:
                raise self.failure("cannot write", (*names, name), exc) from exc

    def remove(self, *names: str) -> None:
        """The file names gone (nothing when it is not there)."""
        try:
            if self.local:
                Path(self.path(*names)).unlink(missing_ok=True)
            else:
                self.fs.rm_file(self.path(*names))
        except FileNotFoundError:
            pass
        except OSError as exc:
            raise self.failure("cannot remove", names, exc) from exc

    def failure(self, what: str, names: tuple[str, ...], exc: OSError) -> GyrogenError:
        """The one line for an OSError on names in this store (what: "cannot
        write", ...), for the store's own operations and the sweep's lock."""
        why = exc.strerror or str(exc) or type(exc).__name__
        return GyrogenError(f"{what} {self.show(*names)}: {why}")


def _kind_of(entry: os.DirEntry[str]) -> str:
    """A directory entry's kind as Store.kind says it (a link: what it
    points to; a dangling link is a file)."""
    try:
        if entry.is_dir():
            return "dir"
        return "file" if entry.is_file() or not os.path.exists(entry.path) else "other"
    except OSError:
        return "other"


def store(out: str | Path | Store) -> Store:
    """The store out names: a local path, or a URL (checked: url_store); an
    empty or blank path is refused (it would be the current directory, or a
    directory named by spaces)."""
    if isinstance(out, Store):
        return out
    if isinstance(out, str) and not out.strip():
        raise GyrogenError(f"{out!r}: an empty path: name a directory or a URL")
    if isinstance(out, str) and ("://" in out or FILE_URL.match(out)):
        return url_store(out)
    return Store(str(out))


def url_store(url: str) -> Store:
    """The store of an fsspec URL (or file:/PATH, the same as file:///PATH),
    or a one-line GyrogenError naming the URL and what is wrong with it: its
    form, an unknown protocol, a protocol whose package is missing,
    memory:// (not shared between processes)."""
    shown = url if url.isprintable() else repr(url)
    match = URL.fullmatch(url) or FILE_URL.fullmatch(url)
    if not url.isprintable():
        raise GyrogenError(f"{shown}: a URL with a character that is not printable")
    authority = match[2].split("/", 1)[0] if match else ""
    if "::" in url.replace(authority, IPV6_HOST.sub("[]", authority), 1):
        # fsspec chains at any ::, after the first :// too (zip://a::file://b); never
        # at an IPv6 host's (sftp://[::1]/x): the store opens no URL, only protocol + options
        raise GyrogenError(f"{shown}: a chained URL (::) is not supported: one PROTOCOL://PATH")
    if match is None:
        raise GyrogenError(f"{shown}: not a URL (PROTOCOL://PATH)")
    protocol, rest = match[1].lower(), match[2]
    if "?" in rest or "#" in rest:
        raise GyrogenError(f"{shown}: a query or fragment (? or #) is not supported")
    if protocol in ("file", "local") and not rest.startswith("/"):
        raise GyrogenError(
            f"{shown}: a file URL names an absolute path on this machine: file:///PATH"
        )
    if not rest.strip("/"):
        raise GyrogenError(f"{shown}: names no path (PROTOCOL://PATH)")
    if protocol in NOT_PLACES:
        raise GyrogenError(
            f"{shown}: {protocol}:// is no directory to write in (it reads through another file "
            "system, an archive or a server, or the URL itself)"
        )
    if protocol == "memory":
        raise GyrogenError(
            f"{shown}: memory:// is each process's own memory: workers would not share it, "
            "and it is gone when the sweep ends"
        )
    try:
        import fsspec
    except ImportError as exc:
        raise GyrogenError(f"{shown}: URLs need fsspec: pip install 'gyrogen[sweep]'") from exc
    try:
        cls = fsspec.get_filesystem_class(protocol)
    except ValueError as exc:
        raise GyrogenError(
            f"{shown}: unknown protocol {protocol!r}: fsspec has no file system of that name"
        ) from exc
    except ImportError as exc:
        raise GyrogenError(
            f"{shown}: the {protocol} protocol needs a package that is not installed ({exc})"
        ) from exc
    # the protocol as fsspec spells it (FILE:///p was the relative path ./FILE:/p)
    canonical = f"{protocol}://{rest}"
    try:  # what the URL gives the file system (ftp: host, port), and all it needs
        options = cls._get_kwargs_from_urls(canonical)
        if "host" in options and IPV6_HOST.search(authority):  # fsspec kept "[::1]" or cut "[:"
            options["host"] = unquote(urlsplit(canonical).hostname or "")
        inspect.signature(cls.__init__).bind(None, **options)
        root = str(cls._strip_protocol(canonical)).rstrip("/") or "/"
    except Exception as exc:  # each file system its own: TypeError, ValueError (a port)
        raise GyrogenError(
            f"{shown}: not a place the {protocol} file system can be made for ({exc})"
        ) from exc
    return Store(url, protocol, root, tuple(sorted(options.items())))
