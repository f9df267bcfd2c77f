"""Compile generated sources and load them into Python through cffi.

C: gcc compiles <prefix>.c to an object; Fortran: gfortran builds
lib<prefix>_f.so. Either way a small cffi module (templates/cffi) links it and
adds a loop over many states. Builds land in the cache (runtime/cache.py)
under a key made of the sources, the flags and the tool versions, so
rebuilding unchanged sources costs nothing; a failed compiler's whole output
is kept in the cache's logs.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from gyrogen import abi
from gyrogen.codegen.render import render
from gyrogen.errors import BuildError
from gyrogen.methods import signature_of
from gyrogen.runtime import cache, flags
from gyrogen.runtime.compiled import Compiled, Language

_PACKAGES = {"gcc": "gcc", "gfortran": "gfortran"}


def require(tool: str) -> str:
    path = shutil.which(tool)
    if path is None:
        pkg = _PACKAGES.get(tool, tool)
        raise BuildError(f"{tool} not found: install it with `apt-get install -y {pkg}`")
    return path


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
    flags: tuple[str, ...]

    @property
    def module_name(self) -> str:
        return f"_gyrogen_{self.manifest['prefix']}_{self.language}_{self.key}"


def build(
    source_dir: Path, language: Language, portable: bool = False, halt: Halt | None = None
) -> Compiled:
    """Compile (or fetch from the cache) and load one backend of the
    generated sources in source_dir (which holds manifest.json); portable:
    for any CPU of the architecture (runtime/flags.py), whatever the
    environment says. halt: once set, the compiler running is ended and the
    build raises Stopped (another thread's Ctrl-C: build_dir)."""
    plan = _plan(Path(source_dir), language, portable)
    entry = cache.cache_dir() / plan.key
    module = cache.fetch(
        plan.module_name, entry, lambda work, final: _compile(plan, work, final, halt)
    )
    return Compiled(language, plan.manifest, module.ffi, module.lib)


def _plan(source_dir: Path, language: Language, portable: bool = False) -> _Plan:
    manifest_path = source_dir / "manifest.json"
    if not manifest_path.is_file():
        raise BuildError(f"no manifest.json in {source_dir}: run `gyrogen generate` first")
    manifest = json.loads(manifest_path.read_text())
    tool = require("gcc")
    if language == "fortran":
        require("gfortran")
    if language not in manifest["targets"]:
        raise BuildError(
            f"scene {manifest['prefix']} has no {language} target (targets: {manifest['targets']})"
        )
    wanted = ["c_header", "c_source", "c_ode_header", "c_ode_source"]
    if language == "fortran":
        wanted = ["fortran", "fortran_ode"]  # in this order: the second uses the first
    units = [manifest, *([manifest["variational"]] if "variational" in manifest else [])]
    sources = [source_dir / u["files"][k] for u in units for k in wanted if k in u["files"]]
    ctx = _glue_context(manifest, language)
    glue = render("cffi/glue.c.jinja", **ctx)
    cdef = render("cffi/cdef.h.jinja", **ctx)
    used = flags.flags_for(language, portable)
    key = _key(language, sources, glue, cdef, used)
    return _Plan(language, manifest, sources, glue, cdef, key, tool, used)


def _glue_context(manifest: dict[str, Any], language: Language) -> dict[str, Any]:
    """What the cffi templates print: the setup, the per-call functions and
    the integrators of the build, by their exported names and signatures."""
    names = manifest["functions"][language]
    per_call = ["rhs", *manifest["outputs"], *(["events"] if manifest.get("events") else [])]
    if "jac" in names:
        per_call.append("jac")
    linear = ["linear"] if "linear" in names else []
    declared = ["setup", *per_call, *linear, *_integrators(manifest["integrators"], names)]
    var = manifest.get("variational")
    augmented = []  # the augmented system's rhs and integrators (<prefix>_var_*)
    if var is not None:
        var_names = var["functions"][language]
        keys = ["rhs", *_integrators(var["integrators"], var_names)]
        augmented = [(signature_of(k), var_names[k]) for k in keys]
    return {
        "functions": [names[f] for f in per_call],
        "declared": [(signature_of(k), names[k]) for k in declared] + augmented,
        "methods": manifest["integrators"],
        "abi": abi,
        "nx": manifest["nx"],
    }


def _integrators(methods: list[str], names: dict[str, str]) -> list[str]:
    """Each method's functions a unit exports: the plain call, _batch, and
    the output grid's (_grid, _grid_batch, _events, _events_batch) where it
    has them."""
    grids = ("_grid", "_grid_batch", "_events", "_events_batch")
    return [n for m in methods
            for n in (m, f"{m}_batch", *(m + g for g in grids if m + g in names))]  # fmt: skip


def _tool_version(tool: str) -> str:
    out = subprocess.run([tool, "--version"], capture_output=True, text=True, check=False)
    return out.stdout.splitlines()[0] if out.stdout else tool


def _key(
    language: Language, sources: list[Path], glue: str, cdef: str, used: tuple[str, ...]
) -> str:
    tool = "gcc" if language == "c" else "gfortran"
    return cache.entry_key((language, _tool_version(tool), " ".join(used), glue, cdef), sources)


def _compile(plan: _Plan, work: Path, final: Path, halt: Halt | None = None) -> None:
    """Compile the sources and the cffi module in work, to be renamed final."""
    for src in plan.sources:
        shutil.copy2(src, work / src.name)
    if plan.language == "c":
        sources = [s for s in plan.sources if s.suffix == ".c"]
        jobs = [([plan.cc, *plan.flags, "-c", "-o", f"{s.stem}.o", s.name],
                 cache.log_path(final, s.name)) for s in sources]  # fmt: skip
        _run_all(jobs, work, halt)
        options = {"extra_objects": [str(work / f"{s.stem}.o") for s in sources],
                   **_glue_args()}  # fmt: skip
    else:
        lib = plan.module_name + "_f"
        gf = require("gfortran")
        names = [src.name for src in plan.sources]
        cmd = [gf, *plan.flags, "-shared", "-J", ".", "-o", f"lib{lib}.so", *names]
        _run(cmd, work, cache.log_path(final, names[-1]), halt)
        options = {
            "libraries": [lib],
            "library_dirs": [str(work)],
            "runtime_library_dirs": [str(final)],
            **_glue_args(),
        }
    _cffi_compile(plan, options, work, cache.log_path(final, "cffi"), halt)


GLUE_FLAGS = ("-g0", "-O1")
"""After Python's CFLAGS (-g -O3): the glue is cffi's wrappers and loops
that call the generated functions in other objects (nothing to inline or
vectorize), and debugging information and -O3 were two thirds of its
compile (cmg4_pyramid's: 1.9 s against 0.7 s)."""


def _glue_args() -> dict[str, list[str]]:
    """The glue's flags: GLUE_FLAGS, and -fopenmp when the C compiler has
    OpenMP, so that it links the runtime and can set the thread count
    (gyrogen_threads)."""
    if not flags.openmp("gcc", "c"):
        return {"extra_compile_args": list(GLUE_FLAGS)}
    return {"extra_compile_args": [*GLUE_FLAGS, flags.OPENMP], "extra_link_args": [flags.OPENMP]}


Halt = threading.Event
"""Set: stop building (build_dir's main thread was interrupted)."""
POLL = 0.1
"""Seconds between a running compiler's looks at its Halt."""


class Stopped(BuildError):
    """A build ended by its Halt: nothing failed, nothing to report."""


def _child(
    cmd: list[str],
    cwd: Path | None,
    out: int | IO[str],
    halt: Halt | None,
    given: str | None = None,
) -> tuple[int, str]:
    """cmd's exit status and output (out: PIPE for it, or a file), given on
    its stdin; killed with what it started (a compiler driver's cc1 and as:
    a process group of its own) if anything interrupts the wait, and
    Stopped raised once halt is set."""
    if halt is not None and halt.is_set():
        raise Stopped(f"stopped before {Path(cmd[0]).name}")
    stdin = subprocess.PIPE if given is not None else None
    proc = subprocess.Popen(cmd, cwd=cwd, stdin=stdin, stdout=out, stderr=subprocess.STDOUT,
                            encoding="utf-8", errors="replace", process_group=0)  # fmt: skip
    try:
        while True:
            try:
                output, _ = proc.communicate(given, timeout=None if halt is None else POLL)
                return proc.returncode, output or ""
            except subprocess.TimeoutExpired:
                given = None  # written already: communicate goes on where it was
                if halt is not None and halt.is_set():
                    raise Stopped(f"stopped {Path(cmd[0]).name}") from None
    finally:
        if proc.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()


def _run(cmd: list[str], cwd: Path, log: Path, halt: Halt | None = None) -> None:
    code, output = _child(cmd, cwd, subprocess.PIPE, halt)
    if code != 0:
        what = f"{Path(cmd[0]).name} failed on {cmd[-1]} (exit status {code})"
        raise cache.failure(what, output, log)


def _run_all(jobs: list[tuple[list[str], Path]], cwd: Path, halt: Halt | None = None) -> None:
    """Each (command, log) run at once, each in a thread: a C build's objects
    (the integrators' file takes most of the time; the model's compiles
    beside it). The first to fail ends the others and is raised, as is
    Stopped once halt is set."""
    if len(jobs) < 2:
        for cmd, log in jobs:
            _run(cmd, cwd, log, halt)
        return
    mine = Halt()  # set: every compiler of these ends
    with ThreadPoolExecutor(len(jobs)) as pool:
        futures = [pool.submit(_run, cmd, cwd, log, mine) for cmd, log in jobs]
        try:
            pending = set(futures)
            while pending and not (halt is not None and halt.is_set()):
                _, pending = wait(pending, timeout=POLL, return_when=FIRST_EXCEPTION)
                if any(f.done() and f.exception() is not None for f in futures):
                    break
        finally:
            mine.set()  # none is left running when this returns or raises
    failed = [f.exception() for f in futures if f.done() and f.exception() is not None]
    first = next((e for e in failed if not isinstance(e, Stopped)), None)
    if first is not None:
        raise first
    if halt is not None and halt.is_set():
        raise Stopped("stopped the C compilers")


_CFFI_COMPILE = """
import json, sys, cffi
a = json.load(sys.stdin)
ffi = cffi.FFI()
ffi.cdef(a["cdef"])
ffi.set_source(a["module"], a["glue"], **a["options"])
ffi.compile(tmpdir=a["tmpdir"], verbose=False)
"""
"""cffi's compile, run in a Python of its own: it changes the working
directory (setuptools runs the compiler from tmpdir), which in this process
would move every relative path under the feet of the other language's
build (build_dir builds them at once)."""


def _cffi_compile(
    plan: _Plan, options: dict[str, list[str]], work: Path, log: Path, halt: Halt | None = None
) -> None:
    """cffi runs the compiler through setuptools, in another process; keep
    its chatter off the terminal, and show the start of it when the glue
    does not compile."""
    chatter = work / "cffi.log"
    job = {"cdef": plan.cdef, "module": plan.module_name, "glue": plan.glue,
           "options": options, "tmpdir": str(work)}  # fmt: skip
    with open(chatter, "w") as out:
        code, _ = _child([sys.executable, "-c", _CFFI_COMPILE], None, out, halt, json.dumps(job))
    if code != 0:
        output = chatter.read_text(encoding="utf-8", errors="replace")
        lines = [line for line in output.splitlines() if line.strip()]
        first = lines[-1] if lines else f"exit status {code}"
        raise cache.failure(f"cffi could not build the glue module ({first})", output, log)
