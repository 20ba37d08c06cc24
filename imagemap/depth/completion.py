"""Small features copied whole: completing an exemplar's eye or lips that the copy cut.

One module for one job: finding small features and completing those the copy cut.

A copy-based map draws a small feature (an eye, lips, a brow) only where the
source map copies it. Where two offsets meet inside it, each copies part of the
feature and the pixels between them copy the skin beside it: the map shows a
shrunken or half feature (a lozenge for lips, half a brow). Seam placement
cannot mend this: its data term is the voted map, whose mean holds only as much
of the feature as the cut copy.

:func:`small_features` finds an exemplar's features from its colours alone (no
labels): components of pixels whose YCbCr colour is at least
``feature_contrast`` from the median colour around them, holes filled (an eye's
iris belongs to its eye), that are

- compact: no wider than ``feature_extent`` of the object's size (not a stripe,
  a hairline or a sleeve); a feature touching a larger part that stands out too
  (a brow touching the hair) is cut from it where the colour steps;
- inside the object: at least ``inside_share`` of its surroundings (not a
  stripe's corner cut by the outline);
- on one ground, and ending at an edge: the pixels just outside are of one
  colour and differ from the feature's boundary (not a blush, whose colour fades
  over its width, nor a shirt's corner cut by a neckline); or, on a ground of
  several colours (an eye across a fish's bands, a spot among veins), ending at
  an edge all around and of a colour rare within ``rare_reach`` of its widths
  (not a check among checks, nor a stripe's piece between others);
- rare: at most ``max_repeats`` of one colour (not a shirt's squares or a
  fish's spots, which the copy draws as texture).

:func:`complete_features` then looks, for each feature, at the pixels of the
map that copy it. Where they lie together (one instance) and cover between
``partial_share`` and ``complete_share`` of it, the whole feature, with a rim of
its surroundings, is copied at the mean offset of those pixels (the most complete
copies first): the feature appears once, whole, where the cut copy had put it
(where the relief calls for it, the matching and the seams have put it there
already: :func:`imagemap.depth.register.position_scales`). Not where the rim would
not match what the map shows there (a feature is completed on its own surroundings,
never pasted over another part), and not
beside a whole feature of the same colour (a piece of a second brow above the
brow is a stray).

A feature can also be skipped whole: the map copies the skin around an eye from
around the example's eye, at offsets near one another, and fills the eye's place
with plain skin from elsewhere (a large map's finer levels wear an eye down this
way). Where the map copies ``skipped_ring_share`` of a feature's ring and nothing
of it, the feature is completed too, at the ring's median offset, under the same
tests, and only where
the map shows nothing there yet that stands out from the ring
(``skipped_place_shown``): the copy may have drawn an eye from pixels that no
example's feature detection found.

The thresholds named here are the fields of
:class:`imagemap.depth.config.Completion`, each with its reason and the measurement it
came from; :func:`small_features` and :func:`complete_features` take one as
``completion`` (default: ``Completion()``, the pipeline passes its configuration's).
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np
from scipy import ndimage

from imagemap.core.blend import copy_through, fill_background, smooth_inside
from imagemap.depth.config import Completion

__all__ = ["complete_features", "copies_features", "small_features"]

log = logging.getLogger(__name__)

#: The defaults of every threshold (a :class:`DepthConfig`'s ``completion``).
_COMPLETION = Completion()
#: Two copies of one feature at offsets this share of its width apart (and more than
#: ``DOUBLE_TOLERANCE`` px) that copy some of the same pixels draw it twice (an eye with two
#: pupils, seen at 512x512 on an ellipsoid fish); 0.15 and 0.4 gave the same figures (#43).
DOUBLE_SHIFT = 0.25
#: Offsets within this many pixels of the main copy's belong to it (#43: 4 gave the same
#: figures; 1 cost 12 fish 0.005 of macro part transfer, their seed spread 0.004).
DOUBLE_TOLERANCE = 2
#: A double is redrawn from its main copy only when that copy holds at least this share
#: of the feature (and under ``complete_share``: a whole copy with a few displaced pixels
#: is a ragged edge, left to the seams); 0.35 and 0.65 within the seed spread (#43).
DOUBLE_MAIN = 0.5


def small_features(
    exemplar: np.ndarray,
    mask: np.ndarray,
    *,
    extent: float | None = None,
    completion: Completion = _COMPLETION,
    filled: bool = False,
):
    """Label an exemplar's small features: compact regions that stand out in colour.

    Parameters
    ----------
    exemplar : ndarray, (H, W, C)
        The exemplar's colours (YCbCr in [0, 1]).
    mask : ndarray of bool, (H, W)
        Its object.
    extent : float, optional
        Largest feature width in pixels; default ``completion.feature_extent`` times
        the square root of the object's area.
    completion : Completion
        The detection's thresholds (``feature_extent``, ``feature_contrast``,
        ``max_repeats``, ``surround_share``, ``inside_share``, ``host_window``).
    filled : bool
        The exemplar's colours outside ``mask`` are already its nearest object pixel's
        (:func:`imagemap.depth.guides.example_ycbcr`'s): not filled again (the same
        colours).

    Returns
    -------
    labels : ndarray of int32, (H, W)
        0 outside features, 1..n a feature (holes filled).
    n : int

    Examples
    --------
    >>> image = np.full((60, 60, 3), 0.5)
    >>> image[28:32, 20:28, 0] = 0.1                 # a dark brow on flat skin
    >>> labels, n = small_features(image, np.ones((60, 60), bool))
    >>> n, int((labels > 0).sum())
    (1, 32)
    """
    mask = np.asarray(mask, bool)
    if exemplar.ndim != 3 or exemplar.shape[:2] != mask.shape:
        raise ValueError(
            f"exemplar of shape {exemplar.shape} and mask of shape {mask.shape}: expected "
            "(H, W, C) colours and an (H, W) mask"
        )
    if extent is None:
        extent = completion.feature_extent * np.sqrt(mask.sum())
    # The dense steps below look only inside the object: they run on its box (the same
    # values: the mask is empty around it, and so is what they make there).
    inside = np.zeros(mask.shape, bool)
    box = _box(mask)
    if box is not None:
        inside[box] = ndimage.binary_erosion(mask[box], iterations=2)
        box = _box(inside)
    colours = np.asarray(exemplar, np.float32)
    if not mask.all() and not filled:
        # The object's own colours continued outside it: its outline is no feature.
        colours = fill_background(colours, mask)
    # The host colour around each pixel: the median over a feature's width, which a
    # feature (under half the window) does not move. Taken at a resolution where that
    # width is ``host_window`` pixels: the host varies slowly, and a large window's
    # median is slow. A pixel stands out when it differs from the hosts of its own
    # low-resolution cell and of the eight around it: next to an edge between two
    # parts one of them has its own side's colour, so the edge is no feature.
    factor = min(1.0, completion.host_window / max(extent, 1.0))
    small = ndimage.zoom(colours, (factor, factor, 1), order=1) if factor < 1 else colours
    size = max(int(round(extent * factor)) | 1, 3)
    # Each channel on its own (a window of one in the last axis): the hosts' medians.
    host = ndimage.median_filter(np.asarray(small, np.float32), size=(size, size, 1))
    cell_y = np.minimum((np.arange(colours.shape[0]) * factor).astype(int), host.shape[0] - 1)
    cell_x = np.minimum((np.arange(colours.shape[1]) * factor).astype(int), host.shape[1] - 1)
    from imagemap.core.kernels import nearest_host_distance  # deferred: start-up (numba)

    stands_out = np.zeros(mask.shape, bool)
    if box is not None:  # a pixel stands out only inside: its distance, there
        distance = nearest_host_distance(
            np.ascontiguousarray(colours[box], np.float32),
            np.ascontiguousarray(host, np.float32),
            cell_y[box[0]].astype(np.int64),
            cell_x[box[1]].astype(np.int64),
        )
        here = distance >= completion.feature_contrast
        here &= inside[box]
        # A hole touching the box's edge runs on into the empty rest: no hole either way.
        stands_out[box] = ndimage.binary_fill_holes(here)
        del distance, here
    labels, n = ndimage.label(stands_out)
    if n == 0:
        return labels.astype(np.int32), 0
    boxes = ndimage.find_objects(labels)
    spans = np.array([0] + [_span(box) for box in boxes])
    # Compact: a stripe or a hairline's band is long; a one-pixel speck is noise.
    keep = (spans <= extent) & (np.bincount(labels.ravel(), minlength=n + 1) >= 4)
    keep[0] = False
    # A feature touching a larger part that also stands out (a brow touching the
    # hair) is one component with it, too wide to be a feature. Such components are
    # cut where the colour steps by half the feature contrast between neighbouring
    # pixels (the brow's edge against the hair; the hair's own shading steps far
    # less), and their compact pieces, holes filled, are candidates too.
    wide = np.flatnonzero(spans > extent)
    first_piece = n + 1
    if len(wide):
        labels, n, keep = _pieces_of_wide(
            colours, labels, n, keep, np.isin(labels, wide), extent, completion.feature_contrast
        )
        boxes = ndimage.find_objects(labels, max_label=n)
    # A texture's elements repeat (a shirt's squares, a fish's spots); a feature is
    # rare (two eyes, two brows, lips). Elements of a texture are drawn by the copy
    # as texture and are left to it: completing some of them breaks its regularity.
    flat = labels.ravel()
    counts = np.maximum(np.bincount(flat, minlength=n + 1), 1).astype(np.float64)
    sums = [
        np.bincount(flat, channel.ravel(), minlength=n + 1)
        for channel in np.moveaxis(colours, -1, 0)
    ]
    means = np.stack(sums, -1) / counts[:, None]
    compact = np.flatnonzero(keep)
    if len(compact):
        repeats = _neighbour_counts(means[compact], completion.feature_contrast * (1 - 1e-6))
        keep[compact] = repeats <= completion.max_repeats
    for i in map(int, np.flatnonzero(keep)):
        box = boxes[i - 1]
        keep[i] = _stands_alone(
            colours, mask, labels, i, box, _span(box), completion, grounds=1 + (i >= first_piece)
        )
    # Numbered 1..n in order, each kept feature its own label (two pieces of one
    # cut component may touch).
    keep[0] = False
    lookup = np.zeros(n + 1, np.int32)
    lookup[keep] = np.arange(1, int(keep.sum()) + 1)
    return lookup[labels], int(keep.sum())


#: Up to this many points :func:`_neighbour_counts` counts from a table of all pairs (8 MB
#: at most) and needs no k-d tree: importing scipy.spatial costs about 0.07 s of CPU, a
#: tenth of a 200x150 synthesis's imports, for the few tens of features of a map.
PAIR_TABLE_POINTS = 1024


def _neighbour_counts(points: np.ndarray, radius: float) -> np.ndarray:
    """For each of ``points`` (N, C), how many of them (itself included) lie within
    ``radius`` (Euclidean): a table of all pairs for up to :data:`PAIR_TABLE_POINTS`, a
    k-d tree above (a noisy photograph can have tens of thousands of compact components).

    Both compare the squared distance, summed channel by channel, with ``radius ** 2``,
    as scipy's ``cKDTree.query_ball_point`` does: the same counts either way.

    Examples
    --------
    >>> _neighbour_counts(np.array([[0.0, 0.0], [0.05, 0.0], [0.2, 0.0]]), 0.07)
    array([2, 2, 1])
    """
    if len(points) > PAIR_TABLE_POINTS:
        from scipy.spatial import cKDTree  # deferred: start-up (0.07 s; many points only)

        return cKDTree(points).query_ball_point(points, r=radius, return_length=True)
    squared = np.zeros((len(points), len(points)))
    for channel in points.T:
        squared += (channel[:, None] - channel[None, :]) ** 2
    return (squared <= radius * radius).sum(1)


def _span(box) -> int:
    """The larger side of a box of slices."""
    return max(box[0].stop - box[0].start, box[1].stop - box[1].start)


def _box(region: np.ndarray) -> tuple[slice, slice] | None:
    """The box of a 2-D boolean ``region``'s pixels (None when it has none)."""
    rows, columns = np.flatnonzero(region.any(1)), np.flatnonzero(region.any(0))
    if not len(rows):
        return None
    return slice(rows[0], rows[-1] + 1), slice(columns[0], columns[-1] + 1)


