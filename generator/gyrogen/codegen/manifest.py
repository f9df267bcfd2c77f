"""manifest.json: a generated directory described for tools and tests,
down to each function's C signature and the stats struct's layout, so that
an FFI (ctypes, say) can be driven from it alone."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from gyrogen.abi import ODE_CODES, STATS_FIELDS, Code
from gyrogen.codegen.context import SceneContext, VariationalContext
from gyrogen.methods import signature_of

FULL_MODEL = ("nx", "np", "ops")
"""What a manifest's full_model entry gives of the full model's sizes."""


def sizes(unit: SceneContext) -> dict[str, Any]:
    """A unit's sizes and op counts, as its manifest gives them."""
    return {"nx": unit.nx, "np": unit.np, "nc": unit.nc, "ops": unit.ops}


def manifest(unit: SceneContext, full: Mapping[str, Any]) -> dict[str, Any]:
    """What tools and tests read instead of parsing C; full, the sizes of the
    paper's full model (sizes of its unit, or its manifest, which holds
    them), is what the scene is compared with."""
    p = unit.prefix
    ode = bool(unit.scene.integrators)
    return {
        "prefix": p,
        "description": unit.scene.description,
        "scene": unit.scene.model_dump(mode="json"),
        "build_id": unit.build_id,
        "states": [s.name for s in unit.states],
        "parameters": [s.name for s in unit.params],
        "folded": unit.scene.folded(),
        **sizes(unit),
        "outputs": {o.name: o.size for o in unit.outputs},
        "events": [e.model_dump(mode="json") for e in unit.scene.events],
        **({"linear": linear(unit)} if unit.optimized.linear is not None else {}),
        "integrators": list(unit.scene.integrators),
        "targets": list(unit.scene.targets),
        "functions": unit.functions,
        "signatures": {
            language: {key: _signature(unit, key, name) for key, name in names.items()}
            for language, names in _exported(unit).items()
        },
        "structs": {f"{p}_stats": [{"name": f.name, "ctype": f.ctype} for f in STATS_FIELDS]}
        if ode
        else {},
        "setup_codes": _codes(unit.setup_codes),
        "ode_codes": _codes(ODE_CODES) if ode else {},
        "full_model": {key: full[key] for key in FULL_MODEL},
        "files": _files(unit),
        "versions": unit.versions,
        **({"variational": variational(unit.variational, full)} if unit.variational else {}),
    }


def variational(var: VariationalContext, full: Mapping[str, Any]) -> dict[str, Any]:
    """The augmented system's unit (<prefix>_var: y = x, then Phi's entries
    that can be nonzero), its layout: Phi's columns (the states' names when
    wrt has "state", then the parameters'), entries[r] = [row, column] of
    y[nx + r], the others 0 for all t; error: what the step control measures."""
    layout = var.layout
    return {
        **manifest(var, full),
        "wrt": list(var.base.scene.sensitivities.wrt)
        if var.base and var.base.scene.sensitivities
        else [],
        "columns": list(layout.columns),
        "entries": [list(e) for e in layout.entries],
        "nx_state": var.nx_state,
        "state_columns": layout.state_columns,
        "error": layout.error,
    }


def linear(unit: SceneContext) -> dict[str, list[str]]:
    """The linear model's inputs u and outputs y, in <prefix>_linear's order
    (an output of several values: name_1, name_2, ...), and the output
    functions y is made of, in that order."""
    y = [
        f"{o.name}_{k}" if o.size > 1 else o.name
        for o in unit.outputs
        for k in range(1, o.size + 1)
    ]
    return {"inputs": list(unit.inputs), "outputs": y, "from": [o.name for o in unit.outputs]}


def _files(unit: SceneContext) -> dict[str, str]:
    p, ode = unit.prefix, bool(unit.scene.integrators)
    files: dict[str, str] = {}
    if "c" in unit.scene.targets:
        files.update(c_header=f"{p}.h", c_source=f"{p}.c")
        if ode:
            files.update(c_ode_header=f"{p}_ode.h", c_ode_source=f"{p}_ode.c")
    if "fortran" in unit.scene.targets:
        files.update(fortran=f"{p}.f90", fortran_c_header=f"{p}_f.h")
        if ode:
            files["fortran_ode"] = f"{p}_ode.f90"
    return files


def _exported(unit: SceneContext) -> dict[str, dict[str, str]]:
    """The functions of each target the scene builds, by key: exported name."""
    names = unit.functions
    return {
        lang: {k: n for k, n in names[lang].items() if k != "module"}
        for lang in ("c", "fortran")
        if lang in unit.scene.targets
    }


def _signature(unit: SceneContext, key: str, name: str) -> dict[str, Any]:
    """One function's C declaration, and its arguments for an FFI: each
    pointer's element count ("count", times the batch's n when per_state,
    and times the grid's ntimes where per_time is given)."""
    sig = signature_of(key)
    sizes = {"nx": unit.nx, "np": unit.np, "nc": unit.nc, "out": unit.outputs_size(key)}
    sizes.update(nu=len(unit.inputs), ny=unit.ny)
    args: list[dict[str, Any]] = []
    for arg in sig.args:
        entry: dict[str, Any] = {"name": arg.name, "ctype": arg.ctype.format(prefix=unit.prefix)}
        if arg.length:
            per = ("n", "ntimes", "capacity")
            factors = [sizes[f] if f in sizes else int(f) for f in arg.length if f not in per]
            entry.update(count=math.prod(factors), per_state="n" in arg.length)
            if "ntimes" in arg.length:
                entry.update(per_time=True)
            if "capacity" in arg.length:
                entry.update(per_event=True)
        args.append(entry)
    return {"c": sig.c(name, unit.prefix), "returns": sig.returns, "args": args}


def _codes(codes: Sequence[Code]) -> dict[str, str]:
    return {str(code.value): code.message for code in codes}
