"""The lane-batched integrators: each trajectory's result does
not depend on the lane width, on the thread count or on the build's
OpenMP, bit for bit, and equals the single-trajectory call's; the codes of
failing lanes (a NaN, gimbal lock, the step budget) are theirs alone; and
the generated sin and cos keep to their documented accuracy.

The C harnesses (tests/harness/lanes.c, trig.c) are built here with gcc.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from sources import write_sources
from wide import WIDE

from gyrogen import abi
from gyrogen.runtime import flags
from gyrogen.runtime.compiled import Compiled
from gyrogen.runtime.scene_build import build_scene
from gyrogen.scene import Scene, builtin_text, load_toml, validate

pytestmark = pytest.mark.slow  # the lane-batched integrators of several scenes, compiled and run

REPO = Path(__file__).resolve().parents[1]
HARNESS = REPO / "tests" / "harness"
N = 37  # not a multiple of any lane width: the last lanes run idle
NX = 14
NAN_TRAJ, LOCKED_TRAJ = 3, 5
NONFINITE, MAX_STEPS, ATTITUDE = 3, 2, 6
FAST = [f for f in (*flags.FAST, flags.OPENMP) if flags.accepts("gcc", "c", f)]
"""A local build's optional flags at users' level (-O3, whatever the suite builds at)."""


def _laned() -> Scene:
    """The default scene with radau5's lanes asked for (`lanes = ["radau5"]`)."""
    data = load_toml(builtin_text("gyrostat"), "gyrostat")
    return validate({**data, "lanes": ["radau5"]}, "gyrostat, radau5 over lanes")


@pytest.fixture(scope="module")
def laned_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_sources(_laned(), tmp_path_factory.mktemp("laned") / "gyrostat")


@pytest.fixture(scope="module")
def laned_backend(tmp_path_factory: pytest.TempPathFactory, cache_dir: Path) -> Compiled:
    """_laned() compiled at users' level (-O3), in the run's build cache."""
    mp = pytest.MonkeyPatch()
    mp.setenv("GYROGEN_CACHE", str(cache_dir))
    mp.setenv(flags.OPT_LEVEL, "3")
    try:
        return build_scene(_laned(), tmp_path_factory.mktemp("laned-c") / "gyrostat", ["c"])["c"]
    finally:
        mp.undo()


def _build(source_dir: Path, out: Path, lanes: int, extra: list[str]) -> Path:
    cmd = ["gcc", "-std=c99", *extra, f"-DGYROSTAT_LANES={lanes}", f"-I{source_dir}",
           str(HARNESS / "lanes.c"), str(source_dir / "gyrostat.c"),
           str(source_dir / "gyrostat_ode.c"), "-o", str(out), "-lm"]  # fmt: skip
    subprocess.run(cmd, check=True, capture_output=True)
    return out