#: Up to this many pixels in the box of the region :func:`_joined_components` labels,
#: the doubled grid (20 bytes a pixel of the box: 20 MB); above, csgraph, whose memory
#: follows the region's pixels, not its box, and whose import is nothing beside a large
#: map's synthesis.
GRID_LABEL_PIXELS = 2**20


def _csgraph_components(
    region: np.ndarray, across: np.ndarray, down: np.ndarray
) -> tuple[np.ndarray, int]:
    """:func:`_joined_components` by ``scipy.sparse.csgraph`` on the pixels in raster order."""
    from scipy.sparse import coo_matrix, csgraph  # deferred: start-up (large regions only)

    index = np.full(region.shape, -1, np.int32)
    size = int(region.sum())
    index[region] = np.arange(size, dtype=np.int32)
    firsts, seconds = [], []
    for a, b, links in ((np.s_[:, :-1], np.s_[:, 1:], across), (np.s_[:-1, :], np.s_[1:, :], down)):
        join = links & region[a] & region[b]
        firsts.append(index[a][join])
        seconds.append(index[b][join])
    del index
    first, second = np.concatenate(firsts), np.concatenate(seconds)
    del firsts, seconds
    graph = coo_matrix((np.ones(len(first), np.int8), (first, second)), (size, size))
    del first, second
    count, which = csgraph.connected_components(graph, directed=False)
    del graph
    components = np.zeros(region.shape, np.int32)
    components[region] = which + 1
    return components, int(count)


