"""A scene's sources rendered into a directory, then built: what every
command that runs the generated code does first."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path

from gyrogen.codegen.context import SceneContext
from gyrogen.codegen.generate import generate
from gyrogen.runtime.build import build
from gyrogen.runtime.compiled import Compiled, Language
from gyrogen.scene import Scene


def build_scene(
    scene: Scene,
    directory: Path,
    languages: Iterable[Language],
    written: Callable[[SceneContext], None] = lambda unit: None,
) -> tuple[SceneContext, dict[Language, Compiled]]:
    """Generate scene into directory (all or nothing), call written with
    its unit, then build each language in turn (or fetch it from the
    cache): the unit and the backends by language."""
    unit = generate(scene, directory)
    written(unit)
    return unit, {language: build(directory, language) for language in languages}
