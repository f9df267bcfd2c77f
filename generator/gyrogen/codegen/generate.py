"""Render a scene's sources and manifest, and write them all or nothing."""

from __future__ import annotations

import json
from collections.abc import Mapping
from functools import cache
from pathlib import Path
from typing import Any

from gyrogen.codegen import buildfiles
from gyrogen.codegen.backends import c, fortran
from gyrogen.codegen.context import SceneContext, make_context
from gyrogen.codegen.manifest import manifest, sizes
from gyrogen.files import claim, write_atomic
from gyrogen.scene import Scene
from gyrogen.scene import default as default_scene
from gyrogen.symbolic.literals import LiteralError


@cache
def full_model_unit() -> SceneContext:
    """The paper's full model, for comparison in every manifest and table."""
    return make_context(default_scene())


def render_all(
    unit: SceneContext, lib: bool = False, full: Mapping[str, Any] | None = None
) -> dict[str, str]:
    """Every file of the scene; with lib, also CMakeLists.txt and <prefix>.mk.
    full: the full model's sizes, which the manifest compares with (what
    manifest.sizes gives of it, or its manifest); derived when not given
    (runtime/scene_build.py's full_model_manifest reads them from the cache)."""
    files: dict[str, str] = {}
    var = unit.variational
    for u in (unit, *([var] if var is not None else [])):
        if "c" in unit.scene.targets:
            files.update(c.files(u))
        if "fortran" in unit.scene.targets:
            files.update(fortran.files(u))
    data = manifest(unit, sizes(full_model_unit()) if full is None else full)
    files["manifest.json"] = json.dumps(data, indent=2, sort_keys=True) + "\n"
    if lib:
        files.update(buildfiles.files(data))
    return files


UNITS_KEPT = 16
"""How many scenes' units a process keeps (the last asked for): a scene
asked for again in one process (a bench's peers after its sources were
rendered; the test suite) is derived once."""
_UNITS: dict[str, SceneContext] = {}


def unit_of(scene: Scene) -> SceneContext:
    """The scene's unit, derived once per process while it is among the
    last UNITS_KEPT asked for; the default scene's is the full model every
    manifest compares with: built once."""
    if scene == default_scene():
        return full_model_unit()
    key = scene.model_dump_json()
    unit = _UNITS.pop(key, None)
    if unit is None:
        try:
            unit = make_context(scene)
        except LiteralError as exc:
            raise LiteralError(f"{scene.name}: {exc}") from exc
    _UNITS[key] = unit  # the most recent last
    for old in list(_UNITS)[:-UNITS_KEPT]:
        _UNITS.pop(old, None)
    return unit


def generate(scene: Scene, out: Path, lib: bool = False) -> SceneContext:
    """Render the scene into out, all or nothing (gyrogen.files)."""
    claim(out, scene.name)
    unit = unit_of(scene)
    write_atomic(out, render_all(unit, lib))
    return unit
