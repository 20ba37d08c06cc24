"""Leave-one-out evaluation of image-map synthesis, with baselines and a static report.

For every object of a database, its image-map is synthesized from the other
objects only (automatic selection of the examples, the class preset) and
compared with its true image-map over its mask (:mod:`imagemap.metrics`). The
same objects are run through four baselines, so that the table shows what each
part of the method is worth:

============== ==================================================================
``full``        the method: a pyramid, hard EM, depth + colour +
                relative position (the class preset as it is)
``copy_nearest`` the nearest example's image-map (``select_examples`` with m=1)
                translated so that its centroid falls on the query's; query
                pixels it does not cover stay black (Fig. 2d of the paper)
``one_pass``    one pass of depth-only matching and voting (Fig. 1 of the
                paper): a single level at full resolution with the preset's
                finest window width, no EM (``max_iterations=0``), no position
                term, the paper's mean vote
``mean_vote``   the full method with the paper's M-step (``vote="mean"``: each
                pixel the weighted mean of its windows) instead of the seam-
                blended copy
``no_position`` the full method with ``position_weight=0``
``laplacian``   the full method on the paper's YCbCr Laplacian bands instead
                of each level's plain colours
                (``appearance_pyramid="laplacian"``)
============== ==================================================================

Objects are independent and run in a process pool; an object whose synthesis
fails is reported (:attr:`Evaluation.failed`) and the others go on. The report
files are written by :mod:`imagemap.report`. The faulty verdict uses the
class reference of :func:`imagemap.metrics.class_reference` (medians of the
metrics of members' maps pasted onto each other), computed once per class from
the whole database.

Besides the three metrics of the results table, every method result carries
``metrics.part_transfer``: the fraction of object pixels whose colour was taken
from the same part of an example (the part label at the matched source pixel
of the finest level equals the query's true part label; for ``copy_nearest``
the pasted labels). It does not depend on the query's palette, which no method
can know, so it isolates whether the right *kinds* of colour went to the right
places.

Example
-------
>>> from imagemap.database import Database
>>> db = Database.from_directory("fish_db")  # doctest: +SKIP
>>> from imagemap.report import write_report
>>> evaluation = leave_one_out(db, preset="fish", workers=2)  # doctest: +SKIP
>>> write_report(evaluation, "report/")  # doctest: +SKIP
"""

from __future__ import annotations

import logging
import os
import re
import time
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field, replace
from multiprocessing import get_context

import numpy as np

from imagemap.align import aligned_source, paste_aligned
from imagemap.core.blend import copy_through, fill_background
from imagemap.database import Database, Example
from imagemap.depth.config import METHODS, PRESETS, DepthConfig, resolve_config
from imagemap.depth.pipeline import colorize, warp_nearest
from imagemap.depth.selection import select_examples
from imagemap.io import InputError
from imagemap.metrics import (
    FaultyRule,
    ImageMetrics,
    blur_ratio,
    class_reference,
    coherence_metrics,
    image_metrics,
    macro_part_transfer,
    source_labels,
)
from imagemap.progress import progress
from imagemap.validate import check_int, check_seed

__all__ = [
    "Evaluation",
    "MethodResult",
    "ObjectEvaluation",
    "class_of",
    "evaluate_object",
    "leave_one_out",
    "method_params",
]

log = logging.getLogger("imagemap")


@dataclass
class MethodResult:
    """One method's result on one object.

    Attributes
    ----------
    method : str
    image : ndarray, (H, W, 3) float32
        The synthesized image-map (background 0).
    metrics : ImageMetrics
        With ``part_transfer``: fraction of object pixels whose colour came from
        the same part of an example (NaN without labels).
    seconds : float
        Wall time of the synthesis (for ``copy_nearest``: selection and paste).
    examples : list of str
        The examples used.
    provenance : ndarray or None
        Provenance picture (engine methods only).
    legend : list of (str, tuple)
        Example name and its tint in the provenance picture.
    faulty : bool
        Set by :func:`leave_one_out` from the class's :class:`FaultyRule`.
    """

    method: str
    image: np.ndarray
    metrics: ImageMetrics
    seconds: float
    examples: list[str]
    provenance: np.ndarray | None = None
    legend: list = field(default_factory=list)
    faulty: bool = False


@dataclass
class ObjectEvaluation:
    """All methods' results on one object, with its depth and truth."""

    name: str
    class_name: str
    depth: np.ndarray
    truth: np.ndarray
    mask: np.ndarray
    results: dict[str, MethodResult]


