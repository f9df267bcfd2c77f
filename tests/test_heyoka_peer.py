"""heyoka, the reports' peer and quadruple-precision reference
(analysis/bench/heyoka_peer.py): its system is gyrogen's rhs, its real128
reference agrees with gyrogen's dop853, its batch with its scalar runs.
heyoka is in the test extra, so nothing here is skipped."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gyrogen.analysis.bench import heyoka_peer
from gyrogen.analysis.simulate.engine import runtime_values
from gyrogen.codegen.generate import unit_of
from gyrogen.oracle.compare import scaled_error
from gyrogen.runtime.compiled import Compiled
from gyrogen.runtime.scene_build import build_scene
from gyrogen.scene import default, load


def _scene(name: str, tmp: Path, cache: Path, mp: pytest.MonkeyPatch) -> tuple[Compiled, ...]:
    mp.setenv("GYROGEN_CACHE", str(cache))
    scene = default() if name == "gyrostat" else load(name)
    built = build_scene(scene, tmp / name, ("c",))
    unit = unit_of(scene)
    comp = built["c"]
    return comp, unit, comp.setup(runtime_values(scene)), np.array(scene.initial_state()), scene


@pytest.mark.slow
@pytest.mark.parametrize("name", ["gyrostat", "dual_spin"])
def test_heyoka_rhs_is_gyrogens(
    name: str, tmp_path: Path, cache_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """At x0 and 100 states drawn around it, to 1e-14 (scaled)."""
    comp, unit, c, x0, _ = _scene(name, tmp_path, cache_dir, monkeypatch)
    sys = heyoka_peer.system(heyoka_peer.module(), unit)
    assert sys.nx == comp.nx and sys.npars <= comp.nc
    err = heyoka_peer.rhs_difference(sys, comp.rhs, c, x0)
    assert err <= heyoka_peer.MATCH
    lines: list[str] = []
    heyoka_peer.check(sys, comp.rhs, c, x0, lines.append)
    assert lines[0].startswith("check heyoka's rhs against the compiled rhs: max difference")

    def off(xs: np.ndarray, c: np.ndarray) -> np.ndarray:
        return comp.rhs(xs, c) * (1.0 + 1e-12)

    with pytest.raises(ValueError, match="heyoka's rhs differs from the compiled rhs by"):
        heyoka_peer.check(sys, off, c, x0, lines.append)


def test_time_dependent_rhs_is_refused() -> None:
    class Unit:
        uses_time = True

    with pytest.raises(ValueError, match="depends on t"):
        heyoka_peer.system(heyoka_peer.module(), Unit())


@pytest.mark.slow
def test_quadruple_reference_and_the_integrators(
    tmp_path: Path, cache_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The real128 reference is consistent to 1e-25 with a looser run of
    itself and within 1e-10 of gyrogen's dop853 at 1e-13; heyoka's double
    integrator at 1e-14 within 1e-12 of it; its batch (width w, one partial
    batch) equals its scalar runs to 1e-12."""
    comp, unit, c, x0, scene = _scene("gyrostat", tmp_path, cache_dir, monkeypatch)
    t1 = scene.simulate.t_end
    sys = heyoka_peer.system(heyoka_peer.module(), unit)
    ref, self_check = heyoka_peer.reference(sys, x0, c, t1)
    assert self_check < 1e-25
    dop, _, code = comp.integrate("dop853", x0, c, 0.0, t1, rtol=1e-13, atol=1e-13)
    assert code == 0 and 1e-16 < scaled_error(dop, ref) < 1e-10
    one = heyoka_peer.Scalar(sys, x0, c, t1, 1e-14)
    assert one.jit > 0 and scaled_error(one.final(), ref) < 1e-12
    batch = heyoka_peer.Batch(sys, x0, c, t1, 1e-12)
    x0s = x0 * np.random.default_rng(2).uniform(0.9, 1.1, (batch.width + 3, sys.nx))
    got = batch.run(x0s, checked=True)
    assert got.shape == x0s.shape
    for x, want in zip(x0s, got, strict=True):
        single = heyoka_peer.Scalar(sys, x, c, t1, 1e-12)
        assert scaled_error(single.final(), want) < 1e-12


