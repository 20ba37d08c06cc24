"""Depth units, and a query that is an example.

A depth map may come in any unit: relief in [0, 1], a 16-bit PNG, millimetres, metres
saved as float. The guide weights are set for the examples' own scale, so the ``pose``
stage (:mod:`imagemap.depth.pose`) always brings the query to the chosen examples'
median :func:`depth_scale`: any positive factor on a query's depth gives the same map,
with no band inside which units would still count.

The ``select`` stage looks for the query among the examples by content
(:func:`exclude_query`; the same depth, value for value): an example chosen
automatically is left out, with a notice (a synthesis would otherwise hand the
example's own image-map back, byte for byte); an example named with ``examples=`` is an
:class:`~imagemap.errors.InputError`. Inside ``with query_in_database():`` the example
stays (a test of the measures with a perfect twin).

Examples
--------
>>> import numpy as np
>>> from imagemap import Database, Example
>>> yy, xx = np.mgrid[:20, :24]
>>> dome = np.clip(1 - ((yy - 10) / 8.0) ** 2 - ((xx - 12) / 10.0) ** 2, 0, None)
>>> examples = [Example.from_arrays(f"e{i}", (0.5 + 0.1 * i) * dome,
...                                 np.full((20, 24, 3), 0.5)) for i in range(3)]
>>> round(depth_scale(1000 * dome) / depth_scale(dome), 6)
1000.0
>>> find_example(0.6 * dome, examples)
'e1'
"""

from __future__ import annotations

import contextlib
import contextvars
import logging
from collections.abc import Iterator, Sequence

import numpy as np

from imagemap.errors import InputError

__all__ = [
    "depth_scale",
    "exclude_query",
    "find_example",
    "query_in_database",
    "scale_of",
]

log = logging.getLogger("imagemap")

_QUERY_IN_DATABASE = contextvars.ContextVar("imagemap_query_in_database", default=False)


@contextlib.contextmanager
def query_in_database(allowed: bool = True) -> Iterator[None]:
    """Keep an example that is the query itself inside a ``with`` block (see above).

    Examples
    --------
    >>> with query_in_database():
    ...     _QUERY_IN_DATABASE.get()
    True
    """
    token = _QUERY_IN_DATABASE.set(bool(allowed))
    try:
        yield
    finally:
        _QUERY_IN_DATABASE.reset(token)


def depth_scale(depth: np.ndarray) -> float:
    """The depth scale of a map: the median depth of its object (0 when it has none).

    Examples
    --------
    >>> depth_scale(np.array([[0.0, 2.0], [4.0, 6.0]]))
    4.0
    """
    depth = np.asarray(depth)
    values = depth[depth > 0]
    return float(np.median(values)) if values.size else 0.0


def scale_of(example) -> float:
    """An example's :func:`depth_scale`, measured once."""
    # Cached on the example (its depth does not change): a database's scales are measured
    # once, not once per query.
    cache = example.__dict__
    if "_depth_scale" not in cache:
        cache["_depth_scale"] = depth_scale(example.depth)
    return cache["_depth_scale"]


def find_example(depth: np.ndarray, examples: Sequence) -> str | None:
    """The name of the first example whose depth is ``depth``, value for value (or None)."""
    depth = np.asarray(depth, np.float32)  # as the pipeline holds depths (and examples)
    for example in examples:
        other = example.depth
        if other.shape == depth.shape and np.array_equal(other, depth):
            return example.name
    return None


def exclude_query(database, names: list[str] | None, depth: np.ndarray):
    """``database`` without an example that is the query itself, and a note on it.

    Raises
    ------
    InputError
        The query is an example named in ``names``, or the database's only example.
    """
    if _QUERY_IN_DATABASE.get():
        return database, ""
    named = [database[name] for name in names] if names else None
    same = find_example(depth, named if named is not None else database)
    if same is None:
        return database, ""
    if named is not None:
        raise InputError(
            f"examples: {same!r} is the query itself (the same depth): its own image-map "
            "would come back; name other examples, or leave it out (--exclude)"
        )
    if len(database) == 1:
        raise InputError(
            f"the query is the database's only example ({same!r}): nothing else to "
            "synthesize it from"
        )
    log.warning(
        "the query is the database's example %r (the same depth): left out of this "
        "synthesis (its own image-map would come back)",
        same,
    )
    return database.without(same), f"{same} (the query itself) left out"
