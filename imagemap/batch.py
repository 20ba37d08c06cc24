"""Batches: every depth map or mesh of a folder, on a local process pool or a Dask cluster.

:func:`run_batch` plans one job per input object (``NAME_depth.png|tif|tiff|npy``
-> ``NAME_image.png``; a mesh ``NAME.glb|obj|ply|...`` -> a textured ``NAME.glb`` or
``NAME.obj``), prepares the database once (every example's arrays loaded, mesh
examples rendered for each requested view) and ships it to the workers once: a
local process pool gets it in its initializer, a Dask cluster by
``client.scatter(..., broadcast=True)``.

Resumable: after an object's outputs are written (each atomically), a small
manifest ``OUT/.imagemap-done/SOURCE.json`` is written last, holding the input's
content hash, the options and the outputs' sizes; an object whose manifest matches
(same input, same options, same engine code, outputs present with the recorded sizes) is
skipped.
A failing object is reported and the others go on. The summary counts done,
skipped and failed objects and the throughput (objects per minute).

Examples
--------
Two depth maps against a database of two painted ellipses (usually a folder),
in this process (``workers=1``), then the same batch again:

>>> import shutil, tempfile
>>> import numpy as np
>>> from imagemap.database import Example
>>> yy, xx = np.mgrid[:24, :32]
>>> def ellipse(height):
...     inside = (yy - 12) ** 2 / (height / 2) ** 2 + (xx - 16) ** 2 / 144 < 1
...     return np.where(inside, 0.7, 0).astype(np.float32)
>>> def paint(depth):
...     return np.where((depth > 0)[..., None] & (yy[..., None] < 12), [0.8, 0.2, 0.1], 0.5)
>>> db = Database([Example.from_arrays(f"e{h}", ellipse(h), paint(ellipse(h))) for h in (12, 18)])
>>> folder = Path(tempfile.mkdtemp())
>>> (folder / "in").mkdir()
>>> for h in (14, 16):
...     np.save(folder / "in" / f"q{h}_depth.npy", ellipse(h))
>>> summary = run_batch(folder / "in", db, folder / "out", BatchOptions(preset="fish"))
>>> summary.done, summary.skipped, summary.failed
(2, 0, 0)
>>> sorted(p.name for p in (folder / "out").iterdir())
['.imagemap-done', 'batch_report.json', 'q14_image.png', 'q16_image.png']
>>> again = run_batch(folder / "in", db, folder / "out", BatchOptions(preset="fish"))
>>> again.done, again.skipped  # complete outputs are skipped
(0, 2)
>>> shutil.rmtree(folder)
"""

from __future__ import annotations

import functools
import hashlib
import json
import logging
import multiprocessing
import os
import pickle
import re
import sys
import time
import traceback
from collections.abc import Callable, Generator, Mapping
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import imagemap
from imagemap.database import Database, database_at_view, prepare_database
from imagemap.depth.config import DepthConfig, resolve_config
from imagemap.io import InputError, atomic_path, read_depth, write_image
from imagemap.mesh import (
    DEFAULT_SIZE,
    FRONT,
    MESH_SUFFIXES,
    View,
    export_textured,
    file_digest,
    load_mesh,
    parse_views,
)
from imagemap.mesh.colorize import colorize_mesh
from imagemap.progress import progress

__all__ = ["BatchOptions", "BatchSummary", "Job", "plan_jobs", "prepare_databases", "run_batch"]

log = logging.getLogger("imagemap")

_DEPTH_RE = re.compile(r"^(?P<name>.+)_depth\.(?:png|tif|tiff|npy)$", re.IGNORECASE)
DONE_DIR = ".imagemap-done"


