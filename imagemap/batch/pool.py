"""A local process pool: spawned workers that receive the database once and end with the batch."""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Generator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

from imagemap.batch.plan import BatchOptions, Job
from imagemap.batch.work import _safe_process, _set_threads
from imagemap.mesh.library import ExampleSet

__all__ = ["PARENT_POLL_SECONDS"]

log = logging.getLogger("imagemap")


# Worker-process state of the local pool: the prepared databases, received once.
_WORKER: dict = {}


#: How often a pool worker looks whether the batch's process is still there (seconds):
#: after a ``kill -9`` of the batch its workers end within this (where prctl's
#: parent-death signal is not available).
PARENT_POLL_SECONDS = 1.0


def _init_pool_worker(databases, threads: int, parent: int | None = None) -> None:
    _WORKER["databases"] = databases
    _end_with_parent(parent)
    _set_threads(threads)


def _end_with_parent(parent: int | None) -> None:
    """End this worker when the batch's process ends, however it ends (``kill -9`` too):
    on Linux the kernel sends SIGKILL (prctl PR_SET_PDEATHSIG); everywhere a watcher
    thread exits when the parent is gone."""
    if parent is None:
        return
    if sys.platform.startswith("linux"):
        import ctypes  # deferred: only pool workers on Linux need it

        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    if os.getppid() != parent:  # gone before the signal was asked for
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(PARENT_POLL_SECONDS)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="imagemap-parent-watch", daemon=True).start()


def _pool_task(job: Job, options: BatchOptions) -> dict:
    return _safe_process(job, _WORKER["databases"], options)


def _usable_workers(workers: int, objects: int) -> int:
    """At most one local worker per core and per object: each holds the whole database,
    and more processes than cores only share the same cores (said with a warning)."""
    cores = os.cpu_count() or 1
    if workers > cores:
        log.warning(
            "--workers %d: this machine has %d cores; using %d worker processes",
            workers,
            cores,
            min(cores, objects),
        )
    return max(1, min(workers, cores, objects))


def _run_pool(
    todo: list[Job],
    databases: ExampleSet,
    options: BatchOptions,
    workers: int,
    cores: int,
) -> Generator[dict, None, None]:
    workers = min(workers, len(todo))
    executor = ProcessPoolExecutor(
        max_workers=workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_init_pool_worker,
        initargs=(databases, max(1, cores // workers), os.getpid()),
    )
    # At most one job per worker in flight: a stop (Ctrl-C) waits only for those,
    # and a batch of thousands holds no queue of pickled jobs.
    pending = iter(todo)
    running = set()
    try:
        for job in pending:
            running.add(executor.submit(_pool_task, job, options))
            if len(running) < workers:
                continue
            finished, running = wait(running, return_when=FIRST_COMPLETED)
            for future in finished:
                yield future.result()
        for future in running:
            yield future.result()
    finally:
        executor.shutdown(wait=True, cancel_futures=True)