def _joined_components(
    region: np.ndarray, across: np.ndarray, down: np.ndarray
) -> tuple[np.ndarray, int]:
    """The connected components of the graph of ``region``'s pixels (H, W) in which a
    pixel is joined to its right neighbour where ``across`` (H, W - 1) and to the one
    below where ``down`` (H - 1, W): (labels (H, W) int32, 0 outside ``region``, 1..m
    numbered in the order of each component's first pixel in raster order; m).

    Up to :data:`GRID_LABEL_PIXELS` in the region's box, ``ndimage.label`` of a grid of
    twice the resolution (pixels at even rows and columns, each join between the two
    pixels it joins), which needs no scipy.sparse import (about 0.07 s of CPU at
    start-up); above, ``scipy.sparse.csgraph.connected_components`` on the pixels in
    raster order. Both give the same components, numbered alike.

    Examples
    --------
    >>> region = np.array([[1, 1, 1], [1, 0, 1]], bool)
    >>> across = np.array([[True, False], [False, False]])
    >>> down = np.array([[True, False, True]])
    >>> _joined_components(region, across, down)
    (array([[1, 1, 2],
           [1, 0, 2]], dtype=int32), 2)
    """
    components = np.zeros(region.shape, np.int32)
    rows, columns = np.flatnonzero(region.any(1)), np.flatnonzero(region.any(0))
    if not len(rows):
        return components, 0
    y0, y1, x0, x1 = rows[0], rows[-1] + 1, columns[0], columns[-1] + 1
    if (y1 - y0) * (x1 - x0) > GRID_LABEL_PIXELS:
        return _csgraph_components(region, across, down)
    inside = region[y0:y1, x0:x1]
    height, width = inside.shape
    grid = np.zeros((2 * height - 1, 2 * width - 1), bool)
    grid[::2, ::2] = inside
    grid[::2, 1::2] = across[y0:y1, x0 : x1 - 1] & inside[:, :-1] & inside[:, 1:]
    grid[1::2, ::2] = down[y0 : y1 - 1, x0:x1] & inside[:-1, :] & inside[1:, :]
    labelled = np.zeros(grid.shape, np.int32)
    count = ndimage.label(grid, output=labelled)  # 4-connected: pixels through joins
    del grid
    components[y0:y1, x0:x1] = labelled[::2, ::2]
    return components, int(count)


