"""Depth units, and a query that is an example.

A depth map may come in any unit: relief in [0, 1], a 16-bit PNG, millimetres, metres
saved as float. So the ``pose`` stage (:mod:`imagemap.depth.pose`) takes the query and
every chosen example :func:`units_free`: divided by its object's median depth and
rounded to :data:`UNIT_STEP`, so that any positive factor on a depth gives the same
values, hence the same map, with no band inside which units would still count.

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
    "UNIT_STEP",
    "depth_scale",
    "exclude_query",
    "find_example",
    "query_in_database",
    "scale_of",
    "units_free",
]

log = logging.getLogger("imagemap")

#: A units-free depth is rounded to multiples of this (of its median): far finer than any
#: file holds (a 16-bit PNG steps 2**-16 of its range), and coarse enough that a depth
#: times a factor, divided again, rounds to the same values (float32 keeps 24 bits).
UNIT_STEP = 2.0**-18

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


def units_free(depth: np.ndarray) -> np.ndarray:
    """``depth`` divided by its object's median depth (:func:`depth_scale`), rounded to
    :data:`UNIT_STEP`: the same values whatever its unit (float32, background 0).

    Examples
    --------
    >>> dome = np.array([[0.0, 0.31, 0.52], [0.0, 0.47, 0.6]], np.float32)
    >>> bool(np.array_equal(units_free(dome), units_free(dome * np.float32(1.6))))
    True
    """
    depth = np.asarray(depth)
    scale = depth_scale(depth)
    if scale <= 0:
        return np.zeros(depth.shape, np.float32)
    relative = np.asarray(depth, np.float64) / scale
    return (np.rint(relative / UNIT_STEP) * UNIT_STEP).astype(np.float32)
