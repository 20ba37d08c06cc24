"""Batches: every depth map or mesh of a folder, on a local process pool or a Dask cluster.

:func:`run_batch` plans one job per input object (``NAME_depth.png|tif|tiff|npy``
-> ``NAME_image.png``; a mesh ``NAME.glb|obj|ply|...`` -> a textured ``NAME.glb`` or
``NAME.obj``), prepares the database once (every example's arrays loaded, mesh
examples rendered for each requested view) and ships it to the workers once: a
local process pool gets it in its initializer, a Dask cluster by
``client.scatter(..., broadcast=True)``.

Safe: every output (and what it brings: an OBJ's ``.mtl`` and texture) is checked
before any work by the same rule as ``imagemap synthesize``
(:class:`imagemap.outputs.OutputPlan`): none is an input, a file an input mesh reads,
a held-out truth beside an input (``NAME_image.png``...), a database file, or in the
database's folder; two inputs may not make one output; an existing file is replaced
only when an earlier batch here wrote it. The output folder must be writable, and is
locked for the run (a second batch into it stops at once). Paths are absolute before
they are shipped (Dask workers have their own working directories). Local workers end
when the batch's process does, even by ``kill -9``.

Resumable: an object's outputs are written as a set (all or none), then a small
manifest ``OUT/.imagemap-done/SOURCE.json`` holding the input's content hash, the
options, and each output's SHA-256; an object whose manifest matches (same input, same
options, same engine code, every output present with the recorded content) is skipped,
so an output changed or damaged since, even at the same size, is made again. Ctrl-C
writes the report and says how to resume. A failing object is reported and the others
go on. The summary counts done, skipped and failed objects and the throughput (objects
per minute).

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

import contextlib
import dataclasses
import functools
import hashlib
import json
import logging
import multiprocessing
import os
import pickle
import re
import shutil
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable, Generator, Mapping
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import imagemap
from imagemap.database import Database, database_at_view, prepare_database
from imagemap.depth.budget import guard_mesh
from imagemap.depth.config import DepthConfig, resolve_config
from imagemap.io import InputError, atomic_path, image_writer, is_temporary_of, read_depth
from imagemap.mesh.colorize import colorize_mesh
from imagemap.outputs import (
    STAGING_PREFIX,
    OutputPlan,
    check_output_directory,
    exported,
    resolve,
    write_all,
    written_companions,
)
from imagemap.progress import progress
from imagemap.scene import (
    DEFAULT_SIZE,
    FRONT,
    MESH_SUFFIXES,
    View,
    export_textured,
    file_digest,
    load_mesh,
    parse_views,
)
from imagemap.validate import check_float, check_int, check_seed

__all__ = ["BatchOptions", "BatchSummary", "Job", "plan_jobs", "prepare_databases", "run_batch"]

log = logging.getLogger("imagemap")

_DEPTH_RE = re.compile(r"^(?P<name>.+)_depth\.(?:png|tif|tiff|npy)$", re.IGNORECASE)
DONE_DIR = ".imagemap-done"
#: The smallest side of a view's depth map (``--size``'s own minimum).
MIN_VIEW_SIDE = 16


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
        if not isinstance(self.options, Mapping | tuple | list):
            raise InputError(f"options: expected a mapping of option names, got {self.options!r}")
        try:
            pairs = self.options.items() if isinstance(self.options, Mapping) else self.options
            options = tuple(sorted((str(k), v) for k, v in dict(pairs).items() if v is not None))
        except (TypeError, ValueError):
            raise InputError(
                f"options: expected (name, value) pairs, got {self.options!r}"
            ) from None
        object.__setattr__(self, "options", options)
        self.config()  # refuses a bad preset, option or combination now
        check_seed(self.seed)
        if isinstance(self.views, str):
            object.__setattr__(self, "views", tuple(parse_views(self.views)))
        if isinstance(self.views, View) or not all(isinstance(v, View) for v in self.views):
            raise InputError(f"views: expected a sequence of View or a string, got {self.views!r}")
        object.__setattr__(self, "views", tuple(self.views))
        if not self.views:
            raise InputError("views: at least one view is needed")
        if len(set(self.views)) != len(self.views):
            raise InputError(f"views: a view is given twice in {[str(v) for v in self.views]}")
        if not (isinstance(self.size, tuple | list) and len(self.size) == 2):
            raise InputError(f"size: expected (width, height), got {self.size!r}")
        size = tuple(check_int("size", v, minimum=MIN_VIEW_SIDE) for v in self.size)
        object.__setattr__(self, "size", size)
        if self.texture_size is not None:
            check_int("texture_size", self.texture_size, minimum=1)
        if self.mesh_format not in ("glb", "obj"):
            raise InputError(f"mesh format must be glb or obj, got {self.mesh_format!r}")
        if self.background is not None:
            colour = tuple(check_float("background", c, 0.0, 1.0) for c in self.background)
            if len(colour) != 3:
                raise InputError(f"background: expected (r, g, b) in [0, 1], got {colour}")
            object.__setattr__(self, "background", colour)

    def record(self) -> dict:
        """The options as a JSON-ready dict (what a manifest records beside :meth:`key`)."""
        record = asdict(self)
        record["views"] = [str(v) for v in self.views]
        return record

    def key(self) -> str:
        """A digest of everything that changes the outputs: the options and the engine's code."""
        record = self.record()
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
    companions: tuple[Path, ...] = ()  # written with the output (an OBJ's .mtl and texture)
    # BatchOptions.key() as the batch's process computed it: a worker started later would
    # digest the engine's files as they are then (an upgrade mid-batch), not as they were.
    options_key: str = ""


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
    """One :class:`Job` per depth map (``NAME_depth.*``) or mesh in ``input_dir``, by name.

    Every path is absolute (a Dask worker resolves a relative one against its own working
    directory). Two inputs whose outputs meet (``a_depth.png`` and ``a.npy``, or a depth
    ``a_depth.png`` and an OBJ mesh ``a_image.obj``, whose texture is ``a_image.png``) are
    an :class:`InputError` naming both.
    """
    shown_input = input_dir
    input_dir, out_dir = resolve(input_dir), resolve(out_dir)
    if not input_dir.exists():
        raise InputError(f"{shown_input}: input directory not found")
    if not input_dir.is_dir():
        raise InputError(f"{shown_input}: not a directory")
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"{out_dir}: output exists and is not a directory")
    jobs = []
    outputs: dict[Path, Path] = {}
    try:
        entries = sorted(input_dir.iterdir())
    except OSError as exc:
        raise InputError(f"{shown_input}: cannot be listed ({exc.strerror or exc})") from None
    for entry in entries:
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
        companions = tuple(written_companions(output))
        for path in (output, *companions):
            if path in outputs:
                raise InputError(
                    f"{entry} and {outputs[path]} would both write {path.name} in {out_dir}: "
                    "rename one of them"
                )
            outputs[path] = entry
        manifest = out_dir / DONE_DIR / f"{entry.name}.json"
        jobs.append(Job(entry, name, kind, output, manifest, companions))
    if not jobs:
        raise InputError(
            f"{input_dir}: no depth maps (NAME_depth.png|tif|npy) or meshes "
            f"({', '.join(MESH_SUFFIXES)}) found"
        )
    return jobs


