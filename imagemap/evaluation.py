"""Leave-one-out evaluation of image-map synthesis, with baselines and a static report.

For every object of a database, its image-map is synthesized from the other
objects only (automatic selection of the examples, the class preset) and
compared with its true image-map over its mask (:mod:`imagemap.metrics`). The
same objects are run through four baselines, so that the table shows what each
part of the method is worth:

============== ==================================================================
``full``        the method: three-level pyramid, hard EM, depth + colour +
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
``no_pyramid``  the full method on plain YCbCr at every level instead of
                Laplacian bands (``use_pyramid=False``)
============== ==================================================================

Objects are independent and run in a process pool. The faulty verdict uses the
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
>>> evaluation = leave_one_out(db, preset="fish", workers=2)  # doctest: +SKIP
>>> write_report(evaluation, "report/")  # doctest: +SKIP
"""

from __future__ import annotations

import csv
import html
import io
import logging
import math
import os
import re
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field, replace
from html.parser import HTMLParser
from multiprocessing import get_context
from pathlib import Path

import numpy as np

from imagemap.blend import copy_through
from imagemap.colorization import (
    PRESETS,
    ColorizeParams,
    centroid_shift,
    colorize,
    select_examples,
)
from imagemap.database import Database, Example
from imagemap.io import InputError, atomic_path, write_image
from imagemap.metrics import (
    FaultyRule,
    ImageMetrics,
    blur_ratio,
    class_reference,
    features_drawn,
    image_metrics,
    macro_part_transfer,
    paste_aligned,
    source_labels,
)
from imagemap.progress import progress

__all__ = [
    "METHODS",
    "Evaluation",
    "MethodResult",
    "ObjectEvaluation",
    "check_report",
    "class_of",
    "evaluate_object",
    "leave_one_out",
    "method_params",
    "summarize",
    "write_report",
]

log = logging.getLogger("imagemap")

#: Method names, in report order.
METHODS: tuple[str, ...] = (
    "full",
    "copy_nearest",
    "one_pass",
    "mean_vote",
    "no_position",
    "no_pyramid",
)

CSV_COLUMNS = (
    "object",
    "method",
    "ciede2000",
    "ssim",
    "part_accuracy",
    "part_transfer",
    "part_transfer_macro",
    "features_drawn",
    "features_measured",
    "blur_ratio",
    "faulty",
    "seconds",
)

#: Grey behind the objects in report pictures, so that black object pixels
#: (holes of copy_nearest) stand out from the background.
_BACKDROP = 0.82


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
    """A leave-one-out run: per-object results and the per-class faulty rules."""

    objects: list[ObjectEvaluation]
    rules: dict[str, FaultyRule]
    reference: dict[str, dict]
    presets: dict[str, str]
    methods: tuple[str, ...]
    seed: int = 0
    seconds: float = 0.0
    workers: int = 1
    examples: dict[str, np.ndarray] = field(default_factory=dict)

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


def method_params(method: str, params: ColorizeParams) -> ColorizeParams | None:
    """The engine parameters of an engine method (None for ``copy_nearest``).

    Parameters
    ----------
    method : str
        One of :data:`METHODS`.
    params : ColorizeParams
        The class preset.

    Returns
    -------
    ColorizeParams or None

    Example
    -------
    >>> method_params("one_pass", PRESETS["fish"]).patch_sizes
    (7,)
    """
    if method == "full":
        return params
    if method == "copy_nearest":
        return None
    if method == "one_pass":
        # Fig. 1: one scale, windows of the paper's k, depth only, one vote.
        return replace(
            params,
            patch_sizes=params.patch_sizes[:1],
            max_iterations=0,
            position_weight=0.0,
            vote="mean",
            grow_pyramid=False,  # one level: Fig. 1 has no pyramid
        )
    if method == "mean_vote":
        return replace(params, vote="mean")
    if method == "no_position":
        return replace(params, position_weight=0.0)
    if method == "no_pyramid":
        return replace(params, use_pyramid=False)
    raise InputError(f"unknown method {method!r}; use some of {', '.join(METHODS)}")


