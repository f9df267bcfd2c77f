"""What several commands share: the scene argument, output options, the
types of number options (each with its range), progress."""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, TypeVar

import click

from gyrogen.limits import MAX_PARAMETER_SETS, MAX_STATES
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

    def _describe_range(self) -> str:
        """'finite' without bounds (click's says 'x<=None')."""
        if self.min is None and self.max is None:
            return "finite"
        return str(super()._describe_range())

    def convert(self, value: Any, param: Any, ctx: Any) -> float:
        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number.", param, ctx)
        return float(number)


POSITIVE = FiniteFloat(min=0.0, min_open=True)
"""A finite number > 0."""


STDOUT = "-"
"""An --out of "-" is standard output (`gyrogen new --out -`), which holds no directory."""
NO_STDOUT_DIRECTORY = (
    "'-' is standard output, which cannot hold a directory: name one (./- for a directory called -)"
)


def _not_stdout(ctx: click.Context, param: click.Parameter, value: Path | None) -> Path | None:
    if value is not None and str(value) == STDOUT:
        raise click.BadParameter(NO_STDOUT_DIRECTORY, ctx, param)
    return value


def directory(flag: str, help: str) -> Callable[[F], F]:
    """An option naming a directory to write into (None when not given; not "-")."""
    return click.option(
        flag,
        type=click.Path(file_okay=False, path_type=Path),
        default=None,
        callback=_not_stdout,
        help=help,
    )


out_dir = directory(
    "--out", "Directory for the scene's sources and manifest.json [default: generated/<scene>]."
)


def default_out(scene: Scene) -> Path:
    return Path("generated") / scene.name


def _counted(flag: str, kind: click.IntRange, default: int, help: str) -> Callable[[F], F]:
    return click.option(flag, type=kind, default=default, show_default=True, help=help)


def verify_options(f: F) -> F:
    """--states, --params and --seed: how much verify compares."""
    for opt in reversed(
        [
            _counted("--states", click.IntRange(1, MAX_STATES), 10_000, "Random states."),
            _counted(
                "--params", click.IntRange(1, MAX_PARAMETER_SETS), 100, "Random parameter sets."
            ),
            _counted("--seed", click.IntRange(min=0), 0, "Random seed (numpy's: >= 0)."),
        ]
    ):
        f = opt(f)
    return f


def progress(label: str, items: Iterable[Any]) -> Iterable[Any]:
    """A progress bar on stderr (just the label when stderr is not a terminal)."""
    with click.progressbar(list(items), label=label, file=sys.stderr) as bar:
        yield from bar