@dataclass
class Evaluation:
    """A leave-one-out run: per-object results and the per-class faulty rules.

    ``objects`` holds the objects that were evaluated; ``failed`` the ``(name,
    message)`` of those whose evaluation raised, in database order; ``interrupted``
    is set when Ctrl-C stopped the run (``objects`` then holds those finished).
    """

    objects: list[ObjectEvaluation]
    rules: dict[str, FaultyRule]
    reference: dict[str, dict]
    presets: dict[str, str]
    methods: tuple[str, ...]
    seed: int = 0
    seconds: float = 0.0
    workers: int = 1
    examples: dict[str, np.ndarray] = field(default_factory=dict)
    failed: list[tuple[str, str]] = field(default_factory=list)
    interrupted: bool = False

    def rows(self) -> list[dict]:
        """One dict per object x method with the columns of ``results.csv``."""
        rows = []
        for obj in self.objects:
            for method in self.methods:
                result = obj.results[method]
                rows.append(
                    {
                        "object": obj.name,
                        "method": method,
                        "ciede2000": result.metrics.ciede2000,
                        "ssim": result.metrics.ssim,
                        "part_accuracy": result.metrics.part_accuracy,
                        "part_transfer": result.metrics.part_transfer,
                        "part_transfer_macro": result.metrics.part_transfer_macro,
                        "features_drawn": result.metrics.features_drawn,
                        "features_measured": result.metrics.features_measured,
                        "blur_ratio": result.metrics.blur_ratio,
                        "fragments_90": result.metrics.fragments_90,
                        "fragment_share": result.metrics.fragment_share,
                        "seam_length": result.metrics.seam_length,
                        "continuity": result.metrics.continuity,
                        "midtone_ratio": result.metrics.midtone_ratio,
                        "parts_one_palette": result.metrics.parts_one_palette,
                        "parts_palette_measured": result.metrics.parts_palette_measured,
                        "faulty": result.faulty,
                        "seconds": result.seconds,
                    }
                )
        return rows


def class_of(example: Example) -> str:
    """The class of an example: its JSON ``class`` field, else its name less a numeric suffix."""
    name = example.info.get("class") if example.json_path is not None else None
    if isinstance(name, str) and name:
        return name
    return re.sub(r"[_-]?\d+$", "", example.name) or example.name


def method_params(method: str, config: DepthConfig) -> DepthConfig | None:
    """The configuration of an engine method (None for ``copy_nearest``).

    Parameters
    ----------
    method : str
        One of :data:`METHODS`.
    config : DepthConfig
        The class preset (with the options the run was given).

    Returns
    -------
    DepthConfig or None

    Example
    -------
    >>> method_params("one_pass", PRESETS["fish"]).pyramid.patch_sizes
    (7,)
    >>> method_params("paper", PRESETS["fish"]).finish.vote
    'mean'
    """
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; use some of {', '.join(METHODS)}")
    make = METHODS[method]
    return None if make is None else make(config)


def _copy_nearest(depth: np.ndarray, others: Database) -> tuple:
    """The nearest example's map pasted at the query's centroid, and its source map."""
    mask = depth > 0
    nearest = others[select_examples(depth, others, 1)[0]]
    image = paste_aligned(nearest.image, nearest.mask, mask)
    return image, aligned_source(nearest.mask, mask), [nearest.name]


def _detail_metrics(
    metrics: ImageMetrics,
    image: np.ndarray,
    source: np.ndarray,
    mask: np.ndarray,
    labels: np.ndarray | None,
    examples: list[Example],
    truth: np.ndarray | None = None,
) -> ImageMetrics:
    """Add the measures that need the source map: part transfer (micro and macro), blur,
    and (given the truth) the coherence measures of :func:`imagemap.metrics.coherence_metrics`."""
    if truth is not None:
        metrics = coherence_metrics(metrics, image, truth, mask, source, labels)
    covered = mask & (source[..., 0] >= 0)
    # Copied from the examples as the synthesis sees them (object colours continued
    # past their outlines): a source pixel at an example's edge would otherwise bring
    # background into the reference and count as detail.
    filled = [fill_background(e.image, e.mask) for e in examples]
    copy = copy_through(filled, source).astype(np.float32)
    copy[~mask] = 0.0  # as the map's own background
    blur = blur_ratio(image, copy, covered, source)
    example_labels = _example_labels(examples)
    if labels is None or example_labels is None:
        return replace(metrics, blur_ratio=blur)
    transferred = source_labels(source, example_labels, mask)
    return replace(
        metrics,
        part_transfer=float(np.mean(transferred[mask] == labels[mask])),
        part_transfer_macro=macro_part_transfer(transferred, labels, mask),
        blur_ratio=blur,
    )


def _example_labels(examples: list[Example]) -> list[np.ndarray] | None:
    """The examples' part labels, or None unless every example has them."""
    labels = [e.labels for e in examples if e.labels is not None]
    return labels if len(labels) == len(examples) else None


