"""gyrogen sweep on the local engine: the rows against the compiled
integrator run directly, resume, the stability map against NOTES.md, the
API, and the refusals of a run (another sweep in --out, no scheduler)."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from sweep_cases import free_port, rows, small

from gyrogen import api
from gyrogen.analysis.sweep_draws import inputs
from gyrogen.analysis.sweep_metrics import NOT_RUN
from gyrogen.oracle import reference
from gyrogen.physics import body_momentum, lumped_inertias
from gyrogen.runtime.segment import integrate_segments
from gyrogen.sweep_spec import load


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
        seg = integrate_segments(model, "dop853", inp.x0[i], c, times, given)  # type: ignore[arg-type]
        finals = frame.loc[i, [f"final_{s}" for s in spec.scene.states]].to_numpy(float)
        assert np.array_equal(finals, seg.states[-1])
        assert frame.loc[i, "rhs_calls"] == seg.totals["rhs_calls"]
        assert frame.loc[i, "max_rate"] == pytest.approx(
            np.max(np.linalg.norm(seg.states[:, 7:10], axis=1)), rel=1e-15
        )


@pytest.mark.slow
def test_metrics_are_what_their_names_say(swept: tuple[Path, Path]) -> None:
    frame = rows(swept[1])
    assert (frame["max_nutation"] >= frame["nutation_0"]).all()
    assert (frame["H_drift"] < 1e-8).all()  # |H| is conserved: rtol 1e-9 holds it
    reached = frame["time_to_u1"].dropna()
    assert len(reached) and reached.isin(np.linspace(0.0, 2.0, 11)).all()
    assert frame["code"].eq(0).all() and frame["t"].eq(2.0).all()


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
    path, out = swept
    other = small(tmp_path / "other.toml", t_end=3.0)
    before = sorted(p.name for p in out.rglob("*"))
    code, stdout, err = cli(["sweep", str(other), "--out", str(out)])
    assert code == 1 and stdout == ""
    assert err == (
        f"gyrogen: error: {out} holds another sweep (small, 60 trajectories in chunks of 25): "
        "use another --out or remove it\n"
    )
    code, _, err = cli(["sweep", str(path), "--out", str(out), "--chunk", "7"])
    assert code == 1 and "in chunks of 25" in err
    assert sorted(p.name for p in out.rglob("*")) == before


def test_no_scheduler_there_is_one_line_exit_1(tmp_path: Path, cache: None, cli) -> None:
    address = f"tcp://127.0.0.1:{free_port()}"
    code, _, err = cli(["sweep", str(small(tmp_path / "s.toml")), "--scheduler", address])
    assert code == 1 and err.startswith(f"gyrogen: error: --scheduler {address}: cannot connect")
    assert err.count("\n") == 1


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