@dataclass(frozen=True)
class BatchOptions:
    """What every object of a batch is synthesized with.

    ``options`` are :data:`imagemap.depth.config.OPTIONS` by name (a mapping; kept
    as sorted pairs), over ``preset``; ``views`` apply to meshes (the first one is
    also the view at which mesh examples are rendered for depth-map queries);
    ``background`` None writes RGBA maps with a transparent background, else RGB on
    that colour. Checked when built: an unknown preset or option, or a value the
    configuration refuses, is an :class:`InputError`.
    """

    preset: str = "busts"
    options: Any = ()
    seed: int = 0
    views: tuple[View, ...] = (FRONT,)
    size: tuple[int, int] = DEFAULT_SIZE
    texture_size: int = 512
    mesh_format: str = "glb"
    background: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        pairs = self.options.items() if isinstance(self.options, Mapping) else self.options
        options = tuple(sorted((str(k), v) for k, v in dict(pairs).items() if v is not None))
        object.__setattr__(self, "options", options)
        self.config()  # refuses a bad preset, option or combination now
        if isinstance(self.views, str):
            object.__setattr__(self, "views", tuple(parse_views(self.views)))
        if self.mesh_format not in ("glb", "obj"):
            raise InputError(f"mesh format must be glb or obj, got {self.mesh_format!r}")
        if not self.views:
            raise InputError("at least one view is needed")

    def key(self) -> str:
        """A digest of everything that changes the outputs: the options and the engine's code."""
        record = asdict(self)
        record["views"] = [str(v) for v in self.views]
        record["engine"] = engine_digest()
        return hashlib.sha256(json.dumps(record, sort_keys=True).encode()).hexdigest()[:16]

    def colorize_options(self) -> dict:
        """The options as keywords of :func:`imagemap.colorize`."""
        return dict(self.options)

    def config(self) -> DepthConfig:
        """The :class:`~imagemap.depth.config.DepthConfig` every object is made with."""
        return resolve_config(self.preset, **self.colorize_options())


@dataclass(frozen=True)
class Job:
    """One object of a batch: its source file, kind and outputs."""

    source: Path
    name: str
    kind: str  # "depth" or "mesh"
    output: Path
    manifest: Path


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


def plan_jobs(
    input_dir: str | os.PathLike, out_dir: str | os.PathLike, options: BatchOptions
) -> list[Job]:
    """One :class:`Job` per depth map (``NAME_depth.*``) or mesh in ``input_dir``, by name."""
    input_dir, out_dir = Path(input_dir), Path(out_dir)
    if not input_dir.exists():
        raise InputError(f"{input_dir}: input directory not found")
    if not input_dir.is_dir():
        raise InputError(f"{input_dir}: not a directory")
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"{out_dir}: output exists and is not a directory")
    jobs = []
    outputs: dict[Path, Path] = {}
    for entry in sorted(input_dir.iterdir()):
        if not entry.is_file():
            continue
        if match := _DEPTH_RE.match(entry.name):
            name, kind = match["name"], "depth"
            output = out_dir / f"{name}_image.png"
        elif entry.suffix.lower() in MESH_SUFFIXES:
            name, kind = entry.stem, "mesh"
            output = out_dir / f"{name}.{options.mesh_format}"
        else:
            continue
        if output in outputs:
            raise InputError(f"{entry}: same output {output.name} as {outputs[output].name}")
        outputs[output] = entry
        manifest = out_dir / DONE_DIR / f"{entry.name}.json"
        jobs.append(Job(entry, name, kind, output, manifest))
    if not jobs:
        raise InputError(
            f"{input_dir}: no depth maps (NAME_depth.png|tif|npy) or meshes "
            f"({', '.join(MESH_SUFFIXES)}) found"
        )
    return jobs


def _outputs_of(job: Job) -> list[Path]:
    if job.output.suffix == ".obj":
        return [job.output.with_suffix(".png"), job.output.with_suffix(".mtl"), job.output]
    return [job.output]


#: The modules whose code shapes a map or a texture. A batch resumed after one of them
#: changed (an upgrade) redoes its objects rather than mix two engines' outputs.
ENGINE_MODULES = (
    "align",
    "core",
    "database",
    "depth",
    "io",
    "mesh",
    "render",
)