def evaluate_object(
    database: Database,
    name: str,
    *,
    preset: str | DepthConfig = "fish",
    methods: tuple[str, ...] = tuple(METHODS),
    seed: int = 0,
) -> ObjectEvaluation:
    """Leave-one-out results of every method on one object of ``database``.

    Parameters
    ----------
    database : Database
        The whole database; the object is left out of it for its own synthesis.
    name : str
        The object.
    preset : str or DepthConfig
        Class preset of the engine methods.
    methods : tuple of str
        Some of :data:`METHODS`.
    seed : int
        Seed of every synthesis.

    Returns
    -------
    ObjectEvaluation
        With ``faulty`` unset (the class rule is applied by :func:`leave_one_out`).

    Example
    -------
    >>> obj = evaluate_object(db, "fish_003", preset="fish")  # doctest: +SKIP
    >>> obj.results["full"].metrics.ciede2000  # doctest: +SKIP
    """
    params = resolve_config(preset)
    example = database[name]
    others = database.without(name)
    if len(others) == 0:
        raise InputError(f"{database.source or 'database'}: leave-one-out needs two examples")
    depth, truth, mask, labels = example.depth, example.image, example.mask, example.labels
    results = {}
    for method in methods:
        start = time.perf_counter()
        engine_params = method_params(method, params)
        provenance, legend = None, []
        if method == "warp_nearest":
            warped = warp_nearest(depth, others, preset=params, seed=seed, quiet=True)
            image, source, used = warped.image, warped.source, warped.example_names
            provenance, legend = warped.provenance, warped.legend
        elif engine_params is None:
            image, source, used = _copy_nearest(depth, others)
        else:
            colorized = colorize(depth, others, preset=engine_params, seed=seed, quiet=True)
            image, source, used = colorized.image, colorized.source, colorized.example_names
            provenance, legend = colorized.provenance, colorized.legend
        seconds = time.perf_counter() - start
        sources = [others[n] for n in used]
        measured = image_metrics(
            image, truth, mask, labels, source=source, example_labels=_example_labels(sources)
        )
        metrics = _detail_metrics(measured, image, source, mask, labels, sources, truth)
        results[method] = MethodResult(
            method=method,
            image=image.astype(np.float32),
            metrics=metrics,
            seconds=seconds,
            examples=list(used),
            provenance=provenance,
            legend=legend,
        )
    return ObjectEvaluation(
        name=name,
        class_name=class_of(example),
        depth=depth,
        truth=truth,
        mask=mask,
        results=results,
    )


def _init_worker(threads: int) -> None:
    # Each worker gets its share of the cores for numba's parallel kernels.
    import numba  # deferred: only pool workers set their thread count

    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))  # type: ignore[attr-defined]


def _task(args: tuple) -> ObjectEvaluation:
    database, name, preset, methods, seed = args
    return evaluate_object(database, name, preset=preset, methods=methods, seed=seed)


