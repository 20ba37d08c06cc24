"""One palette per part: a part copied from two examples, shifted into one example's colours.

A map copied from two examples often shows one part in two palettes where the examples
meet: a face in one skin tone above a neck in another. The gradient-domain blend
(:func:`imagemap.core.blend.seamless_copy`) spreads the step between them over a few pixels,
but the two tones stay. Here each example's colours are clustered, and its *parts* are
the large, solid connected pieces of one cluster (skin, a plain garment; not the colours
of a pattern, whose contrast a shift of one colour would change). A part of one example
and a part of another are *the same part* when the other's is the one its footprint
(centroid-aligned on the query) overlaps most, over half of the smaller footprint, and
no part of the other example is much nearer in colour. Where the copy shows both, the
pixels of the smaller share are shifted by the difference of the two parts' mean
colours; colours far from the part (an eye, the lips) keep theirs.

The shifts move the blend's reference, not the copied pixels: the copy's detail (its
gradients) is kept, and only the colour the blend pulls each region towards changes.

Examples
--------
Two examples with the same layout, skin above and a shirt below, in two skin tones; the
copy took a strip of the face from the second. The strip is shifted into the first's skin:

>>> mask = np.zeros((40, 30), bool); mask[2:38, 5:25] = True
>>> a = np.zeros((40, 30, 3), np.float32); a[:20] = (0.6, 0.45, 0.55); a[20:] = (0.3, 0.6, 0.4)
>>> b = a.copy(); b[:20] = (0.5, 0.48, 0.57)
>>> source = np.zeros((40, 30, 3), np.int32)
>>> source[..., 1], source[..., 2] = np.mgrid[0:40, 0:30]
>>> source[2:20, 18:25, 0] = 1
>>> shift = even_palettes([a, b], [mask, mask], source, mask)
>>> [round(float(v), 2) for v in shift[10, 20]], [round(float(v), 2) for v in shift[10, 10]]
([0.1, -0.03, -0.02], [0.0, 0.0, 0.0])
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy import ndimage

from imagemap.align import centroid_shift, translate
from imagemap.core.blend import EDGE_FLOOR

__all__ = ["even_palettes", "example_parts", "palette_clusters"]

N_COLOURS = 6
"""Colour clusters per example before merging: room for a few large parts (skin, hair,
a garment's two colours). Clusters that overlap (one part's grain split in several)
are merged, so a plain map ends with one cluster per part."""

PART_STEP = EDGE_FLOOR
"""Clusters whose means are closer than this are one part: the smallest step between
two parts (``imagemap.core.blend.EDGE_FLOOR``; smaller steps are shading and grain)."""

SAMPLE = 20000
"""Pixels the clusters are fitted on (all of them are then assigned)."""

MIN_SHARE = 0.05
"""A connected piece of one colour under this share of its example's object is no part
(a feature, a spot, one check of a shirt)."""

SOLID_RADIUS = 0.03
"""A part is solid where it is farther than this share of the object's size (square root
of its area) from its own edge (4 px on a 200 x 150 bust, 2.4 px on a fish)..."""

MIN_SOLID = 0.5
"""...over at least this share of its pixels. Stripes and spots are not shifted. On the
generated busts at 200 x 150 the skins reach 0.61 to 0.89, a checked shirt's colours
0.21; the fish's colours spread from 0 to 0.71 (``docs/presets.md``)."""

MIN_OVERLAP = 0.5
"""Share of the smaller of two footprints the two must share to be one part."""

REACH = 0.05
"""A pixel this share of the object's size from a part (in its example) takes 0.6 of the
part's shift, at twice the distance 0.14 (Gaussian fall-off)."""

COLOUR_RATIO = 2.0
"""Two parts in the same place are one part unless the other example has a part this
many times nearer in colour."""

_FAR = 1e3  # the mean of a cluster merged away: no pixel is near it
_MIN_RADIUS = 0.01  # a flat colour's spread, for the weights (channels in [0, 1])


