"""Registration of each example onto the query: a smooth non-rigid warp of the whole object.

Two objects of one class differ in proportions and pose, not in what they are: a
fish's eye sits behind its mouth, its fins where its body narrows. A smooth warp
that carries the example's outline and relief onto the query's says where every
query pixel lies on the example, so that an example's stripes, spots and parts
can be copied as whole regions, bent with the object, instead of one window at a
time (the coherence window-by-window matching lacks: fragments no larger than a
window, at any resolution).

The warp is an affine map from the objects' second moments composed with a cubic
B-spline free-form deformation (Rueckert et al. 1999), fitted by Levenberg-Marquardt
to a guide image of each object: its signed distance to the outline (soft-clipped)
and its depth relative to its own deepest point, so that depth units do not
matter. It is fitted at a working resolution where the object is
``work_size`` pixels across, coarse to fine over control grids of growing
density, and evaluated at any resolution. Every setting of the fit whose value matters
is a field of :class:`imagemap.depth.config.Registration`, with its reason; the three whose
value did not (``FIT_ITERATIONS``, ``FIT_PIXELS``, ``OUTLINE_REACH``) are constants here.

Examples
--------
>>> yy, xx = np.mgrid[:60, :80]
>>> def blob(cy, cx, ry, rx):
...     u = ((yy - cy) / ry) ** 2 + ((xx - cx) / rx) ** 2
...     return np.where(u < 1, 0.2 + np.sqrt(np.clip(1 - u, 0, 1)), 0).astype(np.float32)
>>> query, example = blob(30, 40, 12, 25), blob(28, 36, 15, 30)
>>> warp = register(query, example)
>>> y, x = warp.forward(np.array([30.0]), np.array([65.0]))  # the query's right tip
>>> round(float(y[0])), round(float(x[0]))
(28, 66)
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy import ndimage
from threadpoolctl import threadpool_limits

from imagemap.depth.config import Registration
from imagemap.depth.schedule import each_example

__all__ = [
    "Warp",
    "block_average",
    "position_scales",
    "register",
    "Registered",
    "register_all",
    "register_with_detail",
    "example_positions",
    "position_frame",
    "query_positions",
    "registration_guide",
    "relief_detail",
]

#: The defaults of every setting of the fit (a :class:`DepthConfig`'s ``registration``).
_REGISTRATION = Registration()
#: Levenberg-Marquardt iterations per grid at most (swept in #43, 12 fish/busts at 1x and the
#: plates' seam F1: 6, 12 and 24 within the seed spread).
FIT_ITERATIONS = 12
#: Pixels of the working grid the fit uses at most (a regular subsample): bounds its cost
#: (swept in #43: 1500, 3000 and 6000 within the seed spread).
FIT_PIXELS = 3000
#: Soft clip (tanh, fraction of the object's size) of the signed distance in the guide
#: image: the outline and the band within a few percent of it lead the fit (swept in #43:
#: 0.02, 0.04 and 0.08 within the seed spread).
OUTLINE_REACH = 0.04
#: Rows of a full-size map interpolated from a coarse grid at a time (their coordinates
#: are 16 bytes a pixel: bounded at 4096^2).
_ROWS = 256


def registration_guide(
    depth: np.ndarray,
    mask: np.ndarray,
    relief_weight: float = _REGISTRATION.registration_relief,
    *,
    relief_scale: float = _REGISTRATION.relief_detail_scale,
) -> np.ndarray:
    """The image the warp is fitted on: soft-clipped signed distance to the outline plus
    the depth relative to the object's deepest point (both in [-0.5, 1]), plus
    ``relief_weight`` times the relief's detail (the relative depth less its smoothing
    over ``relief_scale`` of the object's size, soft-clipped at its 95th percentile
    inside the object). The signed distance is soft-clipped at ``OUTLINE_REACH`` of the
    object's size.

    Examples
    --------
    >>> depth = np.zeros((5, 9), np.float32); depth[1:4, 2:7] = 2.0
    >>> guide = registration_guide(depth, depth > 0)
    >>> bool(guide[2, 4] > 0.5 > guide[0, 0])
    True
    """
    return _guide_and_nearest(depth, mask, relief_weight, relief_scale)[0]


def _guide_and_nearest(
    depth: np.ndarray,
    mask: np.ndarray,
    relief_weight: float,
    relief_scale: float,
    reads: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`registration_guide`, and ``mask``'s nearest object pixels its outside
    distance was made from (:func:`~imagemap.core.blend.nearest_object_pixels`' values),
    None for a mask that is all or nothing (the bands make none for it).

    With ``reads`` (rows, columns: :func:`_zoom_reads`), the guide only at the pixels of
    those rows and columns, 0 elsewhere: the pixels the zoom to the working size reads
    (a sixth of them at 512^2; all of a small map's, which then takes the whole guide's
    way), which then gives the same values. The distances, the relief's smoothing and its
    percentile are the whole map's as before; each pixel's distances come from the feature
    transforms as SciPy makes them (:func:`_distances_at`), its terms by the same
    operations on the same values."""
    size = max(float(np.sqrt(mask.sum())), 1.0)
    if reads is not None and (len(reads[0]), len(reads[1])) == mask.shape:
        reads = None  # every pixel read (a small map): the whole guide
    if reads is None:
        at: tuple = (slice(None), slice(None))
        outside, nearest = ndimage.distance_transform_edt(~mask, return_indices=True)
        signed = _inside_distance(mask) - outside
        del outside
    else:
        at = np.ix_(*reads)
        nearest = ndimage.distance_transform_edt(~mask, return_distances=False, return_indices=True)
        signed = _inside_distance(mask, reads) - _distances_at(nearest, *reads)
    if not mask.any() or mask.all():
        nearest = None
    outline = np.tanh(signed / (OUTLINE_REACH * size))
    deepest = float(depth[mask].max()) if mask.any() else 1.0
    relief = np.where(mask, depth / max(deepest, 1e-30), 0.0)
    guide = 0.5 * outline + 0.5 * relief[at]
    if relief_weight and mask.any():
        smooth = _smoothed_inside_box(relief, mask, relief_scale * size)
        detail = np.where(mask, relief - smooth, 0.0)
        unit = float(np.percentile(np.abs(detail[mask]), 95)) or 1.0
        guide = guide + relief_weight * np.tanh(detail[at] / unit)
    if reads is None:
        return guide.astype(np.float32), nearest
    out = np.zeros(mask.shape, np.float32)
    out[at] = guide
    return out, nearest


