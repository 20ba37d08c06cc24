"""Writing a report's files: ``results.csv``, ``summary.md``, ``index.html`` and its pictures."""

from __future__ import annotations

import csv
import io
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING

from imagemap.io import InputError, atomic_path, write_image
from imagemap.report.page import _report_html
from imagemap.report.pictures import (
    _captioned_sheet,
    _comparison_strip,
    _depth_picture,
    _on_backdrop,
)
from imagemap.report.tables import summary_markdown

if TYPE_CHECKING:
    from imagemap.evaluation import Evaluation

__all__ = ["CSV_COLUMNS", "write_report"]


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
