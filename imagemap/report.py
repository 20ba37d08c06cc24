"""The report of a leave-one-out evaluation: ``results.csv``, ``summary.md``, ``index.html``.

:func:`write_report` writes the files of an :class:`~imagemap.evaluation.Evaluation`
(made by :func:`imagemap.evaluation.leave_one_out`) into a folder: the per-object
rows as CSV, the per-class tables (:func:`summarize`) as Markdown, and a static
HTML page with every object's depth, truth, each method's result and provenance
side by side (pictures under ``images/``, all strips in ``overview.png``). Objects
that failed are listed in the summary and on the page. :func:`check_report` checks
that the page links only files that exist.

Example
-------
>>> from imagemap.evaluation import leave_one_out
>>> evaluation = leave_one_out(db, preset="fish", workers=2)  # doctest: +SKIP
>>> write_report(evaluation, "report/")  # doctest: +SKIP
>>> check_report("report/")  # doctest: +SKIP
[]
"""

from __future__ import annotations

import csv
import html
import io
import math
import os
from html.parser import HTMLParser
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from imagemap.io import InputError, atomic_path, write_image

if TYPE_CHECKING:
    from imagemap.evaluation import Evaluation, ObjectEvaluation

__all__ = [
    "COHERENCE_COLUMNS",
    "CSV_COLUMNS",
    "INTERVAL_COLUMNS",
    "SUMMARY_COLUMNS",
    "bootstrap_intervals",
    "check_report",
    "summarize",
    "summary_markdown",
    "write_report",
]

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
    "fragments_90",
    "fragment_share",
    "seam_length",
    "continuity",
    "midtone_ratio",
    "parts_one_palette",
    "parts_palette_measured",
    "faulty",
    "seconds",
)

#: Grey behind the objects in report pictures, so that black object pixels
#: (holes of copy_nearest) stand out from the background.
_BACKDROP = 0.82


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

#: The coherence table (issue #32, ``docs/measures.md``): (key, title, format).
COHERENCE_COLUMNS = (
    ("fragments_90", "fragments for 90 % ↓", "{:.0f}"),
    ("fragment_share", "fragment share ↑", "{:.3f}"),
    ("seam_length", "seams / outline ↓", "{:.2f}"),
    ("continuity", "continuity ↑", "{:.2f}"),
    ("midtone_ratio", "mid-tones ↓", "{:.2f}"),
    ("parts_one_palette", "parts with one palette ↑", "pct"),
    ("objects_one_palette", "objects with one palette per part ↑", "pct"),
)


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


def _number(value: float, form: str) -> str:
    """A table number in its column's format (``"pct"``: a share as whole per cent)."""
    return f"{100 * value:.0f}" if form == "pct" else form.format(value)


def _missing(value) -> bool:
    return value is None or (isinstance(value, float) and math.isnan(value))


def _interval_cells(row: dict) -> list[str]:
    cells = []
    for key, _, form in INTERVAL_COLUMNS:
        low, high = row[key]
        unit = "%" if form == "pct" else ""
        cells.append(
            "–" if _missing(low) else f"{_number(low, form)} to {_number(high, form)}{unit}"
        )
    return cells


def _summary_cells(row: dict, columns: tuple = SUMMARY_COLUMNS) -> list[str]:
    cells = []
    for key, _, form in columns:
        value = row[key]
        unit = "%" if form == "pct" else ""
        cells.append("–" if _missing(value) else _number(value, form) + unit)
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
    intervals = bootstrap_intervals(evaluation)
    differences = bootstrap_intervals(evaluation, relative_to=evaluation.methods[0])
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
        "its source map copied pixel by pixel (1 = as crisp as copied pixels). The "
        "coherence measures (fragments: regions copied from one example with offsets "
        "changing by at most 1 px between neighbours; continuity: structure-tensor "
        "coherence over the truth's, blind to blur; mid-tones: share of pixels in the middle "
        "of their window's tones over the truth's, blind to order) are defined in "
        "docs/measures.md. Faulty: "
        "part transfer below the median paste of another member's map onto the object, or "
        "a small feature not drawn (without labels: ΔE00 or luminance SSIM worse than that "
        "median): the class's bar below. The generated classes draw a palette per object, "
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
        lines += [
            "",
            "Coherence (does the map hold together): median count of fragments covering "
            "90 % of the object, mean area-weighted fragment share, seam length per outline "
            "length, structure-tensor continuity and mid-tone share as ratios to the "
            "truth's, share of labelled parts (and of objects, every part) painted from one "
            "example.",
            "",
            "| method | " + " | ".join(title for _, title, _ in COHERENCE_COLUMNS) + " |",
            "|---|" + "---:|" * len(COHERENCE_COLUMNS),
        ]
        for method, row in methods.items():
            cells = _summary_cells(row, COHERENCE_COLUMNS)
            lines.append(f"| {method} | " + " | ".join(cells) + " |")
        lines += [
            "",
            f"{100 * INTERVAL_LEVEL:.0f} % intervals of these means over the class's objects "
            f"(bootstrap: {BOOTSTRAP_RESAMPLES} draws of the objects with replacement, the "
            "same draws for every method): how far each mean could move on another set of "
            "objects of the same kind. Two methods or runs on these same objects are "
            "compared object by object in the table after it.",
            "",
            "| method | " + " | ".join(title for _, title, _ in INTERVAL_COLUMNS) + " |",
            "|---|" + "---:|" * len(INTERVAL_COLUMNS),
        ]
        for method, bounds in intervals[class_name].items():
            lines.append(f"| {method} | " + " | ".join(_interval_cells(bounds)) + " |")
        first = evaluation.methods[0]
        if len(evaluation.methods) > 1:
            lines += [
                "",
                f"The same, of each method's difference to `{first}` object by object "
                "(paired): an interval that excludes 0 is a difference these objects support.",
                "",
                "| method | " + " | ".join(title for _, title, _ in INTERVAL_COLUMNS) + " |",
                "|---|" + "---:|" * len(INTERVAL_COLUMNS),
            ]
            for method, bounds in differences[class_name].items():
                if method != first:
                    lines.append(
                        f"| {method} − {first} | " + " | ".join(_interval_cells(bounds)) + " |"
                    )
    problems = _problems(evaluation)
    if problems:
        lines += ["", "## Not evaluated", ""] + [f"- {text}" for text in problems]
    return "\n".join(lines) + "\n"


