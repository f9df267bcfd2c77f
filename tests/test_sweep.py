"""gyrogen sweep on the local engine: the rows against the compiled
integrator run directly, resume (a part is what its footer says), the
stability map against NOTES.md, the API, and the refusals of a run
(another sweep in --out, strays in its parts, no scheduler)."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from ctrl_c import interrupted
from sweep_cases import OBSTACLES, free_port, put, rows, small
from wide import WIDE

from gyrogen import api
from gyrogen.analysis.sweep.draws import inputs
from gyrogen.analysis.sweep.metrics import NOT_RUN
from gyrogen.analysis.sweep.spec import load
from gyrogen.oracle import reference
from gyrogen.physics import body_momentum, lumped_inertias


@pytest.fixture(scope="module")
def cache(cache_dir: Path) -> Iterator[None]:
    """The session's build cache for this module's runs."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("GYROGEN_CACHE", str(cache_dir))
        yield


@pytest.fixture(scope="module")
def swept(tmp_path_factory: pytest.TempPathFactory, cache: None, cli) -> tuple[Path, Path]:
    """The small sweep, run once through the command line: (file, out)."""
    work = tmp_path_factory.mktemp("sweep")
    path, out = small(work / "small.toml"), work / "out"
    code, stdout, err = cli(["sweep", str(path), "--out", str(out), "--workers", "2"])
    assert code == 0, err
    assert "Setup codes {'0': 60}; integrator codes {'0': 60}." in stdout
    return path, out


@pytest.mark.slow
@WIDE
def test_rows_are_the_compiled_integrator_run_directly(swept: tuple[Path, Path]) -> None:
    path, out = swept
    spec, frame = load(str(path)), rows(out)
    assert list(frame["sample"]) == list(range(spec.size))
    model = api.compile(spec.scene)
    inp = inputs(spec, 0, spec.size)
    times = np.linspace(0.0, spec.sweep.t_end, spec.sweep.metrics.points + 1)
    for i in (0, 17, spec.size - 1):
        c = model.setup(inp.p[i])
        given = {"rtol": 1e-9, "atol": 1e-9, "max_steps": 10**6}
        states, _, stats, code = model.integrate_events("dop853", inp.x0[i], c, times, **given)
        finals = frame.loc[i, [f"final_{s}" for s in spec.scene.states]].to_numpy(float)
        assert code == 0 and np.array_equal(finals, states[-1])
        assert frame.loc[i, "rhs_calls"] == stats["rhs_calls"]
        assert frame.loc[i, "max_rate"] == pytest.approx(
            np.max(np.linalg.norm(states[:, 7:10], axis=1)), rel=1e-15
        )


@pytest.mark.slow
def test_metrics_are_what_their_names_say(swept: tuple[Path, Path]) -> None:
    frame = rows(swept[1])
    assert (frame["max_nutation"] >= frame["nutation_0"]).all()
    assert (frame["H_drift"] < 1e-8).all()  # |H| is conserved: rtol 1e-9 holds it
    assert frame["code"].eq(0).all() and frame["t"].eq(2.0).all()
    reached = frame["time_to_u1"].dropna()
    assert len(reached) and not reached.isin(np.linspace(0.0, 2.0, 11)).any()
    # located on the dense output, not the first sample past it: u1 is 0.25 there
    spec = load(str(swept[0]))
    model, inp = api.compile(spec.scene), inputs(spec, 0, spec.size)
    for i in reached.index[:4]:
        c, at = model.setup(inp.p[i]), float(reached[i])
        x, _, code = model.integrate("dop853", inp.x0[i], c, 0.0, at, rtol=1e-12, atol=1e-12)
        assert code == 0 and abs(x[7] - 0.25) < 1e-8


def test_body_momentum_has_the_reference_magnitude() -> None:
    rng = np.random.default_rng(3)
    spec = load("monte_carlo")
    inp = inputs(spec, 0, 50)
    x = inp.x0 + rng.normal(0, 0.5, inp.x0.shape)
    v = dict(zip(spec.scene.runtime, inp.p.T, strict=True))
    names = ("m_a", "m_b", "I11", "I22", "I33", "I13", "I", "l1", "l3")
    h = body_momentum(lumped_inertias(*(v[n] for n in names)), v["J"], *x[:, 7:11].T)
    expected = np.linalg.norm(reference.angular_momentum_n(x, inp.p), axis=-1)
    assert np.allclose(np.linalg.norm(h, axis=0), expected, rtol=1e-13)


