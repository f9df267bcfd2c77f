"""Build files that turn a generated directory into a library.

From the directory's manifest.json: a CMakeLists.txt (static and shared C
libraries, the Fortran module library when there is Fortran, usable by
`add_subdirectory`) and a Makefile fragment `<prefix>.mk` to `include`. Both
are templates (templates/lib); this module only gathers their context.
"""

from __future__ import annotations

from typing import Any

from gyrogen.codegen.render import render
from gyrogen.errors import GyrogenError

__all__ = ["files"]


def _context(manifest: dict[str, Any]) -> dict[str, Any]:
    try:
        prefix = manifest["prefix"]
        names = manifest["files"]
        ctx = {
            "prefix": prefix,
            "macro": prefix.upper(),
            "description": manifest["description"],
            "versions": manifest["versions"],
            # Older manifests have no build id; the preamble then omits it.
            "build_id": manifest.get("build_id"),
            # A scene may render C only; then there is no Fortran library.
            "fortran": names.get("fortran"),
        }
    except KeyError as exc:
        why = f"manifest.json lacks {exc}: regenerate it with `gyrogen generate`"
        raise GyrogenError(why) from exc
    # Both libraries are built around the C sources; Fortran is the extra.
    if "c_source" not in names or "c_header" not in names:
        raise GyrogenError(
            f"scene {prefix} has no C sources: the library build files need the c target"
        )
    c_sources = [names[k] for k in ("c_source", "c_ode_source") if k in names]
    c_headers = [names[k] for k in ("c_header", "c_ode_header") if k in names]
    fortran = [names[k] for k in ("fortran", "fortran_ode") if k in names]  # module order
    return {
        **ctx,
        "c_source": names["c_source"],
        "c_header": names["c_header"],
        "c_sources": c_sources,
        "c_headers": c_headers,
        "fortran_sources": fortran,
    }


def files(manifest: dict[str, Any]) -> dict[str, str]:
    """File name -> text: `CMakeLists.txt` and `<prefix>.mk`, to be written
    beside the generated sources the manifest describes."""
    ctx = _context(manifest)
    mk = f"{ctx['prefix']}.mk"
    return {
        "CMakeLists.txt": render("lib/CMakeLists.txt.jinja", filename="CMakeLists.txt", **ctx),
        mk: render("lib/library.mk.jinja", filename=mk, **ctx),
    }