def _pieces_of_wide(colours, labels, n, keep, region, extent, contrast):
    """Cut the wide components at colour steps (half the feature ``contrast`` between
    neighbouring pixels); their compact pieces become new
    components (numbered after n, holes filled: an enclosed piece is taken in by
    its enclosure) and the rest of them is dropped. Vectorized but for pieces
    with holes: a noisy picture cut at its colour steps has millions of pieces,
    too many to visit one by one."""
    step = contrast / 2
    joined = []
    for a, b in ((np.s_[:, :-1], np.s_[:, 1:]), (np.s_[:-1, :], np.s_[1:, :])):
        join = region[a] & region[b]
        # The colour step of the pairs inside the region only (as (pairs, C) rows: the
        # same sums of the same squares per pair as of the whole picture's).
        pairs = np.nonzero(join)
        near = np.sqrt(((colours[a][pairs] - colours[b][pairs]) ** 2).sum(-1)) < step
        join[pairs] = near
        joined.append(join)
    pieces, m = _joined_components(region, *joined)
    del joined
    labels = np.where(region, 0, labels)
    # Each piece's size and box.
    inside = np.flatnonzero(pieces)
    which = pieces.ravel()[inside] - 1
    ys, xs = np.divmod(inside, pieces.shape[1])
    del inside
    sizes = np.bincount(which, minlength=m)
    top, left = np.full(m, pieces.shape[0]), np.full(m, pieces.shape[1])
    bottom, right = np.full(m, -1), np.full(m, -1)
    np.minimum.at(top, which, ys)
    np.minimum.at(left, which, xs)
    np.maximum.at(bottom, which, ys)
    np.maximum.at(right, which, xs)
    del which, ys, xs
    span = np.maximum(bottom - top, right - left) + 1
    # At least 2 px thick (a 2 x 2 block of its own): the one-pixel lines where two
    # of a texture's elements meet (a check's anti-aliased borders) and single
    # noisy pixels are no features.
    corner = pieces[:-1, :-1]
    block = (corner > 0) & (corner == pieces[1:, :-1])
    block &= (corner == pieces[:-1, 1:]) & (corner == pieces[1:, 1:])
    thick = np.zeros(m, bool)
    thick[corner[block] - 1] = True
    del corner, block
    chosen = (span <= extent) & (sizes >= 4)
    # Pieces with holes (an eye's white around its iris) are filled one by one and
    # take in what they enclose; the solid ones are numbered at once.
    # The pieces' box: every 2 x 2 pattern with a piece in it lies in it, one pixel wider.
    rows, columns = np.flatnonzero(pieces.any(1)), np.flatnonzero(pieces.any(0))
    within = (
        (slice(rows[0], rows[-1] + 1), slice(columns[0], columns[-1] + 1))
        if len(rows)
        else (slice(0, 0), slice(0, 0))
    )
    holed = chosen & (np.rint(_euler_numbers(pieces[within], m)) < 1)
    solid = chosen & thick & ~holed
    number = np.zeros(m + 1, np.int32)
    number[1:][solid] = n + 1 + np.arange(int(solid.sum()), dtype=np.int32)
    labels = np.where(number[pieces] > 0, number[pieces], labels)
    count = int(n) + int(solid.sum())
    filled_pieces = []
    for j in np.flatnonzero(holed):
        box = (slice(top[j], bottom[j] + 1), slice(left[j], right[j] + 1))
        filled = ndimage.binary_fill_holes(pieces[box] == j + 1, np.ones((3, 3), bool))
        if ndimage.binary_erosion(filled, np.ones((2, 2), bool)).any():
            filled_pieces.append((int(filled.sum()), box, filled))
    # Smaller first: an enclosing piece, written later, takes in what it encloses.
    filled_pieces.sort(key=lambda item: item[0])
    for label, (_, box, filled) in enumerate(filled_pieces, start=count + 1):
        labels[box][filled] = label
    count += len(filled_pieces)
    keep = np.concatenate([keep, np.ones(count - n, bool)])
    # A piece taken in entirely by its enclosure has no pixels left.
    keep &= np.bincount(labels.ravel(), minlength=len(keep)) > 0
    return labels, count, keep


def _euler_numbers(pieces, m):
    """Euler number (1 minus the holes) of each 4-connected piece 1..m, from Gray's
    2 x 2 pattern counts (a pattern counted once for each piece it shows)."""
    padded = np.pad(pieces, 1)
    quad = (padded[:-1, :-1], padded[:-1, 1:], padded[1:, :-1], padded[1:, 1:])
    # Counted per corner: a pattern with three of a piece's corners three times,
    # a diagonal pair twice; hence the integer weights below.
    single = np.zeros(m + 1, np.int64)
    triple = np.zeros(m + 1, np.int64)
    diagonal = np.zeros(m + 1, np.int64)
    for p, here in enumerate(quad):
        same = sum((here == other).astype(np.int8) for other in quad)
        sides = [quad[q] for q in range(4) if q not in (p, 3 - p)]  # a-d, b-c: diagonals
        apart = (same == 2) & (here == quad[3 - p]) & (here != sides[0]) & (here != sides[1])
        single += np.bincount(here[same == 1], minlength=m + 1)
        triple += np.bincount(here[same == 3], minlength=m + 1)
        diagonal += np.bincount(here[apart], minlength=m + 1)
    # 4 E = Q1 - Q3 + 2 QD with Q3 = triple / 3 and QD = diagonal / 2.
    return ((3 * single - triple + 3 * diagonal) / 12.0)[1:]


