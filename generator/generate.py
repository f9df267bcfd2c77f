"""Render a scene's sources and manifest, and write them all or nothing."""

from __future__ import annotations

import json
import os
import tempfile
import time
from collections.abc import Mapping
from functools import cache
from pathlib import Path
from typing import Any

from gyrogen import library
from gyrogen.backends import c, fortran
from gyrogen.errors import GyrogenError
from gyrogen.literals import LiteralError
from gyrogen.scene import Scene
from gyrogen.scene import default as default_scene
from gyrogen.unit import Unit, make_unit


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
        files.update(library.files(data))
    return files


def write_atomic(out: Path, files: Mapping[str, str | bytes]) -> None:
    """Every file goes to a temporary name in out, then all are renamed: a
    failure leaves out without any half-written file. Text is UTF-8 with
    newlines as written."""
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise GyrogenError(f"cannot create output directory {out}: {exc.strerror}") from exc
    temps: dict[str, str] = {}
    try:
        for name, text in files.items():
            fd, tmp = tempfile.mkstemp(prefix=f".{name}.", dir=out)
            temps[name] = tmp
            with os.fdopen(fd, "wb") as fh:
                fh.write(text.encode("utf-8") if isinstance(text, str) else text)
        for name, tmp in temps.items():
            os.replace(tmp, out / name)
    except OSError as exc:
        for tmp in temps.values():
            Path(tmp).unlink(missing_ok=True)
        raise GyrogenError(f"cannot write to {out}: {exc.strerror}") from exc


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
    from gyrogen import build, verify

    t0 = time.perf_counter()
    name = unit.scene.name
    with tempfile.TemporaryDirectory(prefix="gyrogen-check-") as tmp:
        for file, text in files.items():
            (Path(tmp) / file).write_text(text, encoding="utf-8")
        try:
            backends = [build.build(Path(tmp), lang) for lang in unit.scene.targets]
        except GyrogenError as exc:
            raise GyrogenError(f"{name}: generated code that does not compile: {exc}") from exc
        report = verify.compare(backends, unit.scene, CHECK_STATES, CHECK_PARAMS, CHECK_ILL, seed=0)
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
        check(unit, files)
    write_atomic(out, files)
    return unit