def _copy_nearest(depth: np.ndarray, others: Database) -> tuple:
    """The nearest example's map pasted at the query's centroid, and its source map."""
    mask = depth > 0
    nearest = others[select_examples(depth, others, 1)[0]]
    image = paste_aligned(nearest.image, nearest.mask, mask)
    dy, dx = (int(round(s)) for s in centroid_shift(nearest.mask, mask))
    yy, xx = np.mgrid[0 : mask.shape[0], 0 : mask.shape[1]]
    sy, sx = yy - dy, xx - dx
    inside = (sy >= 0) & (sy < nearest.mask.shape[0]) & (sx >= 0) & (sx < nearest.mask.shape[1])
    covered = np.zeros_like(mask)
    covered[inside] = nearest.mask[sy[inside], sx[inside]]
    source = np.stack([np.where(covered, 0, -1), np.clip(sy, 0, None), np.clip(sx, 0, None)], -1)
    return image, source.astype(np.int32), [nearest.name]


def _detail_metrics(
    metrics: ImageMetrics,
    image: np.ndarray,
    truth: np.ndarray,
    source: np.ndarray,
    mask: np.ndarray,
    labels: np.ndarray | None,
    examples: list[Example],
) -> ImageMetrics:
    """Add the measures that need the source map: part transfer (micro and macro), blur,
    and small features drawn judged by their sources too."""
    covered = mask & (source[..., 0] >= 0)
    copy = copy_through([e.image for e in examples], source).astype(np.float32)
    copy[~mask] = 0.0  # as the map's own background
    blur = blur_ratio(image, copy, covered)
    if labels is None or any(e.labels is None for e in examples):
        return replace(metrics, blur_ratio=blur)
    transferred = source_labels(source, [e.labels for e in examples], mask)
    drawn, measured = features_drawn(
        image, truth, labels, mask, source=source, example_labels=[e.labels for e in examples]
    )
    return replace(
        metrics,
        features_drawn=drawn,
        features_measured=measured,
        part_transfer=float(np.mean(transferred[mask] == labels[mask])),
        part_transfer_macro=macro_part_transfer(transferred, labels, mask),
        blur_ratio=blur,
    )


def evaluate_object(
    database: Database,
    name: str,
    *,
    preset: str | ColorizeParams = "fish",
    methods: tuple[str, ...] = METHODS,
    seed: int = 0,
) -> ObjectEvaluation:
    """Leave-one-out results of every method on one object of ``database``.

    Parameters
    ----------
    database : Database
        The whole database; the object is left out of it for its own synthesis.
    name : str
        The object.
    preset : str or ColorizeParams
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
    params = PRESETS[preset] if isinstance(preset, str) else preset
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
        if engine_params is None:
            image, source, used = _copy_nearest(depth, others)
        else:
            colorized = colorize(depth, others, preset=engine_params, seed=seed, quiet=True)
            image, source, used = colorized.image, colorized.source, colorized.example_names
            provenance, legend = colorized.provenance, colorized.legend
        seconds = time.perf_counter() - start
        metrics = _detail_metrics(
            image_metrics(image, truth, mask, labels),
            image,
            truth,
            source,
            mask,
            labels,
            [others[n] for n in used],
        )
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
    import numba

    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))


def _task(args: tuple) -> ObjectEvaluation:
    database, name, preset, methods, seed = args
    return evaluate_object(database, name, preset=preset, methods=methods, seed=seed)


def leave_one_out(
    database: Database,
    *,
    preset: str | ColorizeParams | None = None,
    methods: tuple[str, ...] | list[str] = METHODS,
    workers: int = 1,
    limit: int | None = None,
    seed: int = 0,
    quiet: bool = True,
) -> Evaluation:
    """Leave-one-out evaluation of every object of ``database`` with every method.

    Parameters
    ----------
    database : Database
        At least two examples of the same size; labels (``NAME_labels.png``) and a
        JSON ``class`` field are used where present.
    preset : str or ColorizeParams, optional
        Engine parameters; by default each class's preset of the same name
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

    Returns
    -------
    Evaluation

    Example
    -------
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
    if workers < 1:
        raise InputError(f"--workers must be at least 1, got {workers}")
    if limit is not None and limit < 1:
        raise InputError(f"--limit must be at least 1, got {limit}")
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
        if isinstance(preset, ColorizeParams):
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
        chosen = preset if isinstance(preset, ColorizeParams) else presets[class_name]
        tasks.append((database, name, chosen, methods, seed))

    results: dict[str, ObjectEvaluation] = {}
    bar = progress(range(len(tasks)), total=len(tasks), desc="objects", quiet=quiet)
    if workers == 1 or len(tasks) == 1:
        for task in tasks:
            obj = _task(task)
            results[obj.name] = obj
            next(bar, None)
    else:
        # spawn: a forked child would inherit numba's and OpenBLAS's thread pools.
        with ProcessPoolExecutor(
            max_workers=min(workers, len(tasks)),
            mp_context=get_context("spawn"),
            initializer=_init_worker,
            initargs=((os.cpu_count() or 1) // workers,),
        ) as pool:
            futures = [pool.submit(_task, task) for task in tasks]
            for future in as_completed(futures):
                obj = future.result()
                results[obj.name] = obj
                next(bar, None)
    bar.close()
    objects = [results[name] for name in names]
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
    )


