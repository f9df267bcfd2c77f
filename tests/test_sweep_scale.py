"""A sweep at scale: the summary streams over the parts (10^4 parts
under `ulimit -n 256`), its median and p99 are numpy's exactly, another
--chunk resumes the same sweep, the code is built for the workers' CPU,
recorded, which a worker on another refuses (or portable for any), and the
local engine's dashboard is printed."""

from __future__ import annotations

import itertools
import json
import os
import resource
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from sweep_cases import rows, small
from wide import WIDE

from gyrogen.analysis.sweep import columns as sweep_columns
from gyrogen.analysis.sweep.columns import part_name, written

FILES = 256


@pytest.fixture(scope="module")
def cache(cache_dir: Path) -> Iterator[Path]:
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("GYROGEN_CACHE", str(cache_dir))
        yield cache_dir


def _parts(out: Path, columns: dict[str, np.ndarray], cuts: list[int]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    (out / "parts").mkdir(parents=True)
    for a, b in itertools.pairwise(cuts):
        table = pa.table({n: v[a:b] for n, v in columns.items()})
        pq.write_table(table, out / "parts" / part_name(a, b))


@pytest.mark.parametrize("collect", [sweep_columns.COLLECT, 3])
def test_the_streamed_spread_is_numpys(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, collect: int
) -> None:
    """min, median, p99, max and the histogram, streamed over parts of
    uneven sizes with NaN, inf, ties, negative values and counts: numpy's on
    the whole column, bit for bit (collect 3: every order statistic found
    16 bits at a time to the last)."""
    monkeypatch.setattr(sweep_columns, "COLLECT", collect)
    rng = np.random.default_rng(5)
    n = 3000
    columns = {
        "a": rng.normal(size=n) * 1e-3,
        "b": np.exp(rng.normal(size=n) * 6),
        "c": rng.integers(0, 50, n).astype(np.int64),
        "d": np.round(rng.normal(size=n), 1),
        "e": np.full(n, np.nan),
    }
    columns["a"][::37], columns["b"][::11] = np.nan, np.inf
    _parts(tmp_path, columns, [0, 1, 700, 701, 2000, n])
    parts = [part_name(a, b) for a, b in written(tmp_path)]
    counted, got = sweep_columns.spreads(tmp_path, parts, list(columns), ("c",))
    assert counted == {
        "c": {
            str(k): int(c)
            for k, c in zip(*np.unique(columns["c"], return_counts=True), strict=True)
        }
    }
    for name, values in columns.items():
        stats, histogram = got[name]
        finite = values[np.isfinite(values)].astype(float)
        assert stats["finite"] == finite.size and histogram.total == n
        if not finite.size:
            assert set(stats) == {"finite"}
            continue
        median, p99 = np.quantile(finite, [0.5, 0.99])
        assert (stats["min"], stats["median"], stats["p99"], stats["max"]) == (
            finite.min(),
            median,
            p99,
            finite.max(),
        )
        assert stats["mean"] == pytest.approx(finite.mean(), rel=1e-14)
        edges, _ = sweep_columns.edges_of(finite.min(), finite.max())
        assert np.array_equal(histogram.counts, np.histogram(finite, edges)[0])


def _limited() -> None:
    resource.setrlimit(resource.RLIMIT_NOFILE, (FILES, FILES))


@pytest.mark.slow
@WIDE
def test_ten_thousand_parts_are_summarized_under_256_files(
    tmp_path: Path, cache: Path, cli
) -> None:
    """A sweep of 10^4 trajectories as 10^4 one-row parts, resumed with
    --chunk 1 in a process allowed 256 open files: nothing to compute, and
    the summary (which opened every part at once: "Too many open files")
    is the one-part run's."""
    import pyarrow.parquet as pq

    sweep = small(tmp_path / "s.toml", t_end=0.01, chunk=20_000, count=667)
    one = tmp_path / "one"
    code, _, err = cli(["sweep", str(sweep), "--out", str(one), "--quiet", "--no-plots"])
    assert code == 0, err
    many = tmp_path / "many"
    (many / "parts").mkdir(parents=True)
    (many / "sweep.json").write_bytes((one / "sweep.json").read_bytes())
    [(a, b)] = written(one)
    table = pq.read_table(one / "parts" / part_name(a, b))
    assert b == table.num_rows == 10_005
    meta = json.loads(table.schema.metadata[b"gyrogen"])
    for i in range(b):  # each part's footer says its sample
        said = {b"gyrogen": json.dumps({**meta, "samples": [i, i + 1]}).encode()}
        one_row = table.slice(i, 1).replace_schema_metadata(said)
        pq.write_table(one_row, many / "parts" / part_name(i, i + 1))
    proc = subprocess.run(
        [sys.executable, "-m", "gyrogen", "sweep", str(sweep), "--out", str(many), "--chunk", "1",
         "--quiet", "--no-plots"],
        preexec_fn=_limited, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert f"0 chunks computed, {b} already written" in proc.stdout
    got, want = (json.loads((d / "summary.json").read_text()) for d in (many, one))
    assert got["integrator_codes"] == want["integrator_codes"] == {"0": b}
    for name, stats in want["metrics"].items():
        held = got["metrics"][name]
        assert {k: held[k] for k in held if k != "mean"} == {
            k: stats[k] for k in stats if k != "mean"
        }
        assert held.get("mean", 0.0) == pytest.approx(stats.get("mean", 0.0), rel=1e-13)
    assert len(written(many)) == b


@pytest.mark.slow
def test_another_chunk_resumes_the_sweep(tmp_path: Path, cache: Path, cli) -> None:
    """Begun in chunks of 25 (three parts, one lost), resumed in chunks of 7:
    only the lost samples are computed, cut at multiples of 7; the parts
    tile the samples once, and the rows are a clean run's (before: "holds
    another sweep")."""
    sweep = small(tmp_path / "s.toml")
    clean, out = tmp_path / "clean", tmp_path / "out"
    assert cli(["sweep", str(sweep), "--out", str(clean), "--quiet", "--no-plots"]).code == 0
    assert cli(["sweep", str(sweep), "--out", str(out), "--quiet", "--no-plots"]).code == 0
    assert written(out) == [(0, 25), (25, 50), (50, 60)]
    (out / "parts" / part_name(25, 50)).unlink()
    code, stdout, err = cli(["sweep", str(sweep), "--out", str(out), "--chunk", "7", "--quiet"])
    assert code == 0, err
    assert "5 chunks computed, 2 already written" in stdout
    assert written(out) == [(0, 25), (25, 28), (28, 35), (35, 42), (42, 49), (49, 50), (50, 60)]
    assert rows(out).equals(rows(clean))
    code, stdout, _ = cli(["sweep", str(sweep), "--out", str(out), "--chunk", "60", "--quiet"])
    assert code == 0 and "0 chunks computed, 7 already written" in stdout


@pytest.mark.slow
@WIDE
def test_sweeps_record_the_cpu_unless_portable(tmp_path: Path, cache: Path, cli) -> None:
    """By default the code is built for the workers' CPU (-march=native),
    which the identity records; --portable builds for any CPU (no
    -march=native, no contraction into FMAs) and records none, and resuming
    it with native code is another build."""
    from gyrogen.runtime.flags import native_target

    sweep = small(tmp_path / "s.toml")
    out = tmp_path / "out"
    assert cli(["sweep", str(sweep), "--out", str(out), "--quiet", "--no-plots"]).code == 0
    ident = json.loads((out / "summary.json").read_text())["identity"]
    assert "-march=native" in ident["flags"].split() and ident["cpu"] == native_target()
    portable = tmp_path / "portable"
    code, _, err = cli(["sweep", str(sweep), "--out", str(portable), "--portable", "--quiet"])
    assert code == 0, err
    held = json.loads((portable / "summary.json").read_text())["identity"]
    assert "-march=native" not in held["flags"].split() and "cpu" not in held
    assert "-ffp-contract=off" in held["flags"].split()
    assert rows(portable).equals(rows(out))  # here, the same bits (not promised across CPUs)
    code, _, err = cli(["sweep", str(sweep), "--out", str(portable), "--quiet"])
    assert code == 1 and "(changed: flags, cpu)" in err


def test_a_worker_on_another_cpu_refuses_native_code(cache: Path, tmp_path: Path) -> None:
    from gyrogen.analysis.sweep.engine import Job, chunk_task
    from gyrogen.analysis.sweep.spec import load
    from gyrogen.errors import GyrogenError
    from gyrogen.runtime.scene_build import Sources

    spec = load(str(small(tmp_path / "s.toml")))
    job = Job(spec, Sources("x", "c", {}), 25, {"cpu": "another-0"})
    with pytest.raises(GyrogenError, match=r"a worker's CPU is .*, the sweep's another-0"):
        chunk_task(job, 0, 1)


@pytest.mark.slow
def test_the_dashboard_is_served_and_printed(tmp_path: Path, cache: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "gyrogen", "sweep", str(small(tmp_path / "s.toml")), "--out",
         str(tmp_path / "o"), "--no-plots"],
        capture_output=True, text=True, timeout=600,
        env={**os.environ, "GYROGEN_CACHE": str(cache)},
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    line = next(x for x in proc.stderr.splitlines() if x.startswith("dashboard: "))
    assert line.startswith("dashboard: http://127.0.0.1:") and line.endswith("/status")