def _stands_alone(colours, mask, labels, i, box, span, completion, grounds=1):
    """Whether component i is a feature that stands alone on its ground.

    On one ground: the pixels a short way outside it (an eighth of its width, at
    least 2 px) are of one colour (at least ``surround_share`` of them within
    ``feature_contrast`` of their median), and its boundary differs from them by half
    the feature contrast. Lips, eyes and brows on skin do. A blush, whose colour fades
    out over its width, and a piece of a part cut by another (a shirt's corner at a
    neckline, skin on one side and cloth on the other) do not.

    On a ground of several colours (an eye across a fish's bands, a spot among a
    leaf's veins): it ends at an edge all around (:func:`_ends_at_edge`) and its colour
    is rare around it (:func:`_rare_around`). A check of a shirt, a piece of a stripe
    between two others or of a part cut by another ends at edges too, but its colour
    goes on nearby."""
    r = max(2, int(round(span / 8)))
    y0, x0 = max(box[0].start - r - 1, 0), max(box[1].start - r - 1, 0)
    y1, x1 = box[0].stop + r + 1, box[1].stop + r + 1
    own = labels[y0:y1, x0:x1] == i
    edge = own & ~ndimage.binary_erosion(own)
    grown = ndimage.binary_dilation(own, iterations=r)
    ring = grown & ~ndimage.binary_dilation(own, iterations=r - 1)
    outside = ring & mask[y0:y1, x0:x1]
    # A feature shows whole inside its object: one whose surroundings the outline
    # cuts (a shirt's stripe at the neckline, a spot at the hair's edge) is a
    # part's corner, not a feature.
    if outside.sum() < completion.inside_share * ring.sum():
        return False
    contrast = completion.feature_contrast
    here = colours[y0:y1, x0:x1]
    ground = here[outside]
    on_ground = np.sqrt(((ground - np.median(ground, axis=0)) ** 2).sum(-1)) < contrast
    if grounds == 2 and not on_ground.all():
        # A piece cut from a larger part it touches (a brow touching the hair) has
        # that part as its second ground.
        rest = ground[~on_ground]
        on_ground |= np.sqrt(((ground - np.median(rest, axis=0)) ** 2).sum(-1)) < contrast
    if on_ground.mean() >= completion.surround_share:
        step = here[edge].mean(0) - ground.mean(0)
        return bool(np.sqrt((step**2).sum()) >= contrast / 2)
    return _ends_at_edge(here, edge, outside, r, completion) and _rare_around(
        colours, mask, labels, i, box, span, here[edge].mean(0), completion
    )


def _ends_at_edge(colours, edge, ring, r, completion) -> bool:
    """Whether at least ``surround_share`` of the ``ring``'s pixels differ by half the
    feature contrast from the feature's boundary (``edge``) nearest them: it ends at an
    edge, whatever lies beyond. Both sides are local means along the boundary and along
    the ring (a Gaussian of half the ring's distance, normalized over each), so that
    grain does not count."""
    edge_colour = smooth_inside(colours, edge, r / 2)
    ring_colour = smooth_inside(colours, ring, r / 2)
    _, (ny, nx) = ndimage.distance_transform_edt(~edge, return_indices=True)
    ry, rx = np.nonzero(ring)
    step = np.sqrt(((ring_colour[ry, rx] - edge_colour[ny[ry, rx], nx[ry, rx]]) ** 2).sum(-1))
    return bool((step >= completion.feature_contrast / 2).mean() >= completion.surround_share)


def _rare_around(colours, mask, labels, i, box, span, colour, completion) -> bool:
    """Whether, within ``rare_reach`` of its widths around component i, fewer object
    pixels than its own are within ``feature_contrast`` of ``colour`` (its boundary's
    mean): no second piece of it nearby, as there is beside a check or a stripe's piece."""
    reach = int(np.ceil(completion.rare_reach * span))
    y0, x0 = max(box[0].start - reach, 0), max(box[1].start - reach, 0)
    y1, x1 = box[0].stop + reach, box[1].stop + reach
    own = labels[y0:y1, x0:x1] == i
    around = mask[y0:y1, x0:x1] & ~ndimage.binary_dilation(own, iterations=2)
    near = np.sqrt(((colours[y0:y1, x0:x1][around] - colour) ** 2).sum(-1)) < (
        completion.feature_contrast
    )
    return int(near.sum()) < int(own.sum())


class _Instance(NamedTuple):
    """One place where the map copies feature ``f`` of exemplar ``k``."""

    k: int
    f: int
    ys: np.ndarray  # the map's pixels copying it
    xs: np.ndarray
    fy: np.ndarray  # the feature's pixels in the exemplar
    fx: np.ndarray
    size: int
    span: int  # its width, in pixels
    covered: int  # how many of its pixels the map's pixels copy
    colour: np.ndarray  # its mean colour
    offset: tuple[int, int] | None = None  # where to copy it (a skipped one), else the mean


def _within(ys: np.ndarray, xs: np.ndarray, shape: tuple[int, ...]) -> bool:
    """Whether every pixel (ys, xs) lies in ``shape``; False for no pixels (a displaced copy
    wholly outside the object has nothing to recopy: the map is left as it is)."""
    if ys.size == 0:
        return False
    return ys.min() >= 0 and xs.min() >= 0 and ys.max() < shape[0] and xs.max() < shape[1]


