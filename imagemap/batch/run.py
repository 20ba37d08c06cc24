""":func:`run_batch`: plan, check, lock the output folder, run the objects on the chosen
workers (this process, a local pool or a Dask cluster), count them and write the report.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import sys
import time
from collections.abc import Callable, Generator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from imagemap.batch.cluster import _connect, _is_client, _run_dask
from imagemap.batch.locks import _locked
from imagemap.batch.plan import (
    REPORT_NAME,
    BatchOptions,
    Job,
    check_outputs,
    plan_jobs,
    with_map_companions,
)
from imagemap.batch.pool import _run_pool, _usable_workers
from imagemap.batch.work import (
    _remove_stale_temporaries,
    _safe_process,
    is_complete,
    prepare_databases,
)
from imagemap.database import Database
from imagemap.depth.budget import guard_mesh
from imagemap.io import InputError, atomic_path
from imagemap.outputs import resolve
from imagemap.progress import progress
from imagemap.validate import check_int

__all__ = ["BatchSummary", "run_batch"]

log = logging.getLogger("imagemap")


@dataclass
class BatchSummary:
    """Counts and timings of a batch (``records`` holds one dict per object)."""

    done: int = 0
    skipped: int = 0
    failed: int = 0
    seconds: float = 0.0
    prepare_seconds: float = 0.0
    records: list[dict] = field(default_factory=list)

    @property
    def per_minute(self) -> float:
        """Objects synthesized per minute of wall time (skipped ones not counted)."""
        return 60.0 * self.done / self.seconds if self.seconds > 0 else 0.0

    def line(self) -> str:
        return (
            f"{self.done} done, {self.skipped} skipped, {self.failed} failed in "
            f"{self.seconds:.1f} s ({self.per_minute:.1f} objects/min; database prepared in "
            f"{self.prepare_seconds:.1f} s)"
        )


def run_batch(
    input_dir: str | os.PathLike,
    database: Database | str | os.PathLike,
    out_dir: str | os.PathLike,
    options: BatchOptions | None = None,
    *,
    workers: int = 1,
    scheduler: str | object | None = None,
    force: bool = False,
    quiet: bool = True,
    on_result: Callable[[dict], None] | None = None,
) -> BatchSummary:
    """Synthesize every depth map and mesh of ``input_dir`` into ``out_dir``.

    Parameters
    ----------
    input_dir : path
        Depth maps ``NAME_depth.png|tif|tiff|npy`` and meshes (``.glb``, ``.obj``...).
    database : Database or path
        The examples (pictures and/or textured meshes).
    out_dir : path
        ``NAME_image.png`` per depth map, ``NAME.glb`` (or ``.obj``) per mesh.
    options : BatchOptions
    workers : int
        Local processes (1: in this process). Workers are spawned, so a script that
        calls this with ``workers > 1`` must guard its top level with
        ``if __name__ == "__main__":``.
    scheduler : str or dask.distributed.Client, optional
        Run on a Dask cluster instead (``"tcp://host:8786"``, or a client).
    force : bool
        Redo objects whose outputs are complete.
    quiet : bool
        No progress bar.
    on_result : callable, optional
        Called with each object's record as it completes (done or failed).

    Returns
    -------
    BatchSummary
    """
    options = options or BatchOptions()
    if not isinstance(options, BatchOptions):
        raise InputError(f"options: expected BatchOptions, got {type(options).__name__}")
    workers = check_int("workers", workers, minimum=1)
    if scheduler is not None and not isinstance(scheduler, str) and not _is_client(scheduler):
        raise InputError(f"scheduler: expected an address or a Dask Client, got {scheduler!r}")
    jobs = plan_jobs(input_dir, out_dir, options)
    out_dir = resolve(out_dir)
    database_dir = None
    if not isinstance(database, Database):
        if not isinstance(database, str | os.PathLike):
            raise InputError(f"database: expected a Database or a folder, got {database!r}")
        database_dir = database
        database = Database.from_directory(database, view=options.views[0], size=options.size)
    if options.maps:  # the PBR maps every depth map's image-map may have beside it
        from imagemap.materials import database_map_kinds  # deferred: start-up

        jobs = with_map_companions(jobs, database_map_kinds(database))
    check_outputs(jobs, database, out_dir, database_dir)  # before any work
    workers = _usable_workers(workers, len(jobs))
    summary = BatchSummary()
    todo = []
    for job in jobs:  # read only: manifests and outputs
        if not force and is_complete(job, options):
            summary.skipped += 1
            summary.records.append({"status": "skipped", "name": job.name})
        else:
            todo.append(job)
    key = options.key()
    todo = [
        dataclasses.replace(job, options_key=key, size=_view_size(job, options)) for job in todo
    ]
    sizes = [job.size for job in todo if job.kind == "mesh" and job.size is not None]
    if sizes:  # the views and texture every mesh will have (the largest views)
        largest = max(sizes, key=lambda s: s[0] * s[1])
        guard_mesh(largest, len(options.views), options.texture_size or 512, "each mesh")
    # The scheduler answers (or not) before anything is written into the output folder.
    client, own = _connect(scheduler) if scheduler is not None and todo else (None, False)
    start = time.perf_counter()
    try:
        with _locked(out_dir):
            for job in todo:
                _remove_stale_temporaries(job)
            try:
                databases = prepare_databases(database, options, todo) if todo else None
                summary.prepare_seconds = time.perf_counter() - start
                if todo:
                    log.info("database prepared in %.1f s", summary.prepare_seconds)
                results = _run(todo, databases, options, workers, client)
                _collect(results, len(todo), summary, quiet, on_result)
            except KeyboardInterrupt:
                summary.seconds = time.perf_counter() - start
                _write_report(out_dir, summary, options, interrupted=True)
                print(
                    f"imagemap: batch interrupted: {summary.done} done, {summary.skipped} "
                    f"skipped, {summary.failed} failed of {len(jobs)}; every finished object "
                    "is kept and no partial file is left: run the same command again to "
                    f"resume (finished objects are skipped; report in {out_dir / REPORT_NAME})",
                    file=sys.stderr,
                )
                raise
            summary.seconds = time.perf_counter() - start
            _write_report(out_dir, summary, options)
    finally:
        if own and client is not None:  # own: _connect opened client
            client.close()
    return summary


def _view_size(job: Job, options: BatchOptions) -> tuple[int, int] | None:
    """A mesh job's views' size (:meth:`BatchOptions.view_size`: ``imagemap synthesize
    MESH``'s default when ``options.size`` is None); None for a depth map, or a mesh
    that does not load (its worker reports why)."""
    if job.kind != "mesh":
        return None
    if options.size is not None:
        return options.size
    from imagemap.scene.files import load_mesh  # deferred: start-up (trimesh)

    try:
        return options.view_size(load_mesh(job.source))
    except InputError:
        return None


def _collect(
    results: Generator[dict, None, None],
    total: int,
    summary: BatchSummary,
    quiet: bool,
    on_result: Callable[[dict], None] | None,
) -> None:
    """Count the records as they come, with a progress bar."""
    try:
        for record in progress(results, total=total, desc="objects", quiet=quiet):
            summary.records.append(record)
            if record["status"] == "done":
                summary.done += 1
            else:
                summary.failed += 1
                error, source = record["error"], record["source"]
                log.error("failed: %s", error if source in error else f"{source}: {error}")
            if on_result is not None:
                on_result(record)
    finally:
        results.close()


def _run(
    todo: list[Job],
    databases: Any,
    options: BatchOptions,
    workers: int,
    client: Any,
) -> Generator[dict, None, None]:
    """A generator of records as objects complete (closing it stops the workers)."""
    if not todo:
        return
    cores = os.cpu_count() or 1
    if client is not None:
        yield from _run_dask(todo, databases, options, client)
    elif workers == 1:
        for job in todo:
            yield _safe_process(job, databases, options)
    else:
        yield from _run_pool(todo, databases, options, workers, cores)


def _write_report(
    out_dir: Path, summary: BatchSummary, options: BatchOptions, interrupted: bool = False
) -> None:
    if not summary.records and not interrupted:
        return
    report = {
        "interrupted": interrupted,
        "done": summary.done,
        "skipped": summary.skipped,
        "failed": summary.failed,
        "seconds": round(summary.seconds, 3),
        "prepare_seconds": round(summary.prepare_seconds, 3),
        "objects_per_minute": round(summary.per_minute, 2),
        "options": {**asdict(options), "views": [str(v) for v in options.views]},
        "objects": summary.records,
    }
    try:
        with atomic_path(out_dir / "batch_report.json") as tmp:
            tmp.write_text(json.dumps(report, indent=1, default=str) + "\n")
    except OSError as exc:  # the outputs are what matter
        print(f"imagemap: could not write the batch report ({exc})", file=sys.stderr)
