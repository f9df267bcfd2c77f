"""The Dask client a sweep runs on: a local cluster of threads in this
process (its dashboards on 127.0.0.1 only), or an existing dask.distributed
scheduler reached within a bound whatever answers on its port."""

from __future__ import annotations

import logging
import os
import socket
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from gyrogen.errors import GyrogenError

CONNECT_TIMEOUT = 10.0
"""Seconds to reach the scheduler (the TCP connection; the handshake gets as long again)."""
DASK_LOGGER = "distributed"
"""The logger above all of dask.distributed's (each of its modules logs to a child)."""


@contextmanager
def engine(
    scheduler: str | None, threads: int | None, dashboard: bool = False
) -> Iterator[tuple[Any, str, int]]:
    """A dask.distributed client: on scheduler, or on a local cluster of
    threads in this process; dashboard: the local cluster serves its
    dashboard (bokeh's, on 127.0.0.1: its import costs about a second, so a
    quiet run goes without), and where a dashboard is is said on stderr.
    Yields (client, engine name, worker threads)."""
    import dask
    from distributed import Client, LocalCluster, Worker

    _drop_unretrieved_timeouts()

    class Plain(Worker):  # its HTTP routes on 127.0.0.1, without bokeh's dashboard
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **{**kwargs, "dashboard": False})

    if scheduler is None:
        n = threads or os.cpu_count() or 1
        with (  # no sampling profiler in the worker's threads: nobody reads it
            dask.config.set({"distributed.worker.profile.enabled": False}),
            LocalCluster(  # the dashboard on this machine only
                n_workers=1,
                threads_per_worker=n,
                processes=False,
                dashboard_address="127.0.0.1:0",
                worker_dashboard_address="127.0.0.1:0",
                scheduler_kwargs={"dashboard": dashboard},
                worker_class=Worker if dashboard else Plain,
            ) as cluster,
            Client(cluster) as client,
        ):
            if dashboard:
                _dashboard(client, "127.0.0.1")
            with _quiet_when_stopped():
                yield client, f"local ({n} threads)", n
        return
    with _connect(Client, scheduler) as client:
        if dashboard:
            _dashboard(client, scheduler.removeprefix("tcp://").rsplit(":", 1)[0])
        workers = client.scheduler_info(n_workers=-1)["workers"].values()
        n = sum(int(w.get("nthreads", 1)) for w in workers)
        if n == 0:
            raise GyrogenError(f"--scheduler {scheduler}: the cluster has no workers")
        with _quiet_when_stopped():
            yield client, f"dask.distributed at {scheduler} ({n} worker threads)", n


class _UnretrievedTimeout(logging.Filter):
    """Drops asyncio's "Future (or Task) exception was never retrieved" for a
    TimeoutError: on a loaded machine a connection or a close inside Dask
    (tornado's with_timeout) may time out in a future nobody awaits, and
    asyncio prints it to stderr when the future is collected, after the
    sweep has written its output. No result of the sweep is ever read from
    such a future (the sweep awaits each of its own), so it is noise."""

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        unretrieved = "exception was never retrieved" in str(record.msg).split("\n", 1)[0]
        return not (unretrieved and isinstance(exc, TimeoutError))


def _drop_unretrieved_timeouts() -> None:
    """_UnretrievedTimeout on asyncio's logger, once per process."""
    log = logging.getLogger("asyncio")
    if not any(isinstance(f, _UnretrievedTimeout) for f in log.filters):
        log.addFilter(_UnretrievedTimeout())


@contextmanager
def _quiet_when_stopped() -> Iterator[None]:
    """Dask's loggers silenced for the rest of the process when the block
    ends by an exception (Ctrl-C, an error): closing the client and the
    cluster then cancels the tasks under way, and Dask would log a warning
    for each (an "Async instruction ... ended with CancelledError") beside
    the command's one line."""
    try:
        yield
    except BaseException:
        for name in [DASK_LOGGER, *logging.Logger.manager.loggerDict]:
            if name == DASK_LOGGER or name.startswith(DASK_LOGGER + "."):
                logging.getLogger(name).setLevel(logging.CRITICAL + 1)
        raise


def _dashboard(client: Any, host: str) -> None:
    """Where the dashboard is on host (none without bokeh, or when the
    scheduler runs without one)."""
    port = client.scheduler_info().get("services", {}).get("dashboard")
    where = f"http://{host}:{port}/status" if port else "none (the scheduler serves none)"
    print(f"dashboard: {where}", file=sys.stderr)


@contextmanager
def _connect(client_type: Any, scheduler: str) -> Iterator[Any]:
    """A client of the scheduler, or one line: the TCP connection and then
    the handshake each within CONNECT_TIMEOUT, whatever answers on the port
    (an HTTP server takes the connection and never speaks Dask: distributed
    itself would wait for ever)."""
    host, port = scheduler.removeprefix("tcp://").rsplit(":", 1)
    try:
        socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT).close()
    except (OSError, ValueError) as exc:
        why = getattr(exc, "strerror", None) or str(exc)
        raise GyrogenError(f"--scheduler {scheduler}: cannot connect: {why}") from exc
    made: dict[str, Any] = {}

    def connect() -> None:
        try:
            made["client"] = client_type(scheduler, timeout=CONNECT_TIMEOUT)
        except Exception as exc:  # reported below, in one line
            made["error"] = exc

    thread = threading.Thread(target=connect, daemon=True)  # daemon: never holds the exit
    thread.start()
    thread.join(2 * CONNECT_TIMEOUT)
    if thread.is_alive():
        raise GyrogenError(
            f"--scheduler {scheduler}: no Dask scheduler answered within "
            f"{2 * CONNECT_TIMEOUT:g} s (is something else listening on that port?)"
        )
    if "error" in made:
        error = made["error"]
        why = getattr(error, "strerror", None) or str(error) or type(error).__name__
        raise GyrogenError(f"--scheduler {scheduler}: cannot connect: {why}") from error
    with made["client"] as client:
        yield client
