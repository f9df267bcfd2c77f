"""Render a scene's sources and manifest, and write them all or nothing."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

from gyrogen.backends import c, fortran
from gyrogen.errors import GyrogenError
from gyrogen.scene import Scene
from gyrogen.unit import Unit, make_unit


def manifest(unit: Unit) -> dict[str, Any]:
    """What tools and tests read instead of parsing C."""
    p = unit.prefix
    return {
        "prefix": p,
        "description": unit.scene.description,
        "states": [s.name for s in unit.states],
        "parameters": [s.name for s in unit.params],
        "nx": unit.nx,
        "np": unit.np,
        "nc": unit.nc,
        "functions": unit.functions,
        "signatures": {
            "setup": "int setup(const double *p, double *c)",
            "rhs": "void rhs(double t, const double *x, const double *c, double *dxdt)",
        },
        "setup_codes": {str(code.value): code.doc for code in unit.codes},
        "ops": unit.ops,
        "files": {
            "c_header": f"{p}.h",
            "c_source": f"{p}.c",
            "fortran": f"{p}.f90",
        },
        "versions": unit.versions,
    }


def render_all(unit: Unit) -> dict[str, str]:
    files = {**c.files(unit), **fortran.files(unit)}
    files["manifest.json"] = json.dumps(manifest(unit), indent=2, sort_keys=True) + "\n"
    return files


def write_atomic(out: Path, files: dict[str, str]) -> None:
    """Every file goes to a temporary name in out, then all are renamed: a
    failure leaves out without any half-written file."""
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise GyrogenError(f"cannot create output directory {out}: {exc.strerror}") from exc
    temps: dict[str, str] = {}
    try:
        for name, text in files.items():
            fd, tmp = tempfile.mkstemp(prefix=f".{name}.", dir=out)
            temps[name] = tmp
            with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as fh:
                fh.write(text)
        for name, tmp in temps.items():
            os.replace(tmp, out / name)
    except OSError as exc:
        for tmp in temps.values():
            Path(tmp).unlink(missing_ok=True)
        raise GyrogenError(f"cannot write to {out}: {exc.strerror}") from exc


def generate(scene: Scene, out: Path) -> Unit:
    unit = make_unit(scene)
    write_atomic(out, render_all(unit))
    return unit