def _distances_at(features: np.ndarray, rows: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """The distances ``ndimage.distance_transform_edt`` makes from its feature transform
    ``features`` (2, H, W), at the pixels of ``rows`` and ``columns`` only: the same
    operations (the offsets squared as float64, summed, the square root), the same
    values."""
    at = np.ix_(rows, columns)
    dy = (features[0][at] - rows[:, None]).astype(np.float64)
    dx = (features[1][at] - columns[None, :]).astype(np.float64)
    return np.sqrt(np.multiply(dy, dy, out=dy) + np.multiply(dx, dx, out=dx))


def _zoom_reads(shape: tuple[int, int], scale: float) -> tuple[np.ndarray, np.ndarray]:
    """The rows and the columns of an array of ``shape`` that ``ndimage.zoom(array, scale,
    order=1, prefilter=False)`` reads: the two neighbours of each output point along each
    axis, at zoom's own coordinates (output index times (n - 1) / (out - 1), out the
    rounded n * scale; a neighbour past the edge is none)."""
    reads = []
    for n in shape:
        out = int(round(n * scale))
        step = (n - 1) / (out - 1) if out > 1 else 1.0
        first = np.floor(np.arange(out) * step).astype(np.intp)
        reads.append(np.unique(np.clip(np.concatenate([first, first + 1]), 0, n - 1)))
    return reads[0], reads[1]


def _mask_box(mask: np.ndarray, margin: int) -> tuple[slice, slice] | None:
    """The box of ``mask``'s pixels and ``margin`` pixels around it, within the frame
    (None when it has none)."""
    rows, columns = np.flatnonzero(mask.any(1)), np.flatnonzero(mask.any(0))
    if not len(rows):
        return None
    height, width = mask.shape
    return (
        slice(max(rows[0] - margin, 0), min(rows[-1] + 1 + margin, height)),
        slice(max(columns[0] - margin, 0), min(columns[-1] + 1 + margin, width)),
    )


def _inside_distance(
    mask: np.ndarray, reads: tuple[np.ndarray, np.ndarray] | None = None
) -> np.ndarray:
    """``ndimage.distance_transform_edt(mask)``: each object pixel's distance to the
    background, 0 outside, transformed on the object's box and a pixel around it (the
    background's pixels there are at least as near as any beyond: the same distances);
    with ``reads`` (rows, columns), at those rows' and columns' pixels only.

    Examples
    --------
    >>> mask = np.zeros((9, 12), bool); mask[2:7, 3:10] = True; mask[4, 5] = False
    >>> bool(np.array_equal(_inside_distance(mask), ndimage.distance_transform_edt(mask)))
    True
    >>> rows, columns = np.arange(9), np.array([0, 4, 5, 6, 11])
    >>> bool(np.array_equal(_inside_distance(mask, (rows, columns)),
    ...                     ndimage.distance_transform_edt(mask)[np.ix_(rows, columns)]))
    True
    """
    box = _mask_box(mask, 1)
    if reads is None:
        out = np.zeros(mask.shape)
        if box is not None:
            out[box] = ndimage.distance_transform_edt(mask[box])
        return out
    rows, columns = reads
    out = np.zeros((len(rows), len(columns)))
    if box is None:
        return out
    (y0, y1), (x0, x1) = (box[0].start, box[0].stop), (box[1].start, box[1].stop)
    features = ndimage.distance_transform_edt(
        mask[box], return_distances=False, return_indices=True
    )
    inside_rows = np.flatnonzero((rows >= y0) & (rows < y1))
    inside_columns = np.flatnonzero((columns >= x0) & (columns < x1))
    out[np.ix_(inside_rows, inside_columns)] = _distances_at(
        features, rows[inside_rows] - y0, columns[inside_columns] - x0
    )
    return out


def _smoothed_inside_box(values: np.ndarray, mask: np.ndarray, sigma: float) -> np.ndarray:
    """``ndimage.gaussian_filter(values, sigma)`` on ``mask``'s box, 0 elsewhere, for
    ``values`` that are 0 outside ``mask``: filtered on the box and the filter's reach
    around it (beyond which, and in the mirror images of which, all is 0), the same
    values there.

    Examples
    --------
    >>> mask = np.zeros((40, 50), bool); mask[10:25, 12:30] = True
    >>> values = np.where(mask, np.random.default_rng(0).random((40, 50)), 0.0)
    >>> box = _mask_box(mask, 0)
    >>> bool(np.array_equal(_smoothed_inside_box(values, mask, 2.5)[box],
    ...                     ndimage.gaussian_filter(values, 2.5)[box]))
    True
    """
    reach = int(4.0 * float(sigma) + 0.5)  # gaussian_filter's radius (truncate 4)
    outer, inner = _mask_box(mask, reach), _mask_box(mask, 0)
    values = np.asarray(values)
    out = np.zeros(values.shape, values.dtype)  # gaussian_filter's: the input's
    if outer is None or inner is None:
        return out
    smooth = ndimage.gaussian_filter(values[outer], sigma)
    within = tuple(
        slice(i.start - o.start, i.stop - o.start) for i, o in zip(inner, outer, strict=True)
    )
    out[inner] = smooth[within]
    return out


def _moments(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ys, xs = np.nonzero(mask)
    return np.array([ys.mean(), xs.mean()]), np.maximum([ys.std(), xs.std()], 1e-3)


def _bspline_weights(t: np.ndarray, axis: int = -1) -> np.ndarray:
    """Cubic B-spline weights of the four control points around fractional ``t``, stacked
    along ``axis`` (each power of ``t`` made once: the same values)."""
    t2, t3 = t**2, t**3
    return np.stack(
        [
            (1 - t) ** 3 / 6,
            (3 * t3 - 6 * t2 + 4) / 6,
            (-3 * t3 + 3 * t2 + 3 * t + 1) / 6,
            t3 / 6,
        ],
        axis=axis,
    )


def _span(
    coords: np.ndarray, low: float, high: float, n: int, axis: int = -1
) -> tuple[np.ndarray, np.ndarray]:
    """The first of the four control points (of ``n`` over [low, high]) whose cubic
    B-splines cover each coordinate, (N,) int64, and their weights, (N, 4) (``axis`` 0:
    (4, N))."""
    spacing = max(high - low, 1e-6) / (n - 3)
    u = (np.asarray(coords, dtype=np.float64) - low) / spacing
    first = np.clip(np.floor(u).astype(np.int64), 0, n - 4)
    return first, _bspline_weights(np.clip(u - first, 0.0, 1.0), axis)


def _basis(coords: np.ndarray, low: float, high: float, n: int) -> np.ndarray:
    """(len(coords), n) cubic B-spline basis of ``n`` control points over [low, high]."""
    first, weights = _span(coords, low, high, n)
    out = np.zeros((len(first), n))
    rows = np.arange(len(first))
    for k in range(4):
        out[rows, first + k] = weights[:, k]
    return out


def _tensor_basis(ys, xs, box, n) -> np.ndarray:
    by = _basis(ys, box[0], box[1], n)
    bx = _basis(xs, box[2], box[3], n)
    return (by[:, :, None] * bx[:, None, :]).reshape(len(ys), n * n)


@dataclass(frozen=True)
class Warp:
    """A query-to-example map: ``forward(y, x)`` gives the example coordinates of query
    pixel coordinates (any resolution: coordinates are in pixels of the full images).

    ``example = example_centre + linear @ (query + d(query) - query_centre)``.

    Attributes
    ----------
    query_centre, example_centre : ndarray (2,)
    linear : ndarray (2, 2)
        The affine part on (y, x) offsets: a turn and the objects' spreads along their
        own axes.
    box : tuple of float
        The control grid's extent in query pixels (y0, y1, x0, x1).
    coefficients : ndarray (2, n * n)
        The B-spline displacement ``d`` (query pixels) per control point.
    n : int
        Control points per side.
    relief_residual : ndarray (h, w), optional
        The squared difference between the query's relief detail and the example's
        carried onto it by the warp (:func:`relief_detail`, in (-1, 1)), on a grid of
        ``relief_step`` query pixels a cell: where the example's relief disagrees with
        the query's (a groove, ridge or bump that lies elsewhere or nowhere in it).
    relief_step : float
    """

    query_centre: np.ndarray
    example_centre: np.ndarray
    linear: np.ndarray
    box: tuple[float, float, float, float]
    coefficients: np.ndarray
    n: int
    relief_residual: np.ndarray | None = None
    relief_step: float = 1.0

    def displacement(self, ys: np.ndarray, xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The B-spline displacement (query pixels) at query coordinates.

        Summed over the 4 x 4 control points around each coordinate (the others'
        B-splines are 0 there), not as a product with the dense (N, n * n) basis: a
        full-resolution grid costs 16 passes over its coordinates, not n * n."""
        n, box = self.n, self.box
        # Weights as rows (4, N) and every product and sum into buffers: the same
        # operations on each point, in the same order, as a sum of 16 terms.
        first_y, weights_y = _span(np.ravel(ys), box[0], box[1], n, axis=0)
        first_x, weights_x = _span(np.ravel(xs), box[2], box[3], n, axis=0)
        size = first_y.shape[0]
        dy, dx = np.zeros(size), np.zeros(size)
        weight, term = np.empty(size), np.empty(size)
        index = np.empty(size, np.int64)
        along_y, along_x = np.ascontiguousarray(self.coefficients, np.float64)
        for a in range(4):
            row = (first_y + a) * n + first_x
            for b in range(4):
                np.multiply(weights_y[a], weights_x[b], out=weight)
                np.add(row, b, out=index)
                dy += np.multiply(weight, np.take(along_y, index, out=term), out=term)
                dx += np.multiply(weight, np.take(along_x, index, out=term), out=term)
        shape = np.shape(ys)
        return dy.reshape(shape), dx.reshape(shape)

    def displacement_grid(self, ys: np.ndarray, xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`displacement` on the grid of rows ``ys`` (H,) and columns ``xs`` (W,),
        (H, W) each: the same values, each B-spline weight and control point made once
        per row and per column instead of once per point."""
        n, box = self.n, self.box
        first_y, weights_y = _span(np.asarray(ys), box[0], box[1], n)
        first_x, weights_x = _span(np.asarray(xs), box[2], box[3], n)
        shape = (len(first_y), len(first_x))
        dy, dx = np.zeros(shape), np.zeros(shape)
        weight, term = np.empty(shape), np.empty(shape)
        grids = self.coefficients.reshape(2, n, n)
        for a in range(4):
            rows_y, rows_x = grids[0, first_y + a], grids[1, first_y + a]  # (H, n)
            for b in range(4):
                # The products, sums and their order of displacement(), point by point.
                np.multiply(weights_y[:, a, None], weights_x[None, :, b], out=weight)
                dy += np.multiply(weight, rows_y[:, first_x + b], out=term)
                dx += np.multiply(weight, rows_x[:, first_x + b], out=term)
        return dy, dx

    def forward_grid(self, ys: np.ndarray, xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`forward` of the grid of rows ``ys`` (H,) and columns ``xs`` (W,): the same
        values, by :meth:`displacement_grid`.

        Examples
        --------
        >>> warp = Warp(np.array([4.0, 5.0]), np.array([3.0, 6.0]), np.eye(2),
        ...             (0.0, 9.0, 0.0, 11.0), np.linspace(-1, 1, 50).reshape(2, 25), 5)
        >>> ys, xs = np.arange(9.0), np.arange(11.0) * 0.9
        >>> gy, gx = np.meshgrid(ys, xs, indexing="ij")
        >>> all(np.array_equal(a, b) for a, b in zip(warp.forward_grid(ys, xs),
        ...                                          warp.forward(gy, gx)))
        True
        """
        dy, dx = self.displacement_grid(ys, xs)
        return self._affine_part(np.asarray(ys)[:, None] + dy, np.asarray(xs)[None, :] + dx)

    def forward(self, ys: np.ndarray, xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Example coordinates (y, x) of query coordinates."""
        dy, dx = self.displacement(ys, xs)
        return self._affine_part(np.asarray(ys) + dy, np.asarray(xs) + dx)

    def _affine_part(self, ys: np.ndarray, xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The affine map of displaced query coordinates onto the example."""
        oy = ys - self.query_centre[0]
        ox = xs - self.query_centre[1]
        return (
            self.example_centre[0] + self.linear[0, 0] * oy + self.linear[0, 1] * ox,
            self.example_centre[1] + self.linear[1, 0] * oy + self.linear[1, 1] * ox,
        )

    def inverse(self, ys: np.ndarray, xs: np.ndarray, iterations: int = 12) -> tuple:
        """Query coordinates of example coordinates (fixed-point iteration: the
        displacement is smooth and small against the object).

        Each point is iterated until it is a fixed point to the bit (the next step would
        give it again, and so every later one: it is left), or ``iterations`` times: the
        values of ``iterations`` steps for every point. Most points are fixed after five or
        six steps; a few alternate between two neighbouring floats to the end.

        Examples
        --------
        >>> warp = Warp(np.array([4.0, 5.0]), np.array([3.0, 6.0]), np.eye(2),
        ...             (0.0, 9.0, 0.0, 11.0), np.linspace(-1, 1, 50).reshape(2, 25), 5)
        >>> qy, qx = warp.inverse(np.array([2.0, 5.5]), np.array([3.0, 8.0]))
        >>> wy, wx = warp.forward(qy, qx)
        >>> bool(np.allclose(wy, [2.0, 5.5]) and np.allclose(wx, [3.0, 8.0]))
        True
        """
        inverse = np.linalg.inv(self.linear)
        oy, ox = np.asarray(ys) - self.example_centre[0], np.asarray(xs) - self.example_centre[1]
        ty = np.ravel(self.query_centre[0] + inverse[0, 0] * oy + inverse[0, 1] * ox)
        tx = np.ravel(self.query_centre[1] + inverse[1, 0] * oy + inverse[1, 1] * ox)
        qy, qx = ty.copy(), tx.copy()
        moving = np.arange(ty.size)  # the points not yet fixed
        for _ in range(iterations):
            dy, dx = self.displacement(qy[moving], qx[moving])
            ny, nx = ty[moving] - dy, tx[moving] - dx
            # Compared by their bits: the same bits in, the same bits out (signed zeros, NaNs).
            moved = _bits(ny) != _bits(qy[moving])
            moved |= _bits(nx) != _bits(qx[moving])
            qy[moving], qx[moving] = ny, nx
            moving = moving[moved]
            if not moving.size:
                break
        shape = np.shape(oy)
        return qy.reshape(shape), qx.reshape(shape)


def _bits(values: np.ndarray) -> np.ndarray:
    """float64 ``values``' bits, as unsigned integers."""
    return np.ascontiguousarray(values, np.float64).view(np.uint64)


def _affine(fixed_mask, moving_mask, angle: float) -> tuple:
    """Centres and the affine part: the query's offsets turned by ``angle`` degrees (the
    objects' pose), then stretched by the ratio of the objects' spreads along the axes."""
    query_centre, _ = _moments(fixed_mask)
    example_centre, example_spread = _moments(moving_mask)
    theta = np.deg2rad(angle)
    rotation = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    ys, xs = np.nonzero(fixed_mask)
    turned = rotation @ np.stack([ys - query_centre[0], xs - query_centre[1]])
    query_spread = np.maximum(turned.std(axis=1), 1e-3)
    return query_centre, example_centre, np.diag(example_spread / query_spread) @ rotation


def _fit(
    fixed, moving, fixed_mask, moving_mask, registration: Registration, angle: float = 0.0
) -> Warp:
    """The warp of ``moving`` onto ``fixed`` (same working resolution), fitted coarse to
    fine by Levenberg-Marquardt over ``registration``'s control grids."""
    query_centre, example_centre, linear = _affine(fixed_mask, moving_mask, angle)
    scale = np.sqrt(abs(np.linalg.det(linear)))
    region = ndimage.binary_dilation(fixed_mask, iterations=3)
    ys, xs = np.nonzero(region)
    step = max(1, int(np.ceil(len(ys) / FIT_PIXELS)))
    ys, xs = ys[::step].astype(np.float64), xs[::step].astype(np.float64)
    box = (ys.min() - 2.0, ys.max() + 2.0, xs.min() - 2.0, xs.max() + 2.0)
    displacement = None
    coefficients = np.zeros((2, 16))
    n = registration.control_grids[0]
    for n, sigma in zip(registration.control_grids, registration.grid_smoothing, strict=True):
        target = ndimage.gaussian_filter(fixed, sigma)[ys.astype(int), xs.astype(int)]
        image = ndimage.gaussian_filter(moving, sigma * float(scale))
        grad_y, grad_x = np.gradient(image)
        basis = _tensor_basis(ys, xs, box, n)
        if displacement is None:
            coefficients = np.zeros((2, n * n))
        else:  # the coarser grid's displacement, refitted on this grid
            coefficients = np.linalg.lstsq(basis, displacement.T, rcond=None)[0].T
        penalty = registration.stiffness * len(ys) / (n * n)

        def residual(c, basis=basis, image=image, target=target, penalty=penalty):
            oy, ox = ys + basis @ c[0] - query_centre[0], xs + basis @ c[1] - query_centre[1]
            wy = example_centre[0] + linear[0, 0] * oy + linear[0, 1] * ox
            wx = example_centre[1] + linear[1, 0] * oy + linear[1, 1] * ox
            r = ndimage.map_coordinates(image, [wy, wx], order=1, mode="nearest") - target
            return r, wy, wx, float(r @ r + penalty * np.sum(c * c))

        r, wy, wx, energy = residual(coefficients)
        damping = 1e-3
        for _ in range(FIT_ITERATIONS):
            iy = ndimage.map_coordinates(grad_y, [wy, wx], order=1, mode="nearest")
            ix = ndimage.map_coordinates(grad_x, [wy, wx], order=1, mode="nearest")
            # The image's gradient carried back through the affine part (chain rule).
            gy = iy * linear[0, 0] + ix * linear[1, 0]
            gx = iy * linear[0, 1] + ix * linear[1, 1]
            jacobian = np.concatenate([gy[:, None] * basis, gx[:, None] * basis], axis=1)
            hessian = jacobian.T @ jacobian + penalty * np.eye(2 * n * n)
            gradient = jacobian.T @ r + penalty * coefficients.ravel()
            improved = False
            while damping < 1e6:
                lhs = hessian + damping * np.diag(np.diag(hessian) + 1e-12)
                trial = coefficients + np.linalg.solve(lhs, -gradient).reshape(2, -1)
                r_new, wy_new, wx_new, energy_new = residual(trial)
                if energy_new < energy:
                    coefficients, r, wy, wx, energy = trial, r_new, wy_new, wx_new, energy_new
                    damping *= 0.3
                    improved = True
                    break
                damping *= 10.0
            if not improved:
                break
        displacement = np.stack([basis @ coefficients[0], basis @ coefficients[1]])
    return Warp(query_centre, example_centre, linear, box, coefficients, n)


def register(
    query_depth: np.ndarray,
    example_depth: np.ndarray,
    *,
    registration: Registration = _REGISTRATION,
    angle: float = 0.0,
) -> Warp:
    """The smooth warp from the query's object onto the example's (full-resolution pixels),
    with the relief's residual disagreement.

    Parameters
    ----------
    query_depth, example_depth : ndarray (H, W)
        Depth maps, background 0 (any units: each is taken relative to its own range).
    registration : Registration
        The fit's settings (working size, control grids, the guide image's weights; a
        :class:`~imagemap.depth.config.DepthConfig`'s ``registration``).
    angle : float
        The turn (degrees, :class:`~imagemap.depth.pose.Pose`) from the query's axes to
        the example's, where the fit starts.

    Returns
    -------
    Warp
    """
    return register_all(query_depth, [example_depth], registration=registration, angles=[angle])[0]


def register_all(
    query_depth: np.ndarray,
    example_depths: list[np.ndarray],
    *,
    registration: Registration = _REGISTRATION,
    angles: list[float] | None = None,
) -> list[Warp]:
    """:func:`register` of the query onto each example, the query's guide image and relief
    detail made once, not once per example: the same warps as one :func:`register` each.
    (:func:`register_with_detail`: the warps and the relief's detail they were made with.)

    Examples
    --------
    >>> yy, xx = np.mgrid[:60, :80]
    >>> def blob(ry, rx):
    ...     u = ((yy - 30) / ry) ** 2 + ((xx - 40) / rx) ** 2
    ...     return np.where(u < 1, 0.2 + np.sqrt(np.clip(1 - u, 0, 1)), 0).astype(np.float32)
    >>> query, examples = blob(12, 25), [blob(15, 30), blob(10, 20)]
    >>> warps = register_all(query, examples)
    >>> all(np.array_equal(w.coefficients, register(query, e).coefficients)
    ...     for w, e in zip(warps, examples))
    True
    """
    return register_with_detail(
        query_depth, example_depths, registration=registration, angles=angles
    ).warps


#: One example's registration: its warp, its relief detail and block, its nearest object
#: pixels (or None).
_Made = tuple[Warp, tuple[np.ndarray, int], np.ndarray | None]


@dataclass(frozen=True)
class Registered:
    """What :func:`register_with_detail` made: the warps, and the relief's detail of the
    query and of each example at full size (:func:`relief_detail` at the registration's
    ``relief_detail_scale``) where the registration made it at full size (objects up to
    about 1.5 ``detail_size`` across), else None; and the query's then each example's
    :func:`~imagemap.core.blend.nearest_object_pixels` where they were asked for and its
    guide was made from its full-size mask (the bands' fill and depth continuation read
    them), else None."""

    warps: list[Warp]
    detail: tuple[np.ndarray, list[np.ndarray]] | None
    nearest: list[np.ndarray | None]


def register_with_detail(
    query_depth: np.ndarray,
    example_depths: list[np.ndarray],
    *,
    registration: Registration = _REGISTRATION,
    angles: list[float] | None = None,
    keep_nearest: bool = False,
) -> Registered:
    """:func:`register_all`'s warps, and the relief's detail the relief residuals were made
    from where it is the full-size :func:`relief_detail` of the query and of every example
    (:class:`Registered`): the seams' relief channel, not made a second time; with
    ``keep_nearest``, the nearest object pixels its outside distances were made from.

    Examples
    --------
    >>> yy, xx = np.mgrid[:60, :80]
    >>> def blob(ry, rx):
    ...     u = ((yy - 30) / ry) ** 2 + ((xx - 40) / rx) ** 2
    ...     return np.where(u < 1, 0.2 + np.sqrt(np.clip(1 - u, 0, 1)), 0).astype(np.float32)
    >>> query, example = blob(12, 25), blob(15, 30)
    >>> registered = register_with_detail(query, [example])
    >>> query_detail, (example_detail,) = registered.detail
    >>> bool(np.array_equal(example_detail, relief_detail(example, example > 0, 0.03)))
    True
    """
    angles = [0.0] * len(example_depths) if angles is None else list(angles)
    query_mask = query_depth > 0
    size = float(np.sqrt(query_mask.sum()))
    zoom = min(1.0, registration.work_size / max(size, 1.0))

    # The guides are made with the object at most detail_size across: block averages of
    # `block` x `block` pixels first (1: full size, as for maps up to 4x the default).
    block = max(1, int(1.0 / (registration.detail_size / registration.work_size * zoom)))

    def working(depth, mask):
        """The working guide and mask, and the full-size mask's nearest object pixels
        (None where the guide was made from block averages)."""
        if block > 1:
            depth, mask = block_average(depth, mask, block)
        scale = zoom * block
        guide, nearest = _guide_and_nearest(
            depth,
            mask,
            registration.registration_relief,
            registration.relief_detail_scale,
            # Made only where the zoom to the working size reads it: the same zoomed guide.
            _zoom_reads(mask.shape, scale) if scale < 1.0 else None,
        )
        if block > 1 or not keep_nearest:
            nearest = None
        if scale >= 1.0:
            return guide, mask, nearest
        small = ndimage.zoom(guide, scale, order=1, prefilter=False)
        small_mask = ndimage.zoom(mask.astype(np.float32), scale, order=1, prefilter=False) > 0.5
        return small, small_mask if small_mask.any() else small > 0.25, nearest

    # First the guides and the relief's details of the query and of every example, which
    # do not depend on one another: six tasks for two examples, not the query's two on
    # one thread while the other waits (the query's guide and detail, then each example's
    # guide and detail; task 2 i is map i's guide, 2 i + 1 its detail, map 0 the query).
    depths = [query_depth, *example_depths]
    prepared: dict[int, Any] = {}

    def prepare(task: int) -> None:
        depth = depths[task // 2]
        mask = query_mask if task < 2 else depth > 0
        prepared[task] = (
            working(depth, mask) if task % 2 == 0 else _detail_grid(depth, mask, registration)
        )

    # On the kernels' threads (SciPy's filters, distance transforms and interpolation
    # release the GIL): the same bytes, each task its own arrays.
    each_example(prepare, [depth.shape for depth in depths for _ in range(2)])
    fixed, fixed_mask, query_nearest = prepared.pop(0)
    query_detail = prepared.pop(1)

    def one(index: int) -> _Made:
        moving, moving_mask, nearest = prepared.pop(2 + 2 * index)
        example_detail = prepared.pop(3 + 2 * index)
        warp = _fit(fixed, moving, fixed_mask, moving_mask, registration, angles[index])
        if zoom < 1.0:
            # Back to full-resolution pixels: a working pixel centre j is full-resolution
            # coordinate (j + 0.5) / zoom - 0.5; the displacement scales with 1 / zoom.
            def full(v):
                return (np.asarray(v) + 0.5) / zoom - 0.5

            warp = Warp(
                query_centre=full(warp.query_centre),
                example_centre=full(warp.example_centre),
                linear=warp.linear,
                box=tuple(float(full(b)) for b in warp.box),  # type: ignore[arg-type]
                coefficients=warp.coefficients / zoom,
                n=warp.n,
            )
        return _with_relief_residual(warp, query_detail, example_detail), example_detail, nearest

    made_by_index: dict[int, _Made] = {}

    def made_at(index: int) -> None:
        made_by_index[index] = one(index)

    # Then each example's fit and relief residual, on the threads too. Small matrices: one
    # BLAS thread (one limit for all the fits: threadpoolctl finds the loaded libraries
    # anew at each, 2-10 ms; OpenBLAS's limit is the process's).
    with threadpool_limits(limits=1, user_api="blas"):
        each_example(made_at, [depth.shape for depth in example_depths])
    made = [made_by_index[index] for index in range(len(example_depths))]
    warps = [warp for warp, _, _ in made]
    details = [detail for _, detail, _ in made]
    nearest = [query_nearest] + [example_nearest for _, _, example_nearest in made]
    if query_detail[1] != 1 or any(block != 1 for _, block in details):
        return Registered(warps, None, nearest)
    return Registered(warps, (query_detail[0], [detail for detail, _ in details]), nearest)


def relief_detail(depth: np.ndarray, mask: np.ndarray, scale: float) -> np.ndarray:
    """The relief's detail inside the object, units-free: the depth over its median less
    its smoothing inside the object over ``scale`` of the object's size, in units of three
    robust spreads, soft-clipped (tanh) to (-1, 1); 0 outside. A groove, a ridge, a bump:
    not the body's curvature, nor the step down to the background at the outline.

    Examples
    --------
    >>> depth = np.zeros((40, 40), np.float32); depth[5:35, 5:35] = 1.0
    >>> depth[5:35, 19:21] = 0.9  # a groove
    >>> detail = relief_detail(depth, depth > 0, 0.1)
    >>> bool(detail[20, 20] < -0.5 < 0.0 < detail[20, 10] + 0.2)
    True
    """
    size = max(float(np.sqrt(mask.sum())), 1.0)
    relative = np.where(mask, depth / float(np.median(depth[mask])), 0.0)
    # In place on the smoothed map (float64, as the difference is): no full-size
    # temporaries beside it (the relief stage's peak at 1024^2).
    smooth = _smooth_inside(relative, mask, scale * size)
    detail = np.subtract(relative, smooth, out=smooth)
    del relative
    outside = ~mask
    detail[outside] = 0.0
    values = detail[mask]
    spread = 1.4826 * float(np.median(np.abs(values - np.median(values)))) + 1e-12
    del values
    np.divide(detail, 3.0 * spread, out=detail)
    np.tanh(detail, out=detail)
    detail[outside] = 0.0
    return detail.astype(np.float32)


def _smooth_inside(values: np.ndarray, mask: np.ndarray, sigma: float) -> np.ndarray:
    """:func:`imagemap.core.blend.smooth_inside`, for a wide Gaussian on block averages
    of a third of its width, brought back by bilinear interpolation (the smooth part is
    smooth: a 2048^2 map's relief costs what a small one's does)."""
    from imagemap.core.blend import smooth_inside  # deferred: start-up (SciPy's filters)

    block = max(1, int(sigma // 3))
    if block == 1:
        return smooth_inside(values, mask, sigma)
    height, width = mask.shape
    h, w = -(-height // block) * block, -(-width // block) * block

    def block_means(inside: np.ndarray) -> np.ndarray:
        padded = np.zeros((h, w))  # one full-size float64 map at a time
        padded[:height, :width] = inside
        return padded.reshape(h // block, block, w // block, block).mean(axis=(1, 3))

    total = block_means(np.where(mask, values, 0.0))
    cover = block_means(mask)
    weight = ndimage.gaussian_filter(cover, sigma / block)
    smooth = ndimage.gaussian_filter(total, sigma / block) / np.maximum(weight, 1e-12)
    # Brought back on the object's box only: 0 outside the object anyway.
    full = np.zeros(mask.shape, smooth.dtype)
    box = _mask_box(mask, 0)
    if box is not None:
        full[box] = _upsampled(smooth, block, mask.shape, box)
    full[~mask] = 0.0
    return full


def _upsampled(
    grid: np.ndarray,
    step: float,
    shape: tuple[int, int],
    box: tuple[slice, slice] | None = None,
) -> np.ndarray:
    """A coarse ``grid`` of ``step`` x ``step`` blocks brought to ``shape`` by bilinear
    interpolation (of the grid's dtype), ``_ROWS`` rows at a time (each point's value is
    its own: the same as of the whole map's coordinates at once); with ``box``, that box
    of it alone."""
    height, width = shape
    if step == 1.0 and grid.shape == shape and box is None:
        # Each point on a grid point: the bilinear interpolation is the grid's value
        # itself (weights 1 and 0), so the same values, copied, without interpolating.
        return grid.copy()
    # Block pixel j is full-resolution coordinate (j + 0.5) * step - 0.5.
    ys = (np.arange(height) + 0.5) / step - 0.5
    xs = (np.arange(width) + 0.5) / step - 0.5
    if box is not None:
        ys, xs = ys[box[0]], xs[box[1]]
        height, width = len(ys), len(xs)
    full = np.empty((height, width), dtype=grid.dtype)
    for y0 in range(0, height, _ROWS):
        gy, gx = np.meshgrid(ys[y0 : y0 + _ROWS], xs, indexing="ij")
        ndimage.map_coordinates(
            grid, [gy, gx], output=full[y0 : y0 + _ROWS], order=1, mode="nearest"
        )
    return full


def _detail_grid(
    depth: np.ndarray, mask: np.ndarray, registration: Registration
) -> tuple[np.ndarray, int]:
    """The relief's detail with the object about ``detail_size`` pixels across (block
    averages of larger maps), and the block's side."""
    block = max(1, int(round(np.sqrt(mask.sum()) / registration.detail_size)))
    if block > 1:
        depth, mask = block_average(depth, mask, block)
    return relief_detail(depth, mask, registration.relief_detail_scale), block


def _with_relief_residual(
    warp: Warp,
    query_detail: tuple[np.ndarray, int],
    example_detail: tuple[np.ndarray, int],
) -> Warp:
    """``warp`` with its :attr:`Warp.relief_residual`: the query's relief detail against
    the example's carried onto it by the warp (each :func:`_detail_grid`'s, with the
    object about ``detail_size`` pixels across: block averages of larger maps)."""
    query_detail_map, step = query_detail
    example_map, example_step = example_detail
    # The query's grid pixel j is full-resolution coordinate (j + 0.5) * step - 0.5.
    gy = np.arange(query_detail_map.shape[0], dtype=np.float64)
    gx = np.arange(query_detail_map.shape[1], dtype=np.float64)
    ey, ex = warp.forward_grid((gy + 0.5) * step - 0.5, (gx + 0.5) * step - 0.5)
    landed = ndimage.map_coordinates(
        example_map, [(ey + 0.5) / example_step - 0.5, (ex + 0.5) / example_step - 0.5],
        order=1, mode="constant", cval=0.0,
    )  # fmt: skip
    residual = np.square(query_detail_map - landed).astype(np.float32)
    return replace(warp, relief_residual=residual, relief_step=float(step))


def block_average(
    depth: np.ndarray, mask: np.ndarray, block: int, *, pad: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Depth and mask averaged over ``block`` x ``block`` pixels: the mask where at least
    half a block is object, the depth as the mean of its object pixels (pixel ``i`` of
    the result is pixels ``block * i`` to ``block * i + block - 1``). The last partial
    blocks are dropped, or with ``pad`` kept (padded with background).

    Examples
    --------
    >>> depth = np.array([[0, 0, 2, 4, 1], [0, 2, 2, 4, 1]], np.float32)
    >>> block_average(depth, depth > 0, 2)[0].tolist()
    [[0.0, 3.0]]
    >>> block_average(depth, depth > 0, 2, pad=True)[0].tolist()
    [[0.0, 3.0, 1.0]]
    """
    if pad:
        widths = [(0, -depth.shape[0] % block), (0, -depth.shape[1] % block)]
        depth, mask = np.pad(depth, widths), np.pad(mask, widths)
    h, w = (depth.shape[0] // block) * block, (depth.shape[1] // block) * block

    def mean(values: np.ndarray) -> np.ndarray:
        return values[:h, :w].reshape(h // block, block, w // block, block).mean(axis=(1, 3))

    cover = mean(mask.astype(np.float32))
    small_mask = cover >= 0.5
    object_mean = mean(np.where(mask, depth, 0.0).astype(np.float32)) / np.maximum(cover, 1e-6)
    small_depth = np.where(small_mask, object_mean, 0.0)
    return small_depth.astype(np.float32), small_mask


def position_frame(mask: np.ndarray) -> np.ndarray:
    """(yc, xc, r): the query object's centroid and RMS radius, the frame of the engine's
    positions (:func:`query_positions`, :func:`example_positions`)."""
    ys, xs = np.nonzero(mask)
    radius = max(float(np.sqrt(ys.var() + xs.var())), 1.0)
    return np.array([ys.mean(), xs.mean(), radius])


def _level_coordinates(shape: tuple[int, int], level: int) -> tuple[np.ndarray, np.ndarray]:
    """Full-resolution coordinates of the pixel centres of pyramid level ``level``."""
    factor = 2**level
    height, width = (shape[0] + factor - 1) // factor, (shape[1] + factor - 1) // factor
    ys = np.arange(height) * factor + (factor - 1) / 2.0
    xs = np.arange(width) * factor + (factor - 1) / 2.0
    return ys, xs


def query_positions(shape: tuple[int, int], frame: np.ndarray, levels: int) -> list[np.ndarray]:
    """Position bands for the engine, per level (H_l, W_l, 2): each query pixel's position
    relative to the query object's centroid in units of its RMS radius (``frame``:
    :func:`position_frame`)."""
    query_levels = []
    for level in range(levels):
        ys, xs = _level_coordinates(shape, level)
        grid_y, grid_x = np.meshgrid((ys - frame[0]) / frame[2], (xs - frame[1]) / frame[2])
        query_levels.append(np.stack([grid_y.T, grid_x.T], axis=-1).astype(np.float32))
    return query_levels


def example_positions(
    shape: tuple[int, int],
    warp: Warp,
    frame: np.ndarray,
    levels: int,
    grid_step: int = 4,
    grid_points: int | None = None,
) -> list[np.ndarray]:
    """Position bands for the engine, per level (H_l, W_l, 2): where ``warp`` puts each
    pixel of an example of ``shape`` on the query, in :func:`query_positions`' units.

    The inverse warp is evaluated on a grid of every ``grid_step``-th pixel and
    interpolated (it is smooth); with ``grid_points``, the step grows so that the grid
    has about that many points along the example's longer side (its own: each example
    its own step).
    """
    step = grid_step
    if grid_points is not None:
        step = max(grid_step, -(-max(shape) // grid_points))
    coarse_y = np.arange(0, shape[0] + step, step, dtype=np.float64)
    coarse_x = np.arange(0, shape[1] + step, step, dtype=np.float64)
    cy, cx = np.meshgrid(coarse_y, coarse_x, indexing="ij")
    qy, qx = warp.inverse(cy, cx)
    positions = np.stack([(qy - frame[0]) / frame[2], (qx - frame[1]) / frame[2]])
    per_level = []
    for level in range(levels):
        sampled = [_on_level(p, shape, level, step) for p in positions]
        per_level.append(np.stack(sampled, axis=-1).astype(np.float32))
    return per_level


def _on_level(grid: np.ndarray, shape: tuple[int, int], level: int, step: int) -> np.ndarray:
    """``grid`` (a value every ``step`` full-resolution pixels) interpolated bilinearly
    (``mode="nearest"``) at the pixel centres of pyramid level ``level`` of a frame of
    ``shape`` (:func:`_level_coordinates`).

    For a ``step`` that is a power of two every coordinate, ``(i * 2**level + (2**level -
    1) / 2) / step``, is a float exactly, however it is computed: SciPy's zoom and shift
    (``affine_transform`` with a diagonal) then interpolates them as ``map_coordinates``
    does, the same values, with each row's and column's weights made once (half the time
    at 512^2). Other steps round the coordinates differently: ``map_coordinates`` of the
    coordinates as divided here.
    """
    ys, xs = _level_coordinates(shape, level)
    if step & (step - 1) == 0:
        factor = 2**level
        return ndimage.affine_transform(
            grid,
            np.full(2, factor / step),
            (factor - 1) / 2.0 / step,
            output_shape=(len(ys), len(xs)),
            order=1,
            mode="nearest",
        )
    gy, gx = np.meshgrid(ys / step, xs / step, indexing="ij")
    return ndimage.map_coordinates(grid, [gy, gx], order=1, mode="nearest")


def relief_agreement(
    mask: np.ndarray, warps: list[Warp], disagreement: float, reach: float
) -> np.ndarray | None:
    """Per query pixel, how well the relief of the best-fitting registered example agrees
    with the query's own: ``1 / (1 + D / disagreement)``, ``D`` the smallest over the
    examples of :attr:`Warp.relief_residual` averaged over ``reach`` of the object's
    size. 1 where some example's relief lies where the query's does; towards 0 where
    the query's groove, ridge or bump lies elsewhere or nowhere in them. None when no
    warp has a residual or ``disagreement`` is 0.
    """
    residuals = [w for w in warps if w.relief_residual is not None]
    if not residuals or disagreement <= 0:
        return None
    size = float(np.sqrt(mask.sum()))
    smallest = None
    for warp in residuals:
        step = warp.relief_step
        assert warp.relief_residual is not None
        smooth = ndimage.gaussian_filter(warp.relief_residual, reach * size / step)
        full = _upsampled(smooth, step, mask.shape)
        smallest = full if smallest is None else np.minimum(smallest, full, out=smallest)
        del full
    assert smallest is not None
    # 1 / (1 + D / disagreement), in place (in the residuals' dtype, as before).
    np.divide(smallest, disagreement, out=smallest)
    np.add(1.0, smallest, out=smallest)
    np.divide(1.0, smallest, out=smallest)
    return smallest.astype(np.float32)


def position_scales(
    agreement: np.ndarray | None, level_weights: list[float], relative_weight: float
) -> list[np.ndarray | None] | None:
    """Per pyramid level, the query's factor on the position term's weight: where none of
    the registered examples' relief agrees with the query's own (:func:`relief_agreement`
    ``a``), the registered position gives way to the paper's relative position (weight
    ``relative_weight`` against the level's own ``level_weights[l]``), and the windows
    follow the query's relief: ``a + (1 - a) * min(1, relative_weight / level_weights[l])``,
    1 where the relief agrees. None without an agreement.
    """
    if agreement is None:
        return None
    from imagemap.core.pyramid import gaussian_pyramid  # deferred: as the guides' own

    return [
        np.asarray(a + (1.0 - a) * min(1.0, relative_weight / max(weight, 1e-12)), np.float32)
        for a, weight in zip(
            gaussian_pyramid(agreement, len(level_weights)), level_weights, strict=True
        )
    ]