def complete_features(
    exemplars: list[np.ndarray],
    source: np.ndarray,
    features: list[tuple[np.ndarray, int]],
    object_mask: np.ndarray,
    exemplar_masks: list[np.ndarray],
    *,
    completion: Completion = _COMPLETION,
) -> tuple[np.ndarray, int]:
    """A source map in which every partly copied (or skipped) small feature is copied whole.

    Parameters
    ----------
    exemplars : list of ndarray, (H_e, W_e, C)
        The exemplars' colours.
    source : ndarray of int, (H, W, 3)
        Exemplar index, y, x per pixel (index < 0: none).
    features : list of (labels, n)
        Per exemplar, :func:`small_features` of it.
    object_mask : ndarray of bool, (H, W)
        The query's object: a completed feature must lie inside it.
    exemplar_masks : list of ndarray of bool
        The exemplars' objects: a completed feature's rim must come from inside.
    completion : Completion
        The thresholds (``complete_share``, ``partial_share``, ``feature_contrast``,
        ``rim``, ``rim_agreement``, the skipped features').

    Returns
    -------
    source : ndarray of int32, (H, W, 3)
    completed : int
        How many features were completed.
    """
    if not len(exemplars) == len(features) == len(exemplar_masks):
        raise ValueError(
            f"{len(exemplars)} exemplars, {len(features)} feature labellings and "
            f"{len(exemplar_masks)} masks: one of each per exemplar"
        )
    if source.ndim != 3 or source.shape[2] != 3 or source.shape[:2] != object_mask.shape:
        raise ValueError(
            f"source of shape {source.shape} and object mask of shape {object_mask.shape}: "
            "expected (H, W, 3) and (H, W)"
        )
    source = np.array(source, dtype=np.int32, copy=True)
    height, width = source.shape[:2]
    inside = ndimage.binary_erosion(object_mask, iterations=1)
    cross = ndimage.generate_binary_structure(2, 1)
    whole, contrast = completion.complete_share, completion.feature_contrast
    margin = completion.rim  # pixels of surroundings copied with a feature
    instances = _instances(exemplars, source, features)
    if _undouble(source, instances, features, object_mask, exemplar_masks, completion):
        instances = _instances(exemplars, source, features)  # the recopied pixels moved
    instances += _skipped_instances(source, features, exemplars, exemplar_masks, completion)
    # Where the map already shows a whole feature, and its colour: a partial copy
    # beside a whole feature of the same colour (a piece of a second brow above the
    # brow, of a second eye beside the eye) is a stray, not a feature to complete.
    # (An index into ``colours`` per pixel, 0 for none: a full-size colour image
    # would cost 200 MB at 4096².)
    drawn = np.zeros((height, width), np.int32)
    colours = [np.full(exemplars[0].shape[-1], np.inf, np.float32)]
    for item in instances:
        if item.covered >= whole * item.size:
            drawn[item.ys, item.xs] = len(colours)
            colours.append(item.colour)
    taken = np.zeros((height, width), bool)  # completed regions: not overwritten again
    completed = 0
    # The most complete copies first, then larger features: where the map copies
    # most of one eye and a quarter of another beside it, the first is completed
    # and the second, a whole one now beside it, is left.
    for item in sorted(instances, key=lambda item: (-item.covered / item.size, -item.size)):
        k, f, ys, xs, size, span = item.k, item.f, item.ys, item.xs, item.size, item.span
        if item.covered >= whole * size:
            continue
        # A cut copy of under ``partial_share`` is a stray fragment. A skipped feature (its
        # pixels are its ring's at the chosen offset) passed its own ring-share test.
        if item.offset is None and len(ys) < completion.partial_share * size:
            continue
        if item.offset is not None:
            dy, dx = item.offset
        else:
            dy = int(np.rint(np.mean(source[ys, xs, 1] - ys)))
            dx = int(np.rint(np.mean(source[ys, xs, 2] - xs)))
        ty, tx = item.fy - dy, item.fx - dx
        if not _within(ty, tx, (height, width)) or not inside[ty, tx].all():
            continue
        near = np.unique(
            drawn[
                max(ty.min() - span, 0) : ty.max() + span + 1,
                max(tx.min() - span, 0) : tx.max() + span + 1,
            ]
        )
        near = np.asarray([colours[i] for i in near if i > 0]).reshape(-1, len(colours[0]))
        if len(near) and np.sqrt(((near - item.colour) ** 2).sum(-1)).min() < contrast:
            log.debug("feature %d of exemplar %d: a whole one beside it", f, k)
            continue
        by0, bx0 = max(ty.min() - margin, 0), max(tx.min() - margin, 0)
        by1, bx1 = min(ty.max() + margin + 1, height), min(tx.max() + margin + 1, width)
        region = np.zeros((by1 - by0, bx1 - bx0), bool)
        region[ty - by0, tx - bx0] = True
        region = ndimage.binary_dilation(region, cross, iterations=margin)
        region &= object_mask[by0:by1, bx0:bx1]
        ry, rx = np.nonzero(region)
        ry, rx = ry + by0, rx + bx0
        sy, sx = ry + dy, rx + dx
        mask_k = exemplar_masks[k]
        if taken[ry, rx].any() or not _within(sy, sx, mask_k.shape) or not mask_k[sy, sx].all():
            continue
        # The rim must agree with what the map shows there now: a feature is
        # completed on its own surroundings (lips on skin), never pasted over
        # another part (a shirt's square over the neck).
        rim_here = ~np.isin(ry * width + rx, ty * width + tx) & (source[ry, rx, 0] >= 0)
        if rim_here.any():
            now = copy_through(exemplars, source[ry[rim_here], rx[rim_here]][None])[0]
            new = exemplars[k][sy[rim_here], sx[rim_here]]
            disagreement = float(np.sqrt(((now - new) ** 2).sum(-1)).mean())
            if disagreement > completion.rim_agreement:
                log.debug(
                    "feature %d of exemplar %d: rim disagrees by %.3f at y %d x %d",
                    f,
                    k,
                    disagreement,
                    ty.mean(),
                    tx.mean(),
                )
                continue
        source[ry, rx] = np.stack([np.full_like(ry, k), sy, sx], axis=-1)
        taken[ry, rx] = True
        drawn[ty, tx] = len(colours)
        colours.append(item.colour)
        completed += 1
        log.debug("feature %d of exemplar %d completed at y %d x %d", f, k, ty.mean(), tx.mean())
    return source, completed


