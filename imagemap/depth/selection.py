"""Which examples a query uses: the nearest in shape, whatever the query's pose and units.

Hassner & Basri rank the examples by the sum of squared depth differences after
centroid alignment (Sec. 2.3): that ranking changes when the query is turned, scaled,
mirrored or in other depth units. Here every object is compared on its own units-free
grid (:func:`imagemap.depth.pose.shape_grid`), the query turned and mirrored to each
example's pose (:func:`imagemap.depth.pose.pose_distances`): the same examples whatever
the query's pose.
"""

from __future__ import annotations

import numpy as np

from imagemap.database import Database
from imagemap.depth.config import Selection
from imagemap.depth.pose import (
    CoarseQuery,
    Pose,
    coarse_query,
    find_poses,
    pose_distances,
    shape_grid,
)
from imagemap.io import validate_depth
from imagemap.validate import check_int

__all__ = [
    "example_grid",
    "poses_against",
    "select_examples",
    "select_with_poses",
    "selection_distances",
]

_SELECTION = Selection()
#: The examples nearest at the coarse search's angles whose poses are refined before the
#: ``m`` nearest are taken: a coarse angle is up to half a step off, which reorders
#: examples of nearly equal distance (a fish turned 35 degrees chose another first
#: example than upright without it); the refinement costs a few milliseconds an example.
REFINED_EXTRA = 4


def example_grid(example, selection: Selection = _SELECTION) -> np.ndarray:
    """An example's :func:`~imagemap.depth.pose.shape_grid`, made once (cached on the
    example: a database's grids are not made again per query)."""
    cache = example.__dict__
    if "_shape_grid" not in cache:
        cache["_shape_grid"] = shape_grid(example.depth)
    return cache["_shape_grid"]


def selection_distances(
    depth: np.ndarray,
    database: Database,
    selection: Selection = _SELECTION,
    query: CoarseQuery | None = None,
) -> np.ndarray:
    """Each example's shape distance to ``depth`` at its best pose (one value per example,
    in the database's order; :func:`imagemap.depth.pose.pose_distances`; ``query``: the
    query's :func:`~imagemap.depth.pose.coarse_query`, if made)."""
    grids = np.stack([example_grid(example, selection) for example in database])
    distances, _ = pose_distances(
        np.asarray(depth, np.float32),
        grids,
        mirrored=selection.mirror,
        query=query,
    )
    return distances


def select_examples(
    depth: np.ndarray, database: Database, m: int = 2, selection: Selection = _SELECTION
) -> list[int]:
    """Indices of the ``m`` examples nearest in shape to ``depth``, nearest first.

    Examples
    --------
    >>> from imagemap import Database, Example
    >>> yy, xx = np.mgrid[:60, :60]
    >>> def ellipse(rx, ry, cx=30):
    ...     inside = ((xx - cx) / rx) ** 2 + ((yy - 30) / ry) ** 2 < 1
    ...     return np.where(inside, 0.5, 0).astype(np.float32)
    >>> db = Database([Example.from_arrays(f"e{rx}", ellipse(rx, 10), np.zeros((60, 60, 3)))
    ...                for rx in (10, 20, 28)])
    >>> [db[i].name for i in select_examples(ellipse(19, 10), db, m=2)]
    ['e20', 'e28']
    >>> [db[i].name for i in select_examples(ellipse(10, 19, cx=20).T * 3, db, m=1)]
    ['e20']
    """
    return select_with_poses(depth, database, m, selection)[0]


def select_with_poses(
    depth: np.ndarray, database: Database, m: int = 2, selection: Selection = _SELECTION
) -> tuple[list[int], list[Pose]]:
    """The ``m`` examples nearest in shape to ``depth`` and the query's pose against each.

    The nearest ``m`` + :data:`REFINED_EXTRA` at the coarse search's angles get their
    angle refined (:func:`~imagemap.depth.pose.find_poses`); the ``m`` nearest of them at
    their refined poses are taken, nearest first.
    """
    m = check_int("m", m, minimum=1)
    depth = validate_depth(depth)
    # The query's side of the coarse search, made once for the distances and the poses.
    query = coarse_query(depth, mirrored=selection.mirror)
    coarse = np.argsort(selection_distances(depth, database, selection, query), kind="stable")
    candidates = [int(i) for i in coarse[: m + REFINED_EXTRA]]
    poses = poses_against(depth, [database[i] for i in candidates], selection, query)
    order = sorted(range(len(candidates)), key=lambda k: (poses[k].distance, k))[:m]
    return [candidates[k] for k in order], [poses[k] for k in order]


def poses_against(
    depth: np.ndarray,
    examples: list,
    selection: Selection = _SELECTION,
    query: CoarseQuery | None = None,
):
    """The query's refined :class:`~imagemap.depth.pose.Pose` against each example
    (``query``: its :func:`~imagemap.depth.pose.coarse_query`, if made)."""
    return find_poses(
        depth,
        [example.depth for example in examples],
        mirrored=selection.mirror,
        example_grids=np.stack([example_grid(example, selection) for example in examples]),
        query=query,
    )
