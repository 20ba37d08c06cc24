"""Where a query lies against each example: a similarity with or without a mirror image.

A query may lie anywhere in its frame, at any size, turned or facing the other way
than the examples, and its depth may come in any unit. None of that may change which
examples it is made from, nor its map beyond moving it the same way. So every object
is compared in a frame of its own: its depth divided by its own median (units-free),
centred on its centroid and scaled by its size (the square root of its area) on a
small grid (:data:`GRID` cells across). The
query is sampled on that grid turned by every angle of a coarse search and mirrored or
not; each example once, as it lies. The distance of an example is the smallest sum of
squared differences over those candidates, and the candidate that gives it is the pose
(refined by bisection of the angle): a :class:`Pose`, the map from query pixels to the
example's pixels.

The synthesis then runs in the first example's frame (:func:`canonical_frame`): the
query resampled by its pose onto the example's grid, so that its windows see the
relief turned, scaled and mirrored as the examples have it, and the map is brought
back to the query's frame at the end. Rotation, scale and mirror are thereby the
same for every query, whatever its pose (Hassner & Basri select by depth after
centroid alignment only, Sec. 2.3; moments give translation, scale and rotation but
not a reflection, hence the mirrored candidates and a fit that chooses).

Examples
--------
>>> yy, xx = np.mgrid[:60, :80]
>>> def fish(cx, flip=False):
...     u = (xx - cx) / 25.0
...     u = -u if flip else u
...     v = (yy - 30) / (10.0 + 4 * u)  # a body thicker at one end
...     return np.where(u**2 + v**2 < 1, 1 + 0.3 * u, 0).astype(np.float32)
>>> pose = find_poses(fish(40, flip=True), [fish(38)])[0]
>>> pose.mirrored, round(abs(pose.angle)) % 180
(True, 0)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

__all__ = [
    "ANGLE_STEP",
    "GRID",
    "MIRROR_TIE",
    "SPAN",
    "CanonicalFrame",
    "CoarseQuery",
    "Pose",
    "canonical_frame",
    "coarse_query",
    "find_poses",
    "pose_distances",
    "shape_grid",
]


#: Cells across the units-free grid objects are compared on, and the share of the
#: object's size (square root of its area) the grid spans: it must hold a long object
#: turned any way (a fish is up to 2.5 sizes long) with cells coarser than a pixel of a
#: small map (48 cells of 3.5 sizes: 0.07 of the size a cell). 96 cells did no better
#: (warp_nearest's macro part transfer on 12 fish 0.705 / 0.700, 12 busts 0.706 / 0.696).
GRID = 48
SPAN = 3.5
#: Degrees between the turns of the query tried over (-90, 90], before bisection to a
#: quarter degree: the objects' moments give an axis only up to a half turn and none for
#: a round object, so the turn is searched, not read off; at 7.5 the bisection starts
#: within 3.75 degrees of the best turn, where the distance is still one valley.
ANGLE_STEP = 7.5
#: A mirror image is taken only where it fits better than the query as it lies by more
#: than this share of the distance: a shape that cannot tell (an ellipsoid, distances
#: equal to 0.1 %) keeps the examples' side, where a choice by chance put the painted
#: eye of benchmarks/ellipsoid_fish.py on the other side at 200x150 and not at 512^2.
#: 1 % is above the grid's resampling noise and below what most shapes say (12 generated
#: fish: the wrong side 2.5x the distance at least; busts: 12 % of pairs within 2 %).
MIRROR_TIE = 0.01


@dataclass(frozen=True)
class Pose:
    """A similarity from query pixels to an example's pixels, mirrored or not.

    ``example = example_centre + scale * R(angle) @ F @ (query - query_centre)`` on
    (y, x) coordinates, ``F`` flipping x when ``mirrored``; ``distance`` is the shape
    distance at the best-fitting pose (:func:`pose_distances`; the mirror image may fit a
    little better than the pose kept, :data:`MIRROR_TIE`).
    """

    query_centre: tuple[float, float]
    example_centre: tuple[float, float]
    scale: float
    angle: float  # degrees, counter-clockwise on screen
    mirrored: bool
    distance: float = 0.0

    @property
    def linear(self) -> np.ndarray:
        """The 2x2 matrix acting on (y, x) offsets from the query's centroid."""
        theta = np.deg2rad(self.angle)
        # (y, x) with y down: a counter-clockwise turn on screen.
        rotation = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
        flip = np.diag([1.0, -1.0]) if self.mirrored else np.eye(2)
        return self.scale * rotation @ flip

    def forward(self, ys: np.ndarray, xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Example coordinates of query coordinates."""
        linear = self.linear
        dy, dx = np.asarray(ys) - self.query_centre[0], np.asarray(xs) - self.query_centre[1]
        return (
            self.example_centre[0] + linear[0, 0] * dy + linear[0, 1] * dx,
            self.example_centre[1] + linear[1, 0] * dy + linear[1, 1] * dx,
        )

    def inverse(self, ys: np.ndarray, xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Query coordinates of example coordinates."""
        inverse = np.linalg.inv(self.linear)
        dy, dx = np.asarray(ys) - self.example_centre[0], np.asarray(xs) - self.example_centre[1]
        return (
            self.query_centre[0] + inverse[0, 0] * dy + inverse[0, 1] * dx,
            self.query_centre[1] + inverse[1, 0] * dy + inverse[1, 1] * dx,
        )


def _frame(depth: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """(centroid (y, x), size in pixels, the depth divided by its object's median)."""
    mask = depth > 0
    centre, size = _centre_size(mask)
    return centre, size, np.where(mask, depth / float(np.median(depth[mask])), 0.0)


def _centre_size(mask: np.ndarray) -> tuple[np.ndarray, float]:
    """(centroid (y, x), size in pixels: the square root of the area) of ``mask``."""
    ys, xs = np.nonzero(mask)
    return np.array([ys.mean(), xs.mean()]), float(np.sqrt(len(ys)))


def _smoothed(
    normalized: np.ndarray, size: float, grid: int, span: float
) -> tuple[np.ndarray, int]:
    """The normalized depth low-passed for sampling on a grid of ``grid`` cells over
    ``span`` sizes (one grid cell: ``span * size / grid`` pixels): no aliasing. A large
    map is block-averaged first, ``block`` pixels a side (a third of a cell: the low-pass
    is wider): a 2048x1536 map's grids cost what a small one's do."""
    cell = span * size / grid
    if cell <= 1.5:
        return normalized.astype(np.float32), 1
    block = max(1, int(cell // 3))
    image = normalized.astype(np.float32)
    if block > 1:
        h, w = (image.shape[0] // block) * block, (image.shape[1] // block) * block
        image = image[:h, :w].reshape(h // block, block, w // block, block).mean(axis=(1, 3))
    return ndimage.gaussian_filter(image, 0.5 * cell / block, mode="constant"), block


def _sample(smoothed, centre, size, linear, grid, span) -> np.ndarray:
    """The smoothed image at ``centre + size * linear @ u`` (full-resolution pixels) for the
    grid's offsets ``u``, flat."""
    image, _ = smoothed
    at = _coordinates(smoothed, centre, size, linear, grid, span)
    return ndimage.map_coordinates(image, at, order=1, mode="constant", cval=0.0).ravel()


def _coordinates(smoothed, centre, size, linear, grid, span) -> np.ndarray:
    """(2, grid, grid): where :func:`_sample` reads the smoothed image (its pixels)."""
    _, block = smoothed
    u = (np.arange(grid) - (grid - 1) / 2.0) * (span / grid)
    gy, gx = np.meshgrid(u, u, indexing="ij")
    ys = centre[0] + size * (linear[0, 0] * gy + linear[0, 1] * gx)
    xs = centre[1] + size * (linear[1, 0] * gy + linear[1, 1] * gx)
    # Full-resolution coordinate p is block pixel (p + 0.5) / block - 0.5.
    return np.stack([(ys + 0.5) / block - 0.5, (xs + 0.5) / block - 0.5])


def shape_grid(depth: np.ndarray, grid: int = GRID, span: float = SPAN) -> np.ndarray:
    """An object's depth as it lies, on its own units-free grid (flat, ``grid**2``).

    Centred on the object's centroid, one cell ``span / grid`` of its size (the square
    root of its area), the depth divided by its object's median.

    Examples
    --------
    >>> disc = np.zeros((40, 40), np.float32); disc[10:30, 10:30] = 2.0
    >>> a, b = shape_grid(disc, 16), shape_grid(5 * np.roll(disc, 4, axis=1), 16)
    >>> bool(np.allclose(a, b))
    True
    """
    centre, size, normalized = _frame(np.asarray(depth, np.float64))
    image = _smoothed(normalized, size, grid, span)
    return _sample(image, centre, size, np.eye(2), grid, span).astype(np.float32)


def _linear(angle: float, mirrored: bool) -> np.ndarray:
    return Pose((0.0, 0.0), (0.0, 0.0), 1.0, angle, mirrored).linear


def _query_grids(image, centre, size, poses, grid, span) -> np.ndarray:
    """The query sampled for each (angle, mirrored): rows of the shape grid an example
    would show if the query were turned to it (the inverse map of each pose)."""
    # One interpolation for all the poses (each point's value is its own: the same as one
    # _sample per pose, without a call's overhead 48 times).
    at = np.stack(
        [_coordinates(image, centre, size, np.linalg.inv(_linear(a, m)), grid, span)
         for a, m in poses],
        axis=1,
    )  # fmt: skip
    found = ndimage.map_coordinates(image[0], at, order=1, mode="constant", cval=0.0)
    return found.reshape(len(poses), grid * grid)


@dataclass(frozen=True)
class CoarseQuery:
    """The query as the coarse search compares it (:func:`coarse_query`): its smoothed
    image (and block), centroid and size, and its shape grid turned to every angle of the
    search, each mirror hypothesis (unmirrored first) in turn: (hypotheses * angles,
    grid**2)."""

    image: tuple[np.ndarray, int]
    centre: np.ndarray
    size: float
    angles: np.ndarray
    flips: tuple[bool, ...]
    grids: np.ndarray
    settings: tuple[bool, float, int, float]  # made for: mirrored, angle step, grid, span


def coarse_query(
    depth: np.ndarray,
    *,
    mirrored: bool = True,
    angle_step: float = ANGLE_STEP,
    grid: int = GRID,
    span: float = SPAN,
) -> CoarseQuery:
    """The query's side of the coarse search (arguments as :func:`pose_distances`), made
    once for the selection's distances and the poses' refinement (the same query)."""
    centre, size, normalized = _frame(np.asarray(depth, np.float64))
    image = _smoothed(normalized, size, grid, span)
    angles = np.arange(-90.0 + angle_step, 90.0 + 1e-9, angle_step)
    flips = (False, True) if mirrored else (False,)
    poses = [(a, m) for m in flips for a in angles]
    grids = _query_grids(image, centre, size, poses, grid, span).astype(np.float64)
    settings = (mirrored, angle_step, grid, span)
    return CoarseQuery(image, centre, size, angles, flips, grids, settings)


def _coarse(depth, example_grids, mirrored, angle_step, grid, span, query=None):
    """(query image, centre, size), and per example and mirror hypothesis (unmirrored
    first) the coarse search's best distance and angle: arrays (N, hypotheses).
    ``query``: the :func:`coarse_query` of ``depth``, if made (for these settings)."""
    if query is None:
        query = coarse_query(depth, mirrored=mirrored, angle_step=angle_step, grid=grid, span=span)
    elif query.settings != (mirrored, angle_step, grid, span):
        raise ValueError("coarse_query was made for other settings than the search's")
    image, centre, size = query.image, query.centre, query.size
    angles, flips, queries = query.angles, query.flips, query.grids
    examples = np.asarray(example_grids, np.float64)
    ssd = (
        np.square(queries).sum(1)[:, None]
        + np.square(examples).sum(1)[None, :]
        - 2.0 * queries @ examples.T
    ) / queries.shape[1]
    ssd = ssd.reshape(len(flips), len(angles), len(examples))
    best = np.argmin(ssd, axis=1)  # (hypotheses, N)
    distances = np.take_along_axis(ssd, best[:, None, :], axis=1)[:, 0, :]
    return (image, centre, size), distances.T, angles[best].T


def pose_distances(
    depth: np.ndarray,
    example_grids: np.ndarray,
    *,
    mirrored: bool = True,
    angle_step: float = ANGLE_STEP,
    grid: int = GRID,
    span: float = SPAN,
    query: CoarseQuery | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Each example's shape distance to the query at the coarse search's best pose.

    Parameters
    ----------
    depth : ndarray (H, W)
        The query (background 0).
    example_grids : ndarray (N, grid**2)
        The examples' :func:`shape_grid`.
    mirrored : bool
        Try the query mirrored too.
    angle_step : float
        Degrees between the angles tried over (-90, 90].
    query : CoarseQuery, optional
        :func:`coarse_query` of ``depth`` for these settings, if made.

    Returns
    -------
    distances : ndarray (N,)
        The mean squared difference per grid cell at the best candidate.
    candidates : ndarray (N, 2)
        Its angle (degrees) and whether it is mirrored (0 or 1).
    """
    _, distances, angles = _coarse(depth, example_grids, mirrored, angle_step, grid, span, query)
    hypothesis = np.argmin(distances, axis=1)
    rows = np.arange(len(distances))
    candidates = np.stack([angles[rows, hypothesis], hypothesis.astype(np.float64)], axis=1)
    return distances[rows, hypothesis], candidates


def find_poses(
    depth: np.ndarray,
    examples: list[np.ndarray],
    *,
    mirrored: bool = True,
    angle_step: float = ANGLE_STEP,
    grid: int = GRID,
    span: float = SPAN,
    example_grids: np.ndarray | None = None,
    query: CoarseQuery | None = None,
) -> list[Pose]:
    """The pose of ``depth`` against each example depth: for each mirror hypothesis the
    coarse search's best angle refined by bisection, then the better hypothesis (each
    refined on its own: a nearly symmetric object's two hypotheses are close, and the
    coarse angles alone chose them by chance), the mirror image only by
    :data:`MIRROR_TIE`.

    Parameters
    ----------
    depth : ndarray (H, W)
        The query.
    examples : list of ndarray
        The examples' depths.
    mirrored, angle_step, grid, span
        As :func:`pose_distances`.
    example_grids : ndarray, optional
        The examples' :func:`shape_grid` (made here if not given).
    query : CoarseQuery, optional
        :func:`coarse_query` of ``depth`` for these settings (made here if not given).

    Returns
    -------
    list of Pose
    """
    if example_grids is None:
        example_grids = np.stack([shape_grid(e, grid, span) for e in examples])
    (image, centre, size), distances, angles = _coarse(
        depth, example_grids, mirrored, angle_step, grid, span, query
    )
    poses = []
    for k, (example, target) in enumerate(
        zip(examples, np.asarray(example_grids, np.float64), strict=True)
    ):
        best_pose: tuple[float, float, bool] | None = None
        shape_distance = np.inf  # the best fit, whichever hypothesis is taken
        for hypothesis in range(distances.shape[1]):
            mirror = bool(hypothesis)

            def costs(trials, mirror: bool = mirror, target: Any = target) -> list[float]:
                poses = [(a, mirror) for a in trials]
                queries = _query_grids(image, centre, size, poses, grid, span)
                return [float(np.mean(np.square(query - target))) for query in queries]

            # Bisection of the angle within a step of the coarse search's best (both
            # trials of a step sampled at once: they do not depend on each other).
            angle, value = float(angles[k, hypothesis]), float(distances[k, hypothesis])
            step = angle_step / 2.0
            while step > 0.25:
                trials = (angle - step, angle + step)
                for trial, trial_value in zip(trials, costs(trials), strict=True):
                    if trial_value < value:
                        angle, value = trial, trial_value
                step /= 2.0
            # The unmirrored hypothesis comes first; the mirror image must beat it by
            # MIRROR_TIE.
            if best_pose is None or value < best_pose[0] * (1.0 - MIRROR_TIE):
                best_pose = (value, angle, mirror)
            shape_distance = min(shape_distance, value)
        assert best_pose is not None
        _, angle, mirror = best_pose
        example_centre, example_size = _centre_size(np.asarray(example) > 0)
        poses.append(
            Pose(
                query_centre=(float(centre[0]), float(centre[1])),
                example_centre=(float(example_centre[0]), float(example_centre[1])),
                scale=example_size / size,
                angle=angle,
                mirrored=mirror,
                # The selection ranks by the shape's fit, not by the side the tie keeps.
                distance=shape_distance,
            )
        )
    return poses


@dataclass(frozen=True)
class CanonicalFrame:
    """Where the synthesis runs: a box of the first example's pixel grid that holds the
    query moved by its pose onto that example.

    Canonical pixel (i, j) is example pixel (``origin[0] + i``, ``origin[1] + j``), query
    coordinates ``pose.inverse`` of that.
    """

    pose: Pose
    origin: tuple[int, int]
    shape: tuple[int, int]

    def to_query(self, rows: slice | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Query coordinates (y, x) of every canonical pixel, (H_c, W_c) each; with
        ``rows``, of those rows only (the same values as the whole grid's)."""
        start, stop, _ = (rows or slice(None)).indices(self.shape[0])
        ys, xs = np.mgrid[start:stop, 0 : self.shape[1]].astype(np.float64)
        return self.pose.inverse(ys + self.origin[0], xs + self.origin[1])

    def from_query(self, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        """Canonical coordinates (y, x) of every query pixel of a frame of ``shape``."""
        ys, xs = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
        cy, cx = self.pose.forward(ys, xs)
        return cy - self.origin[0], cx - self.origin[1]


def absorbed_pose(pose: Pose, selection: Any) -> Pose:
    """``pose`` as the synthesis uses it: where its turn and scale are within what the
    registration's warp absorbs (``selection.pose_turn_tolerance`` degrees, a scale within
    ``selection.pose_scale_tolerance``), a move by whole pixels (and the mirror image)
    only, so that the query is not resampled; else ``pose`` itself.

    Examples
    --------
    >>> from imagemap.depth.config import Selection
    >>> pose = Pose((10.2, 20.7), (12.0, 25.5), 1.05, 3.0, False)
    >>> moved = absorbed_pose(pose, Selection())
    >>> moved.scale, moved.angle, moved.forward(np.array([10.0]), np.array([20.0]))
    (1.0, 0.0, (array([12.]), array([25.])))
    """
    tolerance = selection.pose_scale_tolerance
    if abs(pose.angle) > selection.pose_turn_tolerance or not (
        1.0 / tolerance <= pose.scale <= tolerance
    ):
        return pose
    # example = example_centre + F (query - query_centre): whole pixels when the
    # centres' difference (their sum in x, mirrored) is.
    cy, cx = pose.query_centre
    ey, ex = pose.example_centre
    shift_y = float(np.rint(ey - cy))
    if pose.mirrored:
        ex = float(np.rint(ex + cx)) - cx
    else:
        ex = cx + float(np.rint(ex - cx))
    return Pose((cy, cx), (cy + shift_y, ex), 1.0, 0.0, pose.mirrored, pose.distance)


def canonical_frame(mask: np.ndarray, pose: Pose, margin: float, align: int = 1) -> CanonicalFrame:
    """The box of the example's grid that holds the query's object moved by ``pose``,
    with ``margin`` pixels around it (the windows' and the guides' room), its origin on a
    multiple of ``align`` pixels: the pyramids' coarser levels of the frame and of the
    example then sample the same points (pixel 2i of a level is pixel i of the next)."""
    ys, xs = np.nonzero(mask)
    corners_y = np.array([ys.min() - 1, ys.min() - 1, ys.max() + 1, ys.max() + 1], float)
    corners_x = np.array([xs.min() - 1, xs.max() + 1, xs.min() - 1, xs.max() + 1], float)
    cy, cx = pose.forward(corners_y, corners_x)
    y0 = int(np.floor((cy.min() - margin) / align)) * align
    x0 = int(np.floor((cx.min() - margin) / align)) * align
    y1, x1 = int(np.ceil(cy.max() + margin)) + 1, int(np.ceil(cx.max() + margin)) + 1
    return CanonicalFrame(pose=pose, origin=(y0, x0), shape=(y1 - y0, x1 - x0))


#: Rows of a frame resampled at a time (the canonical frame's in :func:`resample_depth`,
#: the query's in :func:`unpose`): bounded float64 temporaries at 4096^2.
_ROWS = 512


def resample_depth(depth: np.ndarray, frame: CanonicalFrame) -> np.ndarray:
    """The query's depth on the canonical grid: interpolated inside its object (the
    background continued from it first, so the outline is not averaged with 0), 0 outside.
    """
    mask = depth > 0
    filled = inside_mask = None  # made at the first block whose points fall between pixels
    # A block of the canonical frame's rows at a time: no full-size float64 coordinates
    # (four of them, and SciPy's stacked copy of each pair).
    out = np.empty(frame.shape, np.float32)
    for y0 in range(0, frame.shape[0], _ROWS):
        rows = slice(y0, y0 + _ROWS)
        qy, qx = frame.to_query(rows)
        if _on_pixels(qy, qx):
            # A pose the warp absorbs moves the query by whole pixels: each point is a
            # pixel, whose interpolation is its own value (weights 1 and 0): the object's
            # depth where the mask is 1, else 0, taken without the fill or the
            # interpolation (at 512^2 the fill's distance transform was 20 of 35 ms).
            out[rows] = _taken(depth, mask, qy, qx)
            continue
        if filled is None:
            # The nearest object pixel's indices only: the distances (SciPy makes them in
            # float64 from three more (2, H, W) arrays) were most of the pose stage's peak
            # at 4096^2.
            iy, ix = ndimage.distance_transform_edt(
                ~mask, return_distances=False, return_indices=True
            )
            filled = depth[iy, ix].astype(np.float32, copy=False)
            del iy, ix
            inside_mask = mask.astype(np.float32)
        values = ndimage.map_coordinates(filled, [qy, qx], order=1, mode="nearest")
        inside = ndimage.map_coordinates(inside_mask, [qy, qx], order=1, cval=0.0)
        out[rows] = np.where(inside > 0.5, values, 0.0)
    return out


def _on_pixels(qy: np.ndarray, qx: np.ndarray) -> bool:
    """Whether every point (qy, qx) is a pixel centre: whole coordinates (any, inside the
    frame or not)."""
    return bool(np.array_equal(qy, np.rint(qy)) and np.array_equal(qx, np.rint(qx)))


def _taken(depth: np.ndarray, mask: np.ndarray, qy: np.ndarray, qx: np.ndarray) -> np.ndarray:
    """:func:`resample_depth`'s values at whole coordinates (qy, qx): the depth (as
    float32) where the point is an object pixel of the frame, else 0."""
    height, width = mask.shape
    iy, ix = qy.astype(np.intp), qx.astype(np.intp)
    within = (iy >= 0) & (iy < height) & (ix >= 0) & (ix < width)
    np.clip(iy, 0, height - 1, out=iy)
    np.clip(ix, 0, width - 1, out=ix)
    within &= mask[iy, ix]
    return np.where(within, depth[iy, ix].astype(np.float32, copy=False), np.float32(0.0))


@dataclass
class PosedExample:
    """An example as the synthesis in the canonical frame uses it: its depth units-free
    (:func:`~imagemap.depth.units.units_free`), mirrored left-right when ``mirrored`` (its
    columns reversed: exact, nothing resampled). Its image and labels are read from the
    example when asked and mirrored the same way, not held (a full-size image per
    example less through the synthesis, as :func:`imagemap.depth.guides.example_ycbcr`
    keeps it)."""

    example: Any
    depth: np.ndarray
    mirrored: bool = False

    @classmethod
    def of(cls, example: Any, mirrored: bool = False) -> PosedExample:
        from imagemap.depth.units import units_free  # deferred: units imports nothing here

        return cls(example, _arranged(units_free(example.depth), mirrored), mirrored)

    @property
    def name(self) -> str:
        return self.example.name

    @property
    def mask(self) -> np.ndarray:
        return self.depth > 0

    @property
    def shape(self) -> tuple[int, int]:
        """Its frame's (H, W), as :attr:`imagemap.example.Example.shape` (no mask made)."""
        height, width = self.depth.shape
        return height, width

    @property
    def image(self) -> np.ndarray:
        return _arranged(_read_uncached(self.example, "image"), self.mirrored)

    @property
    def labels(self) -> np.ndarray | None:
        return _arranged(self.example.labels, self.mirrored)


def _arranged(array, mirrored: bool):
    return None if array is None else np.ascontiguousarray(array[:, ::-1] if mirrored else array)


def _read_uncached(example: Any, name: str) -> Any:
    """``example.<name>`` without leaving it cached on the example if it was not."""
    cache = getattr(example, "__dict__", {})
    cached = name in cache
    value = getattr(example, name)
    if not cached and name in cache:
        del cache[name]
    return value


#: Brought back to the query's frame, the map's nearest pixel is taken while the query's
#: pixels and the canonical frame's differ in size by at most this factor: crisp, as the
#: map (a pixel now and then taken twice or skipped). A query larger still is
#: interpolated (twice the example's size would show 2 x 2 blocks); a smaller one
#: low-passed first (skipped pixels would alias).
COPY_RANGE = 1.5


def unpose(
    frame: CanonicalFrame,
    query_mask: np.ndarray,
    ycbcr: np.ndarray,
    source: np.ndarray,
    exemplars: list[np.ndarray] | None,
) -> tuple[np.ndarray, np.ndarray]:
    """The finished canonical map, and its source map, in the query's frame.

    While the query's pixels and the canonical frame's differ in size by at most
    :data:`COPY_RANGE`, every query pixel takes its nearest canonical pixel, colour and
    source: the map's own pixels, as crisp as it (a pixel now and then taken twice or
    skipped). A query larger still is, where the map is a copy (``exemplars`` given),
    copied from its examples through the canonical source map at its sub-pixel places
    (interpolated) plus the blend's correction there (as
    :func:`imagemap.mesh.uvspace.fine_texture` makes a texture finer than its
    synthesis), else the map interpolated; a smaller one is the map low-passed (over the
    canonical pixels a query pixel covers) and interpolated.

    Returns
    -------
    ycbcr : ndarray (H, W, 3) float32
    source : ndarray (H, W, 3) int32
        Example index, y, x in the example's own pixels (as the canonical synthesis used
        it: a mirrored example's columns are still reversed).
    """
    from imagemap.core.blend import copy_through  # deferred: start-up (numba kernels)

    height, width = query_mask.shape
    ch, cw = ycbcr.shape[:2]
    scale = frame.pose.scale
    nearest = 1.0 / COPY_RANGE <= scale <= COPY_RANGE
    copied = exemplars if exemplars is not None and scale < 1.0 / COPY_RANGE else None
    if copied is not None:
        colours = ycbcr - copy_through(copied, source).astype(np.float32)  # the correction
    elif scale > COPY_RANGE:
        sigma = 0.5 * float(np.sqrt(scale * scale - 1.0))
        colours = ndimage.gaussian_filter(ycbcr, (sigma, sigma, 0))
    else:
        colours = ycbcr
    out = np.zeros((height, width, 3), np.float32)
    out_source = np.zeros((height, width, 3), np.int32)
    axes = _nearest_axes(frame, (height, width)) if nearest else None
    if axes is not None:  # no turn: each row and each column its own canonical one
        iy, ix = np.clip(axes[0], 0, ch - 1), np.clip(axes[1], 0, cw - 1)
        for y0 in range(0, height, _ROWS):
            rows = slice(y0, y0 + _ROWS)
            # The rows taken, then the columns of those (the same pixels as one index of
            # both: 2 ms against 11 for a 512^2 source map).
            out_source[rows] = source.take(iy[rows], axis=0).take(ix, axis=1)
            out[rows] = colours.take(iy[rows], axis=0).take(ix, axis=1)
        out[~query_mask] = 0.0
        return out, out_source
    for y0 in range(0, height, _ROWS):
        ys, xs = np.mgrid[y0 : min(height, y0 + _ROWS), 0:width].astype(np.float64)
        cy, cx = frame.pose.forward(ys, xs)
        cy, cx = cy - frame.origin[0], cx - frame.origin[1]
        iy = np.clip(np.rint(cy), 0, ch - 1).astype(np.int64)
        ix = np.clip(np.rint(cx), 0, cw - 1).astype(np.int64)
        block_source = source[iy, ix]
        rows = slice(y0, y0 + ys.shape[0])
        out_source[rows] = block_source
        if nearest:
            out[rows] = colours[iy, ix]
            continue
        at = [np.clip(cy, 0, ch - 1), np.clip(cx, 0, cw - 1)]
        block = np.stack(
            [ndimage.map_coordinates(colours[..., c], at, order=1) for c in range(3)], axis=-1
        )
        for index, exemplar in enumerate(copied or []):
            mine = block_source[..., 0] == index
            if not mine.any():
                continue
            h, w = exemplar.shape[:2]
            sy = np.clip(block_source[..., 1][mine] + (cy - iy)[mine], 0, h - 1)
            sx = np.clip(block_source[..., 2][mine] + (cx - ix)[mine], 0, w - 1)
            block[mine] += np.stack(
                [ndimage.map_coordinates(exemplar[..., c], [sy, sx], order=1) for c in range(3)],
                axis=-1,
            )
            # The source: the example's pixel at the sub-pixel place.
            out_source[rows][..., 1][mine] = np.rint(sy)
            out_source[rows][..., 2][mine] = np.rint(sx)
        out[rows] = block
    out[~query_mask] = 0.0
    return out, out_source


def _nearest_axes(
    frame: CanonicalFrame, shape: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray] | None:
    """Where the pose does not turn (its matrix diagonal), the canonical row of each of
    ``shape``'s rows and the canonical column of each of its columns (rounded, not
    clipped): the other axis's term is a zero, which changes no sum, so these are the
    rows and columns the whole grid's :meth:`Pose.forward` rounds to. None otherwise."""
    linear = frame.pose.linear
    if linear[0, 1] != 0.0 or linear[1, 0] != 0.0:
        return None
    ys = np.arange(shape[0], dtype=np.float64)
    xs = np.arange(shape[1], dtype=np.float64)
    cy, _ = frame.pose.forward(ys, np.zeros_like(ys))
    _, cx = frame.pose.forward(np.zeros_like(xs), xs)
    iy = np.rint(cy - frame.origin[0]).astype(np.int64)
    ix = np.rint(cx - frame.origin[1]).astype(np.int64)
    return iy, ix


def unpose_nearest(frame: CanonicalFrame, shape: tuple[int, int], values: np.ndarray):
    """A canonical per-pixel array (a cost map) in the query's frame: each query pixel
    takes its nearest canonical pixel's value (NaN outside the canonical frame)."""
    out = np.full(shape, np.nan, dtype=np.float32)
    axes = _nearest_axes(frame, shape)
    if axes is not None:  # no turn: the rows and columns inside the canonical frame
        iy, ix = axes
        rows = np.flatnonzero((iy >= 0) & (iy < values.shape[0]))
        columns = np.flatnonzero((ix >= 0) & (ix < values.shape[1]))
        out[np.ix_(rows, columns)] = values.take(iy[rows], axis=0).take(ix[columns], axis=1)
        return out
    for y0 in range(0, shape[0], _ROWS):  # by blocks of rows: no full-size float64 grids
        ys, xs = np.mgrid[y0 : min(shape[0], y0 + _ROWS), 0 : shape[1]].astype(np.float64)
        cy, cx = frame.pose.forward(ys, xs)
        iy = np.rint(cy - frame.origin[0]).astype(np.int64)
        ix = np.rint(cx - frame.origin[1]).astype(np.int64)
        inside = (iy >= 0) & (iy < values.shape[0]) & (ix >= 0) & (ix < values.shape[1])
        out[y0 : y0 + len(ys)][inside] = values[iy[inside], ix[inside]]
    return out
