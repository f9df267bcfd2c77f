"""Compile generated sources and load them into Python through cffi.

C: gcc compiles <prefix>.c to an object; Fortran: gfortran builds
lib<prefix>_f.so. Either way a small cffi module (templates/cffi) links it and
adds a loop over many states. Builds land in a cache directory keyed by a
hash of the sources, the flags and the tool versions, so rebuilding unchanged
sources costs nothing. An entry is trusted only when its completion marker
(MARKER, written last) matches its files; anything else is rebuilt. A failed
compiler's whole output is kept under the cache's logs/ directory.
"""

from __future__ import annotations

import errno
import hashlib
import importlib.util
import json
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from types import ModuleType
from typing import Any, Literal

import cffi
import numpy as np

from gyrogen import abi, methods
from gyrogen.abi import COMPILER_LOG_LINES
from gyrogen.codegen.render import render
from gyrogen.errors import BuildError

Language = Literal["c", "fortran"]

C_FLAGS = (
    "-std=c99",
    "-O2",
    "-fPIC",
    "-fno-math-errno",
    "-Wall",
    "-Wextra",
    "-Wpedantic",
    "-Werror",
)
FORTRAN_FLAGS = ("-std=f2008", "-O2", "-fPIC", "-fno-math-errno", "-Wall", "-Wextra", "-Werror")
_PACKAGES = {"gcc": "gcc", "gfortran": "gfortran"}

CACHE_FORMAT = "2"
"""Part of every cache key. 2: entries carry MARKER, so the entries of
earlier versions are never looked at (neither trusted nor warned about)."""
MARKER = "complete.json"
"""Written last into a cache entry: the SHA-256 of each shared object in it.
An entry without it, or whose files do not match it, is rebuilt."""


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


def require(tool: str) -> str:
    path = shutil.which(tool)
    if path is None:
        pkg = _PACKAGES.get(tool, tool)
        raise BuildError(f"{tool} not found: install it with `apt-get install -y {pkg}`")
    return path