def _outputs_of(job: Job) -> list[Path]:
    return [*job.companions, job.output]


def _names(job: Job) -> list[str]:
    return [p.name for p in _outputs_of(job)]


def _started(job: Job) -> Path:
    """Where a job records, before writing, the outputs it is about to write."""
    return job.manifest.with_name(job.manifest.name + ".started")


#: The batch's summary, written into the output folder.
REPORT_NAME = "batch_report.json"


def _claimed(out_dir: Path) -> list[Path]:
    """The files an earlier batch wrote into ``out_dir``: every output its manifests name
    (finished or started), and its report."""
    claimed = []
    done = out_dir / DONE_DIR
    manifests = [*done.glob("*.json"), *done.glob("*.json.started")] if done.is_dir() else []
    for manifest in sorted(manifests):
        try:
            record = json.loads(manifest.read_text())
        except (OSError, ValueError):
            continue
        if isinstance(record, dict):
            names = [*(record.get("outputs") or {}), *(record.get("planned") or [])]
            claimed += [out_dir / str(name) for name in names if Path(str(name)).name == name]
    report = out_dir / REPORT_NAME
    try:
        if {"done", "objects"} <= set(json.loads(report.read_text())):
            claimed.append(report)
    except (OSError, ValueError, TypeError):
        pass
    return claimed