def palette_clusters(exemplar, mask, *, n_colours=N_COLOURS, seed=0):
    """Cluster an example's object colours into its large parts.

    k-means (``n_colours``) on a sample of the object's pixels, then clusters whose
    means are closer than the sum of their spreads, or than ``PART_STEP``, are merged.

    Parameters
    ----------
    exemplar : ndarray, (H, W, C)
    mask : ndarray of bool, (H, W)
    n_colours : int
    seed : int

    Returns
    -------
    labels : ndarray of int32, (H, W)
        Cluster per pixel (-1 outside the object).
    means : ndarray of float32, (n_colours, C)
        Each cluster's mean colour (far away for a cluster merged into another).
    """
    from scipy.cluster.vq import kmeans2  # only with the option on: not on every start

    colours = np.asarray(exemplar, dtype=np.float32)[mask]
    rng = np.random.default_rng(seed)
    sample = colours[rng.choice(len(colours), min(len(colours), SAMPLE), replace=False)]
    with warnings.catch_warnings():  # a map of fewer colours leaves clusters empty
        warnings.simplefilter("ignore")
        centres, _ = kmeans2(sample.astype(np.float64), n_colours, minit="++", seed=rng)
    assigned = _nearest(colours, centres.astype(np.float32))
    while True:
        means, radii, sizes = _cluster_stats(colours, assigned, n_colours)
        present = np.flatnonzero(sizes)
        gaps = np.sqrt(((means[present, None] - means[None, present]) ** 2).sum(-1))
        reach = radii[present, None] + radii[None, present]
        # One part: overlapping clusters, or means closer than a part edge's step.
        reach = np.maximum(reach, PART_STEP)
        ratio = np.where(np.eye(len(present), dtype=bool), np.inf, gaps / reach)
        i, j = np.unravel_index(np.argmin(ratio), ratio.shape)
        if ratio[i, j] >= 1.0:
            break
        keep, gone = present[min(i, j)], present[max(i, j)]
        assigned[assigned == gone] = keep
    labels = np.full(mask.shape, -1, np.int32)
    labels[mask] = assigned
    return labels, means


def _nearest(colours, centres):
    best = np.zeros(len(colours), np.int32)
    best_d2 = np.full(len(colours), np.inf, np.float32)
    for c, centre in enumerate(centres):
        d2 = ((colours - centre) ** 2).sum(1)
        closer = d2 < best_d2
        best[closer], best_d2[closer] = c, d2[closer]
    return best


def _cluster_stats(colours, assigned, k):
    sizes = np.bincount(assigned, minlength=k)
    means = np.full((k, colours.shape[1]), _FAR, np.float32)
    radii = np.zeros(k, np.float32)
    for c in np.flatnonzero(sizes):
        own = colours[assigned == c]
        means[c] = own.mean(0)
        radii[c] = np.sqrt(((own - means[c]) ** 2).sum(1).mean())
    return means, radii, sizes


def example_parts(exemplar, mask, *, seed=0):
    """An example's large parts: solid connected pieces of one colour cluster.

    A cluster alone is not a part: a checked shirt's middle tone can be the skin's
    colour. A part is a connected piece of one cluster of at least ``MIN_SHARE`` of
    the object, solid (``MIN_SOLID`` of it farther than ``SOLID_RADIUS`` x size from
    its edge).

    Returns
    -------
    parts : ndarray of int32, (H, W)
        Part per pixel (-1: none).
    means : ndarray of float32, (n_parts, C)
    spreads : ndarray of float32, (n_parts,)
        The 95th percentile of each part's distances to its mean.
    """
    labels, _ = palette_clusters(exemplar, mask, seed=seed)
    colours = np.asarray(exemplar, dtype=np.float32)
    size = np.sqrt(mask.sum())
    parts = np.full(mask.shape, -1, np.int32)
    means, spreads = [], []
    for c in range(labels.max() + 1):
        pieces, n_pieces = ndimage.label(labels == c)
        if not n_pieces:
            continue
        areas = np.bincount(pieces.ravel(), minlength=n_pieces + 1)
        boxes = ndimage.find_objects(pieces)
        for piece in np.flatnonzero(areas >= MIN_SHARE * mask.sum()):
            if piece == 0:
                continue
            # The piece's box and a pixel around it (all not the piece): the distance to
            # its edge is the same as over the whole image.
            box = tuple(
                slice(max(s.start - 1, 0), min(s.stop + 1, n))
                for s, n in zip(boxes[piece - 1], mask.shape, strict=True)
            )
            own = pieces[box] == piece
            if (ndimage.distance_transform_edt(own)[own] > SOLID_RADIUS * size).mean() < MIN_SOLID:
                continue
            parts[box][own] = len(means)
            values = colours[box][own]
            means.append(values.mean(0))
            spreads.append(np.quantile(np.sqrt(((values - means[-1]) ** 2).sum(1)), 0.95))
    n_channels = colours.shape[2]
    return (
        parts,
        np.array(means, np.float32).reshape(-1, n_channels),
        np.array(spreads, np.float32),
    )