MONTE_CARLO_FAILING = """
scene = "gyrostat"
method = "dop853"
t_end = 10.0
rtol = 1e-9
atol = 1e-9
max_steps = 40
[draws]
seed = 1
count = 20
I11 = { normal = [12.0, 0.3] }
u4  = { uniform = [1.0, 3000.0] }
[metrics]
keep = ["final_state", "stats", "max_nutation", "max_rate", "invariant_drift", "time_to"]
samples = 2
time_to = { nutation = 0.3 }
"""


def test_a_monte_carlo_whose_runs_fail_midway_keeps_every_row() -> None:
    """A parameter set per trajectory, some of whose runs exhaust max_steps
    (one budget per trajectory) between the samples: each row has its code,
    the time it reached and metrics over the samples it reached, and the
    others are the grid's (the metrics of the rows still running once read
    every row's inertias: a chunk with a run failing after the first
    sample stopped with a shape mismatch)."""
    from gyrogen.analysis.sweep.metrics import run_chunk
    from gyrogen.runtime.scene_build import compiled, scene_sources

    spec = api.load_sweep(MONTE_CARLO_FAILING)
    model = compiled(scene_sources(spec.scene))
    cols = run_chunk(model, spec, 0, 20)
    failed = cols["code"] == 2  # ODE_ERR_MAX_STEPS
    assert failed.any() and not failed.all() and set(cols["code"]) == {0, 2}
    assert (cols["t"][failed] < 10.0).all() and (cols["t"][~failed] == 10.0).all()
    assert np.isfinite(cols["max_rate"]).all() and np.isfinite(cols["max_nutation"]).all()
    inp = inputs(spec, 0, 20)
    times = np.linspace(0.0, 10.0, 3)
    for i in range(20):
        states, stats, code = model.integrate_grid(
            "dop853", inp.x0[i], model.setup(inp.p[i]), times, rtol=1e-9, atol=1e-9, max_steps=40
        )
        assert code == cols["code"][i] and stats["t"] == cols["t"][i]
        seen = states[~np.isnan(states[:, 0])]
        assert cols["max_rate"][i] == np.max(np.linalg.norm(seen[:, 7:10], axis=1))


@pytest.mark.parametrize("method", ["dop853", "taylor", "rodas4"])
def test_a_sweeps_sampled_rows_are_its_grid_calls(method: str) -> None:
    """One parameter set, sampled metrics: the chunk is one _grid_batch call
    (over SIMD lanes for dop853 and taylor, 37 states: the lanes refilled),
    and each row's final state and statistics are its own integrate_grid
    call's (the batch's ends read back), its max_rate the grid's."""
    from gyrogen.analysis.sweep.metrics import run_chunk
    from gyrogen.runtime.scene_build import compiled, scene_sources

    text = MONTE_CARLO_FAILING.replace('method = "dop853"', f'method = "{method}"')
    text = text.replace("max_steps = 40\n", "").replace("I11 = { normal = [12.0, 0.3] }\n", "")
    text = text.replace("samples = 2", "samples = 7").replace("count = 20", "count = 37")
    spec = api.load_sweep(text.replace("[1.0, 3000.0]", "[1.0, 60.0]").replace(
        '"invariant_drift", "time_to"]\n', '"invariant_drift"]\n').replace(
        "time_to = { nutation = 0.3 }\n", ""))  # fmt: skip
    assert not spec.scene.events and spec.size == 37
    model = compiled(scene_sources(spec.scene))
    cols = run_chunk(model, spec, 0, 37)
    inp = inputs(spec, 0, 37)
    assert (inp.p == inp.p[0]).all()  # one parameter set: one batch
    c, times = model.setup(inp.p[0]), np.linspace(0.0, 10.0, 8)
    for i in range(37):
        states, stats, code = model.integrate_grid(method, inp.x0[i], c, times, rtol=1e-9,
                                                   atol=1e-9)  # fmt: skip
        finals = np.array([cols[f"final_{n}"][i] for n in spec.scene.states])
        assert code == cols["code"][i] == 0 and np.array_equal(finals, states[-1])
        assert cols["rhs_calls"][i] == stats["rhs_calls"]
        assert cols["max_rate"][i] == np.max(np.linalg.norm(states[:, 7:10], axis=1))


