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
from imagemap.database import Database
from imagemap.depth.budget import guard_mesh
from imagemap.io import InputError, atomic_path, image_writer, is_temporary_of, read_depth
from imagemap.mesh.library import ExampleSet
from imagemap.outputs import STAGING_PREFIX, write_all
from imagemap.scene import DEFAULT_SIZE, FRONT, file_digest, load_mesh

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
    # The outputs written, each with its digest (a PBR map none of the examples used has
    # is planned, not written): each must be there with the same content.
    if not isinstance(outputs, dict) or job.output.name not in outputs:
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


def prepare_databases(
    database: Database, options: BatchOptions, jobs: list[Job] | None = None
) -> ExampleSet:
    """The database as every worker needs it, needing no file (:meth:`ExampleSet.prepared`):
    every example loaded, mesh examples rendered at every view of ``options`` (the
    candidates of ``--views auto``) when a job is a mesh, every mesh example's mesh loaded
    for the uv-space path, and the front at the default size when a job is a depth map."""
    kinds = {job.kind for job in jobs} if jobs is not None else {"mesh", "depth"}
    views = options.views if "mesh" in kinds else ()
    # Each mesh's views' size (Job.size, chosen by run_batch when options.size is None).
    sizes: list[tuple[int, int]] = sorted(
        {s for job in jobs or () if job.kind == "mesh" if (s := job.size or options.size)}
    )
    if not sizes:
        sizes = [options.size or DEFAULT_SIZE]
    return ExampleSet.of(database).prepared(
        views, sizes, meshes="mesh" in kinds, pictures="depth" in kinds
    )


def process_job(job: Job, databases: ExampleSet, options: BatchOptions) -> dict:
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
        from imagemap.materials import maps_written  # deferred: start-up (see above)

        # As imagemap synthesize DEPTH reads the database: mesh examples from the front
        # at the default size.
        examples = ExampleSet.of(databases).at_view(FRONT, DEFAULT_SIZE)
        depth = read_depth(job.source)
        result = colorize(depth, examples, preset=options.config(), seed=options.seed)
        picture = (
            result.rgba if options.background is None else result.on_background(options.background)
        )
        writers = {job.output: image_writer(picture)}
        # The PBR maps, as imagemap synthesize writes them (planned: NAME_KIND.png).
        planned = {p.stem[len(job.name) + 1 :]: p for p in job.companions}
        maps, _ = maps_written(result, examples, list(planned))
        for kind, array in maps.items():
            writers[planned[kind]] = image_writer(array, bits=16 if kind == "height" else 8)
        written = write_all(writers)
        used = result.example_names
    else:
        from imagemap.mesh.route import mesh_writers, texture_mesh  # deferred: start-up

        mesh = load_mesh(job.source)
        size = job.size or options.view_size(mesh)
        # This mesh's texture (chosen from its own when not given): refused here, reported.
        guard_mesh(size, len(options.views), _texture_size(mesh, options, size), job.name)
        done = texture_mesh(mesh, ExampleSet.of(databases), options.mesh_request(size))
        writers, cleanup = mesh_writers(done, job.output, job.companions, options.scale)
        try:
            written = write_all(writers)
        finally:
            cleanup()
        used = sorted({n for r in done.made.results for n in r.example_names})
    outputs = {p.name: file_digest(p) for p in sorted(written)}
    seconds = time.perf_counter() - start
    record = {
        "name": job.name,
        "source": str(job.source),
        "input_sha256": digest,
        "options": job.options_key or options.key(),
        "settings": options.record(),
        "outputs": outputs,
        "examples": used,
        "seconds": round(seconds, 3),
    }
    with atomic_path(job.manifest) as tmp:
        tmp.write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")
    _started(job).unlink(missing_ok=True)
    return {"status": "done", **record}


def _texture_size(mesh, options: BatchOptions, size: tuple[int, int]) -> int:
    """The texture side the bake will choose for ``mesh`` seen at ``size``
    (``options.texture_size`` if set)."""
    import numpy as np  # deferred: start-up (the parent of a pool never needs it here)

    from imagemap.scene.bake import texture_size_for  # deferred: start-up (workers only)
    from imagemap.scene.views import DEFAULT_MARGIN  # deferred: start-up (workers only)

    if options.texture_size:
        return int(options.texture_size)
    extent = float(np.ptp(np.asarray(mesh.vertices), axis=0).max())
    try:
        return texture_size_for(mesh, extent / (min(size) * (1 - 2 * DEFAULT_MARGIN)))
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