def even_palettes(exemplars, masks, source, mask, *, seed=0):
    """Colour shifts that put each part the copy shows in one example's colours.

    Parameters
    ----------
    exemplars : list of ndarray, (H_e, W_e, C)
        The examples' colours (e.g. YCbCr), indexed by ``source[..., 0]``.
    masks : list of ndarray of bool
        The examples' objects.
    source : ndarray of int, (H, W, 3)
        The copy's source map: example, y, x per pixel (example < 0: none).
    mask : ndarray of bool, (H, W)
        The query's object.
    seed : int
        Seed of the clustering (the same seed, the same shifts).

    Returns
    -------
    ndarray of float32, (H, W, C), or None
        The shift of each pixel's colour, to be added to the blend's reference; None
        when nothing is shifted (one example, or no part in two palettes).
    """
    n = len(exemplars)
    if n < 2:
        return None
    found = [example_parts(e, m, seed=seed) for e, m in zip(exemplars, masks, strict=True)]
    # Each example's parts placed on the query by centroid alignment.
    footprints = []
    for (parts, _, _), m in zip(found, masks, strict=True):
        moved = translate((parts + 1).astype(np.float32), centroid_shift(m, mask), mask.shape)
        footprints.append(np.rint(moved).astype(np.int64)[mask] - 1)
    # Which parts the copy takes, and how much of each.
    inside = mask & (source[..., 0] >= 0)
    e = source[..., 0][inside]
    ys, xs = source[..., 1][inside], source[..., 2][inside]
    counts = []
    for a in range(n):
        here = e == a
        used = found[a][0][ys[here], xs[here]]
        counts.append(np.bincount(used[used >= 0], minlength=len(found[a][1])))
    areas = [
        np.bincount(f[f >= 0], minlength=len(p[1])) for f, p in zip(footprints, found, strict=True)
    ]
    tables = {}  # (a, b): pixels of the query under a's part i and b's part j
    for a in range(n):
        for b in range(n):
            if a != b and len(found[a][1]) and len(found[b][1]):
                both = (footprints[a] >= 0) & (footprints[b] >= 0)
                table = np.zeros((len(found[a][1]), len(found[b][1])), np.int64)
                np.add.at(table, (footprints[a][both], footprints[b][both]), 1)
                tables[a, b] = table
    shifts = [np.zeros_like(means) for _, means, _ in found]
    for b in range(n):
        for j in np.flatnonzero(counts[b]):
            best, best_count = None, counts[b][j]  # a partner must be the larger share
            for a in range(n):
                if (a, b) not in tables:
                    continue
                table = tables[a, b]
                i = int(table[:, j].argmax())  # the same place: the largest overlap...
                # ...and not much farther in colour than the other's nearest part (a
                # shirt where the other example has skin is no skin; two skins can be as
                # far apart in lightness as a skin and its hair).
                gaps = np.sqrt(((found[a][1] - found[b][1][j]) ** 2).sum(1))
                if gaps[i] > COLOUR_RATIO * gaps.min():
                    continue
                # ...covering at least half of the smaller of the two.
                smaller = min(areas[a][i], areas[b][j])
                if table[i, j] >= MIN_OVERLAP * smaller and counts[a][i] > best_count:
                    best, best_count = (a, i), counts[a][i]
            if best is not None:
                a, i = best
                shifts[b][j] = found[a][1][i] - found[b][1][j]
    if not any(s.any() for s in shifts):
        return None
    # A copied pixel takes a shifted part's shift as a smooth function of its colour and
    # of its distance to the part in its example: full within the part's colour spread
    # and inside or next to it (the blush and shading within a face), falling off in
    # colour (an eye, the lips keep theirs) and in distance (a pixel of the same colour
    # elsewhere, a check of a shirt, is not that part).
    values = np.zeros((len(e), exemplars[0].shape[2]), np.float32)
    for b in range(n):
        parts, means, spreads = found[b]
        moved = np.flatnonzero(np.abs(shifts[b]).sum(1) > 0)
        if not len(moved):
            continue
        here = np.flatnonzero(e == b)
        colours = np.asarray(exemplars[b], dtype=np.float32)[ys[here], xs[here]]
        reach = REACH * np.sqrt(masks[b].sum())
        weights = np.zeros((len(here), len(moved)), np.float32)
        for column, j in enumerate(moved):
            beyond = np.maximum(np.sqrt(((colours - means[j]) ** 2).sum(1)) - spreads[j], 0)
            width = max(0.5 * float(spreads[j]), _MIN_RADIUS)
            distance = ndimage.distance_transform_edt(parts != j)[ys[here], xs[here]]
            weights[:, column] = np.exp(
                -0.5 * (beyond / width) ** 2 - 0.5 * (distance / reach) ** 2
            )
        weights /= np.maximum(weights.sum(1, keepdims=True), 1.0)
        values[here] = weights @ shifts[b][moved]
    shift = np.zeros(source.shape[:2] + exemplars[0].shape[2:], np.float32)
    shift[inside] = values
    return shift
