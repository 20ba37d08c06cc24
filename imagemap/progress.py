"""Progress reporting: a bar on a terminal, silence elsewhere or when asked."""

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