@functools.cache
def engine_digest() -> str:
    """A digest of the source of :data:`ENGINE_MODULES` (the version where it is unreadable).

    The files are read beside this one, not imported: no module's import cost or side
    effects for a digest."""
    digest = hashlib.sha256()
    package = Path(__file__).parent
    try:
        for name in ENGINE_MODULES:
            # A module, or every module of a subpackage in a fixed order.
            files = [package / f"{name}.py"] if (package / f"{name}.py").exists() else []
            files = files or sorted((package / name).rglob("*.py"))
            if not files:
                raise OSError(name)
            for path in files:
                digest.update(path.relative_to(package).as_posix().encode())
                digest.update(path.read_bytes())
    except OSError:  # no source files (a frozen install)
        return f"version {imagemap.__version__}"
    return digest.hexdigest()[:16]


def is_complete(job: Job, options: BatchOptions, digest: str | None = None) -> bool:
    """True when ``job``'s manifest matches its input, the options and its outputs."""
    try:
        manifest = json.loads(job.manifest.read_text())
    except (OSError, ValueError):
        return False
    if manifest.get("options") != options.key():
        return False
    if manifest.get("input_sha256") != (digest or file_digest(job.source)):
        return False
    for name, size in manifest.get("outputs", {}).items():
        path = job.output.parent / name
        if not path.is_file() or path.stat().st_size != size:
            return False
    return bool(manifest.get("outputs"))


def _remove_stale_temporaries(job: Job) -> None:
    """Delete what a killed run left of this job's atomic writes (``.STEM.xxxx.SUFFIX``)."""
    for output in [*_outputs_of(job), job.manifest]:
        for stale in output.parent.glob(f".{output.stem}.*{output.suffix}"):
            if stale.name != output.name:
                stale.unlink(missing_ok=True)


def prepare_databases(database: Database, options: BatchOptions) -> dict[str, Database]:
    """The database with every example loaded (and mesh examples rendered), by view ("az,el")."""
    return {
        str(view): prepare_database(database_at_view(database, view, options.size))
        for view in options.views
    }


def process_job(job: Job, databases: dict[str, Database], options: BatchOptions) -> dict:
    """Synthesize one object and write its outputs, then its manifest (all atomically)."""
    # A pool's parent process and a Dask client never synthesize: the pipeline and its
    # numba kernels (2-3 s) are loaded in the workers only.
    from imagemap.depth.pipeline import colorize  # deferred: start-up (see above)

    start = time.perf_counter()
    digest = file_digest(job.source)
    if job.kind == "depth":
        depth = read_depth(job.source)
        result = colorize(
            depth,
            databases[str(options.views[0])],
            preset=options.config(),
            seed=options.seed,
        )
        picture = (
            result.rgba if options.background is None else result.on_background(options.background)
        )
        write_image(job.output, picture)
        examples = result.example_names
    else:
        mesh = load_mesh(job.source)
        made = colorize_mesh(
            mesh,
            databases,
            list(options.views),
            size=options.size,
            texture_size=options.texture_size,
            preset=options.config(),
            seed=options.seed,
        )
        export_textured(made.mesh, job.output)
        examples = sorted({n for r in made.results for n in r.example_names})
    outputs = {p.name: p.stat().st_size for p in _outputs_of(job) if p.is_file()}
    seconds = time.perf_counter() - start
    record = {
        "name": job.name,
        "source": str(job.source),
        "input_sha256": digest,
        "options": options.key(),
        "outputs": outputs,
        "examples": examples,
        "seconds": round(seconds, 3),
    }
    with atomic_path(job.manifest) as tmp:
        tmp.write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")
    return {"status": "done", **record}