def check_outputs(
    jobs: list[Job], database: Database, out_dir: str | os.PathLike, database_dir=None
) -> None:
    """Every output of a batch checked before any work (see the module docstring).

    Raises
    ------
    InputError
        Naming the output and what it would replace, or the folder that cannot be written.
    """
    out_dir = resolve(out_dir)
    check_output_directory(out_dir, "-o directory")
    plan = OutputPlan()
    for job in jobs:
        plan.add_query(job.source, f"input {job.kind}")
    if database_dir is None and database.source and Path(database.source).is_dir():
        database_dir = database.source
    plan.add_database(database, database_dir)
    for job in jobs:
        plan.add_output(job.output, "-o", companions=job.companions, fresh=True)
    plan.add_output(out_dir / REPORT_NAME, "the batch report", fresh=True)
    plan.claim(_claimed(out_dir))
    plan.check()


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
    """True when ``job``'s manifest matches its input, the options and its outputs' content.

    Each output's SHA-256 is compared with the manifest's: an output changed or damaged
    since it was written (even at the same size) makes the object incomplete.
    """
    try:
        manifest = json.loads(job.manifest.read_text())
    except (OSError, ValueError):
        return False
    if not isinstance(manifest, dict) or manifest.get("options") != options.key():
        return False
    if manifest.get("input_sha256") != (digest or file_digest(job.source)):
        return False
    outputs = manifest.get("outputs")
    if not isinstance(outputs, dict) or set(outputs) != {p.name for p in _outputs_of(job)}:
        return False
    for name, recorded in outputs.items():
        path = job.output.parent / name
        if not path.is_file() or not isinstance(recorded, str) or file_digest(path) != recorded:
            return False
    return True


def _remove_stale_temporaries(job: Job) -> None:
    """Delete what a killed run left of this job's writes: temporary files named by
    :func:`imagemap.io.make_temporary` for its outputs and manifest, and staging folders
    (never a user's ``.NAME.*.png``)."""
    for output in [*_outputs_of(job), job.manifest]:
        if not output.parent.is_dir():
            continue
        for stale in output.parent.glob(f".{output.stem}.*"):
            if is_temporary_of(stale, output):
                stale.unlink(missing_ok=True)
    for staging in job.output.parent.glob(f"{STAGING_PREFIX}*"):
        if staging.is_dir() and (staging / job.output.name).exists():
            shutil.rmtree(staging, ignore_errors=True)


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
    # Started: the outputs about to be written are this batch's (a rerun may replace them).
    started = {"name": job.name, "source": str(job.source), "planned": _names(job)}
    with atomic_path(_started(job)) as tmp:
        tmp.write_text(json.dumps(started, indent=1, sort_keys=True) + "\n")
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
        write_all({job.output: image_writer(picture)})
        examples = result.example_names
    else:
        mesh = load_mesh(job.source)
        # This mesh's texture (chosen from its own when not given): refused here, reported.
        guard_mesh(options.size, len(options.views), _texture_size(mesh, options), job.name)
        made = colorize_mesh(
            mesh,
            databases,
            list(options.views),
            size=options.size,
            texture_size=options.texture_size,
            preset=options.config(),
            seed=options.seed,
        )
        writers, cleanup = exported(
            lambda path: export_textured(made.mesh, path), job.output, job.companions
        )
        try:
            write_all(writers)
        finally:
            cleanup()
        examples = sorted({n for r in made.results for n in r.example_names})
    outputs = {p.name: file_digest(p) for p in _outputs_of(job) if p.is_file()}
    seconds = time.perf_counter() - start
    record = {
        "name": job.name,
        "source": str(job.source),
        "input_sha256": digest,
        "options": job.options_key or options.key(),
        "settings": options.record(),
        "outputs": outputs,
        "examples": examples,
        "seconds": round(seconds, 3),
    }
    with atomic_path(job.manifest) as tmp:
        tmp.write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")
    _started(job).unlink(missing_ok=True)
    return {"status": "done", **record}


