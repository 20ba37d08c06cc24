"""One palette per part: a part copied from two examples, shifted into one example's colours.

A map copied from two examples often shows one part in two palettes where the examples
meet: a face in one skin tone above a neck in another. The gradient-domain blend
(:func:`imagemap.blend.seamless_copy`) spreads the step between them over a few pixels,
but the two tones stay. Here each example's colours are clustered; a cluster of one
example and a cluster of another are *the same part* when they cover the same place of
the object (their footprints, centroid-aligned on the query, overlap, each the other's
best match); and where the copy shows both, the pixels of the smaller share are shifted
by the difference of the two clusters' mean colours. Only solid parts are shifted (skin,
a plain garment), not the colours of a pattern (stripes, spots), whose contrast a shift of
one colour would change, nor colours far from every part (an eye, the lips).

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
from scipy.cluster.vq import kmeans2

from imagemap.align import centroid_shift, translate
from imagemap.blend import EDGE_FLOOR

__all__ = ["even_palettes", "palette_clusters"]

N_COLOURS = 6
"""Colour clusters per example before merging: room for a few large parts (skin, hair,
a garment's two colours). Clusters that overlap (one part's grain split in several)
are merged, so a plain map ends with one cluster per part."""

PART_STEP = EDGE_FLOOR
"""Clusters whose means are closer than this are one part: the smallest step between
two parts (``imagemap.blend.EDGE_FLOOR``; smaller steps are shading and grain)."""

SAMPLE = 20000
"""Pixels the clusters are fitted on (all of them are then assigned)."""

MIN_SHARE = 0.02
"""A cluster under this share of its example's object is no part (a feature, a spot)."""

SOLID_RADIUS = 0.03
"""A part is solid where it is farther than this share of the object's size (square root
of its area) from its own edge (4 px on a 200 x 150 bust, 2.4 px on a fish)..."""

MIN_SOLID = 0.5
"""...over at least this share of its pixels. Stripes and spots are not shifted. On the
generated busts at 200 x 150 the skins reach 0.61 to 0.89, a checked shirt's colours
0.21; the fish's colours spread from 0 to 0.71 (``docs/presets.md``)."""

MIN_OVERLAP = 0.5
"""Share of the smaller of two footprints the two must share to be one part."""

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
    spreads : ndarray of float32, (n_colours,)
        The 95th percentile of each cluster's distances to its mean (0 when merged away).
    """
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
    spreads = np.zeros(n_colours, np.float32)
    for c in np.flatnonzero(sizes):
        spreads[c] = np.quantile(np.sqrt(((colours[assigned == c] - means[c]) ** 2).sum(1)), 0.95)
    return labels, means, spreads


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


def _solid(labels, mask, k):
    """Per cluster: whether it is a solid part rather than a pattern (``MIN_SOLID``)."""
    radius = SOLID_RADIUS * np.sqrt(mask.sum())
    solid = np.zeros(k, bool)
    for c in range(k):
        own = labels == c
        n = own.sum()
        if n:
            # Surviving an erosion by the radius: farther than it from the cluster's edge.
            inner = ndimage.distance_transform_edt(own) > radius
            solid[c] = inner.sum() >= MIN_SOLID * n
    return solid


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
    clusters = [palette_clusters(e, m, seed=seed) for e, m in zip(exemplars, masks, strict=True)]
    k = clusters[0][1].shape[0]
    # Each example's clusters placed on the query by centroid alignment.
    footprints = []
    for (labels, _, _), m in zip(clusters, masks, strict=True):
        moved = translate((labels + 1).astype(np.float32), centroid_shift(m, mask), mask.shape)
        footprints.append(np.rint(moved).astype(np.int64)[mask] - 1)
    # Which clusters the copy takes, and how much of each.
    inside = mask & (source[..., 0] >= 0)
    e = source[..., 0][inside]
    ys, xs = source[..., 1][inside], source[..., 2][inside]
    used = np.full(len(e), -1, np.int64)
    for a in range(n):
        here = e == a
        used[here] = clusters[a][0][ys[here], xs[here]]
    counts = np.zeros((n, k), np.int64)
    ok = used >= 0
    np.add.at(counts, (e[ok], used[ok]), 1)
    is_part = [
        (np.bincount(c[0][c[0] >= 0], minlength=k) >= MIN_SHARE * m.sum()) & _solid(c[0], m, k)
        for c, m in zip(clusters, masks, strict=True)
    ]
    shifts = np.zeros((n, k, exemplars[0].shape[2]), np.float32)
    for b in range(n):
        for j in np.flatnonzero(is_part[b] & (counts[b] > 0)):
            best, best_count = None, counts[b, j]  # a partner must be the larger share
            for a in range(n):
                if a == b:
                    continue
                both = (footprints[a] >= 0) & (footprints[b] >= 0)
                table = np.zeros((k, k), np.int64)
                np.add.at(table, (footprints[a][both], footprints[b][both]), 1)
                i = int(table[:, j].argmax())
                if not is_part[a][i] or int(table[i].argmax()) != j:
                    continue
                # ...and the nearest in colour of the other's parts (a shirt where the
                # other example has skin is no skin).
                parts = np.flatnonzero(is_part[a])
                gaps = ((clusters[a][1][parts] - clusters[b][1][j]) ** 2).sum(1)
                if parts[gaps.argmin()] != i:
                    continue
                smaller = min((footprints[a] == i).sum(), (footprints[b] == j).sum())
                if table[i, j] >= MIN_OVERLAP * smaller and counts[a, i] > best_count:
                    best, best_count = (a, i), counts[a, i]
            if best is not None:
                a, i = best
                shifts[b, j] = clusters[a][1][i] - clusters[b][1][j]
    if not shifts.any():
        return None
    # Each copied pixel's shift is a smooth function of its colour: a pixel within a
    # shifted cluster's spread takes its shift, one between two clusters a blend of
    # theirs, and one far from every cluster (an eye, a lip) keeps its colour.
    values = np.zeros((len(e), exemplars[0].shape[2]), np.float32)
    for b in range(n):
        if not shifts[b].any():
            continue
        _, means, spreads = clusters[b]
        here = np.flatnonzero(e == b)
        colours = np.asarray(exemplars[b], dtype=np.float32)[ys[here], xs[here]]
        weights = np.zeros((len(here), k), np.float32)
        for c in np.flatnonzero(means[:, 0] < _FAR):
            beyond = np.maximum(np.sqrt(((colours - means[c]) ** 2).sum(1)) - spreads[c], 0)
            width = max(0.5 * float(spreads[c]), _MIN_RADIUS)
            weights[:, c] = np.exp(-0.5 * (beyond / width) ** 2)
        weights /= np.maximum(weights.sum(1, keepdims=True), 1.0)
        values[here] = weights @ shifts[b]
    shift = np.zeros(source.shape[:2] + exemplars[0].shape[2:], np.float32)
    shift[inside] = values
    return shift
