"""The report's link check: :func:`check_report`."""

from __future__ import annotations

import html
import os
from html.parser import HTMLParser
from pathlib import Path

from imagemap.io import InputError

__all__ = ["check_report"]


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
