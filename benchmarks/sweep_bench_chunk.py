"""`make sweep-bench`'s per-chunk costs: what one chunk task does, phase by
phase, in this process, each the best of `repeats` (CPU seconds of this
thread, and wall), beside the bare batch call on the same start states:
the draws, run_chunk (draws, batch call, metrics), the Parquet bytes, the
write into a local directory (fsynced, renamed) and through a file:// URL
(fsspec: a temporary name, renamed), and the resume's check of the part
written (parts.verdict: its footer and its sample column)."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from gyrogen import api
from gyrogen.analysis.sweep.draws import inputs
from gyrogen.analysis.sweep.engine import Job, identity, part_metadata
from gyrogen.analysis.sweep.metrics import run_chunk
from gyrogen.analysis.sweep.parts import parquet_bytes, verdict, write_part
from gyrogen.analysis.sweep.store import store
from gyrogen.runtime.flags import native_target
from gyrogen.runtime.scene_build import compiled, scene_sources


def _timed(f: Callable[..., Any], *args: Any, **kwargs: Any) -> tuple[float, float, Any]:
    """(CPU seconds of this thread, wall seconds, result) of f(*args, **kwargs)."""
    t, c = time.perf_counter(), time.thread_time()
    got = f(*args, **kwargs)
    return time.thread_time() - c, time.perf_counter() - t, got


def per_chunk(spec: api.Spec, tol: float, chunk: int, work: Path, repeats: int = 5) -> None:
    sources = scene_sources(spec.scene)
    comp = compiled(sources)
    job = Job(spec, sources, chunk, identity(spec, sources, native_target()))
    meta = part_metadata(job, 0, chunk)
    state = {k: meta["gyrogen"][k] for k in ("fingerprint", "identity")}
    local, url = store(work / "chunk-local"), store(f"file://{work / 'chunk-url'}")
    for where in (local, url):
        where.make_dir("parts")
    best: dict[str, tuple[float, float]] = {}

    def keep(name: str, cpu: float, wall: float) -> None:
        was = best.get(name, (float("inf"), float("inf")))
        best[name] = (min(was[0], cpu), min(was[1], wall))

    a, b = 0, chunk  # the same samples each time: the phases' best are of one chunk
    for _ in range(repeats):  # interleaved
        inp = inputs(spec, a, b)
        c = comp.setup(inp.p[0])
        method, t_end = spec.sweep.method, spec.sweep.t_end
        cpu, wall, _ = _timed(comp.integrate_batch, method, inp.x0, c, 0.0, t_end, threads=1,
                              rtol=tol, atol=tol)  # fmt: skip
        keep("bare batch call", cpu, wall)
        keep("the draws (inputs)", *_timed(inputs, spec, a, b)[:2])
        cpu, wall, cols = _timed(run_chunk, comp, spec, a, b)
        keep("run_chunk (draws, batch call, metrics)", cpu, wall)
        cpu, wall, data = _timed(parquet_bytes, cols, meta)
        keep("Parquet bytes", cpu, wall)
        for name, where in (("local directory", local), ("file:// URL (fsspec)", url)):
            keep(f"write, {name}", *_timed(write_part, where, a, b, data)[:2])
            cpu, wall, why = _timed(verdict, where, a, b, state)
            assert why is None, why
            keep(f"check (verdict), {name}", cpu, wall)
    size = len(data)
    bare = best["bare batch call"][0]
    print(f"per chunk of {chunk:,} (best of {repeats}; CPU of this thread, wall):")
    for name, (cpu, wall) in best.items():
        print(f"  {name}: {cpu * 1e3:.2f} ms CPU ({100 * cpu / bare:.1f}% of the bare call), "
              f"{wall * 1e3:.2f} ms wall")  # fmt: skip
    task = sum(best[n][0] for n in best if n.startswith(("run_chunk", "Parquet", "write, local")))
    print(f"  a task's CPU (run_chunk + Parquet + local write): {task * 1e3:.2f} ms, "
          f"{task / bare:.3f}x the bare call; part {size / 1e6:.2f} MB")  # fmt: skip
