"""What the user wants to generate. The foundation knows one scene: the
paper's full model with every parameter supplied at run time."""

from __future__ import annotations

import keyword
import re
from dataclasses import dataclass

from gyrogen.errors import GyrogenError

_C_KEYWORDS = frozenset(
    (
        "auto break case char const continue default do double else enum extern float for "
        "goto if inline int long register restrict return short signed sizeof static struct "
        "switch typedef union unsigned void volatile while _Bool _Complex _Imaginary"
    ).split()
)


@dataclass(frozen=True)
class Scene:
    name: str
    """Also the prefix of every generated C symbol and file."""
    description: str

    def __post_init__(self) -> None:
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", self.name):
            raise GyrogenError(f"scene name {self.name!r} is not a valid C identifier")
        if self.name in _C_KEYWORDS or keyword.iskeyword(self.name):
            raise GyrogenError(f"scene name {self.name!r} is a reserved word")


DEFAULT = Scene(
    name="gyrostat",
    description="the paper's full model: 14 states, all 12 parameters at run time",
)
