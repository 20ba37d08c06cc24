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

from imagemap.report.links import check_report
from imagemap.report.statistics import (
    BOOTSTRAP_RESAMPLES,
    INTERVAL_COLUMNS,
    INTERVAL_LEVEL,
    MIN_BOOTSTRAP_OBJECTS,
    bootstrap_intervals,
    summarize,
)
from imagemap.report.tables import COHERENCE_COLUMNS, SUMMARY_COLUMNS, summary_markdown
from imagemap.report.write import CSV_COLUMNS, write_report

__all__ = [
    "BOOTSTRAP_RESAMPLES",
    "COHERENCE_COLUMNS",
    "CSV_COLUMNS",
    "INTERVAL_COLUMNS",
    "INTERVAL_LEVEL",
    "MIN_BOOTSTRAP_OBJECTS",
    "SUMMARY_COLUMNS",
    "bootstrap_intervals",
    "check_report",
    "summarize",
    "summary_markdown",
    "write_report",
]