def _run(exe: Path, tmp: Path, threads: int = 1) -> tuple[bytes, bytes]:
    """(the batches' bytes, the single calls' bytes)."""
    out = tmp / f"{exe.name}-{threads}.bin"
    env = {**os.environ, "OMP_NUM_THREADS": str(threads)}
    subprocess.run([str(exe), str(N), str(out)], check=True, env=env)
    data = out.read_bytes()
    return data[: len(data) // 2], data[len(data) // 2 :]


def _stats(block: bytes, which: int, field: str) -> np.ndarray:
    """One integer field of the which-th batch's statistics in a run's bytes."""
    size = N * NX * 8 + N * 8 * len(abi.STATS_FIELDS) + N * 4
    part = block[which * size + N * NX * 8 : which * size + size - N * 4]
    names = [f.name for f in abi.STATS_FIELDS]
    return np.frombuffer(part, dtype=np.int64).reshape(N, len(names))[:, names.index(field)]


def _codes(block: bytes, which: int) -> np.ndarray:
    """The codes of the which-th batch in a run's bytes."""
    size = N * NX * 8 + N * 8 * len(abi.STATS_FIELDS) + N * 4
    part = block[which * size : (which + 1) * size]
    return np.frombuffer(part[-N * 4 :], dtype=np.int32)


@pytest.mark.parametrize("sources", ["default", "radau5 laned"])
@pytest.mark.parametrize("build", ["fast", "portable"])
@WIDE
def test_results_do_not_depend_on_lanes_or_threads(
    request: pytest.FixtureRequest, tmp_path: Path, build: str, sources: str
) -> None:
    """One build's flags (this machine's fast ones with OpenMP, or plain
    -O2): lane widths 1, 4 and 8, one and two threads, every batch equal to
    the single-trajectory calls, bit for bit; stats and codes included. The
    default scene's sources (radau5's batch: a loop of its calls) and those
    that ask for radau5's lanes (its batch over lanes, struct lanes on the
    heap)."""
    source_dir = request.getfixturevalue("source_dir" if sources == "default" else "laned_dir")
    extra = FAST if build == "fast" else ["-O2"]
    runs = []
    for lanes in (1, 4, 8):
        exe = _build(source_dir, tmp_path / f"lanes{lanes}", lanes, extra)
        runs += [_run(exe, tmp_path, threads) for threads in (1, 2)]
    batch, single = runs[0]
    assert batch == single
    for other in runs[1:]:
        assert other == (batch, single)
    dop853, budget, rk4 = _codes(batch, 0), _codes(batch, 1), _codes(batch, 3)
    assert dop853[NAN_TRAJ] == NONFINITE and np.count_nonzero(dop853) == 1
    assert set(budget) == {0, MAX_STEPS, NONFINITE}
    assert rk4[LOCKED_TRAJ] == ATTITUDE and np.count_nonzero(rk4) == 2
    rodas4, rodas4_budget = _codes(batch, 4), _codes(batch, 5)
    assert rodas4[NAN_TRAJ] == NONFINITE and np.count_nonzero(rodas4) == 1
    assert set(rodas4_budget) == {MAX_STEPS, NONFINITE}
    radau5, radau5_budget = _codes(batch, 6), _codes(batch, 7)
    assert radau5[NAN_TRAJ] == NONFINITE and np.count_nonzero(radau5) == 1
    assert set(radau5_budget) == {MAX_STEPS, NONFINITE}
    # lanes that reject steps and take Newton iterations of their own number
    assert np.count_nonzero(_stats(batch, 6, "rejected")) > 0
    assert len(set(_stats(batch, 6, "rhs_calls") - 2 * _stats(batch, 6, "accepted"))) > 2


def test_radau5_lanes_only_where_asked_for(source_dir: Path, laned_dir: Path) -> None:
    """Without `lanes`, radau5 has no lanes code (its batches: a loop of
    its single calls) and struct lanes lives on pair_lanes's stack as
    before; asked for, radau5's steps over lanes are there and struct
    lanes is on the heap, one per thread."""
    plain = (source_dir / "gyrostat_ode.c").read_text()
    laned = (laned_dir / "gyrostat_ode.c").read_text()
    for name in ("radau5_step_lanes", "radau5_grid_step_lanes", "lu_decompose_complex_lanes"):
        assert name not in plain and name in laned, name
    assert "    struct lanes L;\n" in plain and "malloc(" not in plain
    assert "    struct lanes L;\n" not in laned and "malloc(threads * sizeof(struct lanes)" in laned
    batch = laned[laned.index("size_t gyrostat_radau5_batch(") :]
    assert "pair_batch(radau5_step_lanes," in batch[: batch.index("\n}\n")]


def test_radau5_batches_over_lanes_equal_its_single_calls(laned_backend: Compiled) -> None:
    """radau5's lanes asked for: _batch and _grid_batch over 21 states
    (rates over a factor of 30, one not finite, a step budget some run
    out of), on one thread and on two, each state's end (rows), stats and
    code its single call's bit for bit."""
    b = laned_backend
    p = np.array([100, 5, 12, 9, 15, 0.8, 0.02, 0.03, 0.2, -0.1, 9.81, 0.01])
    c = b.setup(p)
    x0 = np.zeros(NX)
    x0[[1, 7, 8, 9, 10, 11]] = 0.1, 0.2, 1.0, -0.1, 50.0, 1.0
    x0s = np.tile(x0, (21, 1))
    x0s[:, 7:10] *= np.random.default_rng(5).uniform(0.3, 10.0, (21, 1))
    x0s[4, 0] = np.nan
    times = np.linspace(0.0, 2.0, 9)
    kw = {"rtol": 1e-8, "atol": 1e-8, "max_steps": 40}
    for threads in (1, 2):
        xs, stats, codes = b.integrate_batch("radau5", x0s, c, 0.0, 2.0, threads, **kw)
        rows, gstats, gcodes = b.integrate_grid_batch("radau5", x0s, c, times, threads, **kw)
        assert set(codes) == {0, MAX_STEPS, NONFINITE}, codes
        for k, start in enumerate(x0s):
            x, st, code = b.integrate("radau5", start, c, 0.0, 2.0, **kw)
            assert code == codes[k] and np.array_equal(x, xs[k], equal_nan=True), k
            assert all(np.array_equal(v, stats[f][k], equal_nan=True) for f, v in st.items()), k
            one, gst, gcode = b.integrate_grid("radau5", start, c, times, **kw)
            assert gcode == gcodes[k] and np.array_equal(one, rows[k], equal_nan=True), k
            assert all(np.array_equal(v, gstats[f][k], equal_nan=True) for f, v in gst.items()), k


def test_batch_agrees_with_single_through_python(backends: dict[str, Compiled]) -> None:
    """Compiled.integrate_batch on one and on two threads against
    Compiled.integrate (the single-trajectory function) for each method."""
    b = backends["c"]
    p = np.array([100, 5, 12, 9, 15, 0.8, 0.02, 0.03, 0.2, -0.1, 9.81, 0.01])
    c = b.setup(p)
    x0 = np.zeros(NX)
    x0[[1, 7, 8, 9, 10, 11]] = 0.1, 0.2, 1.0, -0.1, 50.0, 1.0
    x0s = x0 * (1 + 0.1 * np.random.default_rng(3).uniform(-1, 1, (50, NX)))
    for method in ("dopri5", "dop853", "rk4"):
        kw = {"steps": 300} if method == "rk4" else {"rtol": 1e-8, "atol": 1e-8}
        one = b.integrate_batch(method, x0s, c, 0.0, 5.0, threads=1, **kw)
        two = b.integrate_batch(method, x0s, c, 0.0, 5.0, threads=2, **kw)
        for got, want in zip(one, two, strict=True):
            np.testing.assert_array_equal(got, want)
        for i in range(0, 50, 7):
            x, st, code = b.integrate(method, x0s[i], c, 0.0, 5.0, **kw)
            assert code == one[2][i] == 0 and st["rhs_calls"] == one[1]["rhs_calls"][i]
            np.testing.assert_allclose(one[0][i], x, rtol=1e-12, atol=1e-12)


def test_threads_must_be_positive(backends: dict[str, Compiled]) -> None:
    b = backends["c"]
    with pytest.raises(ValueError, match="threads must be an integer from 1 to 4096, not 0"):
        b.integrate_batch("rk4", np.zeros((2, NX)), np.zeros(b.nc), 0.0, 1.0, threads=0, steps=1)


def test_trig_accuracy(source_dir: Path, tmp_path: Path) -> None:
    """<prefix>_sin and _cos against glibc: within 1 ulp (2 allowed) up to
    2^20 pi/2, near every k pi/2 there too; beyond, within half an ulp of x
    in the argument; NaN past 2^50 and for Inf and NaN. The scalar functions
    (a shortcut for |x| <= pi/4) and their branch-free _lanes twins give the
    same bits for every argument tried."""
    exe = tmp_path / "trig"
    subprocess.run(["gcc", "-std=c99", "-O2", f"-I{source_dir}", str(HARNESS / "trig.c"),
                    "-o", str(exe), "-lm"], check=True)  # fmt: skip
    ranges = ["1e-300", "1e-8", "1e-8", "1", "1", "100", "100", "1e4", "1e4", "1.6e6",
              "1.6e6", "1e9", "1e9", "1.1e15"]  # fmt: skip
    out = subprocess.run([str(exe), "200000", *ranges], check=True, capture_output=True, text=True)
    rows = {
        (r[0], r[1]): (float(r[2]), float(r[3]))
        for r in map(str.split, out.stdout.splitlines())
        if len(r) == 4
    }
    for lo, hi in zip(ranges[::2], ranges[1::2], strict=True):
        ulp, backward = rows[(f"{float(lo):g}", f"{float(hi):g}")]
        if float(hi) <= 1.6e6:
            assert ulp <= 2.0, (lo, hi, ulp)
        else:
            assert backward <= 0.5, (lo, hi, backward)
    assert rows[("near_k_pi/2", "-")][0] <= 2.0
    assert out.stdout.splitlines()[-1] == "lanes_twins_differ 0"
    special = out.stdout.splitlines()[-2].split()[1:]
    assert special[:2] == ["-0", "1"] and special[2:4] == ["nan", "nan"]
    assert abs(float(special[4])) <= 1.0 and special[5] == "nan"


def test_bench_ensemble_prints_its_figures(cli) -> None:
    """The command runs end to end on a small ensemble (no peers: their
    compiles take a minute); the figures are for the reader, not asserted.
    A skipped peer reads "skipped" (it read inf), and --n 16 is measured once
    among the sizes (it was twice)."""
    out = cli(["bench-ensemble", "--n", "16", "--repeats", "1", "--no-peers"])
    assert out.code == 0, out.err
    assert "single trajectory, default scene" in out.out
    assert "lanes on 1 core vs the single-trajectory loop" in out.out
    assert "N =     16, 1 thread(s)" in out.out
    assert out.out.count("N =     16, 1 thread(s)") == 1  # --n 16 is one of the sizes: once
    rows = [r.split() for r in out.out.splitlines() if r.strip().startswith("1e-")][:3]
    assert [r[2:] for r in rows] == [["skipped", "-"]] * 3  # no peers: not "inf"
    assert "numbalsoda timed inside" not in out.out