@pytest.mark.slow  # 2 worker processes and a JIT per tolerance
def test_ensemble_table_and_fronts(monkeypatch: pytest.MonkeyPatch, cache_dir: Path) -> None:
    """bench-ensemble's table against heyoka on 16 members and a short
    ladder: a row per level, six fronts (dop853 and taylor on 1 and 2 cores,
    heyoka on 1 and 2; taylor and heyoka on the tail too, above their
    DBL_EPSILON bound), the faster gyrogen method named, CPU / wall said,
    a real figure."""
    import io

    import matplotlib.image

    from gyrogen.analysis.bench import ensemble as ens
    from gyrogen.analysis.bench import ensemble_levels

    monkeypatch.setenv("GYROGEN_CACHE", str(cache_dir))
    monkeypatch.setattr(ens, "LADDER", (1e-5, 1e-8, 1e-11, 1e-13))
    monkeypatch.setattr(ensemble_levels, "HEYOKA_TAIL", (1e-15,))
    lines: list[str] = []
    runs = ensemble_levels.table(ens.problem(), 16, 1, lines.append)
    assert set(runs) == set(ensemble_levels.LABELS)
    assert [len(runs[k]) for k in ("g1", "g2", "t1", "t2", "h1", "h2")] == [4, 4, 5, 5, 5, 5]
    rows = [line for line in lines if line.startswith("| 1e-")]
    levels = [f"| {x:.0e}" for x in ensemble_levels.LEVELS]
    assert [r.split(" | ")[0] for r in rows] == levels + levels  # wall, then CPU
    assert all("(taylor)" in r or "(dop853)" in r or " - " in r for r in rows)
    assert "CPU time (user + system" in "\n".join(lines)
    assert "CPU / wall at the runs: g1" in lines[-1]
    img = matplotlib.image.imread(io.BytesIO(ensemble_levels.figure(runs, 16)))
    assert img.shape[:2] == (600, 1000) and float(img.std()) > 0.01


@pytest.mark.slow
@pytest.mark.parametrize("name", ["gyrostat", "dual_spin"])
def test_taylor_meets_the_quadruple_reference(
    name: str, tmp_path: Path, cache_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """gyrogen's Taylor method against heyoka's real128 reference: its
    error falls with the tolerance (within 20 tol at 1e-8 .. 1e-14). Its
    step's scale is each group's largest state (taylor.state_scales), never
    more than heyoka's largest state of all (the wheel on both scenes), so
    its steps are never longer than heyoka's at the same state: its error
    is at most twice heyoka's. Where every state stays within atol / rtol =
    1 (dual_spin with its wheel at 0.6 rad/s, 10 s) every scale is heyoka's:
    the same step rule, the same steps, the same state to rounding."""
    comp, unit, c, x0, scene = _scene(name, tmp_path, cache_dir, monkeypatch)
    t1 = scene.simulate.t_end
    sys = heyoka_peer.system(heyoka_peer.module(), unit)
    ref, _ = heyoka_peer.reference(sys, x0, c, t1)
    for tol in (1e-8, 1e-11, 1e-14):
        got, _, code = comp.integrate("taylor", x0, c, 0.0, t1, rtol=tol, atol=tol)
        theirs = heyoka_peer.Scalar(sys, x0, c, t1, tol).final()
        assert code == 0 and scaled_error(got, ref) <= 20 * tol, (tol, scaled_error(got, ref))
        mine, their = scaled_error(got, ref), scaled_error(theirs, ref)
        assert mine <= 2.0 * their + 1e-15, (tol, mine, their)
    if name == "dual_spin":
        small = x0.copy()
        small[scene.states.index("u4")] = 0.6
        for tol in (1e-8, 1e-11, 1e-14):
            got, stats, code = comp.integrate("taylor", small, c, 0.0, 10.0, rtol=tol, atol=tol)
            peer = heyoka_peer.Scalar(sys, small, c, 10.0, tol)
            assert code == 0 and stats["accepted"] == int(peer.run()[3]), tol
            assert scaled_error(got, peer.final()) <= 1e-14, tol