def test_time_to_is_located_where_the_quantity_is_its_threshold() -> None:
    """time_to's nutation, rate and state thresholds are events the sweep
    adds to its scene, located on the dense output: the compiled integrator
    run to the time found has the quantity at its threshold (to the
    location's precision), where the first sample past it was up to a
    sample interval late."""
    from gyrogen.analysis.sweep.metrics import located, run_chunk
    from gyrogen.runtime.scene_build import compiled, scene_sources

    text = (
        MONTE_CARLO_FAILING.replace("max_steps = 40\n", "")
        .replace(
            "[1.0, 3000.0]",
            "[1.0, 60.0] }\nu1 = { uniform = [-0.3, 0.3] }\nu3 = { uniform = [-0.3, 0.3]",
        )
        .replace(
            "time_to = { nutation = 0.3 }", "time_to = { nutation = 0.3, rate = 0.35, u1 = 0.1 }"
        )
    )
    spec = api.load_sweep(text)
    names = [e.name for e in spec.scene.events]
    assert names == ["time_to_nutation", "time_to_rate", "time_to_u1"] and not located(spec)
    model = compiled(scene_sources(spec.scene))
    cols = run_chunk(model, spec, 0, 20)
    inp = inputs(spec, 0, 20)
    found = 0
    for i in range(20):
        c = model.setup(inp.p[i])
        values = {**spec.scene.folded(), **dict(zip(spec.scene.runtime, inp.p[i], strict=True))}
        lumped = lumped_inertias(
            *(values[n] for n in ("m_a", "m_b", "I11", "I22", "I33", "I13", "I", "l1", "l3"))
        )
        for q, thr in (("nutation", 0.3), ("rate", 0.35), ("u1", 0.1)):
            at = cols[f"time_to_{q}"][i]
            if not 0 < at < 10:
                continue
            found += 1
            x, _, code = model.integrate("dop853", inp.x0[i], c, 0.0, at, rtol=1e-13, atol=1e-13)
            u = x[7:11]
            if q == "nutation":
                h = body_momentum(lumped, values["J"], *u)
                value = np.arctan2(np.hypot(h[0], h[2]), h[1])
            else:
                value = np.linalg.norm(u[:3]) if q == "rate" else u[0]
            assert code == 0 and abs(value - thr) < 1e-8, (q, i, value)
    assert found >= 10


@pytest.mark.slow
def test_refused_parameters_are_rows_with_their_code(tmp_path: Path, cache: None, cli) -> None:
    text = small(tmp_path / "s.toml").read_text().replace("[8.0, 9.0, 10.0]", "[9.0, -1.0, 9.5]")
    (tmp_path / "s.toml").write_text(text)
    code, _, err = cli(["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o")])
    assert code == 0, err
    frame = rows(tmp_path / "o")
    bad = frame["I22"] < 0
    assert (frame.loc[bad, "setup_code"] == 4).all() and (frame.loc[bad, "code"] == NOT_RUN).all()
    assert frame.loc[bad, "max_nutation"].isna().all()
    assert (frame.loc[~bad, "setup_code"] == 0).all()


@pytest.mark.slow
def test_a_grid_setup_refuses_throughout_is_reported(tmp_path: Path, cache: None, cli) -> None:
    """Every parameter set refused by setup (a 2-D grid of I22 < 0): the rows
    carry the code, the summary and histograms are written, and the map,
    with no value to show, is left out (it was a traceback)."""
    text = small(tmp_path / "s.toml").read_text().replace("[8.0, 9.0, 10.0]", "[-2.0, -1.0]")
    (tmp_path / "s.toml").write_text(text)
    code, _, err = cli(["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o"), "--quiet"])
    assert (code, err) == (0, "")
    assert (rows(tmp_path / "o")["setup_code"] == 4).all()
    names = {p.name for p in (tmp_path / "o").iterdir()}
    assert {"summary.json", "summary.md", "histograms.png"} <= names and "map.png" not in names


@pytest.mark.slow
def test_rerun_skips_the_parts_written(swept: tuple[Path, Path], tmp_path: Path, cli) -> None:
    path, done = swept
    out = tmp_path / "out"
    assert cli(["sweep", str(path), "--out", str(out), "--quiet"]).code == 0
    parts = sorted((out / "parts").iterdir())
    (parts[1]).unlink()
    (parts[-1]).unlink()
    before = {p.name: p.stat().st_mtime_ns for p in (out / "parts").iterdir()}
    code, stdout, err = cli(["sweep", str(path), "--out", str(out), "--quiet"])
    assert code == 0, err
    assert "2 chunks computed, 1 already written" in stdout
    after = {p.name: p.stat().st_mtime_ns for p in (out / "parts").iterdir()}
    assert len(after) == 3 and all(after[name] == ns for name, ns in before.items())
    assert rows(out).equals(rows(done))


@pytest.mark.slow
def test_another_sweep_in_out_is_refused(swept: tuple[Path, Path], tmp_path: Path, cli) -> None:
    _path, out = swept
    other = small(tmp_path / "other.toml", t_end=3.0)
    before = sorted(p.name for p in out.rglob("*"))
    code, stdout, err = cli(["sweep", str(other), "--out", str(out)])
    assert code == 1 and stdout == ""
    assert err == (
        f"gyrogen: error: {out} holds another sweep (small, 60 trajectories): "
        "use another --out or remove it\n"
    )
    assert sorted(p.name for p in out.rglob("*")) == before


