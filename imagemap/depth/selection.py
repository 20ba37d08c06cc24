"""Which examples a query uses: the nearest in depth after centroid alignment (paper, Sec. 2.3)."""

from __future__ import annotations

import numpy as np

from imagemap.align import centroid as _centroid
from imagemap.database import Database
from imagemap.io import validate_depth
from imagemap.validate import check_int

__all__ = ["select_examples", "selection_distances"]


def select_examples(depth: np.ndarray, database: Database, m: int = 2) -> list[int]:
    """Indices of the ``m`` examples whose depth is nearest to ``depth`` after centroid alignment.

    The distance is the sum of squared differences once each example's depth is
    translated so that its foreground centroid falls on the query's (paper, Sec. 2.3).

    Examples
    --------
    >>> from imagemap import Database, Example
    >>> def disc(radius):
    ...     yy, xx = np.mgrid[:40, :40]
    ...     return np.where((yy - 20) ** 2 + (xx - 20) ** 2 < radius**2, 0.5, 0).astype(np.float32)
    >>> db = Database([Example.from_arrays(f"disc_{r}", disc(r), np.zeros((40, 40, 3)))
    ...                for r in (6, 10, 14)])
    >>> [db[i].name for i in select_examples(disc(11), db, m=2)]
    ['disc_10', 'disc_14']
    """
    m = check_int("m", m, minimum=1)
    depth = validate_depth(depth)
    order = np.argsort(selection_distances(depth, database), kind="stable")
    return [int(i) for i in order[:m]]


def selection_distances(depth: np.ndarray, database: Database) -> np.ndarray:
    """Each example's selection distance to ``depth`` (as :func:`select_examples` ranks them).

    The sum of squared depth differences once the example's foreground centroid is on
    the query's, the example's depth outside the query's frame counted in full
    (paper, Sec. 2.3). One value per example, in the database's order.
    """
    depth = np.asarray(depth, dtype=np.float32)
    # SSD over the query frame plus the example's depth that falls outside it (a larger
    # object is a worse fit) = |D|^2 + |Di|^2 - 2 <D, shifted Di> over their overlap, with
    # each example's centroid and |Di|^2 computed once (Example.selection_stats).
    query_centroid = _centroid(depth > 0)
    query_norm = float(np.square(depth, dtype=np.float64).sum())
    height, width = depth.shape
    distances = np.empty(len(database))
    for k, example in enumerate(database):
        other = example.depth
        centroid, other_norm = example.selection_stats
        dy, dx = (int(round(s)) for s in query_centroid - centroid)
        y0, x0 = max(0, dy), max(0, dx)
        y1, x1 = min(height, other.shape[0] + dy), min(width, other.shape[1] + dx)
        cross = 0.0
        if y1 > y0 and x1 > x0:
            here = depth[y0:y1, x0:x1]
            there = other[y0 - dy : y1 - dy, x0 - dx : x1 - dx]
            # Not a BLAS dot: a multithreaded BLAS spins on a busy machine (15 ms a call).
            cross = float(np.multiply(here, there, dtype=np.float64).sum())
        distances[k] = query_norm + other_norm - 2.0 * cross
    return distances