@dataclass(frozen=True)
class Compiled:
    """One backend loaded in this process: setup and rhs on numpy arrays."""

    language: Language
    manifest: dict[str, Any]
    ffi: Any
    lib: Any

    @property
    def nx(self) -> int:
        return int(self.manifest["nx"])

    @property
    def nc(self) -> int:
        return int(self.manifest["nc"])

    def symbol(self, name: str) -> str:
        """The exported name of a function: setup, rhs, jac, an output or an
        integrator (rk4, dop853_batch, ...), as the manifest lists it."""
        return str(self.manifest["functions"][self.language][name])

    def function(self, name: str) -> Any:
        """That function, callable through cffi."""
        return getattr(self.lib, self.symbol(name))

    def setup_code(self, p: np.ndarray) -> tuple[int, np.ndarray]:
        p = np.ascontiguousarray(p, dtype=np.float64)
        c = np.zeros(self.nc)
        fn = self.function("setup")
        code = fn(self.ffi.from_buffer("double[]", p), self.ffi.from_buffer("double[]", c))
        return int(code), c

    def setup(self, p: np.ndarray) -> np.ndarray:
        code, c = self.setup_code(p)
        if code != 0:
            why = self.manifest["setup_codes"][str(code)]
            raise ValueError(f"setup refused the parameters (code {code}): {why}")
        return c

    def output(self, name: str, x: np.ndarray, c: np.ndarray, t: float = 0.0) -> np.ndarray:
        """An output function (kinetic_energy, angular_momentum, power) for a
        batch of states (n, nx): shape (n, size)."""
        return self._apply(name, int(self.manifest["outputs"][name]), x, c, t)

    def jacobian(self, x: np.ndarray, c: np.ndarray, t: float = 0.0) -> np.ndarray:
        """d(dx/dt)/dx at one state: shape (nx, nx) (scenes with rodas4)."""
        if "jac" not in self.manifest["functions"][self.language]:
            raise BuildError(f"scene {self.manifest['prefix']} has no Jacobian (add rodas4)")
        return self._apply("jac", self.nx * self.nx, x, c, t).reshape(self.nx, self.nx)

    def _apply(self, name: str, size: int, x: np.ndarray, c: np.ndarray, t: float) -> np.ndarray:
        x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, self.nx)
        out = np.empty((x.shape[0], size))
        fn = self.ffi.addressof(self.lib, self.symbol(name))
        self.lib.gyrogen_batch(
            fn,
            x.shape[0],
            size,
            t,
            self.ffi.from_buffer("double[]", x),
            self.ffi.from_buffer("double[]", np.ascontiguousarray(c, dtype=np.float64)),
            self.ffi.from_buffer("double[]", out),
        )
        return out

    def rhs(self, x: np.ndarray, c: np.ndarray, t: float = 0.0) -> np.ndarray:
        """dx/dt for a batch of states x (n, nx) or one state (nx,)."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        out = np.empty_like(x)
        n = x.size // self.nx
        self.lib.gyrogen_rhs_batch(
            n,
            t,
            self.ffi.from_buffer("double[]", x),
            self.ffi.from_buffer("double[]", np.ascontiguousarray(c, dtype=np.float64)),
            self.ffi.from_buffer("double[]", out),
        )
        return out

    def integrate(
        self,
        method: str,
        x0: np.ndarray,
        c: np.ndarray,
        t0: float,
        t1: float,
        *,
        rtol: float = 1e-8,
        atol: float = 1e-8,
        h0: float = 0.0,
        max_steps: int = 10**7,
        steps: int | None = None,
    ) -> tuple[np.ndarray, dict[str, float | int], int]:
        """One compiled integration of x0 (nx,) from t0 to t1: the final state
        (the last good one on failure), the statistics (abi.STATS_FIELDS) and the
        return code (abi.ODE_CODES). rk4 takes `steps`; the others rtol, atol, h0
        (<= 0: automatic) and max_steps."""
        x, stats, codes = self.integrate_batch(
            method, np.reshape(x0, (1, -1)), c, t0, t1,
            rtol=rtol, atol=atol, h0=h0, max_steps=max_steps, steps=steps,
        )  # fmt: skip
        fields = (f.name for f in abi.STATS_FIELDS)
        return x[0], {name: stats[name][0].item() for name in fields}, int(codes[0])

    def integrate_batch(
        self,
        method: str,
        x0s: np.ndarray,
        c: np.ndarray,
        t0: float,
        t1: float,
        *,
        rtol: float = 1e-8,
        atol: float = 1e-8,
        h0: float = 0.0,
        max_steps: int = 10**7,
        steps: int | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """integrate() for many initial states (n, nx) in one compiled call:
        final states (n, nx), statistics as a structured array (n,) with the
        fields of abi.STATS_FIELDS, and return codes (n,)."""
        if method not in self.manifest["integrators"]:
            raise ValueError(
                f"no integrator {method!r} in this build "
                f"(scene integrators: {', '.join(self.manifest['integrators'])})"
            )
        fixed = methods.get(method).fixed_step
        if (steps is None) == fixed:
            raise ValueError(
                f"{method}: steps= goes with the fixed-step methods, and only with them"
            )
        x = np.array(x0s, dtype=np.float64, order="C", ndmin=2)  # a copy: integrated in place
        if x.ndim != 2 or x.shape[1] != self.nx:
            raise ValueError(f"initial states must have shape (n, {self.nx}), not {x.shape}")
        n = x.shape[0]
        stats = np.zeros(n, dtype=self._stats_dtype)
        codes = np.zeros(n, dtype=np.intc)
        fn = self.function(f"{method}_batch")
        tail = (
            self.ffi.from_buffer("double[]", x),
            self.ffi.from_buffer("double[]", np.ascontiguousarray(c, dtype=np.float64)),
        )
        tolerances = (rtol, atol, h0, max_steps)
        args: tuple[Any, ...] = (
            (n, t0, t1, steps, *tail) if fixed else (n, t0, t1, *tail, *tolerances)
        )
        fn(
            *args,
            self.ffi.from_buffer("gyrogen_stats[]", stats),
            self.ffi.from_buffer("int[]", codes),
        )
        return x, stats, codes

    @cached_property
    def _stats_dtype(self) -> np.dtype:
        """gyrogen_stats as numpy sees it, offsets and size from cffi."""
        long = f"i{self.ffi.sizeof('long')}"
        fields = abi.STATS_FIELDS
        return np.dtype(
            {
                "names": [f.name for f in fields],
                "formats": ["f8" if f.ctype == "double" else long for f in fields],
                "offsets": [self.ffi.offsetof("gyrogen_stats", f.name) for f in fields],
                "itemsize": self.ffi.sizeof("gyrogen_stats"),
            }
        )


def _tool_version(tool: str) -> str:
    out = subprocess.run([tool, "--version"], capture_output=True, text=True, check=False)
    return out.stdout.splitlines()[0] if out.stdout else tool


def _key(language: Language, sources: list[Path], glue: str, cdef: str) -> str:
    h = hashlib.sha256()
    tool = "gcc" if language == "c" else "gfortran"
    flags = C_FLAGS if language == "c" else FORTRAN_FLAGS
    parts = (CACHE_FORMAT, language, _tool_version(tool), " ".join(flags), glue, cdef, sys.version)
    for part in parts:
        h.update(part.encode() + b"\0")
    h.update(cffi.__version__.encode())
    for src in sources:
        h.update(src.name.encode() + b"\0" + src.read_bytes() + b"\0")
    return h.hexdigest()[:20]


@dataclass(frozen=True)
class _Plan:
    """What one build compiles, and the cache key that names it."""

    language: Language
    manifest: dict[str, Any]
    sources: list[Path]
    glue: str
    cdef: str
    key: str
    cc: str

    @property
    def module_name(self) -> str:
        return f"_gyrogen_{self.manifest['prefix']}_{self.language}_{self.key}"


class _Damaged(BuildError):
    """A cache entry that is not whole or does not load: why."""


_LOADED: dict[str, ModuleType] = {}


def build(source_dir: Path, language: Language) -> Compiled:
    """Compile (or fetch from the cache) and load one backend of the
    generated sources in source_dir (which holds manifest.json)."""
    plan = _plan(Path(source_dir), language)
    module = _fetch(plan, cache_dir() / plan.key)
    return Compiled(language, plan.manifest, module.ffi, module.lib)


def _plan(source_dir: Path, language: Language) -> _Plan:
    manifest_path = source_dir / "manifest.json"
    if not manifest_path.is_file():
        raise BuildError(f"no manifest.json in {source_dir}: run `gyrogen generate` first")
    manifest = json.loads(manifest_path.read_text())
    prefix = manifest["prefix"]
    names = manifest["functions"][language]
    tool = require("gcc")
    if language == "fortran":
        require("gfortran")
    if language not in manifest["targets"]:
        raise BuildError(
            f"scene {prefix} has no {language} target (targets: {manifest['targets']})"
        )
    files = manifest["files"]
    wanted = ["c_header", "c_source", "c_ode_header", "c_ode_source"]
    if language == "fortran":
        wanted = ["fortran", "fortran_ode"]  # in this order: the second uses the first
    sources = [source_dir / files[k] for k in wanted if k in files]
    per_call = ["rhs", *manifest["outputs"]]
    if "jac" in names:
        per_call.append("jac")
    ctx = {
        "prefix": prefix,
        "setup": names["setup"],
        "functions": [names[f] for f in per_call],
        "methods": [
            (m, names[m], names[f"{m}_batch"], methods.get(m).fixed_step)
            for m in manifest["integrators"]
        ],
        "abi": abi,
        "nx": manifest["nx"],
    }
    glue = render("cffi/glue.c.jinja", **ctx)
    cdef = render("cffi/cdef.h.jinja", **ctx)
    key = _key(language, sources, glue, cdef)
    return _Plan(language, manifest, sources, glue, cdef, key, tool)


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


def _fetch(plan: _Plan, entry: Path) -> ModuleType:
    """The module of the plan from its cache entry, built first if the
    entry is missing. A damaged entry (a build cut short, a file truncated or
    removed since, a module that does not load) is rebuilt, with a warning."""
    if not os.path.lexists(entry):
        _compile(plan, entry)
    try:
        return _load(plan.module_name, entry)
    except _Damaged as exc:
        print(f"gyrogen: warning: rebuilding cache entry {entry}: {exc}", file=sys.stderr)
    _discard(entry)
    _compile(plan, entry)
    return _load(plan.module_name, entry)


def _load(module_name: str, entry: Path) -> ModuleType:
    """The module from a whole entry (loaded once per process)."""
    so = _verified(entry)
    if module_name in _LOADED:
        return _LOADED[module_name]
    try:
        spec = importlib.util.spec_from_file_location(module_name, so)
        if spec is None or spec.loader is None:
            raise ImportError("not a Python extension module")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    except ImportError as exc:
        raise _Damaged(f"cannot load {so.name}: {exc}") from exc
    _LOADED[module_name] = module
    return module


def _verified(entry: Path) -> Path:
    """The module's shared object in a whole entry: its MARKER is there and
    every shared object it lists has the SHA-256 it lists."""
    try:
        marker = json.loads((entry / MARKER).read_text())
        hashes, module = dict(marker["sha256"]), str(marker["module"])
        if module not in hashes:
            raise ValueError(f"{module} is not hashed")
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise _Damaged(f"no readable {MARKER}: its build did not finish") from exc
    for name, digest in hashes.items():
        if _sha256(entry / name) != digest:
            raise _Damaged(f"{name} is missing or not as built")
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


def _compile(plan: _Plan, final: Path) -> None:
    try:
        work = Path(tempfile.mkdtemp(prefix=".build-", dir=final.parent))
    except OSError as exc:
        raise _cache_error(final.parent, exc) from exc
    try:
        _compile_in(plan, work, final)
        _seal(work, plan.module_name)
        try:
            work.rename(final)
        except OSError:  # another process built the same key first
            if not final.is_dir():
                raise
    except OSError as exc:
        raise BuildError(f"cannot build in the cache {final.parent}: {exc.strerror}") from exc
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _compile_in(plan: _Plan, work: Path, final: Path) -> None:
    """Compile the sources and the cffi module in work, to be renamed final."""
    for src in plan.sources:
        shutil.copy2(src, work / src.name)
    ffi = cffi.FFI()
    ffi.cdef(plan.cdef)
    if plan.language == "c":
        objects = []
        for src in (s for s in plan.sources if s.suffix == ".c"):
            obj = work / f"{src.stem}.o"
            _run([plan.cc, *C_FLAGS, "-c", "-o", obj.name, src.name], work, _log(final, src.name))
            objects.append(str(obj))
        ffi.set_source(plan.module_name, plan.glue, extra_objects=objects)
    else:
        lib = plan.module_name + "_f"
        gf = require("gfortran")
        names = [src.name for src in plan.sources]
        cmd = [gf, *FORTRAN_FLAGS, "-shared", "-J", ".", "-o", f"lib{lib}.so", *names]
        _run(cmd, work, _log(final, names[-1]))
        ffi.set_source(
            plan.module_name,
            plan.glue,
            libraries=[lib],
            library_dirs=[str(work)],
            runtime_library_dirs=[str(final)],
        )
    _cffi_compile(ffi, work, _log(final, "cffi"))


def _log(final: Path, what: str) -> Path:
    """Where the whole output of a failed step of the build of final is kept."""
    return final.parent / "logs" / f"{final.name}-{what}.log"


def _run(cmd: list[str], cwd: Path, log: Path) -> None:
    proc = subprocess.run(
        cmd,
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        encoding="utf-8",
        errors="replace",
        check=False,
    )
    if proc.returncode != 0:
        what = f"{Path(cmd[0]).name} failed on {cmd[-1]} (exit status {proc.returncode})"
        raise _failure(what, proc.stdout, log)


def _failure(what: str, output: str, log: Path) -> BuildError:
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


@contextmanager
def _output_to(path: Path) -> Iterator[None]:
    """File descriptors 1 and 2 (what a compiler run by setuptools writes to)
    go to path for the duration."""
    with open(path, "w") as fh:
        saved = os.dup(1), os.dup(2)
        try:
            os.dup2(fh.fileno(), 1)
            os.dup2(fh.fileno(), 2)
            yield
        finally:
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])


def _cffi_compile(ffi: cffi.FFI, work: Path, log: Path) -> None:
    """cffi runs the compiler through setuptools; keep its chatter off the
    terminal, and show the start of it when the glue does not compile."""
    chatter = work / "cffi.log"
    try:
        with _output_to(chatter):
            ffi.compile(tmpdir=str(work), verbose=False)
    except Exception as exc:
        first = (str(exc).splitlines() or [type(exc).__name__])[0]
        output = chatter.read_text(encoding="utf-8", errors="replace")
        raise _failure(f"cffi could not build the glue module ({first})", output, log) from exc