def summarize(evaluation: Evaluation) -> dict[str, dict[str, dict[str, float]]]:
    """Per class, per method: means of the metrics, fraction faulty, mean seconds.

    Returns
    -------
    dict
        ``{class: {method: {"objects", "ciede2000", "ssim", "part_accuracy",
        "part_transfer", "faulty", "seconds"}}}``; NaN means are skipped (a
        metric NaN for every object stays NaN).
    """
    table: dict[str, dict[str, dict[str, float]]] = {}
    for class_name in dict.fromkeys(obj.class_name for obj in evaluation.objects):
        members = [obj for obj in evaluation.objects if obj.class_name == class_name]
        table[class_name] = {}
        for method in evaluation.methods:
            results = [obj.results[method] for obj in members]
            with_features = [r for r in results if r.metrics.features_measured]

            def mean(values):
                values = np.asarray(values, dtype=np.float64)
                return (
                    float(values[np.isfinite(values)].mean())
                    if np.isfinite(values).any()
                    else math.nan
                )

            table[class_name][method] = {
                "objects": len(results),
                "ciede2000": mean([r.metrics.ciede2000 for r in results]),
                "ssim": mean([r.metrics.ssim for r in results]),
                "part_accuracy": mean([r.metrics.part_accuracy for r in results]),
                "part_transfer": mean([r.metrics.part_transfer for r in results]),
                "part_transfer_macro": mean([r.metrics.part_transfer_macro for r in results]),
                # Share of all measurable small features drawn, and of objects with all drawn.
                "features_drawn": _share(
                    sum(r.metrics.features_drawn for r in results),
                    sum(r.metrics.features_measured for r in results),
                ),
                "objects_features_drawn": _share(
                    sum(not r.metrics.features_missing for r in with_features),
                    len(with_features),
                ),
                "blur_ratio": mean([r.metrics.blur_ratio for r in results]),
                "faulty": mean([float(r.faulty) for r in results]),
                "seconds": mean([r.seconds for r in results]),
            }
    return table


#: Summary table columns: (key of :func:`summarize`'s rows, title, format).
SUMMARY_COLUMNS = (
    ("ciede2000", "ΔE00 ↓", "{:.2f}"),
    ("ssim", "SSIM ↑", "{:.3f}"),
    ("part_accuracy", "part acc. ↑", "{:.3f}"),
    ("part_transfer", "part transfer ↑", "{:.3f}"),
    ("part_transfer_macro", "macro part transfer ↑", "{:.3f}"),
    ("features_drawn", "features drawn ↑", "pct"),
    ("objects_features_drawn", "objects with all features ↑", "pct"),
    ("blur_ratio", "blur ratio ↑", "{:.2f}"),
    ("faulty", "faulty ↓", "pct"),
    ("seconds", "s / object", "{:.2f}"),
)


def _summary_cells(row: dict) -> list[str]:
    cells = []
    for key, _, form in SUMMARY_COLUMNS:
        value = row[key]
        if value is None or (isinstance(value, float) and math.isnan(value)):
            cells.append("–")
        elif form == "pct":
            cells.append(f"{100 * value:.0f}%")
        else:
            cells.append(form.format(value))
    return cells


def _share(part: int, whole: int) -> float:
    return part / whole if whole else math.nan


def _fmt(value: float, digits: int = 3) -> str:
    return (
        "–"
        if value is None or (isinstance(value, float) and math.isnan(value))
        else f"{value:.{digits}f}"
    )


