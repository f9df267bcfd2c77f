"""manifest.json: a generated directory described for tools and tests."""

from __future__ import annotations

from typing import Any

from gyrogen.abi import SIGNATURES
from gyrogen.codegen.context import Unit


def manifest(unit: Unit, full: Unit) -> dict[str, Any]:
    """What tools and tests read instead of parsing C; full, the paper's full
    model, is what the scene is compared with (its caller derives it)."""
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
            "setup": SIGNATURES["setup"].c("setup"),
            "rhs": SIGNATURES["rhs"].c("rhs"),
            "outputs": SIGNATURES["output"].c("output"),
        },
        "setup_codes": {str(code.value): code.message for code in unit.setup_codes},
        "ops": unit.ops,
        "full_model": {"nx": full.nx, "np": full.np, "ops": full.ops},
        "files": files,
        "versions": unit.versions,
    }
