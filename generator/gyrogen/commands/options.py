"""What several commands share: the scene argument, output options, the
types of number options (each with its range), progress."""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, TypeVar

import click

from gyrogen.abi import MAX_PARAMETER_SETS, MAX_STATES
from gyrogen.scene import Scene, load

F = TypeVar("F", bound=Callable[..., Any])


class SceneType(click.ParamType):
    """A built-in scene name or a path to a .toml file."""

    name = "SCENE"

    def convert(self, value: Any, param: Any, ctx: Any) -> Scene:
        return value if isinstance(value, Scene) else load(str(value))


SCENE = SceneType()


class FiniteFloat(click.FloatRange):
    """A FloatRange that also refuses nan and inf (click's lets nan through
    every bound, and inf through an open one)."""

    def convert(self, value: Any, param: Any, ctx: Any) -> float:
        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number.", param, ctx)
        return float(number)


POSITIVE = FiniteFloat(min=0.0, min_open=True)
"""A finite number > 0."""

out_dir = click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Directory for the scene's sources and manifest.json [default: generated/<scene>].",
)


def default_out(scene: Scene) -> Path:
    return Path("generated") / scene.name


def verify_options(f: F) -> F:
    for opt in reversed(
        [
            click.option(
                "--states",
                type=click.IntRange(1, MAX_STATES),
                default=10_000,
                show_default=True,
                help="Random states.",
            ),
            click.option(
                "--params",
                type=click.IntRange(1, MAX_PARAMETER_SETS),
                default=100,
                show_default=True,
                help="Random parameter sets.",
            ),
            click.option(
                "--seed",
                type=click.IntRange(min=0),
                default=0,
                show_default=True,
                help="Random seed (numpy's: >= 0).",
            ),
        ]
    ):
        f = opt(f)
    return f


def progress(label: str, items: Iterable[Any]) -> Iterable[Any]:
    """A progress bar on stderr (just the label when stderr is not a terminal)."""
    with click.progressbar(list(items), label=label, file=sys.stderr) as bar:
        yield from bar
