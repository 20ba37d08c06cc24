"""One object's work: synthesize it and write its outputs and manifest (:func:`process_job`);
whether a finished object's manifest still matches (:func:`is_complete`).
"""

from __future__ import annotations

import json
import logging
import shutil
import time
import traceback

from imagemap.batch.plan import BatchOptions, Job, _names, _outputs_of, _started
from imagemap.database import Database, database_at_view, prepare_database
from imagemap.depth.budget import guard_mesh
from imagemap.io import InputError, atomic_path, image_writer, is_temporary_of, read_depth
from imagemap.mesh.colorize import colorize_mesh
from imagemap.outputs import STAGING_PREFIX, exported, write_all
from imagemap.scene import export_textured, file_digest, load_mesh

__all__ = ["is_complete", "prepare_databases", "process_job"]

log = logging.getLogger("imagemap")


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


def _set_threads(threads: int) -> None:
    """Each worker's share of the cores for numba's parallel kernels."""
    import numba  # deferred: start-up (0.5 s; only workers set their threads)

    # numba.config makes its settings at run time from the environment (globals()), out of
    # a type checker's sight.
    most = numba.config.NUMBA_NUM_THREADS  # type: ignore[attr-defined]
    numba.set_num_threads(max(1, min(threads, most)))