def summary_markdown(evaluation: Evaluation) -> str:
    """The per-class summary tables as Markdown."""
    table = summarize(evaluation)
    lines = ["# Leave-one-out evaluation", ""]
    lines.append(
        f"{len(evaluation.objects)} objects, methods {', '.join(evaluation.methods)}, "
        f"seed {evaluation.seed}, {evaluation.workers} worker(s), "
        f"{evaluation.seconds:.0f} s in all."
    )
    lines.append("")
    lines.append(
        "ΔE00: mean CIEDE2000 over the object (lower is better). SSIM: luminance SSIM "
        "over the object. Part acc.: fraction of object pixels nearer to their own part's "
        "true colours than to another part's. Part transfer: fraction of object pixels "
        "whose colour was taken from the same part of an example (independent of the "
        "query's palette); macro: the same averaged over parts, so a small eye counts as "
        "much as the body. Features drawn: small labelled parts (under 1.5% of the object: "
        "eyes, lips, eyebrows) whose L* pattern correlates with the truth's (NCC >= 0.5, "
        "best over shifts of 3 px). Blur ratio: fine-band energy of the map over that of "
        "its source map copied pixel by pixel (1 = as crisp as copied pixels). Faulty: "
        "worse than the median paste of another member's map onto the object in luminance "
        "SSIM or in part transfer (ΔE00 where there are no labels), or a small feature not "
        "drawn: the class's bar below. The generated classes draw a palette per object, "
        "which no method can know from the depth, so ΔE00 and part accuracy mostly measure "
        "that lottery and reward blurred averages; SSIM and part transfer do not."
    )
    for class_name, methods in table.items():
        rule = evaluation.rules[class_name]
        ref = evaluation.reference.get(class_name, {})
        lines += ["", f"## {class_name}", ""]
        lines.append(
            f"{methods[evaluation.methods[0]]['objects']} objects, preset "
            f"`{evaluation.presets.get(class_name, '?')}`. Faulty when {rule.describe()} "
            f"(medians over {ref.get('pairs', 0)} centroid-aligned pastes of one member's "
            "map onto another's mask)."
        )
        lines += [
            "",
            "| method | " + " | ".join(title for _, title, _ in SUMMARY_COLUMNS) + " |",
            "|---|" + "---:|" * len(SUMMARY_COLUMNS),
        ]
        for method, row in methods.items():
            lines.append(f"| {method} | " + " | ".join(_summary_cells(row)) + " |")
    return "\n".join(lines) + "\n"


