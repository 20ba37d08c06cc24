"""Depth units: a query's depth brought to its database's scale; a query that is an example.

A depth map may come in any unit: relief in [0, 1], a 16-bit PNG, millimetres, metres
saved as float. The guide weights are set for the database's own scale, and the maps
depend on it strongly: measured on the generated fish (``fish_000`` against the other
eleven at 200x150, seed 0), the mean |RGB| difference from the map of the query as it
is was 0.055 at x1.1, 0.12 at x0.9, 0.22 at x0.5 (other examples chosen), 0.22 at
x1e-3 (a nearly flat, one-colour fish) and 0.27 at x1e6, against 0.009 between two
seeds at x1.

So the ``units`` stage (the first of :data:`imagemap.depth.pipeline.STAGES`) measures the
query's depth scale (the median depth of its object) against the examples'. Within
:attr:`~imagemap.depth.config.Selection.scale_tolerance` (1.5) of theirs the query is
used as it is (every map of a query in the database's own units stays byte for byte
what it was); further away it is multiplied so that its scale is the examples' median
scale, with a notice: then a query's map does not depend on its unit (x1e-6 to x1e6,
millimetres, a 16-bit PNG give the same map).

The same stage looks for the query among the examples by content (the same depth,
value for value): an example chosen automatically is left out, with a notice (a
synthesis would otherwise hand the example's own image-map back, byte for byte); an
example named with ``examples=`` is an :class:`~imagemap.errors.InputError`. Inside
``with query_in_database():`` the example stays (a test of the measures with a perfect
twin).

Examples
--------
>>> import numpy as np
>>> from imagemap import Database, Example
>>> yy, xx = np.mgrid[:20, :24]
>>> dome = np.clip(1 - ((yy - 10) / 8.0) ** 2 - ((xx - 12) / 10.0) ** 2, 0, None)
>>> examples = [Example.from_arrays(f"e{i}", (0.5 + 0.1 * i) * dome,
...                                 np.full((20, 24, 3), 0.5)) for i in range(3)]
>>> scaled, factor = match_scale(1000 * dome, examples)       # millimetres
>>> round(factor, 6), round(float(depth_scale(scaled)), 4) == round(float(
...     np.median([depth_scale(e.depth) for e in examples])), 4)
(0.0006, True)
>>> match_scale(0.55 * dome, examples)[1]                      # in the examples' units
1.0
>>> find_example(0.6 * dome, examples)
'e1'
"""

from __future__ import annotations

import contextlib
import contextvars
import logging
from collections.abc import Iterator, Sequence

import numpy as np

from imagemap.depth.config import Selection
from imagemap.errors import InputError

__all__ = [
    "depth_scale",
    "find_example",
    "match_scale",
    "query_in_database",
    "units_stage",
]

log = logging.getLogger("imagemap")

#: The default tolerance of :func:`match_scale` (the reason for its value is at
#: :attr:`imagemap.depth.config.Selection.scale_tolerance`).
_TOLERANCE = Selection().scale_tolerance


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


def _scale_of(example) -> float:
    # Cached on the example (its depth does not change): a database's scales are measured
    # once, not once per query.
    cache = example.__dict__
    if "_depth_scale" not in cache:
        cache["_depth_scale"] = depth_scale(example.depth)
    return cache["_depth_scale"]


def match_scale(
    depth: np.ndarray, examples: Sequence, tolerance: float = _TOLERANCE
) -> tuple[np.ndarray, float]:
    """``depth`` at the examples' scale, and the factor it was multiplied by (1.0: as it is).

    Parameters
    ----------
    depth : ndarray, (H, W)
        The query's depth (background 0).
    examples : sequence of Example
        The examples it will be matched with.
    tolerance : float
        Within this factor of the examples' range of scales the query is used as it is
        (see :attr:`~imagemap.depth.config.Selection.scale_tolerance`).

    Returns
    -------
    depth : ndarray of float32
    factor : float
    """
    scales = [s for s in (_scale_of(e) for e in examples) if s > 0]
    scale = depth_scale(depth)
    if not scales or scale <= 0:
        return depth, 1.0
    if min(scales) / tolerance <= scale <= max(scales) * tolerance:
        return depth, 1.0
    factor = float(np.median(scales)) / scale
    # In float64, then once to float32: the same relief at any scale rounds alike.
    return (np.asarray(depth, np.float64) * factor).astype(np.float32), factor


def find_example(depth: np.ndarray, examples: Sequence) -> str | None:
    """The name of the first example whose depth is ``depth``, value for value (or None)."""
    depth = np.asarray(depth, np.float32)  # as the pipeline holds depths (and examples)
    for example in examples:
        other = example.depth
        if other.shape == depth.shape and np.array_equal(other, depth):
            return example.name
    return None


def units_stage(state, config):
    """The pipeline's ``units`` stage: the query out of the database, then at its scale."""
    database = state.database
    named = [database[name] for name in state.names] if state.names else None
    same = None
    if not _QUERY_IN_DATABASE.get():
        same = find_example(state.depth, named if named is not None else database)
    notes = []
    if same is not None:
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
        state.database = database.without(same)
        notes.append(f"{same} (the query itself) left out")
    scale = depth_scale(state.depth)
    state.depth, factor = match_scale(
        state.depth, named or state.database, config.selection.scale_tolerance
    )
    if factor != 1.0:
        log.warning(
            "the query's depth scale (%.3g, its object's median depth) is far from the "
            "examples' (%.3g): multiplied by %.3g to match them (depth units do not matter)",
            scale,
            depth_scale(state.depth),
            factor,
        )
        notes.append(f"depth x{factor:.4g} to the examples' scale")
    else:
        notes.append(f"depth scale {scale:.3g} as it is")
    state.changed = "; ".join(notes)
    return state
