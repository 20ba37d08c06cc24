"""The report's static HTML page (``index.html``): the tables, then every object side by side."""

from __future__ import annotations

import html
import math
from typing import TYPE_CHECKING

from imagemap.report.statistics import INTERVAL_COLUMNS, bootstrap_intervals, summarize
from imagemap.report.tables import (
    COHERENCE_COLUMNS,
    SUMMARY_COLUMNS,
    _interval_cells,
    _problems,
    _summary_cells,
)

if TYPE_CHECKING:
    from imagemap.evaluation import Evaluation


def _fmt(value: float, digits: int = 3) -> str:
    return (
        "–"
        if value is None or (isinstance(value, float) and math.isnan(value))
        else f"{value:.{digits}f}"
    )


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
