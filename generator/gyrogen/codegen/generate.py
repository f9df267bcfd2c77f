"""Render a scene's sources and manifest, and write them all or nothing."""

from __future__ import annotations

import json
import os
import stat
import tempfile
import time
from collections.abc import Iterable, Mapping
from contextlib import suppress
from functools import cache
from pathlib import Path
from typing import Any

from gyrogen.codegen import buildfiles
from gyrogen.codegen.backends import c, fortran
from gyrogen.codegen.context import Unit, make_unit
from gyrogen.errors import GyrogenError
from gyrogen.scene import Scene
from gyrogen.scene import default as default_scene
from gyrogen.symbolic.literals import LiteralError


def manifest(unit: Unit) -> dict[str, Any]:
    """What tools and tests read instead of parsing C."""
    p = unit.prefix
    files: dict[str, str] = {}
    ode = bool(unit.scene.integrators)
    if "c" in unit.scene.targets:
        files.update(c_header=f"{p}.h", c_source=f"{p}.c")
        if ode:
            files.update(c_ode_header=f"{p}_ode.h", c_ode_source=f"{p}_ode.c")
    if "fortran" in unit.scene.targets:
        files["fortran"] = f"{p}.f90"
        if ode:
            files["fortran_ode"] = f"{p}_ode.f90"
    full = full_model_unit()
    return {
        "prefix": p,
        "description": unit.scene.description,
        "scene": unit.scene.model_dump(mode="json"),
        "build_id": unit.build_id,
        "states": [s.name for s in unit.states],
        "parameters": [s.name for s in unit.params],
        "folded": unit.scene.folded(),
        "nx": unit.nx,
        "np": unit.np,
        "nc": unit.nc,
        "outputs": {o.name: o.size for o in unit.outputs},
        "integrators": list(unit.scene.integrators),
        "targets": list(unit.scene.targets),
        "functions": unit.functions,
        "signatures": {
            "setup": "int setup(const double *p, double *c)",
            "rhs": "void rhs(double t, const double *x, const double *c, double *dxdt)",
            "outputs": "void output(double t, const double *x, const double *c, double *out)",
        },
        "setup_codes": {str(code.value): code.doc for code in unit.codes},
        "ops": unit.ops,
        "full_model": {"nx": full.nx, "np": full.np, "ops": full.ops},
        "files": files,
        "versions": unit.versions,
    }


@cache
def full_model_unit() -> Unit:
    """The paper's full model, for comparison in every manifest and table."""
    return make_unit(default_scene())


def render_all(unit: Unit, lib: bool = False) -> dict[str, str]:
    """Every file of the scene; with lib, also CMakeLists.txt and <prefix>.mk."""
    files: dict[str, str] = {}
    if "c" in unit.scene.targets:
        files.update(c.files(unit))
    if "fortran" in unit.scene.targets:
        files.update(fortran.files(unit))
    data = manifest(unit)
    files["manifest.json"] = json.dumps(data, indent=2, sort_keys=True) + "\n"
    if lib:
        files.update(buildfiles.files(data))
    return files


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


def make_dir(out: Path) -> None:
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise GyrogenError(f"cannot create output directory {out}: {exc.strerror}") from exc


def write_atomic(out: Path, files: Mapping[str, str | bytes]) -> None:
    """Write every file into out, or none. A target that is not a regular
    file (a directory, a FIFO) is refused before anything is written. Each
    file goes to a temporary name in out first, with the mode open() would
    give it (NEW_FILE_MODE less the umask); then each target's old version is
    moved aside to a temporary name and the new one renamed in. A failure
    anywhere (a full disk, a refused rename, an interrupt) puts every old
    version back and removes the new files. Text is UTF-8 as written."""
    make_dir(out)
    targets = can_write(out, files)
    staged: dict[Path, Path] = {}
    saved: dict[Path, Path] = {}
    placed: list[Path] = []
    current = out
    try:
        for name, data in files.items():
            current = targets[name]
            staged[current] = _stage(current, data)
        for target, tmp in staged.items():
            current = target
            if os.path.lexists(target):
                saved[target] = _move_aside(target)
            os.replace(tmp, target)
            placed.append(target)
    except BaseException as exc:
        _roll_back(placed, saved)
        _remove(staged.values())
        if isinstance(exc, OSError):
            raise GyrogenError(f"cannot write {current}: {exc.strerror or exc}") from exc
        raise
    _remove(saved.values())


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


CHECK_STATES = 200
CHECK_PARAMS = 5
CHECK_ILL = 2
"""What `gyrogen generate` compares before it writes: states x parameter
sets (well-conditioned, ill-conditioned), as `gyrogen verify` does in full."""


def check(unit: Unit, files: Mapping[str, str]) -> float:
    """Compile every target in files (C with the strict flags, Fortran with
    -std=f2008 -Werror) and compare the rhs, outputs and Jacobian with the
    numpy reference; raise GyrogenError naming the scene and what differs.
    Returns the seconds it took."""
    from gyrogen.oracle import compare
    from gyrogen.runtime import build

    t0 = time.perf_counter()
    name = unit.scene.name
    with tempfile.TemporaryDirectory(prefix="gyrogen-check-") as tmp:
        for file, text in files.items():
            (Path(tmp) / file).write_text(text, encoding="utf-8")
        try:
            backends = [build.build(Path(tmp), lang) for lang in unit.scene.targets]
        except GyrogenError as exc:
            raise GyrogenError(f"{name}: generated code that does not compile: {exc}") from exc
        given = compare.given_parameters(unit.scene)
        report = compare.compare(
            backends, unit.scene, CHECK_STATES, CHECK_PARAMS, CHECK_ILL, seed=0, given=given
        )
    if report.refusal_failures:
        raise GyrogenError(f"{name}: the generated setup differs: {report.refusal_failures[0]}")
    failed = [r for r in report.rows if not r.passed]
    if failed:
        r = max(failed, key=lambda r: r.error / r.bar)
        raise GyrogenError(
            f"{name}: the generated code differs from the reference: {r.pair}, error "
            f"{r.error:.2e} above {r.bar:.2e} (cond {r.worst_condition:.3g})"
        )
    return time.perf_counter() - t0


def unit_of(scene: Scene) -> Unit:
    """The scene's unit; the default scene's is the full model every
    manifest compares with: built once."""
    if scene == default_scene():
        return full_model_unit()
    try:
        return make_unit(scene)
    except LiteralError as exc:
        raise LiteralError(f"{scene.name}: {exc}") from exc


def generate(scene: Scene, out: Path, lib: bool = False, checked: bool = False) -> Unit:
    """Render the scene into out, all or nothing; with checked, first compile
    and compare what would be written (see check): a failure writes nothing."""
    unit = unit_of(scene)
    files = render_all(unit, lib)
    if checked:
        can_write(out, files)  # before the check's seconds, not after
        check(unit, files)
    write_atomic(out, files)
    return unit
