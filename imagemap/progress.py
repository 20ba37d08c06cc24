"""Progress reporting: a bar on a terminal, silence elsewhere or when asked; and the
mesh command's step lines (:func:`step_line`), which a program running it reads."""

from __future__ import annotations

import sys
from collections.abc import Generator, Iterable
from typing import TypeVar

T = TypeVar("T")


def progress(
    iterable: Iterable[T],
    *,
    total: int | None = None,
    desc: str = "",
    quiet: bool = False,
) -> Generator[T, None, None]:
    """Wrap ``iterable`` in a tqdm bar when stderr is a terminal and not ``quiet``."""
    if quiet or not sys.stderr.isatty():
        yield from iterable
        return
    from tqdm.auto import tqdm  # deferred: start-up (0.1-0.2 s; only a terminal shows a bar)

    yield from tqdm(iterable, total=total, desc=desc, leave=False, dynamic_ncols=True)


def step_line(step: int, total: int, text: str) -> str:
    """The mesh command's progress line for step ``step`` of ``total`` (then ``text``).

    Written on stderr, prefixed ``imagemap: ``, when each step begins, whether or not
    stderr is a terminal: the Blender add-on reads them to show the progress within one
    object (``imagemap.blender.addon_tools.parse_progress``: keep the two in step).

    Examples
    --------
    >>> step_line(2, 5, "synthesizing view 90,0")
    '[2/5] synthesizing view 90,0'
    """
    if not 1 <= step <= total:
        raise ValueError(f"step {step} of {total}: expected 1 <= step <= total")
    return f"[{step}/{total}] {text}"