def _undouble(source, instances, features, object_mask, exemplar_masks, completion) -> int:
    """Recopy, in ``source`` (in place), every feature drawn twice over itself; return
    how many were.

    Where the map copies one feature at two offsets so far apart that the copies
    overlap in the feature's own pixels (the lower half of an eye again below the
    eye: two pupils), and no copy is whole, the displaced copy's pixels, and those
    around them copied at its offset within a quarter of the feature's width, take
    the main copy's offset (the one most of the feature's pixels came from). The
    main copy is then completed like any cut feature. ``instances``: the map's
    :func:`_instances`; ``completion``: the thresholds (``complete_share``,
    ``partial_share``, ``rim``; the doubles' own are ``DOUBLE_SHIFT``, ``DOUBLE_TOLERANCE``
    and ``DOUBLE_MAIN``)."""
    height, width = source.shape[:2]
    tolerance = DOUBLE_TOLERANCE
    recopied = 0
    for item in instances:
        k, ys, xs = item.k, item.ys, item.xs
        offsets = np.stack([source[ys, xs, 1] - ys, source[ys, xs, 2] - xs], axis=1)
        distinct, counts = np.unique(offsets, axis=0, return_counts=True)
        main = distinct[np.argmax(counts)]
        threshold = max(tolerance + 1, item.span * DOUBLE_SHIFT)
        far = np.abs(offsets - main).max(1) >= threshold
        if not far.any():
            continue
        columns = features[k][0].shape[1]
        covers = [
            np.unique(source[ys[part], xs[part], 1] * columns + source[ys[part], xs[part], 2])
            for part in (~far, far)
        ]
        doubled = np.intersect1d(covers[0], covers[1], assume_unique=True).size
        main_copy, whole = len(covers[0]), completion.complete_share
        if not DOUBLE_MAIN * item.size <= main_copy < whole * item.size:
            continue
        if doubled < completion.partial_share * item.size:
            continue  # the displaced copy fills in what the main one lacks: no double
        # The displaced copy and what it brought along: pixels near it at its offsets.
        reach = max(completion.rim, item.span // 4)
        y0, x0 = max(ys.min() - reach, 0), max(xs.min() - reach, 0)
        y1, x1 = min(ys.max() + reach + 1, height), min(xs.max() + reach + 1, width)
        box = source[y0:y1, x0:x1]
        by, bx = np.mgrid[y0:y1, x0:x1]
        box_offsets = np.stack([box[..., 1] - by, box[..., 2] - bx], axis=-1)
        along = np.zeros(box.shape[:2], bool)
        for offset in distinct[np.abs(distinct - main).max(1) >= threshold]:
            along |= np.abs(box_offsets - offset).max(-1) <= tolerance
        along &= box[..., 0] == k
        seeds = np.zeros(box.shape[:2], bool)
        seeds[ys[far] - y0, xs[far] - x0] = True
        along &= ndimage.binary_dilation(seeds, iterations=reach)
        along &= object_mask[y0:y1, x0:x1]
        ry, rx = np.nonzero(along)
        ry, rx = ry + y0, rx + x0
        sy, sx = ry + main[0], rx + main[1]
        if not _within(sy, sx, exemplar_masks[k].shape) or not exemplar_masks[k][sy, sx].all():
            continue
        source[ry, rx] = np.stack([np.full_like(ry, k), sy, sx], axis=-1)
        recopied += 1
        log.debug("feature %d of exemplar %d drawn twice: %d pixels recopied", item.f, k, len(ry))
    return recopied


def _feature_pixels(labels, box, f):
    """Feature ``f``'s pixels in its exemplar (inside its ``box``), its width in
    pixels, and half that (at least 1): how far its ring and its copies reach."""
    fy, fx = np.nonzero(labels[box] == f)
    fy, fx = fy + box[0].start, fx + box[1].start
    span = int(max(np.ptp(fy), np.ptp(fx))) + 1
    return fy, fx, span, max(span // 2, 1)


def _skipped_instances(source, features, exemplars, exemplar_masks, completion):
    """Features whose surroundings the map copies around one place, without them: an
    eye's ring of skin copied around a hole that other offsets filled with plain skin.

    For each feature, its ring (the pixels within half its width around it, inside its
    exemplar) is looked up in the source map. Where the map copies at least
    ``skipped_ring_share`` of the ring's pixels at offsets within half the feature's
    width of their median, the feature belongs there. Where no pixel
    the feature would cover at that offset copies a feature of any exemplar, the
    feature is an instance with nothing of it covered: :func:`complete_features`
    copies it there, under the same tests as a cut one. Not where the map already
    shows something at that place (:func:`_shows_something`).
    """
    height, width = source.shape[:2]
    ring_share = completion.skipped_ring_share
    found = []
    for k, (labels, n) in enumerate(features):
        if n == 0:
            continue
        here = np.flatnonzero(source[..., 0] == k)
        sy, sx = source[..., 1].ravel()[here], source[..., 2].ravel()[here]
        for f, box in enumerate(ndimage.find_objects(labels), start=1):
            if box is None:
                continue
            fy, fx, span, reach = _feature_pixels(labels, box, f)
            y0, x0 = max(box[0].start - reach, 0), max(box[1].start - reach, 0)
            y1 = min(box[0].stop + reach, labels.shape[0])
            x1 = min(box[1].stop + reach, labels.shape[1])
            feature = labels[y0:y1, x0:x1] == f
            ring = ndimage.binary_dilation(feature, iterations=reach) & ~feature
            ring &= exemplar_masks[k][y0:y1, x0:x1]
            n_ring = int(ring.sum())
            if n_ring == 0:
                continue
            inside = np.flatnonzero((sy >= y0) & (sy < y1) & (sx >= x0) & (sx < x1))
            pick = inside[ring[sy[inside] - y0, sx[inside] - x0]]  # the map's ring copies
            if len(pick) < ring_share * n_ring:
                continue
            ys, xs = np.divmod(here[pick], width)
            dy, dx = sy[pick] - ys, sx[pick] - xs
            my, mx = int(np.median(dy)), int(np.median(dx))
            near = pick[(np.abs(dy - my) <= reach) & (np.abs(dx - mx) <= reach)]
            covered = np.unique(sy[near] * labels.shape[1] + sx[near]).size
            if covered < ring_share * n_ring:
                continue
            ty, tx = fy - my, fx - mx
            if (
                not _within(ty, tx, (height, width))
                or copies_features(source[ty, tx][None], features).any()
            ):
                continue
            colour = exemplars[k][fy, fx].mean(0)
            # The ring's pixels at the chosen offset stand for the map's pixels of the
            # instance; the offset itself says where complete_features copies it.
            ry, rx = np.nonzero(ring)
            ry, rx = ry + y0 - my, rx + x0 - mx
            keep = (ry >= 0) & (rx >= 0) & (ry < height) & (rx < width)
            if _shows_something(exemplars, source, ty, tx, ry[keep], rx[keep], completion):
                continue
            found.append(
                _Instance(k, f, ry[keep], rx[keep], fy, fx, len(fy), span, 0, colour, (my, mx))
            )
    return found


def _shows_something(exemplars, source, ys, xs, ring_ys, ring_xs, completion) -> bool:
    """Whether the map already shows something at (ys, xs) that stands out from what it
    shows on the ring around: at least ``skipped_place_shown`` of those pixels
    ``feature_contrast`` or more from the ring's median colour (an eye the copy drew
    from pixels that no feature detection found). Independent of the detection."""
    here = source[ys, xs][None]
    around = source[ring_ys, ring_xs]
    around = around[around[:, 0] >= 0][None]
    if (here[..., 0] < 0).any() or around.shape[1] == 0:
        return True  # a place the map does not cover, or nothing to compare it with
    shown = copy_through(exemplars, here)[0]
    ground = np.median(copy_through(exemplars, around)[0], axis=0)
    stands_out = np.sqrt(((shown - ground) ** 2).sum(-1)) >= completion.feature_contrast
    log.debug(
        "skipped feature at y %d x %d: %.2f of its place stands out",
        ys.mean(),
        xs.mean(),
        stands_out.mean(),
    )
    return bool(stands_out.mean() >= completion.skipped_place_shown)


def copies_features(source: np.ndarray, features: list[tuple[np.ndarray, int]]) -> np.ndarray:
    """Where a source map copies a small feature of its exemplar.

    Parameters
    ----------
    source : ndarray of int, (H, W, 3)
        Exemplar index, y, x per pixel (index < 0: none).
    features : list of (labels, n)
        Per exemplar, :func:`small_features` of it.

    Returns
    -------
    ndarray of bool, (H, W)
    """
    found = np.zeros(source.shape[:2], bool)
    for k, (labels, _) in enumerate(features):
        at = source[..., 0] == k
        sy = np.clip(source[..., 1][at], 0, labels.shape[0] - 1)
        sx = np.clip(source[..., 2][at], 0, labels.shape[1] - 1)
        found[at] = labels[sy, sx] > 0
    return found


def _instances(exemplars, source, features) -> list[_Instance]:
    """Each place where the map copies an exemplar's feature: the pixels copying
    it within half its width of one another, how many of its pixels they cover."""
    height, width = source.shape[:2]
    found = []
    for k, (labels, n) in enumerate(features):
        if n == 0:
            continue
        here = np.nonzero(source[..., 0] == k)
        feature_of = np.zeros((height, width), np.int32)
        feature_of[here] = labels[source[..., 1][here], source[..., 2][here]]
        sizes = np.bincount(labels.ravel(), minlength=n + 1)
        boxes = ndimage.find_objects(labels)
        # The pixels that copy a feature, grouped by feature (a few of the map's pixels:
        # no sort of the whole map).
        copying = np.flatnonzero(feature_of)
        which = feature_of.ravel()[copying]
        order = np.argsort(which, kind="stable")
        copying, which = copying[order], which[order]
        starts = np.searchsorted(which, np.arange(n + 2))
        for f in np.unique(which):
            fy, fx, span, reach = _feature_pixels(labels, boxes[f - 1], f)
            cy, cx = np.divmod(copying[starts[f] : starts[f + 1]], width)
            # Work in the box around this feature's copies: a feature is small.
            y0, x0 = max(cy.min() - reach, 0), max(cx.min() - reach, 0)
            y1, x1 = min(cy.max() + reach + 1, height), min(cx.max() + reach + 1, width)
            copies = np.zeros((y1 - y0, x1 - x0), bool)
            copies[cy - y0, cx - x0] = True
            groups, m = ndimage.label(ndimage.binary_dilation(copies, iterations=reach))
            colour = exemplars[k][fy, fx].mean(0)
            for i in range(1, m + 1):
                ys, xs = np.nonzero(copies & (groups == i))
                ys, xs = ys + y0, xs + x0
                covered = np.unique(source[ys, xs, 1] * labels.shape[1] + source[ys, xs, 2]).size
                found.append(
                    _Instance(k, int(f), ys, xs, fy, fx, int(sizes[f]), span, int(covered), colour)
                )
    return found