def _display(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    return np.where(mask[..., None], image, _BACKDROP).astype(np.float32)


def _depth_picture(depth: np.ndarray) -> np.ndarray:
    mask = depth > 0
    lo, hi = float(depth[mask].min()), float(depth[mask].max())
    grey = 0.15 + 0.85 * (depth - lo) / max(hi - lo, 1e-6)
    return np.where(mask, grey, _BACKDROP).astype(np.float32)


def _comparison_strip(obj: ObjectEvaluation, methods: tuple[str, ...], gap: int = 4) -> np.ndarray:
    """depth | truth | each method | provenance of full, side by side."""
    tiles = [_depth_picture(obj.depth)[..., None].repeat(3, axis=2), _display(obj.truth, obj.mask)]
    tiles += [_display(obj.results[m].image, obj.mask) for m in methods]
    engine = next((obj.results[m] for m in methods if obj.results[m].provenance is not None), None)
    if engine is not None:
        tiles.append(engine.provenance)
    h, w = obj.depth.shape
    strip = np.ones((h, len(tiles) * (w + gap) - gap, 3), dtype=np.float32)
    for k, tile in enumerate(tiles):
        strip[:, k * (w + gap) : k * (w + gap) + w] = tile
    return strip


def _strip_captions(methods: tuple[str, ...], has_provenance: bool) -> list[str]:
    return ["depth", "truth", *methods] + (["provenance"] if has_provenance else [])


def _captioned_sheet(evaluation: Evaluation, gap: int = 4, caption_height: int = 16) -> np.ndarray:
    """All objects' strips stacked under one caption row (an overview picture)."""
    from PIL import Image, ImageDraw

    strips = [_comparison_strip(obj, evaluation.methods, gap) for obj in evaluation.objects]
    width = max(s.shape[1] for s in strips)
    h, w = evaluation.objects[0].depth.shape
    sheet = np.ones((caption_height + sum(s.shape[0] + gap for s in strips), width, 3), np.float32)
    top = caption_height
    for strip in strips:
        sheet[top : top + strip.shape[0], : strip.shape[1]] = strip
        top += strip.shape[0] + gap
    picture = Image.fromarray(np.round(sheet * 255).astype(np.uint8))
    draw = ImageDraw.Draw(picture)
    has_provenance = any(r.provenance is not None for r in evaluation.objects[0].results.values())
    for k, text in enumerate(_strip_captions(evaluation.methods, has_provenance)):
        draw.text((k * (w + gap) + 2, 2), text, fill=(0, 0, 0))
    return np.asarray(picture, dtype=np.float32) / 255.0


_CSS = """
body{font-family:system-ui,sans-serif;margin:1.5em;color:#222;background:#fafafa}
table{border-collapse:collapse;margin:.5em 0 1.5em}
td,th{border:1px solid #bbb;padding:.25em .6em;text-align:right}
th:first-child,td:first-child{text-align:left}
section{border-top:1px solid #ccc;padding:.6em 0}
.row{display:flex;flex-wrap:wrap;gap:.5em;align-items:flex-start}
figure{margin:0;font-size:.8em;text-align:center}
figure img{display:block;image-rendering:pixelated;border:1px solid #999}
.faulty{color:#b00;font-weight:bold}
.ex{margin-top:.4em}
.ex img{width:100px}
"""


def _report_html(evaluation: Evaluation, image_paths: dict, example_paths: dict) -> str:
    esc = html.escape
    table = summarize(evaluation)
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        "<title>imagemap leave-one-out evaluation</title>",
        f"<style>{_CSS}</style></head><body>",
        "<h1>Leave-one-out evaluation</h1>",
        f"<p>{len(evaluation.objects)} objects, seed {evaluation.seed}, "
        f"{evaluation.workers} worker(s), {evaluation.seconds:.0f} s. Each object's image-map "
        "was synthesized from the other objects only. ΔE00: mean CIEDE2000 over the object; "
        "SSIM on luminance; part accuracy: pixels nearer to their own part's true colours; "
        "part transfer: pixels whose colour came from the same part of an example. "
        'Files: <a href="results.csv">results.csv</a>, <a href="summary.md">summary.md</a>, '
        '<a href="overview.png">overview.png</a>.</p>',
    ]
    for class_name, methods in table.items():
        rule = evaluation.rules[class_name]
        parts.append(f"<h2>{esc(class_name)}</h2>")
        parts.append(
            f"<p>Preset <code>{esc(evaluation.presets.get(class_name, '?'))}</code>. "
            f"Faulty when {esc(rule.describe())} (medians of pastes of one member's map "
            "onto another).</p>"
        )
        parts.append(
            "<table><tr><th>method</th>"
            + "".join(f"<th>{esc(title)}</th>" for _, title, _ in SUMMARY_COLUMNS)
            + "</tr>"
        )
        for method, row in methods.items():
            cells = "".join(f"<td>{esc(cell)}</td>" for cell in _summary_cells(row))
            parts.append(f"<tr><td>{esc(method)}</td>{cells}</tr>")
        parts.append("</table>")
    parts.append("<h2>Objects</h2>")
    for obj in evaluation.objects:
        paths = image_paths[obj.name]
        full = obj.results.get("full") or next(iter(obj.results.values()))
        parts.append(f'<section id="{esc(obj.name)}"><h3>{esc(obj.name)}</h3><div class="row">')
        for key, caption in (("depth", "input depth"), ("truth", "truth")):
            parts.append(
                f'<figure><img src="{esc(paths[key])}" alt="{caption} of {esc(obj.name)}">'
                f"<figcaption>{caption}</figcaption></figure>"
            )
        for method in evaluation.methods:
            result = obj.results[method]
            m = result.metrics
            flag = ' <span class="faulty">faulty</span>' if result.faulty else ""
            parts.append(
                f'<figure><img src="{esc(paths[method])}" alt="{esc(method)}">'
                f"<figcaption><b>{esc(method)}</b>{flag}<br>ΔE00 {_fmt(m.ciede2000, 1)} · "
                f"SSIM {_fmt(m.ssim, 2)}<br>part acc. {_fmt(m.part_accuracy, 2)} · "
                f"transfer {_fmt(m.part_transfer, 2)}<br>features {m.features_drawn}/"
                f"{m.features_measured} · blur {_fmt(m.blur_ratio, 2)}<br>"
                f"{result.seconds:.2f} s</figcaption>"
                "</figure>"
            )
        if "provenance" in paths:
            parts.append(
                f'<figure><img src="{esc(paths["provenance"])}" alt="provenance">'
                "<figcaption>provenance (full)</figcaption></figure>"
            )
        parts.append("</div>")
        tints = dict(full.legend)
        parts.append(
            '<div class="row ex"><small>examples chosen (full),<br>framed in their '
            "provenance tint:</small>"
        )
        for name in full.examples:
            tint = tints.get(name)
            style = ""
            if tint is not None:
                r, g, b = (int(round(255 * c)) for c in tint)
                style = f' style="border:4px solid rgb({r},{g},{b})"'
            parts.append(
                f'<figure><img src="{esc(example_paths[name])}" alt="{esc(name)}"{style}>'
                f"<figcaption>{esc(name)}</figcaption></figure>"
            )
        parts.append("</div></section>")
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"