def _problems(evaluation: Evaluation) -> list[str]:
    """Lines naming the objects that failed (and an interruption): none when all went well."""
    lines = [f"{name}: failed: {message}" for name, message in evaluation.failed]
    if evaluation.interrupted:
        lines.append("interrupted (Ctrl-C): the objects not evaluated by then are missing")
    return lines


def _on_backdrop(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    return np.where(mask[..., None], image, _BACKDROP).astype(np.float32)


def _depth_picture(depth: np.ndarray) -> np.ndarray:
    mask = depth > 0
    lo, hi = float(depth[mask].min()), float(depth[mask].max())
    grey = 0.15 + 0.85 * (depth - lo) / max(hi - lo, 1e-6)
    return np.where(mask, grey, _BACKDROP).astype(np.float32)


def _comparison_strip(obj: ObjectEvaluation, methods: tuple[str, ...], gap: int = 4) -> np.ndarray:
    """depth | truth | each method | provenance of full, side by side."""
    tiles = [
        _depth_picture(obj.depth)[..., None].repeat(3, axis=2),
        _on_backdrop(obj.truth, obj.mask),
    ]
    tiles += [_on_backdrop(obj.results[m].image, obj.mask) for m in methods]
    provenance = next(
        (p for p in (obj.results[m].provenance for m in methods) if p is not None), None
    )
    if provenance is not None:
        tiles.append(provenance)
    h, w = obj.depth.shape
    strip = np.ones((h, len(tiles) * (w + gap) - gap, 3), dtype=np.float32)
    for k, tile in enumerate(tiles):
        strip[:, k * (w + gap) : k * (w + gap) + w] = tile
    return strip


def _strip_captions(methods: tuple[str, ...], has_provenance: bool) -> list[str]:
    return ["depth", "truth", *methods] + (["provenance"] if has_provenance else [])


def _captioned_sheet(evaluation: Evaluation, gap: int = 4, caption_height: int = 16) -> np.ndarray:
    """All objects' strips stacked under one caption row (an overview picture)."""
    from PIL import Image, ImageDraw  # deferred: the overview picture only

    if not evaluation.objects:  # every object failed: a blank picture keeps the link valid
        return np.ones((caption_height, 200, 3), np.float32)
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
    differences = bootstrap_intervals(evaluation, relative_to=evaluation.methods[0])
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
    problems = _problems(evaluation)
    if problems:
        parts.append('<h2 class="faulty">Not evaluated</h2><ul>')
        parts += [f"<li>{esc(text)}</li>" for text in problems]
        parts.append("</ul>")
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
        parts.append(
            "<p>Coherence: does the map hold together (fragments, seams, continuity and "
            "mid-tones against the truth, palettes per part; definitions in "
            "docs/measures.md).</p><table><tr><th>method</th>"
            + "".join(f"<th>{esc(title)}</th>" for _, title, _ in COHERENCE_COLUMNS)
            + "</tr>"
        )
        for method, row in methods.items():
            cells = "".join(
                f"<td>{esc(cell)}</td>" for cell in _summary_cells(row, COHERENCE_COLUMNS)
            )
            parts.append(f"<tr><td>{esc(method)}</td>{cells}</tr>")
        parts.append("</table>")
        first = evaluation.methods[0]
        if len(evaluation.methods) > 1:
            parts.append(
                f"<p>Each method minus <code>{esc(first)}</code>, object by object: 95 % "
                "bootstrap interval of the mean difference (an interval that excludes 0 is a "
                "difference these objects support; more in summary.md).</p>"
            )
            parts.append(
                "<table><tr><th>method</th>"
                + "".join(f"<th>{esc(title)}</th>" for _, title, _ in INTERVAL_COLUMNS)
                + "</tr>"
            )
            for method, bounds in differences[class_name].items():
                if method != first:
                    cells = "".join(f"<td>{esc(cell)}</td>" for cell in _interval_cells(bounds))
                    parts.append(f"<tr><td>{esc(method)} − {esc(first)}</td>{cells}</tr>")
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
                f"fragments {_fmt(m.fragments_90, 0)} · continuity {_fmt(m.continuity, 2)}"
                f" · mid-tones {_fmt(m.midtone_ratio, 2)}<br>"
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
                        "fragment_share",
                        "seam_length",
                        "continuity",
                        "midtone_ratio",
                    )
                },
                "fragments_90": "" if math.isnan(row["fragments_90"]) else int(row["fragments_90"]),
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
        write_image(out / entries["truth"], _on_backdrop(obj.truth, obj.mask))
        for method in evaluation.methods:
            result = obj.results[method]
            entries[method] = f"{folder}/{method}.png"
            write_image(out / entries[method], _on_backdrop(result.image, obj.mask))
        provenance = next(
            (r.provenance for r in obj.results.values() if r.provenance is not None), None
        )
        if provenance is not None:
            entries["provenance"] = f"{folder}/provenance.png"
            write_image(out / entries["provenance"], provenance)
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