def test_no_scheduler_there_is_one_line_exit_1(tmp_path: Path, cache: None, cli) -> None:
    address = f"tcp://127.0.0.1:{free_port()}"
    code, _, err = cli(["sweep", str(small(tmp_path / "s.toml")), "--scheduler", address])
    assert code == 1 and err.startswith(f"gyrogen: error: --scheduler {address}: cannot connect")
    assert err.count("\n") == 1


def test_no_scheduler_writes_nothing(tmp_path: Path, cache: None, cli) -> None:
    """Refused before the output directory is touched (it held sweep.json)."""
    out = tmp_path / "o"
    address = f"tcp://127.0.0.1:{free_port()}"
    code, _, err = cli(["sweep", str(small(tmp_path / "s.toml")), "--scheduler", address,
                        "--out", str(out)])  # fmt: skip
    assert code == 1 and not out.exists(), err


@pytest.mark.parametrize("port", ["0", "65536", "99999"])
def test_a_port_out_of_range_is_a_usage_error(tmp_path: Path, cli, port: str) -> None:
    address, out = f"tcp://127.0.0.1:{port}", tmp_path / "o"
    code, stdout, err = cli(["sweep", str(small(tmp_path / "s.toml")), "--scheduler", address,
                             "--out", str(out)])  # fmt: skip
    assert (code, stdout) == (2, "") and not out.exists()
    assert err == (
        f"gyrogen sweep: error: Invalid value for '--scheduler': '{address}': the port must be "
        "1 to 65535 (see --help)\n"
    )


@pytest.mark.slow
@WIDE
def test_a_server_that_is_not_dask_is_one_line_in_bounded_time(
    tmp_path: Path, cache: None, cli
) -> None:
    """An HTTP server on the port takes the connection and never speaks Dask:
    distributed alone waited for ever; now one line within 2 CONNECT_TIMEOUT."""
    import http.server
    import threading
    import time

    from gyrogen.analysis.sweep.dask_client import CONNECT_TIMEOUT

    class Quiet(http.server.BaseHTTPRequestHandler):
        def log_message(self, *args: object) -> None:
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Quiet)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    address, out = f"tcp://127.0.0.1:{server.server_address[1]}", tmp_path / "o"
    try:
        t0 = time.monotonic()
        code, _, err = cli(["sweep", str(small(tmp_path / "s.toml")), "--scheduler", address,
                            "--out", str(out)])  # fmt: skip
        waited = time.monotonic() - t0
    finally:
        server.shutdown()
    assert code == 1 and not out.exists()
    assert err == (
        f"gyrogen: error: --scheduler {address}: no Dask scheduler answered within "
        f"{2 * CONNECT_TIMEOUT:g} s (is something else listening on that port?)\n"
    )
    assert waited < 4 * CONNECT_TIMEOUT  # bounded, not a speed figure: it hung for ever


@pytest.mark.parametrize(("name", "text", "message"), OBSTACLES, ids=[o[0] for o in OBSTACLES])
def test_obstacles_in_out_are_refused_before_any_work(
    tmp_path: Path, cli, name: str, text: str | None, message: str
) -> None:
    out = tmp_path / "o"
    before = put(out, name, text)
    code, stdout, err = cli(["sweep", str(small(tmp_path / "s.toml")), "--out", str(out)])
    assert (code, stdout) == (1, "") and err.count("\n") == 1
    assert err.startswith("gyrogen: error: " + message.format(out=out)), err
    assert {p.name: p.read_bytes() if p.is_file() else None for p in out.rglob("*")} == before


@pytest.mark.slow
@pytest.mark.parametrize("figure", ["histograms.png", "map.png"])
def test_without_plots_a_figures_place_is_no_obstacle(
    tmp_path: Path, cache: None, cli, figure: str
) -> None:
    """--no-plots writes no figure: a directory of its name is left alone
    (it was refused before any work, as if the figure were to be written)."""
    out = tmp_path / "o"
    put(out, figure, None)
    code, _, err = cli(["sweep", str(small(tmp_path / "s.toml", count=1)), "--out", str(out),
                        "--quiet", "--no-plots"])  # fmt: skip
    assert (code, err) == (0, "")
    names = {p.name for p in out.iterdir()}
    assert names == {"sweep.json", "parts", "summary.json", "summary.md", figure}
    assert (out / figure).is_dir() and not any((out / figure).iterdir())