def _write_text(path: Path, text: str) -> Path:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


def write_report(evaluation: Evaluation, out_dir: str | os.PathLike) -> dict[str, Path]:
    """Write ``results.csv``, ``summary.md``, ``index.html`` and its pictures into ``out_dir``.

    Pictures go to ``out_dir/images/`` (per object: depth, truth, each method,
    provenance, a comparison strip) and ``out_dir/overview.png`` (all strips).
    Every file is written atomically; the HTML is static and links only files
    written here.

    Parameters
    ----------
    evaluation : Evaluation
    out_dir : str or path-like

    Returns
    -------
    dict
        ``{"csv", "summary", "html", "overview"}`` -> paths.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=CSV_COLUMNS, lineterminator="\n")
    writer.writeheader()
    for row in evaluation.rows():
        writer.writerow(
            {
                **row,
                **{
                    key: "" if math.isnan(row[key]) else f"{row[key]:.4f}"
                    for key in (
                        "ciede2000",
                        "ssim",
                        "part_accuracy",
                        "part_transfer",
                        "part_transfer_macro",
                        "blur_ratio",
                    )
                },
                "faulty": int(row["faulty"]),
                "seconds": f"{row['seconds']:.3f}",
            }
        )
    paths = {"csv": _write_text(out / "results.csv", buffer.getvalue())}
    paths["summary"] = _write_text(out / "summary.md", summary_markdown(evaluation))

    example_paths = {}
    for name, image in evaluation.examples.items():
        relative = f"images/examples/{name}.png"
        write_image(out / relative, image)
        example_paths[name] = relative
    image_paths: dict[str, dict[str, str]] = {}
    for obj in evaluation.objects:
        folder = f"images/{obj.name}"
        entries = {"depth": f"{folder}/depth.png", "truth": f"{folder}/truth.png"}
        write_image(out / entries["depth"], _depth_picture(obj.depth))
        write_image(out / entries["truth"], _display(obj.truth, obj.mask))
        for method in evaluation.methods:
            result = obj.results[method]
            entries[method] = f"{folder}/{method}.png"
            write_image(out / entries[method], _display(result.image, obj.mask))
        engine = next((r for r in obj.results.values() if r.provenance is not None), None)
        if engine is not None:
            entries["provenance"] = f"{folder}/provenance.png"
            write_image(out / entries["provenance"], engine.provenance)
        entries["comparison"] = f"{folder}/comparison.png"
        write_image(out / entries["comparison"], _comparison_strip(obj, evaluation.methods))
        image_paths[obj.name] = entries
    paths["overview"] = write_image(out / "overview.png", _captioned_sheet(evaluation))
    paths["html"] = _write_text(
        out / "index.html", _report_html(evaluation, image_paths, example_paths)
    )
    return paths


class _Links(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.links: list[str] = []

    def handle_starttag(self, tag, attrs):
        for key, value in attrs:
            if key in ("src", "href") and value and not value.startswith("#"):
                self.links.append(value)


def check_report(out_dir: str | os.PathLike) -> list[str]:
    """Links of ``out_dir/index.html`` that do not resolve to a file (empty when all do).

    Example
    -------
    >>> check_report("report/")  # doctest: +SKIP
    []
    """
    out = Path(out_dir)
    index = out / "index.html"
    if not index.is_file():
        raise InputError(f"{index}: no report here")
    parser = _Links()
    parser.feed(index.read_text(encoding="utf-8"))
    missing = []
    for link in parser.links:
        if "://" in link or link.startswith("/"):
            missing.append(link)  # a static report links only its own files
        elif not (out / html.unescape(link)).is_file():
            missing.append(link)
    return missing
