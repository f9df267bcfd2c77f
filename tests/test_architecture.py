"""The house rules of ARCHITECTURE.md: the flow runs one way (no module
imports a later stage), and no module outgrows 400 lines."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "generator" / "gyrogen"
STAGES = (
    (
        "errors",
        "abi_rotors",
        "abi",
        "limits",
        "methods",
        "tableaus",
        "physics",
        "setup_checks",
        "files",
    ),
    ("scene", "scene_rules", "scene_rotors", "sweep_values", "sweep_spec"),
    ("symbolic",),
    ("codegen",),
    ("runtime",),
    ("oracle",),
    ("analysis",),
    ("commands", "api"),
    ("cli", "__main__"),
)
"""In the order the flow runs; a module may import its own stage and earlier ones."""


def stage(module: str) -> int:
    first = module.removeprefix("gyrogen.").split(".")[0]
    return next((i for i, names in enumerate(STAGES) if first in names), -1)


def modules() -> list[Path]:
    return sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


def imports(path: Path) -> set[str]:
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("gyrogen"):
            if node.module == "gyrogen":
                found |= {f"gyrogen.{a.name}" for a in node.names if a.name != "__version__"}
            else:
                found.add(node.module)
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith("gyrogen.")}
    return found


@pytest.mark.parametrize("path", modules(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_module_imports_a_later_stage(path: Path) -> None:
    name = "gyrogen." + ".".join(path.relative_to(PACKAGE).with_suffix("").parts)
    later = [m for m in imports(path) if stage(m) > stage(name)]
    assert not later, f"{name} imports {later}"


def test_every_module_has_a_stage() -> None:
    assert all(stage("gyrogen." + p.relative_to(PACKAGE).parts[0].removesuffix(".py")) >= 0
               for p in modules() if p.name != "__init__.py" or p.parent != PACKAGE)  # fmt: skip


@pytest.mark.parametrize("path", modules(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_module_over_400_lines(path: Path) -> None:
    assert len(path.read_text().splitlines()) <= 400


def test_running_compiled_code_never_imports_sympy() -> None:
    """runtime/ and what a sweep worker imports need no sympy (it cost every
    process 0.8 s of imports): a new interpreter imports them, and sympy is
    not among its modules."""
    import subprocess
    import sys

    code = (
        "import sys, gyrogen.runtime.build, gyrogen.runtime.compiled, gyrogen.runtime.rhs, "
        "gyrogen.runtime.segment, gyrogen.analysis.sweep_engine; print('sympy' in sys.modules)"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert proc.stdout.strip() == "False", proc.stderr
