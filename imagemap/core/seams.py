"""The copy's seams, placed by graph cuts: :func:`place_seams`.

The labels of a copy (exemplar and offset per pixel) are chosen again by
alpha-expansion (Boykov, Veksler & Zabih 2001) on Kwatra et al.'s seam cost (2003,
"Graphcut textures"), each move one minimum cut (PyMaxflow); the terms of a move are
a numba kernel (:func:`imagemap.core.kernels.expansion_terms`). The seams left are
blended by :func:`imagemap.core.poisson.seamless_copy`.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

__all__ = ["place_seams"]


def place_seams(
    exemplars: list[np.ndarray],
    source: np.ndarray,
    reference: np.ndarray,
    *,
    smoothness: float = 1.0,
    spread: float = 2.0,
    sweeps: int = 2,
    mask: np.ndarray | None = None,
    exemplar_masks: list[np.ndarray] | None = None,
    groups: np.ndarray | None = None,
) -> np.ndarray:
    """A source map with fewer, cheaper seams, placed where the sources agree.

    Every pixel's source is an exemplar and an offset: a *label*. The labels are
    chosen again, among those the map already uses, to minimise the squared
    distance of each copied colour to ``reference`` plus ``smoothness`` times the
    seam costs: zero between equal labels, else the two sources' colour gap on both
    pixels (Kwatra et al. 2003, "Graphcut textures"). The minimisation is Boykov,
    Veksler & Zabih's alpha-expansion (2001): each label in turn, largest first, may
    take over any set of pixels near where it is used (``spread``), chosen by one
    minimum cut (PyMaxflow). Unlike pixel-by-pixel moves, a whole fragment can give
    way to its neighbour's copy at once, so a few large copies replace many small
    ones and the boundaries between them run where they show the same colours.
    Deterministic.

    Parameters
    ----------
    exemplars : list of ndarray, (H_e, W_e, C)
    source : ndarray of int, (H, W, 3)
        Exemplar index, y, x per pixel (index < 0: none, left alone).
    reference : ndarray, (H, W, C)
        The colours the copy should stay near (the voted map).
    smoothness : float
        Weight of the seam costs against the data cost.
    spread : float
        How far a label may spread in one move, in units of its own size (the square
        root of its area): a move's cost grows with its reach, and a copy of a few
        pixels rarely wins more than its surroundings.
    sweeps : int
        Passes over the labels.
    mask : ndarray of bool, (H, W), optional
        The pixels whose labels may change (default: every pixel with a source).
    exemplar_masks : list of ndarray of bool, (H_e, W_e), optional
        The exemplars' objects: a pixel only takes a new label whose source lies
        inside one (the exemplars' colours past their outlines are a continuation for
        the windows, not a part to copy). Default: anywhere in the exemplar.
    groups : ndarray of int, (H, W), optional
        Pixels of group g > 0 (a small feature, say) only take labels the group
        used at the start of the sweep: a feature copied in pieces from two
        examples can become one of its own copies, never a piece of its
        surroundings. Their seams with the surroundings are weighed like any other.

    Returns
    -------
    ndarray of int32, (H, W, 3)

    Examples
    --------
    Stripes copied through two offsets 3 rows apart, in a checkerboard of 8-px tiles
    (16 pieces), where the voted map cannot tell them apart (it is their mean): the
    first move gives the whole map to one offset.

    >>> stripes = np.repeat(np.sin(np.arange(64) / 2.0)[:, None], 64, axis=1)[..., None]
    >>> rows, columns = np.mgrid[0:32, 0:32]
    >>> shift = 3 * (((rows // 8) + (columns // 8)) % 2)
    >>> source = np.stack([np.zeros_like(rows), rows + 8 + shift, columns + 8], -1)
    >>> voted = (stripes[rows + 8, columns + 8] + stripes[rows + 11, columns + 8]) / 2
    >>> placed = place_seams([stripes], source, voted)
    >>> np.unique(placed[..., 1] - rows).tolist()  # one offset left
    [8]
    """
    packed, shapes = _packed(exemplars)
    inside = np.zeros(packed.shape[:3], bool)
    for k, exemplar in enumerate(exemplars):
        inside[k, : exemplar.shape[0], : exemplar.shape[1]] = (
            True if exemplar_masks is None else exemplar_masks[k]
        )
    height, width = source.shape[:2]
    yy, xx = np.ogrid[0:height, 0:width]
    label_e = source[..., 0].astype(np.int64)
    label_y = (source[..., 1] - yy).astype(np.int64)
    label_x = (source[..., 2] - xx).astype(np.int64)
    movable = label_e >= 0 if mask is None else np.asarray(mask, bool) & (label_e >= 0)
    reference = np.ascontiguousarray(reference, dtype=np.float32)
    # The move after which each pixel last changed, and each label's last move: a
    # label's move is not repeated while nothing in or around its crop has changed
    # since (it would find the same cut), unless that move spread it.
    changed_at = np.zeros((height, width), np.int64)
    expanded_at: dict[tuple[int, ...], int] = {}
    moves = 0
    for _ in range(sweeps):
        alphas, ids, areas, boxes = _label_table(label_e, label_y, label_x, movable)
        in_groups = _group_labels(label_e, label_y, label_x, groups, movable)
        for k in np.argsort(-areas, kind="stable"):  # largest first, ties in label order
            if areas[k] == 0:  # taken over by the others' moves
                continue
            alpha = alphas[k]
            # The boxes are from the start of the sweep: a label only ever loses
            # pixels to the others' moves, so its box still holds it.
            reach = int(np.ceil(spread * np.sqrt(areas[k])))
            box_rows, box_columns = boxes[k]
            rows = slice(max(box_rows.start - reach, 0), min(box_rows.stop + reach, height))
            columns = slice(max(box_columns.start - reach, 0), min(box_columns.stop + reach, width))
            key = tuple(int(v) for v in alpha)
            around = changed_at[
                max(rows.start - 1, 0) : rows.stop + 1, max(columns.start - 1, 0) : columns.stop + 1
            ]
            if key in expanded_at and around.max() <= expanded_at[key]:
                continue
            region = ndimage.maximum_filter(ids[rows, columns] == k + 1, size=2 * reach + 1)
            moves += 1
            if groups is not None:  # a group's pixels only take its own labels
                grouped = groups[rows, columns]
                region &= (grouped == 0) | np.isin(grouped, in_groups.get(key, ()))
            moved = _expand(
                (packed, shapes, inside),
                reference,
                (label_e, label_y, label_x),
                movable,
                (rows, columns),
                region,
                alpha,
                smoothness,
            )
            if moved is None:
                expanded_at[key] = moves
                continue
            # it spread: its next move reaches further
            expanded_at[key] = moves - 1
            changed_at[rows, columns][moved] = moves
            losers = ids[rows, columns][moved]
            areas -= np.bincount(losers - 1, minlength=len(areas))[: len(areas)]
            areas[k] += int(moved.sum())
            ids[rows, columns][moved] = k + 1
    return np.stack([label_e, label_y + yy, label_x + xx], axis=-1).astype(np.int32)


#: Cost of a seam besides the colour gap: between two sources that show the same
#: colours, one copy is still preferred over two.
_SEAM_FLOOR = 1e-3


def _group_labels(label_e, label_y, label_x, groups, movable):
    """For each label used inside groups (``groups`` > 0), those groups' numbers."""
    if groups is None:
        return {}
    held = (groups > 0) & movable
    pairs = np.unique(
        np.stack([_label_keys(label_e, label_y, label_x, held), groups[held].astype(np.int64)], 1),
        axis=0,
    )
    table: dict[tuple[int, ...], list[int]] = {}
    for label, group in zip(_label_values(pairs[:, 0]).tolist(), pairs[:, 1].tolist(), strict=True):
        table.setdefault(tuple(label), []).append(group)
    return {label: np.array(numbers) for label, numbers in table.items()}


def _label_keys(label_e, label_y, label_x, where):
    """One integer per label of the pixels ``where``: offsets fit in 20 bits whatever the
    image size (< 2^19 px)."""
    key = (label_e[where] << 40) | ((label_y[where] + (1 << 19)) << 20)
    return key | (label_x[where] + (1 << 19))


def _label_values(keys):
    """(exemplar, dy, dx) of each key of :func:`_label_keys`, (n, 3)."""
    return np.stack(
        [keys >> 40, ((keys >> 20) & 0xFFFFF) - (1 << 19), (keys & 0xFFFFF) - (1 << 19)], axis=1
    )


def _label_table(label_e, label_y, label_x, movable):
    """The labels in use: (exemplar, dy, dx) of each, a map of their numbers + 1 (0: none),
    their areas and their bounding boxes."""
    keys, inverse, areas = np.unique(
        _label_keys(label_e, label_y, label_x, movable), return_inverse=True, return_counts=True
    )
    ids = np.zeros(movable.shape, np.int64)
    ids[movable] = inverse.ravel() + 1
    alphas = _label_values(keys)
    return alphas, ids, areas.astype(np.int64), ndimage.find_objects(ids, max_label=len(keys))


def _expand(exemplars, reference, labels, movable, crop, region, alpha, smoothness):
    """One alpha-expansion move over ``region`` (inside ``crop``), labels updated in place;
    the pixels that took ``alpha`` (in the crop), or None."""
    import maxflow  # deferred: start-up: only the copy's seams need it

    from imagemap.core import kernels  # deferred: start-up (numba)

    label_e, label_y, label_x = labels
    rows, columns = crop
    packed, shapes, inside = exemplars
    node, cost0, cost1, first, second, capacity = kernels.expansion_terms(
        packed,
        shapes,
        inside,
        reference,
        label_e,
        label_y,
        label_x,
        movable,
        region,
        rows.start,
        columns.start,
        alpha,
        float(smoothness),
        _SEAM_FLOOR,
    )
    n = len(cost0)
    if n == 0:
        return None
    graph = maxflow.Graph[float](n, len(first))
    nodes = graph.add_nodes(n)
    graph.add_edges(first, second, capacity, np.zeros_like(capacity))
    low = np.minimum(cost0, cost1)
    # A node ends on the sink side (takes alpha) by cutting its source edge: cost1.
    graph.add_grid_tedges(nodes, cost1 - low, cost0 - low)
    graph.maxflow()
    takes = graph.get_grid_segments(nodes)
    if not takes.any():
        return None
    free = node >= 0
    moved = np.zeros(node.shape, bool)
    moved[free] = takes[node[free]]
    label_e[rows, columns][moved] = alpha[0]
    label_y[rows, columns][moved] = alpha[1]
    label_x[rows, columns][moved] = alpha[2]
    return moved


def _packed(exemplars):
    """The exemplars in one zero-padded float32 array, and their (height, width)."""
    n_channels = exemplars[0].shape[2]
    heights = [e.shape[0] for e in exemplars]
    widths = [e.shape[1] for e in exemplars]
    packed = np.zeros((len(exemplars), max(heights), max(widths), n_channels), np.float32)
    for k, exemplar in enumerate(exemplars):
        packed[k, : exemplar.shape[0], : exemplar.shape[1]] = exemplar
    return packed, np.array([heights, widths], dtype=np.int64).T.copy()