def _texture_size(mesh, options: BatchOptions) -> int:
    """The texture side the bake will choose for ``mesh`` (``options.texture_size`` if set)."""
    import numpy as np  # deferred: start-up (the parent of a pool never needs it here)

    from imagemap.scene.bake import texture_size_for  # deferred: start-up (workers only)
    from imagemap.scene.views import DEFAULT_MARGIN  # deferred: start-up (workers only)

    if options.texture_size:
        return int(options.texture_size)
    extent = float(np.ptp(np.asarray(mesh.vertices), axis=0).max())
    try:
        return texture_size_for(mesh, extent / (min(options.size) * (1 - 2 * DEFAULT_MARGIN)))
    except InputError:  # no usable UVs: the bake says so itself
        return 512


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
    check_outputs(jobs, database, out_dir, database_dir)  # before any work
    if any(job.kind == "mesh" for job in jobs):  # the views and texture every mesh will have
        guard_mesh(options.size, len(options.views), options.texture_size or 512, "each mesh")
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
    todo = [dataclasses.replace(job, options_key=key) for job in todo]
    # The scheduler answers (or not) before anything is written into the output folder.
    client, own = _connect(scheduler) if scheduler is not None and todo else (None, False)
    start = time.perf_counter()
    try:
        with _locked(out_dir):
            for job in todo:
                _remove_stale_temporaries(job)
            try:
                databases = prepare_databases(database, options) if todo else {}
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


def _is_client(value) -> bool:
    client = sys.modules.get("distributed")
    return client is not None and isinstance(value, client.Client)


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


#: The lock file of an output folder (inside :data:`DONE_DIR`): held while a batch writes.
LOCK_NAME = "lock"


@contextlib.contextmanager
def _locked(out_dir: Path):
    """Hold ``out_dir``'s lock for the batch; another batch holding it is an InputError.

    An advisory ``flock`` on ``OUT/.imagemap-done/lock``: the system releases it when the
    holder ends, however it ends, so a killed batch never leaves a stale lock."""
    try:
        import fcntl  # deferred: optional dependency (POSIX only; no lock elsewhere)
    except ImportError:
        yield
        return
    folder = out_dir / DONE_DIR
    folder.mkdir(parents=True, exist_ok=True)
    handle = open(folder / LOCK_NAME, "a+")  # noqa: SIM115 (held for the whole batch)
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.seek(0)
            holder = handle.read().strip() or "unknown"
            raise InputError(
                f"{out_dir}: another batch is writing into this folder (process {holder}); "
                "wait for it to finish, or give another -o"
            ) from None
        handle.seek(0)
        handle.truncate()
        handle.write(f"{os.getpid()}\n")
        handle.flush()
        yield
    finally:
        handle.close()


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
        error = outcome["error"]  # not 'exc': that name is the except clause's above
        raise InputError(
            f"--scheduler {scheduler}: cannot connect ({type(error).__name__}: {error})"
        ) from None
    return outcome["client"], True


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