@pytest.mark.slow
@pytest.mark.parametrize("size", [0, 100])
@WIDE
def test_a_damaged_part_is_computed_again(
    swept: tuple[Path, Path], tmp_path: Path, cli, size: int
) -> None:
    """A part cut short (0 or 100 bytes: a crash, a full disk) is detected by
    its footer on the rerun and computed again; the rows equal a clean run
    (before: an ArrowInvalid traceback on every rerun)."""
    path, done = swept
    out = tmp_path / "out"
    assert cli(["sweep", str(path), "--out", str(out), "--quiet"]).code == 0
    damaged = sorted((out / "parts").iterdir())[1]
    with damaged.open("r+b") as fh:
        fh.truncate(size)
    code, stdout, err = cli(["sweep", str(path), "--out", str(out), "--quiet"])
    assert code == 0, err
    assert err == f"{damaged}: damaged or cut short: computing it again\n"
    assert "1 chunks computed, 2 already written" in stdout
    assert rows(out).equals(rows(done))


@pytest.mark.slow
def test_stability_map_agrees_with_notes(tmp_path: Path, cache: None, cli) -> None:
    out = tmp_path / "map"
    code, stdout, err = cli(["sweep", "stability_map", "--out", str(out), "--quiet"])
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text())
    spin = summary["spin_stability"]
    assert spin["cells"] == 1681 and spin["judged"] > 1400 and spin["share"] >= 0.99
    assert spin["predicted_unstable"] > 200 and spin["not_finished"] == 0
    assert {"map.png", "histograms.png", "summary.md"} <= set(summary["files"])
    assert (out / "map.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "agree with the criterion" in stdout


@pytest.mark.slow
def test_api_sweep_is_the_command_lines(swept: tuple[Path, Path], tmp_path: Path) -> None:
    path, out = swept
    frame = api.sweep(str(path), out=tmp_path / "api", workers=1, plots=False)
    assert isinstance(frame, pd.DataFrame) and frame.equals(rows(out))
    spec = api.load_sweep(path.read_text(), name="text", here=path.parent)
    assert api.sweep(spec, out=tmp_path / "text", chunk=60, plots=False).equals(frame)


@pytest.mark.slow
def test_a_resume_never_mixes_two_builds(swept: tuple[Path, Path], tmp_path: Path, cli) -> None:
    """A sweep begun by another build (here: its state says other generated
    sources) is refused with what changed; --restart computes it anew, and
    the rows are a clean run's (before: it resumed, old rows beside new)."""
    import json
    import shutil

    path, done = swept
    out = tmp_path / "out"
    shutil.copytree(done, out)
    state = json.loads((out / "sweep.json").read_text())
    state["identity"]["sources"] = "0" * 16
    (out / "sweep.json").write_text(json.dumps(state))
    before = {p.name: p.read_bytes() for p in (out / "parts").iterdir()}
    code, stdout, err = cli(["sweep", str(path), "--out", str(out), "--quiet"])
    assert (code, stdout) == (1, "")
    assert err == (
        f"gyrogen: error: {out} holds this sweep begun with another build (changed: sources): "
        "its rows would mix two codes; --restart computes it anew, or use another --out\n"
    )
    assert {p.name: p.read_bytes() for p in (out / "parts").iterdir()} == before
    code, stdout, err = cli(["sweep", str(path), "--out", str(out), "--quiet", "--restart"])
    assert code == 0, err
    assert "3 chunks computed, 0 already written" in stdout
    assert rows(out).equals(rows(done))


@pytest.mark.slow
def test_a_part_of_another_build_is_computed_again(
    swept: tuple[Path, Path], tmp_path: Path, cli
) -> None:
    """Each part records the identity it was computed with; a resume keeps
    only the parts of its own."""
    import shutil

    import pyarrow.parquet as pq

    path, done = swept
    out = tmp_path / "out"
    shutil.copytree(done, out)
    part = sorted((out / "parts").iterdir())[0]
    table = pq.read_table(part)
    meta = json.loads(table.schema.metadata[b"gyrogen"])
    meta["identity"]["code"] = "0" * 16
    pq.write_table(table.replace_schema_metadata({"gyrogen": json.dumps(meta)}), part)
    code, _, err = cli(["sweep", str(path), "--out", str(out), "--quiet"])
    why = "computed with another build (its footer)"
    assert code == 0 and err == f"{part}: {why}: computing it again\n"
    assert rows(out).equals(rows(done))


def _copy(done: Path, out: Path) -> Path:
    """A copy of the sweep in done at out; out's parts directory."""
    import shutil

    shutil.copytree(done, out)
    return out / "parts"


@pytest.mark.slow
def test_a_part_is_what_its_footer_says_not_its_name(
    swept: tuple[Path, Path], tmp_path: Path, cli
) -> None:
    """The first part copied over the second (its name says samples 25 to
    50, its footer 0 to 25): the resume names it and why, computes it again,
    and the rows are a clean run's (before: '0 chunks computed, 3 already
    written', samples 0 to 24 twice and 25 to 49 never)."""
    path, done = swept
    parts = _copy(done, tmp_path / "out")
    first, second, _ = sorted(parts.iterdir())
    second.write_bytes(first.read_bytes())
    code, stdout, err = cli(["sweep", str(path), "--out", str(tmp_path / "out"), "--quiet"])
    assert code == 0, err
    why = "holds samples 0 to 25 (its footer), not 25 to 50"
    assert err == f"{second}: {why}: computing it again\n"
    assert "1 chunks computed, 2 already written" in stdout
    assert "Setup codes {'0': 60}; integrator codes {'0': 60}." in stdout
    assert rows(tmp_path / "out").equals(rows(done))


@pytest.mark.slow
def test_the_reader_refuses_a_part_whose_footer_disagrees(
    swept: tuple[Path, Path], tmp_path: Path
) -> None:
    """api.read lists and checks the parts as the resume does: a part whose
    footer says other samples than its name is one line naming it (before:
    its rows read twice, the samples of its name never)."""
    from gyrogen.errors import GyrogenError

    _, done = swept
    parts = _copy(done, tmp_path / "out")
    first, second, _ = sorted(parts.iterdir())
    second.write_bytes(first.read_bytes())
    with pytest.raises(GyrogenError) as exc:
        api.read(tmp_path / "out")
    assert str(exc.value) == (
        f"{second}: holds samples 0 to 25 (its footer), not 25 to 50: rerun the sweep to compute "
        "it again"
    )


FOOTERS = [
    ({}, None),
    ({"gyrogen": None}, "its footer records no samples"),
    ({"samples": [0, 5]}, "holds samples 0 to 5 (its footer), not 5 to 10"),
    # was "holds samples 5 to 10 (its footer), not 5 to 10"
    ({"samples": ["5", "10"]}, 'its footer records its samples as ["5", "10"], not [5, 10]'),
    ({"samples": [5, True]}, "its footer records its samples as [5, true], not [5, 10]"),
    ({"rows": range(5, 9)}, "holds 4 rows (its footer), not 5"),
    ({"rows": range(0, 5)}, "its rows are not samples 5 to 10, each once, in order"),
    # the least and greatest samples right, one doubled and one missing: the rows'
    # statistics agreed, and api.read gave sample 5 twice, 6 never
    ({"rows": [5, 5, 7, 8, 9]}, "its rows are not samples 5 to 10, each once, in order"),
    ({"rows": [5, 7, 6, 8, 9]}, "its rows are not samples 5 to 10, each once, in order"),
    ({"rows": np.arange(5.0, 10.0)}, "its sample column is not integers (it is double)"),
    ({"column": "trajectory"}, "holds no sample column"),
    ({"fingerprint": "another"}, "computed for another sweep (its footer)"),
    ({"identity": {"code": "another"}}, "computed with another build (its footer)"),
    ({"bytes": b"PAR1"}, "damaged or cut short"),
]
"""(what differs from a true part of samples 5..10, why the resume computes it again)"""


@pytest.mark.parametrize(("change", "why"), FOOTERS, ids=[str(f[1]) for f in FOOTERS])
def test_the_verdict_on_a_part_reads_its_footer(
    tmp_path: Path, change: dict[str, object], why: str | None
) -> None:
    """A part of samples 5..10 is its sweep's only when its footer says so
    (its samples, its rows' count, fingerprint and identity) and its sample
    column holds 5 to 9, each once, in order."""
    from gyrogen.analysis.sweep.columns import part_name
    from gyrogen.analysis.sweep.parts import parquet_bytes, verdict
    from gyrogen.analysis.sweep.store import store

    state = {"fingerprint": "mine", "identity": {"code": "mine"}}
    meta = {"samples": [5, 10], **state}
    meta |= {k: v for k, v in change.items() if k in ("samples", "fingerprint", "identity")}
    sample = np.asarray(change.get("rows", range(5, 10)))
    said = {"gyrogen": meta} if "gyrogen" not in change else None
    data = change.get("bytes") or parquet_bytes({str(change.get("column", "sample")): sample}, said)
    (tmp_path / "parts").mkdir()
    (tmp_path / "parts" / part_name(5, 10)).write_bytes(data)  # type: ignore[arg-type]
    assert verdict(store(tmp_path), 5, 10, state) == why


def _sweep_of(out: Path, parts: list[tuple[int, int]]) -> dict[str, object]:
    """out holding a sweep of 32 samples (its state, returned) and true parts
    of the samples in parts."""
    from gyrogen.analysis.sweep.columns import part_name
    from gyrogen.analysis.sweep.parts import STATE_FILE, parquet_bytes

    state = {"sweep": "s", "fingerprint": "mine", "trajectories": 32, "scene": "gyrostat"}
    state["identity"] = {"code": "mine"}
    (out / "parts").mkdir(parents=True)
    (out / STATE_FILE).write_text(json.dumps(state))
    for a, b in parts:
        meta = {"gyrogen": {"samples": [a, b], "fingerprint": "mine", "identity": {"code": "mine"}}}
        sample = np.arange(a, b, dtype=np.int64)
        (out / "parts" / part_name(a, b)).write_bytes(parquet_bytes({"sample": sample}, meta))
    return state


OVERLAPS = [
    # was "computing it again": 0 chunks were computed
    ([(0, 8), (0, 16), (8, 16), (16, 32)], [(0, 8), (8, 16), (16, 32)],
     "overlaps part-00000000000-00000000008.parquet: removed: the parts kept hold all its "
     "samples"),
    ([(0, 8), (0, 16), (16, 32)], [(0, 8), (16, 32)],
     "overlaps part-00000000000-00000000008.parquet: removed: computing again the 8 of its 16 "
     "samples no part kept holds"),
    ([(0, 16), (8, 24), (24, 32)], [(0, 16), (24, 32)],
     "overlaps part-00000000000-00000000016.parquet: removed: computing again the 8 of its 16 "
     "samples no part kept holds"),
]  # fmt: skip
"""(the parts written, those a resume keeps, its note on the one it removes)"""


@pytest.mark.parametrize(("parts", "kept", "note"), OVERLAPS)
def test_a_part_overlapping_another_is_removed_with_what_is_computed(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    parts: list[tuple[int, int]],
    kept: list[tuple[int, int]],
    note: str,
) -> None:
    """A resume keeps the first of two parts that overlap and removes the
    other, its note saying which it overlaps and how many of its samples
    are computed again (none when the parts kept hold them all); api.read
    refuses it, naming the part it overlaps."""
    from gyrogen.analysis.sweep.columns import part_name, written
    from gyrogen.analysis.sweep.parts import claim, trusted
    from gyrogen.analysis.sweep.store import store
    from gyrogen.errors import GyrogenError

    state = _sweep_of(tmp_path, parts)
    (removed,) = set(parts) - set(kept)
    with pytest.raises(GyrogenError) as exc:
        trusted(store(tmp_path))
    other = note.split()[1].rstrip(":")
    assert str(exc.value) == (
        f"{tmp_path / 'parts' / part_name(*removed)}: overlaps {other}: rerun the sweep to remove "
        "it (and compute what of it no other part holds)"
    )
    assert claim(store(tmp_path), state) == kept
    assert written(store(tmp_path)) == kept
    assert capsys.readouterr().err == f"{tmp_path / 'parts' / part_name(*removed)}: {note}\n"


STRAYS = [
    ("part-00000000060-00000000085.parquet", "file",
     "names samples 60 to 85, not within this sweep's 0 to 60: not its part"),
    ("part-00000000030-00000000030.parquet", "file",
     "names samples 30 to 30, not within this sweep's 0 to 60: not its part"),
    ("part-00000000025-00000000050.parquet", "dir",
     "a directory, and the parts folder holds files only"),
    ("notes", "dir", "a directory, and the parts folder holds files only"),
]  # fmt: skip
"""(a name in parts, what is put there, the refusal's words)"""


@pytest.mark.slow
@pytest.mark.parametrize(("name", "kind", "why"), STRAYS, ids=[s[0][:20] + s[1] for s in STRAYS])
def test_a_stray_in_the_parts_folder_is_refused_before_any_work(
    swept: tuple[Path, Path], tmp_path: Path, cli, name: str, kind: str, why: str
) -> None:
    """A part-named file outside the sweep's samples (it was 'overlaps
    another part'), or a directory (named like a part, it was 'cannot remove
    ...: Is a directory', exit 1, once the engine had started): one line,
    exit 1, nothing written."""
    path, done = swept
    out = tmp_path / "out"
    parts = _copy(done, out)
    first = sorted(parts.iterdir())[0]
    if kind == "dir":
        (parts / name).unlink(missing_ok=True)
        (parts / name).mkdir()
    else:
        (parts / name).write_bytes(first.read_bytes())
    before = {p: p.read_bytes() if p.is_file() else None for p in out.rglob("*")}
    code, stdout, err = cli(["sweep", str(path), "--out", str(out), "--quiet"])
    assert (code, stdout) == (1, "")
    assert err == f"gyrogen: error: {parts / name}: {why}: remove it or use another --out\n"
    assert {p: p.read_bytes() if p.is_file() else None for p in out.rglob("*")} == before


@pytest.mark.slow
def test_the_data_explains_itself(swept: tuple[Path, Path]) -> None:
    """Without gyrogen: each part's fields carry unit and meaning, its schema
    the sweep's identity, spec, seed and scene; summary.json too."""
    import pyarrow.parquet as pq

    path, out = swept
    schema = pq.read_schema(sorted((out / "parts").iterdir())[0])
    assert schema.field("final_u4").metadata == {
        b"unit": b"rad/s",
        b"meaning": b"final value (the last good one on failure) of: absolute angular velocity "
        b"of B, a2",
    }
    assert schema.field("max_nutation").metadata[b"unit"] == b"rad"
    meta = json.loads(schema.metadata[b"gyrogen"])
    assert meta["sweep"] == "small" and meta["scene"] == "gyrostat" and meta["seed"] == 11
    assert meta["spec"]["draws"]["count"] == 4 and meta["chunk"] == 25
    assert meta["samples"] == [0, 25] and meta["fingerprint"] == load(str(path)).fingerprint()
    assert set(meta["identity"]) == {"gyrogen", "code", "build_id", "sources", "flags", "cpu"}
    summary = json.loads((out / "summary.json").read_text())
    assert summary["seed"] == 11 and summary["identity"] == meta["identity"]
    assert summary["spec"] == meta["spec"]


@pytest.mark.parametrize("dashboard", [False, True])
def test_the_local_engine_listens_on_this_machine_only(dashboard: bool) -> None:
    """With its dashboard (bokeh's) or without (a quiet run: no bokeh
    imported), the local engine's HTTP routes listen on 127.0.0.1 only
    (distributed's default, and its fallback without an address, is every
    interface)."""
    import psutil

    from gyrogen.analysis.sweep.dask_client import engine

    with engine(None, 1, dashboard=dashboard):
        listening = [c for c in psutil.Process().net_connections("inet")
                     if c.status == psutil.CONN_LISTEN]  # fmt: skip
    assert listening and {c.laddr.ip for c in listening} == {"127.0.0.1"}


HUGE = """
scene = "gyrostat"
method = "dop853"
t_end = 1.0
chunk = 10
[parameters]
I = {I}
[initial]
u1 = 1e300
u2 = 0.1
[draws]
seed = 1
count = 4
u3 = {{ uniform = [-0.2, 0.2] }}
[metrics]
keep = ["max_nutation", "max_rate", "invariant_drift", "time_to"]
samples = 4
time_to = {{ nutation = 0.3, rate = 1.0 }}
"""
"""A start rate of 1e300 rad/s (in range: an axis or a draw reaches it
too); with I = 1e40 its momentum, 1e340, is beyond doubles."""


@pytest.mark.slow  # a sweep of its own scene: its derivation and build
@pytest.mark.filterwarnings("error")  # a numpy warning in a chunk fails the sweep
@pytest.mark.parametrize("inertia", [0.02, 1e40])
@WIDE
def test_a_huge_start_rate_is_measured_without_overflow(
    tmp_path: Path, cache: None, cli, inertia: float
) -> None:
    """Before: 'overflow encountered in square' on stderr and max_rate inf
    (with I = 1e40 'overflow encountered in multiply' too, in the momentum)."""
    sweep, out = tmp_path / "huge.toml", tmp_path / "o"
    sweep.write_text(HUGE.format(I=inertia))
    with np.errstate(all="raise"):
        code, _, err = cli(["sweep", str(sweep), "--out", str(out), "--quiet", "--no-plots"])
    assert code == 0 and "Warning" not in err, err
    found = rows(out)
    assert (found["max_rate"] == 1e300).all() and (found["H_drift"] == 0).all()
    assert np.allclose(found["nutation_0"], np.pi / 2, rtol=0, atol=1e-12)  # H along a1


@pytest.mark.slow  # a sweep in a process of its own
def test_interrupted_sweep_says_one_line(tmp_path: Path, cache_dir: Path) -> None:
    """A real SIGINT while a task runs: closing the cluster cancels it, and
    before, Dask logged a warning for it ("Async instruction ... ended with
    CancelledError") before gyrogen's line. Now stderr is that one line."""
    path, out = small(tmp_path / "small.toml"), tmp_path / "out"
    argv = ["sweep", str(path), "--out", str(out), "--workers", "1", "--quiet"]
    code, err = interrupted("task", argv, cache_dir)
    assert (code, err) == (130, "gyrogen: aborted\n")