def _safe_process(job: Job, databases, options: BatchOptions) -> dict:
    """:func:`process_job`, with any failure turned into a record (the batch goes on)."""
    try:
        return process_job(job, databases, options)
    except Exception as exc:  # one bad object must not stop the batch
        message = str(exc) if isinstance(exc, InputError) else f"{type(exc).__name__}: {exc}"
        if not isinstance(exc, InputError):
            log.debug("%s", traceback.format_exc())
        return {"status": "failed", "name": job.name, "source": str(job.source), "error": message}


# Worker-process state of the local pool: the prepared databases, received once.
_WORKER: dict = {}


def _init_pool_worker(databases, threads: int) -> None:
    _WORKER["databases"] = databases
    _set_threads(threads)


def _set_threads(threads: int) -> None:
    """Each worker's share of the cores for numba's parallel kernels."""
    import numba  # deferred: start-up (0.5 s; only workers set their threads)

    # numba.config makes its settings at run time from the environment (globals()), out of
    # a type checker's sight.
    most = numba.config.NUMBA_NUM_THREADS  # type: ignore[attr-defined]
    numba.set_num_threads(max(1, min(threads, most)))


def _pool_task(job: Job, options: BatchOptions) -> dict:
    return _safe_process(job, _WORKER["databases"], options)


def _dask_task(payload: bytes, databases, host_threads: dict[str, int]) -> dict:
    # Job and options travel pickled: Dask's msgpack cannot carry them (and says so).
    job, options = pickle.loads(payload)
    _set_threads(_dask_threads(host_threads))
    return _safe_process(job, databases, options)


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
    if workers < 1:
        raise InputError(f"--workers must be at least 1, got {workers}")
    jobs = plan_jobs(input_dir, out_dir, options)
    if not isinstance(database, Database):
        database = Database.from_directory(database, view=options.views[0], size=options.size)
    summary = BatchSummary()
    todo = []
    for job in jobs:
        if not force and is_complete(job, options):
            summary.skipped += 1
            summary.records.append({"status": "skipped", "name": job.name})
        else:
            todo.append(job)
            _remove_stale_temporaries(job)
    client, own_client = _connect(scheduler) if scheduler is not None and todo else (None, False)
    try:
        start = time.perf_counter()
        databases = prepare_databases(database, options) if todo else {}
        summary.prepare_seconds = time.perf_counter() - start
        if todo:
            log.info("database prepared in %.1f s", summary.prepare_seconds)
        results = _run(todo, databases, options, workers, client)
        _collect(results, len(todo), summary, quiet, on_result)
        summary.seconds = time.perf_counter() - start
    finally:
        if own_client and client is not None:  # own_client: _connect opened client
            client.close()
    _write_report(Path(out_dir), summary, options)
    return summary


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
    databases: dict[str, Database],
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


def _run_pool(
    todo: list[Job],
    databases: dict[str, Database],
    options: BatchOptions,
    workers: int,
    cores: int,
) -> Generator[dict, None, None]:
    workers = min(workers, len(todo))
    executor = ProcessPoolExecutor(
        max_workers=workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_init_pool_worker,
        initargs=(databases, max(1, cores // workers)),
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
    try:
        return Client(scheduler, timeout="20s"), True
    except OSError as exc:
        raise InputError(f"--scheduler {scheduler}: cannot connect ({exc})") from exc


def _dask_threads(host_threads: dict[str, int]) -> int:
    """This worker's share of its machine's cores (all Dask threads on a host share it)."""
    from distributed import get_worker  # deferred: optional dependency (imagemap[dask])

    address = get_worker().address
    host = address.split("://")[-1].rsplit(":", 1)[0]
    return max(1, (os.cpu_count() or 1) // max(1, host_threads.get(host, 1)))


def _run_dask(
    todo: list[Job], databases: dict[str, Database], options: BatchOptions, client: Any
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


def _write_report(out_dir: Path, summary: BatchSummary, options: BatchOptions) -> None:
    if not summary.records:
        return
    report = {
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
