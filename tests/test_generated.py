"""generated/ is what the generator renders today, byte for byte, and the
rendered files say what they are."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import sympy
from wide import WIDE

import gyrogen
from gyrogen.abi import PARAMETERS, STATES
from gyrogen.codegen.generate import generate
from gyrogen.runtime.scene_build import rendered_by
from gyrogen.scene import builtin_names, default, load

REPO = Path(__file__).resolve().parents[1]
CHECKED_IN = REPO / "generated" / default().name
FILES = ["gyrostat.h", "gyrostat.c", "gyrostat.f90", "gyrostat_f.h", "manifest.json"]
FILES += ["gyrostat_ode.h", "gyrostat_ode.c", "gyrostat_ode.f90"]  # the integrators
FILES += ["CMakeLists.txt", "gyrostat.mk", "gyrostatConfig.cmake.in", "gyrostat.pc.in"]  # --lib


def test_checked_in_default_scene_is_fresh(source_dir: Path) -> None:
    """Run `make generate` when this fails: a template or the generator changed."""
    assert sorted(p.name for p in CHECKED_IN.iterdir()) == sorted(FILES)
    for name in FILES:
        fresh = (source_dir / name).read_bytes()
        assert (CHECKED_IN / name).read_bytes() == fresh, (
            f"generated/{default().name}/{name} is stale"
        )


STAMP = REPO / "generated" / "RENDERED_BY"


def test_generated_is_stamped_by_the_code_that_renders_today() -> None:
    """generated/RENDERED_BY names the rendering code, sympy and the built-in
    scenes that `make generate` last rendered generated/ with: any edit to
    them since (a template, a module rendering imports, a scene file) fails
    here until generated/ is rendered again."""
    stamp = STAMP.read_text(encoding="utf-8").strip()
    assert stamp == rendered_by(map(load, builtin_names())), (
        "generated/ is stale: run `make generate`"
    )


RENDERED_IN_THE_SUITE = ("torque_free", "dual_spin", "rw3_orthogonal")
"""Besides the default scene, the built-in scenes the suite renders again and
compares byte for byte (the stamp says the rest are fresh; `make test-wide`
and `make check-generated` render them all)."""


@pytest.mark.slow
@pytest.mark.parametrize(
    "name",
    [
        n if n in RENDERED_IN_THE_SUITE else pytest.param(n, marks=WIDE)
        for n in builtin_names()
        if n != default().name
    ],
)
def test_checked_in_scene_is_fresh(name: str, tmp_path: Path) -> None:
    """Every built-in scene has its sources in generated/<scene>/, up to date."""
    generate(load(name), tmp_path, lib=True)
    checked_in = REPO / "generated" / name
    assert sorted(p.name for p in checked_in.iterdir()) == sorted(
        p.name for p in tmp_path.iterdir()
    )
    for fresh in tmp_path.iterdir():
        assert (checked_in / fresh.name).read_bytes() == fresh.read_bytes(), (
            f"generated/{name}/{fresh.name} is stale: run `make generate`"
        )


def test_generated_holds_only_builtin_scenes() -> None:
    held = sorted(p.name for p in (REPO / "generated").iterdir() if p != STAMP)
    assert held == sorted(builtin_names())


def test_generation_is_deterministic(tmp_path: Path, source_dir: Path) -> None:
    generate(default(), tmp_path / "again", lib=True)
    for name in FILES:
        assert (tmp_path / "again" / name).read_bytes() == (source_dir / name).read_bytes()


def test_no_absolute_paths_or_timestamps(source_dir: Path) -> None:
    for name in FILES:
        text = (source_dir / name).read_text()
        assert str(source_dir) not in text and str(REPO) not in text
        assert "2026" not in text and "UTC" not in text


def test_preambles(source_dir: Path) -> None:
    manifest = json.loads((source_dir / "manifest.json").read_text())
    ops = manifest["ops"]
    for name, template in [
        ("gyrostat.h", "c/header.h.jinja"),
        ("gyrostat.c", "c/source.c.jinja"),
        ("gyrostat.f90", "fortran/module.f90.jinja"),
    ]:
        head = "\n".join((source_dir / name).read_text().splitlines()[:16])
        assert template in head
        assert "Do not edit" in head
        assert f"{ops['setup']} ops" in head and f"{ops['rhs']} ops" in head


def test_header_interface(source_dir: Path) -> None:
    h = (source_dir / "gyrostat.h").read_text()
    assert "#define GYROSTAT_NX 14" in h
    assert "#define GYROSTAT_NP 12" in h
    assert "#define GYROSTAT_NC " in h
    assert "int  gyrostat_setup(const double *p, double *c);" in h
    assert "void gyrostat_rhs(double t, const double *x, const double *c, double *dxdt);" in h
    assert 'extern "C"' in h
    for i, name in enumerate(STATES):
        assert f"x[{i:2d}]  {name}" in h
    for j, name in enumerate(PARAMETERS):
        assert f"p[{j:2d}]  {name}" in h


def test_fortran_interface(source_dir: Path) -> None:
    f = (source_dir / "gyrostat.f90").read_text()
    assert 'bind(C, name="gyrostat_f_setup")' in f
    assert 'bind(C, name="gyrostat_f_rhs")' in f
    assert "use, intrinsic :: iso_c_binding" in f
    assert max(len(line) for line in f.splitlines()) <= 132


def test_manifest(source_dir: Path) -> None:
    m = json.loads((source_dir / "manifest.json").read_text())
    assert m["prefix"] == "gyrostat"
    assert m["states"] == list(STATES)
    assert m["parameters"] == list(PARAMETERS)
    assert (m["nx"], m["np"]) == (14, 12)
    assert m["nc"] > 0
    methods = {f"{i}{b}": f"gyrostat_{i}{b}" for i in m["integrators"] for b in ("", "_batch")}
    grids = [f"{i}{g}" for i in m["integrators"] if i != "rk4" for g in ("_grid", "_grid_batch")]
    methods |= {g: f"gyrostat_{g}" for g in grids}  # the adaptive methods' output grids
    assert m["functions"]["c"] == {
        "setup": "gyrostat_setup",
        "rhs": "gyrostat_rhs",
        "strerror": "gyrostat_strerror",
        "jac": "gyrostat_jac",
        **methods,
        "ode_strerror": "gyrostat_ode_strerror",
    }
    assert m["functions"]["fortran"]["setup"] == "gyrostat_f_setup"
    assert m["functions"]["fortran"]["rhs"] == "gyrostat_f_rhs"
    assert m["ops"]["rhs"] <= 50 and m["ops"]["setup"] > 0
    assert m["versions"] == {"gyrogen": gyrogen.__version__, "sympy": sympy.__version__}
    assert m["setup_codes"]["0"] and len(m["setup_codes"]) == 9  # all but 8, a cluster axis
