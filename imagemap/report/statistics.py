"""The numbers of a report: per-class means (:func:`summarize`) and their bootstrap intervals."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from imagemap.evaluation import Evaluation

__all__ = [
    "BOOTSTRAP_RESAMPLES",
    "INTERVAL_COLUMNS",
    "INTERVAL_LEVEL",
    "MIN_BOOTSTRAP_OBJECTS",
    "bootstrap_intervals",
    "summarize",
]


def summarize(evaluation: Evaluation) -> dict[str, dict[str, dict[str, float]]]:
    """Per class, per method: means of the metrics, fraction faulty, mean seconds.

    Returns
    -------
    dict
        ``{class: {method: {"objects", "ciede2000", "ssim", "part_accuracy",
        "part_transfer", ..., "fragments_90", "fragment_share", "seam_length",
        "continuity", "midtone_ratio", "parts_one_palette", "objects_one_palette",
        "faulty", "seconds"}}}``; NaN values are skipped (a metric NaN for every
        object stays NaN). ``fragments_90`` is the median over the objects.
    """
    table: dict[str, dict[str, dict[str, float]]] = {}
    for class_name in dict.fromkeys(obj.class_name for obj in evaluation.objects):
        members = [obj for obj in evaluation.objects if obj.class_name == class_name]
        table[class_name] = {}
        for method in evaluation.methods:
            results = [obj.results[method] for obj in members]
            with_features = [r for r in results if r.metrics.features_measured]
            with_parts = [r for r in results if r.metrics.parts_palette_measured]

            def mean(values):
                values = np.asarray(values, dtype=np.float64)
                return (
                    float(values[np.isfinite(values)].mean())
                    if np.isfinite(values).any()
                    else math.nan
                )

            def median(values):
                values = np.asarray(values, dtype=np.float64)
                finite = values[np.isfinite(values)]
                return float(np.median(finite)) if finite.size else math.nan

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
                # Coherence (issue #32): the fragment count is skewed (a few maps in
                # thousands of pieces), so its median; the others are means.
                "fragments_90": median([r.metrics.fragments_90 for r in results]),
                "fragment_share": mean([r.metrics.fragment_share for r in results]),
                "seam_length": mean([r.metrics.seam_length for r in results]),
                "continuity": mean([r.metrics.continuity for r in results]),
                "midtone_ratio": mean([r.metrics.midtone_ratio for r in results]),
                # Share of all labelled parts with one palette, and of objects with
                # one palette in every part.
                "parts_one_palette": _share(
                    sum(r.metrics.parts_one_palette for r in results),
                    sum(r.metrics.parts_palette_measured for r in results),
                ),
                "objects_one_palette": _share(
                    sum(
                        r.metrics.parts_one_palette == r.metrics.parts_palette_measured
                        for r in with_parts
                    ),
                    len(with_parts),
                ),
                "faulty": mean([float(r.faulty) for r in results]),
                "seconds": mean([r.seconds for r in results]),
            }
    return table


def _share(part: int, whole: int) -> float:
    return part / whole if whole else math.nan


#: The summary's intervals: how many resamples of a class's objects, and their level.
BOOTSTRAP_RESAMPLES = 2000
INTERVAL_LEVEL = 0.95
#: Fewer objects of a class than this get no bootstrap intervals (n/a): n objects give at
#: most C(2n - 1, n) distinct resampled means (2: 3, 3: 10, 4: 35), too few below 4 for a
#: 95 % interval's tails; from 2 objects intervals and "supported" differences were
#: printed (issue #35).
MIN_BOOTSTRAP_OBJECTS = 4
#: Interval table columns: (key of :func:`summarize`'s rows, title, format).
INTERVAL_COLUMNS = (
    ("ciede2000", "ΔE00", "{:.2f}"),
    ("ssim", "SSIM", "{:.3f}"),
    ("part_transfer_macro", "macro part transfer", "{:.3f}"),
    ("objects_features_drawn", "objects with all features", "pct"),
    ("blur_ratio", "blur ratio", "{:.2f}"),
    ("fragment_share", "fragment share", "{:.3f}"),
    ("continuity", "continuity", "{:.2f}"),
    ("midtone_ratio", "mid-tones", "{:.2f}"),
    ("faulty", "faulty", "pct"),
)


def _object_values(results: list, key: str) -> np.ndarray:
    """One value per object for an interval column (NaN where it is not measured)."""
    if key == "objects_features_drawn":
        values = [
            float(not r.metrics.features_missing) if r.metrics.features_measured else math.nan
            for r in results
        ]
    elif key == "faulty":
        values = [float(r.faulty) for r in results]
    else:
        values = [getattr(r.metrics, key) for r in results]
    return np.asarray(values, dtype=np.float64)


def bootstrap_intervals(
    evaluation: Evaluation,
    resamples: int = BOOTSTRAP_RESAMPLES,
    level: float = INTERVAL_LEVEL,
    seed: int = 0,
    relative_to: str | None = None,
) -> dict[str, dict[str, dict[str, tuple[float, float]]]]:
    """Per class and method, an interval for each mean of :data:`INTERVAL_COLUMNS`.

    The class's objects are drawn ``resamples`` times with replacement and each mean
    is taken over every draw; the interval holds the central ``level`` of those means
    (percentile bootstrap). It says how far the mean could move with another set of
    objects of the same kind (with 12 objects, one object more or less with all its
    features is 8 points). Every method is resampled with the same draws, and the same
    seed gives the same intervals.

    With ``relative_to`` (a method), the intervals are of each method's mean minus that
    method's, object by object (paired): whether one method beats another on these
    objects beyond the chance of which objects were drawn. An interval that excludes 0
    is a difference the set supports.

    Returns
    -------
    dict
        ``{class: {method: {key: (low, high)}}}``; (NaN, NaN) where the column is not
        measured.
    """
    rng = np.random.default_rng(seed)
    tails = (100 * (1 - level) / 2, 100 * (1 + level) / 2)
    intervals: dict[str, dict[str, dict[str, tuple[float, float]]]] = {}
    for class_name in dict.fromkeys(obj.class_name for obj in evaluation.objects):
        members = [obj for obj in evaluation.objects if obj.class_name == class_name]
        if len(members) < MIN_BOOTSTRAP_OBJECTS:  # no interval says anything: not given
            intervals[class_name] = {
                method: {key: (math.nan, math.nan) for key, _, _ in INTERVAL_COLUMNS}
                for method in evaluation.methods
            }
            continue
        draws = rng.integers(0, len(members), (resamples, len(members)))
        intervals[class_name] = {}
        base: dict[str, float | np.ndarray] = {key: 0.0 for key, _, _ in INTERVAL_COLUMNS}
        if relative_to is not None:
            reference = [obj.results[relative_to] for obj in members]
            base = {key: _object_values(reference, key) for key, _, _ in INTERVAL_COLUMNS}
        for method in evaluation.methods:
            results = [obj.results[method] for obj in members]
            row = {}
            for key, _, _ in INTERVAL_COLUMNS:
                values = (_object_values(results, key) - base[key])[draws]
                measured = np.isfinite(values)
                counts = measured.sum(axis=1)
                sums = np.where(measured, values, 0.0).sum(axis=1)
                means = sums[counts > 0] / counts[counts > 0]
                low, high = np.percentile(means, tails) if means.size else (math.nan,) * 2
                row[key] = (float(low), float(high))
            intervals[class_name][method] = row
    return intervals
