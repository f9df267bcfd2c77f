"""Build files that turn a generated directory into a library.

From the directory's manifest.json: a CMakeLists.txt (the C library, the
Fortran module library when there is Fortran and the parent enables it,
usable by `add_subdirectory` or installed as a CMake package), the package's
`<prefix>Config.cmake.in` and pkg-config's `<prefix>.pc.in` that it
configures, and a Makefile fragment `<prefix>.mk` to `include`. All are
templates (templates/lib); this module only gathers their context.
"""

from __future__ import annotations

from typing import Any

from gyrogen.codegen.render import hash_comment, render
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
            "escapes": CONFIGURE_ESCAPES,
            "versions": manifest["versions"],
            # Older manifests have no build id; the preamble then omits it.
            "build_id": manifest.get("build_id"),
            # A scene may render C only; then there is no Fortran library.
            "fortran": names.get("fortran"),
            "fortran_header": names.get("fortran_c_header"),
            **_versions(manifest["versions"]["gyrogen"]),
        }
    except KeyError as exc:
        why = f"manifest.json lacks {exc}: regenerate it with `gyrogen generate`"
        raise GyrogenError(why) from exc
    # Both libraries are built around the C sources; Fortran is the extra.
    if "c_source" not in names or "c_header" not in names:
        raise GyrogenError(
            f"scene {prefix} has no C sources: the library build files need the c target"
        )
    # the scene's files, then its augmented system's (<prefix>_var, [sensitivities])
    units = [names, *([manifest["variational"]["files"]] if "variational" in manifest else [])]
    c_sources = [u[k] for u in units for k in ("c_source", "c_ode_source") if k in u]
    c_headers = [u[k] for u in units for k in ("c_header", "c_ode_header") if k in u]
    fortran = [u[k] for u in units for k in ("fortran", "fortran_ode") if k in u]  # module order
    return {
        **ctx,
        "c_source": names["c_source"],
        "c_header": names["c_header"],
        "c_sources": c_sources,
        "c_headers": c_headers,
        "fortran_sources": fortran,
    }


def _versions(gyrogen: str) -> dict[str, str]:
    """The library's version is gyrogen's; its SOVERSION the major, or
    0.minor before 1.0 (where a minor release may change the interface)."""
    major, minor = gyrogen.split(".")[:2]
    return {"version": gyrogen, "soversion": major if major != "0" else f"0.{minor}"}


CONFIGURE_ESCAPES = {"AT": "@", "CMAKEDEFINE": "cmakedefine"}
"""What configure_file acts on even in a comment of the files it configures
(the .in files: <prefix>Config.cmake.in, <prefix>.pc.in), in the order the
description's comment there is escaped: @VAR@ is substituted (a description's
@PACKAGE_INIT@ put live lines in the installed config) and a line holding
#cmakedefine becomes a live "/* #undef ... */". Each is written there as
@<MACRO>_<KEY>@, a variable CMakeLists.txt sets to the text itself;
configure_file substitutes once, so the text comes back as written."""


def configured(text: str, macro: str) -> str:
    """text as a file configure_file reads must hold it (CONFIGURE_ESCAPES)."""
    for key, literal in CONFIGURE_ESCAPES.items():
        text = text.replace(literal, f"@{macro}_{key}@")
    return text


TEMPLATES = {
    "CMakeLists.txt": "lib/CMakeLists.txt.jinja",
    "{prefix}.mk": "lib/library.mk.jinja",
    "{prefix}Config.cmake.in": "lib/Config.cmake.in.jinja",
    "{prefix}.pc.in": "lib/pc.in.jinja",
}
"""Each build file's name and its template."""


def names(prefix: str) -> set[str]:
    """The names of the files of TEMPLATES for a scene of this prefix."""
    return {pattern.format(prefix=prefix) for pattern in TEMPLATES}


def files(manifest: dict[str, Any]) -> dict[str, str]:
    """File name -> text: the files of TEMPLATES, to be written beside the
    generated sources the manifest describes."""
    ctx = _context(manifest)
    comment = hash_comment(ctx["description"])
    out = {}
    for pattern, template in TEMPLATES.items():
        name = pattern.format(prefix=ctx["prefix"])
        # The description's comment, escaped where configure_file reads it.
        text = configured(comment, ctx["macro"]) if name.endswith(".in") else comment
        out[name] = render(template, filename=name, description_comment=text, **ctx)
    return out
