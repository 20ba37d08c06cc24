"""The report's tables: their columns and cells, and ``summary.md`` (:func:`summary_markdown`)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

from imagemap.report.statistics import (
    BOOTSTRAP_RESAMPLES,
    INTERVAL_COLUMNS,
    INTERVAL_LEVEL,
    bootstrap_intervals,
    summarize,
)

if TYPE_CHECKING:
    from imagemap.evaluation import Evaluation

__all__ = ["COHERENCE_COLUMNS", "SUMMARY_COLUMNS", "summary_markdown"]


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


def code_line() -> str:
    """Which imagemap made the report: its package folder and version. Two runs of one
    command can run different code: ``python -m imagemap`` imports the package from the
    current folder before ``PYTHONPATH``, so a run started inside another checkout runs
    that checkout's code (two fish reports of one seed, 0.812 and 0.816, were two
    checkouts, not two outcomes of one)."""
    import imagemap  # deferred: the package itself, for its folder

    folder = Path(imagemap.__file__).resolve().parent
    return f"Code: imagemap {imagemap.__version__} from `{folder}`."


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
    lines.append(code_line())
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