def leave_one_out(
    database: Database,
    *,
    preset: str | DepthConfig | None = None,
    methods: tuple[str, ...] | list[str] = tuple(METHODS),
    workers: int = 1,
    limit: int | None = None,
    seed: int = 0,
    quiet: bool = True,
    options: dict | None = None,
) -> Evaluation:
    """Leave-one-out evaluation of every object of ``database`` with every method.

    Parameters
    ----------
    database : Database
        At least two examples of the same size; labels (``NAME_labels.png``) and a
        JSON ``class`` field are used where present.
    preset : str or DepthConfig, optional
        The configuration; by default each class's preset of the same name
        (``"busts"`` for a class with no preset of its name).
    methods : sequence of str
        Some of :data:`METHODS` (all by default).
    workers : int
        Processes; 1 runs in this process. Workers are spawned (not forked), so a
        script that calls this with ``workers > 1`` must guard its top level with
        ``if __name__ == "__main__":``, as for any ``multiprocessing`` spawn.
    limit : int, optional
        Evaluate only the first ``limit`` objects (each still synthesized from all
        the others).
    seed : int
        Seed of every synthesis; results do not depend on ``workers``.
    quiet : bool
        No progress bar.
    options : dict, optional
        :data:`imagemap.depth.config.OPTIONS` by name, applied to every class's
        preset before the methods derive from it.

    Returns
    -------
    Evaluation
        An object whose evaluation raises is listed in ``failed`` with its message
        and the others go on. On Ctrl-C the running objects are abandoned (the
        worker processes stopped) and the evaluation of those finished is returned
        with ``interrupted`` set, so that its report can still be written.

    Example
    -------
    >>> from imagemap.report import summarize
    >>> evaluation = leave_one_out(db, workers=2, limit=4)  # doctest: +SKIP
    >>> summarize(evaluation)["fish"]["full"]["ciede2000"]  # doctest: +SKIP
    """
    methods = tuple(methods)
    for method in methods:
        method_params(method, PRESETS["busts"])  # raises on an unknown name
    if not methods:
        raise InputError("no methods to evaluate")
    if len(database) < 2:
        raise InputError(f"{database.source or 'database'}: leave-one-out needs two examples")
    workers = check_int("workers", workers, minimum=1)
    if limit is not None:
        limit = check_int("limit", limit, minimum=1)
    seed = check_seed(seed)
    start = time.perf_counter()
    shapes = {e.depth.shape for e in database}
    if len(shapes) > 1:
        raise InputError(
            f"{database.source or 'database'}: examples differ in size ({sorted(shapes)}); "
            "leave-one-out needs one size"
        )
    classes: dict[str, list[Example]] = {}
    for example in database:
        classes.setdefault(class_of(example), []).append(example)
    presets: dict[str, str] = {}
    rules: dict[str, FaultyRule] = {}
    reference: dict[str, dict] = {}
    for class_name, members in classes.items():
        if isinstance(preset, DepthConfig):
            presets[class_name] = "custom"
        else:
            presets[class_name] = preset or (class_name if class_name in PRESETS else "busts")
            if presets[class_name] not in PRESETS:
                raise InputError(f"unknown preset {preset!r}; use one of {sorted(PRESETS)}")
        if len(members) >= 2:
            rules[class_name], reference[class_name] = class_reference(members, seed=seed)
        else:
            rules[class_name], reference[class_name] = FaultyRule(), {"pairs": 0}
    names = database.names[:limit] if limit else database.names
    tasks = []
    for name in names:
        class_name = class_of(database[name])
        chosen = preset if isinstance(preset, DepthConfig) else presets[class_name]
        tasks.append((database, name, resolve_config(chosen, **(options or {})), methods, seed))

    results: dict[str, ObjectEvaluation] = {}
    errors: dict[str, str] = {}
    interrupted = False
    bar = progress(range(len(tasks)), total=len(tasks), desc="objects", quiet=quiet)
    try:
        if workers == 1 or len(tasks) == 1:
            for task in tasks:
                try:
                    results[task[1]] = _task(task)
                except Exception as exc:  # one failing object is reported, the rest go on
                    errors[task[1]] = _failure(task[1], exc)
                next(bar, None)
        else:
            _run_pool(tasks, workers, results, errors, bar)
    except KeyboardInterrupt:
        interrupted = True
        log.warning(
            "interrupted: %d of %d objects evaluated", len(results) + len(errors), len(tasks)
        )
    finally:
        bar.close()
    objects = [results[name] for name in names if name in results]
    failed = [(name, errors[name]) for name in names if name in errors]
    for obj in objects:
        for result in obj.results.values():
            result.faulty = rules[obj.class_name].is_faulty(result.metrics)
    used = sorted({n for obj in objects for r in obj.results.values() for n in r.examples})
    return Evaluation(
        objects=objects,
        rules=rules,
        reference=reference,
        presets=presets,
        methods=methods,
        seed=seed,
        seconds=time.perf_counter() - start,
        workers=workers,
        examples={n: database[n].image for n in used},
        failed=failed,
        interrupted=interrupted,
    )


def _failure(name: str, exc: Exception) -> str:
    """The message of a failed object (logged with its traceback at debug level)."""
    log.debug("%s: evaluation failed", name, exc_info=exc)
    text = str(exc)
    return text if isinstance(exc, InputError) and text else f"{type(exc).__name__}: {text}"


def _run_pool(
    tasks: list[tuple],
    workers: int,
    results: dict[str, ObjectEvaluation],
    errors: dict[str, str],
    bar,
) -> None:
    """Evaluate ``tasks`` in spawned worker processes, filling ``results`` and ``errors``.

    On any interruption (Ctrl-C) the queued objects are cancelled and the workers
    stopped before the exception goes on: nothing is left running.
    """
    # spawn: a forked child would inherit numba's and OpenBLAS's thread pools.
    pool = ProcessPoolExecutor(
        max_workers=min(workers, len(tasks)),
        mp_context=get_context("spawn"),
        initializer=_init_worker,
        initargs=((os.cpu_count() or 1) // workers,),
    )
    futures: dict[Future, str] = {}
    try:
        futures = {pool.submit(_task, task): task[1] for task in tasks}
        for future in as_completed(futures):
            name = futures[future]
            try:
                results[name] = future.result()
            except Exception as exc:  # a worker that died (BrokenProcessPool) too
                errors[name] = _failure(name, exc)
            next(bar, None)
    except BaseException:
        for future in futures:
            future.cancel()
        # The running objects are abandoned: their workers are stopped now rather
        # than waited for (ProcessPoolExecutor has no public way to do this).
        processes = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            process.terminate()
        raise
    pool.shutdown()
