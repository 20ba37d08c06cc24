"""A Dask cluster: the database scattered to every worker once, one task per object."""

from __future__ import annotations

import os
import pickle
import sys
import threading
from collections.abc import Generator
from typing import Any

from imagemap.batch.plan import BatchOptions, Job
from imagemap.batch.work import _safe_process, _set_threads
from imagemap.io import InputError
from imagemap.mesh.library import ExampleSet

__all__ = ["CONNECT_SECONDS"]


def _dask_task(payload: bytes, databases, host_threads: dict[str, int]) -> dict:
    # Job and options travel pickled: Dask's msgpack cannot carry them (and says so).
    job, options = pickle.loads(payload)
    _set_threads(_dask_threads(host_threads))
    return _safe_process(job, databases, options)


def _is_client(value) -> bool:
    client = sys.modules.get("distributed")
    return client is not None and isinstance(value, client.Client)


#: Seconds a scheduler has to answer. dask's own ``timeout`` is not kept when the port
#: accepts but never speaks its protocol (a silent port or an HTTP server: measured, a
#: 5 s timeout still waiting at 100 s), so the connection is given this long in a thread.
CONNECT_SECONDS = 20.0


def _connect(scheduler: Any) -> tuple[Any, bool]:
    """(client, whether we opened it) for an address or a ``dask.distributed.Client``."""
    try:
        from dask.distributed import Client  # deferred: optional dependency (imagemap[dask])
    except ImportError as exc:
        raise InputError(
            "--scheduler needs Dask: pip install 'imagemap[dask]' (dask[distributed])"
        ) from exc
    if isinstance(scheduler, Client):
        return scheduler, False
    outcome: dict[str, Any] = {}

    def connect() -> None:
        try:
            outcome["client"] = Client(scheduler, timeout=f"{CONNECT_SECONDS:g}s")
        except BaseException as exc:  # reported below, in the caller's thread
            outcome["error"] = exc

    thread = threading.Thread(target=connect, name="imagemap-dask-connect", daemon=True)
    thread.start()
    thread.join(CONNECT_SECONDS + 1.0)
    if thread.is_alive():
        raise InputError(
            f"--scheduler {scheduler}: no answer from a Dask scheduler in "
            f"{CONNECT_SECONDS:g} s (is it a Dask scheduler's address, tcp://HOST:8786?)"
        )
    if "error" in outcome:
        raise InputError(f"--scheduler {scheduler}: {_why_not(outcome['error'])}") from None
    return outcome["client"], True


def _why_not(error: BaseException) -> str:
    """Why a scheduler address gave no client, in words: no answer, or an answer that is
    not Dask's protocol (a Dask client reading another server's bytes as a frame length
    asked for 3.07 EiB: a MemoryError is what that looks like)."""
    if isinstance(error, OSError | TimeoutError):  # refused, unreachable, timed out
        reason = str(error).split("\n")[0] or type(error).__name__
        return (
            f"no Dask scheduler answered ({reason}); is a scheduler running there "
            "(dask scheduler), and is the address tcp://HOST:PORT?"
        )
    return (
        "what answers at this address does not speak Dask's protocol (it is not a Dask "
        "scheduler: check the host and port, tcp://HOST:8786)"
    )


def _dask_threads(host_threads: dict[str, int]) -> int:
    """This worker's share of its machine's cores (all Dask threads on a host share it)."""
    from distributed import get_worker  # deferred: optional dependency (imagemap[dask])

    address = get_worker().address
    host = address.split("://")[-1].rsplit(":", 1)[0]
    return max(1, (os.cpu_count() or 1) // max(1, host_threads.get(host, 1)))


def _run_dask(
    todo: list[Job], databases: ExampleSet, options: BatchOptions, client: Any
) -> Generator[dict, None, None]:
    from dask.distributed import as_completed  # deferred: optional dependency (imagemap[dask])

    host_threads: dict[str, int] = {}
    for worker in client.scheduler_info().get("workers", {}).values():
        host = str(worker.get("host", ""))
        host_threads[host] = host_threads.get(host, 0) + int(worker.get("nthreads", 1))
    shipped = client.scatter(databases, broadcast=True, hash=False)
    futures = [
        client.submit(_dask_task, pickle.dumps((job, options)), shipped, host_threads, pure=False)
        for job in todo
    ]
    job_of = {future.key: job for future, job in zip(futures, todo, strict=True)}
    try:
        for future in as_completed(futures):
            try:
                yield future.result()
            except Exception as exc:  # a worker lost: report the object, go on
                job = job_of[future.key]
                yield {
                    "status": "failed",
                    "name": job.name,
                    "source": str(job.source),
                    "error": f"{type(exc).__name__}: {exc}",
                }
    finally:
        client.cancel(futures)
