"""A scene's sources written for a test whose subject is what they compute,
not how they are rendered: generate's files (without --lib's), taken from
the build cache's sources/ when this gyrogen's code and sympy rendered the
same scene before (runtime/scene_build.write_scene, keyed by all three),
so that a rerun of the suite does not derive the scene again. The tests of
generate itself call codegen.generate.generate."""

from __future__ import annotations

from pathlib import Path

from gyrogen.runtime.scene_build import write_scene
from gyrogen.scene import Scene


def write_sources(scene: Scene, out: Path) -> Path:
    """scene's sources written into out, all or nothing (as generate does); out."""
    write_scene(scene, out)
    return out
