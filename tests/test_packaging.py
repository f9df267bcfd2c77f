"""The templates ship inside the wheel, so a plain `pip install .` finds them."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_wheel_contains_every_template(tmp_path: Path) -> None:
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation",
         "-w", str(tmp_path), str(REPO)],
        check=True,
        capture_output=True,
    )  # fmt: skip
    (wheel,) = tmp_path.glob("gyrogen-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    templates = REPO / "templates"
    expected = {
        f"gyrogen/templates/{p.relative_to(templates).as_posix()}"
        for p in templates.rglob("*.jinja")
    }
    assert expected and expected <= names
    assert "gyrogen/cli.py" in names and "gyrogen/backends/c.py" in names
