"""Seamless copying: exemplar pixels copied through a source map, seams blended.

A map whose every pixel is copied from an exemplar pixel keeps the exemplars'
detail (eyes, stripes, edges) exactly where the source map is coherent, and
shows hard seams where two sources meet. :func:`seamless_copy` keeps the
copy's gradients inside coherent regions and takes the gradients of a smooth
reference (the voted result) across seams, then solves the screened Poisson
equation that also holds the result near the reference at large scales
(gradient-domain blending, Pérez, Gangnet & Blake 2003, "Poisson image
editing"). It is one DCT solve per channel: O(N log N), no iterations.

Examples
--------
The left half copied from a dark exemplar, the right half from a bright one,
both with the same texture: the step between the palettes is spread out, the
texture kept.

>>> rng = np.random.default_rng(0)
>>> texture = 0.05 * rng.standard_normal((32, 32, 1))
>>> dark, bright = texture + 0.2, texture + 0.8
>>> source = np.zeros((32, 32, 3), np.int32)
>>> source[..., 1], source[..., 2] = np.mgrid[0:32, 0:32]
>>> source[:, 16:, 0] = 1
>>> out = seamless_copy([dark, bright], source, np.full((32, 32, 1), 0.5), scale=8.0)
>>> step = abs(out[:, 16, 0] - out[:, 15, 0]).mean()
>>> bool(step < 0.1)          # the 0.6 jump is gone
True
>>> detail = out[..., 0] - ndimage.uniform_filter(out[..., 0], 5)
>>> truth = texture[..., 0] - ndimage.uniform_filter(texture[..., 0], 5)
>>> bool(np.corrcoef(detail.ravel(), truth.ravel())[0, 1] > 0.95)
True
"""

from __future__ import annotations

import numpy as np
from scipy import fft, ndimage

__all__ = [
    "coherent_edges",
    "copy_through",
    "fill_background",
    "place_seams",
    "seamless_copy",
    "smooth_inside",
]


def fill_background(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Extend the object's values into the background (nearest object pixel).

    A window at the silhouette then carries object-like colours beyond the edge,
    so no background colour bleeds into a synthesised object.

    Examples
    --------
    >>> image = np.array([[0.0, 5.0, 7.0]]); fill_background(image, image > 0)
    array([[5., 5., 7.]])
    """
    ny, nx = ndimage.distance_transform_edt(~mask, return_distances=False, return_indices=True)
    return image[ny, nx]


def smooth_inside(values: np.ndarray, region: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian smoothing of ``values`` over ``region`` only (normalized convolution),
    0 outside it: what lies outside (the background past an outline, another part)
    does not bleed in. ``values`` is (H, W), or (H, W, C) smoothed per channel.

    Examples
    --------
    >>> values = np.array([[0.0, 4.0, 4.0, 9.0]])
    >>> smooth_inside(values, values == 4.0, 1.0)
    array([[0., 4., 4., 0.]])
    """
    region = np.asarray(region, bool)
    weight = ndimage.gaussian_filter(region.astype(np.float64), sigma)
    if values.ndim == region.ndim + 1:
        weight = weight[..., None]
        region = region[..., None]
        sigma = (sigma, sigma, 0.0)  # type: ignore[assignment]  # not across channels
    smooth = ndimage.gaussian_filter(np.where(region, values, 0.0), sigma)
    return np.where(region, smooth / np.maximum(weight, 1e-12), 0.0)


def coherent_edges(source: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where neighbouring pixels were copied from neighbouring exemplar pixels.

    Parameters
    ----------
    source : ndarray of int, (H, W, 3)
        Exemplar index, source y, source x per pixel (index < 0: no source).

    Returns
    -------
    horizontal : ndarray of bool, (H, W - 1)
        Pixel (y, x + 1) was copied from the right neighbour of the source of (y, x).
    vertical : ndarray of bool, (H - 1, W)
        Likewise downwards.
    """
    e, sy, sx = source[..., 0], source[..., 1], source[..., 2]
    valid = e >= 0
    horizontal = (
        valid[:, :-1]
        & (e[:, 1:] == e[:, :-1])
        & (sy[:, 1:] == sy[:, :-1])
        & (sx[:, 1:] == sx[:, :-1] + 1)
    )
    vertical = valid[:-1] & (e[1:] == e[:-1]) & (sy[1:] == sy[:-1] + 1) & (sx[1:] == sx[:-1])
    return horizontal, vertical


def copy_through(exemplars: list[np.ndarray], source: np.ndarray, dy: int = 0, dx: int = 0):
    """Each pixel the exemplar value at its source pixel shifted by (dy, dx) (clipped);
    0 where it has no source."""
    e, sy, sx = source[..., 0], source[..., 1] + dy, source[..., 2] + dx
    out = np.zeros(source.shape[:2] + exemplars[0].shape[2:], dtype=np.float64)
    for k, exemplar in enumerate(exemplars):
        here = e == k
        h, w = exemplar.shape[:2]
        out[here] = exemplar[np.clip(sy[here], 0, h - 1), np.clip(sx[here], 0, w - 1)]
    return out


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


def seamless_copy(
    exemplars: list[np.ndarray],
    source: np.ndarray,
    reference: np.ndarray,
    *,
    scale: float = 8.0,
    edge_support: float = 0.0,
    edge_contrast: float = 2.0,
    edge_floor: float = 0.05,
    mask: np.ndarray | None = None,
) -> np.ndarray:
    """Copy exemplar pixels through a source map, blending the seams in the gradient domain.

    Solves, per channel, for the image O minimising

        sum over neighbour pairs (O_q - O_p - g_pq)^2 + lam * sum_p (O_p - R_p)^2

    with lam = 1 / scale^2 and R the reference. The target difference g_pq is
    what the two pixels' own sources say about it: the difference between p's
    source pixel and its neighbour in p's exemplar, and likewise for q. Where p
    and q were copied coherently (neighbouring source pixels) both equal the
    copy's own difference, so the copy's detail is kept exactly; across a seam
    the stronger of the two is taken, so edges and stripes continue at full
    contrast, and only the colour offset between the sources is spread out, over
    about ``scale`` pixels, towards the reference's colour layout.

    With ``edge_support`` > 0, a seam between two pixels copied from the *same*
    exemplar keeps the copy's own step where that step is an edge (at least
    ``edge_contrast`` times as strong as either side's own gradient, and at
    least ``edge_floor``: smaller steps are shading) that the reference shows too
    (a change in the same direction, over the four pixels around the pair, of at
    least ``edge_support`` times the step). A part
    boundary that the copy put on a seam (a sleeve copied from one place ending
    where a hand copied from another begins) then stays one pixel sharp instead
    of being spread over ``scale`` pixels. A step between two exemplars is a
    palette difference and is always spread.

    Parameters
    ----------
    exemplars : list of ndarray, (H_e, W_e, C)
        The exemplars' bands (e.g. YCbCr images), indexed by ``source[..., 0]``.
    source : ndarray of int, (H, W, 3)
        Exemplar index, y, x of the pixel each output pixel copies (index < 0:
        none; the reference is kept there).
    reference : ndarray, (H, W, C)
        A seamless estimate of the result (the voted map) holding the large scales.
    scale : float
        Pixels over which the copy may drift towards the reference.
    edge_support : float
        Share of a same-exemplar seam's step the reference must show for the step
        to be kept (0: every seam blended).
    edge_contrast : float
        A seam's step is an edge only when it is at least this many times as strong
        as either side's own gradient (weaker steps are texture, continued by the
        stronger side).
    edge_floor : float
        ...and at least this large (norm of the step, in the bands' units: for YCbCr
        in [0, 1], 0.05 is about ΔE00 5 in luminance alone; smaller steps between two
        offsets of a smooth region are shading). The depth pipeline passes
        :class:`imagemap.depth.config.Finish`'s values, where their measurements are.
    mask : ndarray of bool, (H, W), optional
        The object. Across its outline the target difference is the reference's
        own step: the outline is not a seam to blend across, so colours copied
        beside the object (its margin) do not bleed into it.

    Returns
    -------
    ndarray, (H, W, C) float32
    """
    from imagemap.core.solver import (
        trim_heap as _trim_heap,
    )  # deferred: start-up: the solver loads the numba kernels

    _trim_heap()  # the caller's freed temporaries (seam placement): not kept resident
    reference = np.asarray(reference)
    if reference.ndim != 3 or source.shape[:2] != reference.shape[:2] or source.shape[2] != 3:
        raise ValueError(f"reference {reference.shape} and source {source.shape} do not fit")
    if scale <= 0:
        raise ValueError(f"scale must be positive, got {scale}")
    if not 0 <= edge_support <= 1:
        raise ValueError(f"edge_support must be in [0, 1], got {edge_support}")
    if edge_contrast < 0 or edge_floor < 0:
        raise ValueError(
            f"edge_contrast and edge_floor must be >= 0, got {edge_contrast}, {edge_floor}"
        )
    h, w, n_channels = reference.shape
    has = source[..., 0] >= 0
    none_x = ~(has[:, 1:] & has[:, :-1])
    none_y = ~(has[1:] & has[:-1])
    if mask is not None:  # the outline keeps the reference's step
        if mask.shape != (h, w):
            raise ValueError(f"mask {mask.shape} does not fit the reference {reference.shape}")
        none_x |= mask[:, 1:] != mask[:, :-1]
        none_y |= mask[1:] != mask[:-1]
    groups = _source_groups(exemplars, source)
    # One channel at a time (a third of the memory of all at once), and within a channel
    # one side's gradient at a time; the reference is made float64 a channel at a time.
    # Only the choice of the stronger gradient across a seam couples the channels (it
    # compares their summed squares), so a first pass sums those squares.
    norms = [np.zeros((h, w - 1)), np.zeros((h, w - 1)), np.zeros((h - 1, w)), np.zeros((h - 1, w))]
    for channel in range(n_channels):
        ref = reference[..., channel].astype(np.float64)
        for norm, difference in zip(norms, _side_gradients(groups, has, ref, channel), strict=True):
            norm += np.square(difference, out=difference)
        del difference
    right_wins = norms[0] >= norms[1]
    down_wins = norms[2] >= norms[3]
    strongest = None
    if edge_support > 0:  # the sides are chosen: each direction's stronger side, in place
        strongest = (
            np.maximum(norms[0], norms[1], out=norms[0]),
            np.maximum(norms[2], norms[3], out=norms[2]),
        )
    del norms
    edges = None
    if strongest is not None:
        edges = _supported_edges(
            groups,
            has,
            source,
            reference,
            edge_support,
            strongest,
            edge_contrast,
            edge_floor,
        )
    del strongest
    lam = 1.0 / scale**2
    # -L is diagonal in the DCT-II basis: eigenvalues (2 - 2cos(pi u / H)) + (2 - 2cos(pi v / W)).
    eig_y = 2.0 - 2.0 * np.cos(np.pi * np.arange(h) / h)
    eig_x = 2.0 - 2.0 * np.cos(np.pi * np.arange(w) / w)
    out = np.empty((h, w, n_channels), dtype=np.float32)
    for channel in range(n_channels):
        ref = reference[..., channel].astype(np.float64)
        gradients = _side_gradients(groups, has, ref, channel)
        # Each side's own exemplar gradient (equal where the copy is coherent); across a
        # seam the stronger of the two, so an edge or stripe that meets the seam goes on
        # at full contrast instead of an average of two unrelated textures.
        gx = next(gradients)
        np.copyto(gx, next(gradients), where=~right_wins)
        gy = next(gradients)
        np.copyto(gy, next(gradients), where=~down_wins)
        gradients.close()
        if edges is not None:  # the copy's own step across the supported edges
            copy = _copy_channel(groups, has, ref, channel)
            np.subtract(copy[:, 1:], copy[:, :-1], out=gx, where=edges[0])
            np.subtract(copy[1:], copy[:-1], out=gy, where=edges[1])
            del copy
        np.subtract(ref[:, 1:], ref[:, :-1], out=gx, where=none_x)
        np.subtract(ref[1:], ref[:-1], out=gy, where=none_y)
        # Normal equations: (lam - L) O = lam R + div g (L: Neumann graph Laplacian).
        rhs = np.multiply(lam, ref, out=ref)
        rhs[:, 1:] += gx
        rhs[:, :-1] -= gx
        rhs[1:] += gy
        rhs[:-1] -= gy
        del gx, gy
        spectrum = fft.dctn(rhs, type=2, axes=(0, 1), norm="ortho", overwrite_x=True)
        del rhs, ref
        for y0 in range(0, h, _ROWS):  # the denominator a block of rows at a time
            rows = slice(y0, y0 + _ROWS)
            spectrum[rows] /= lam + eig_y[rows, None] + eig_x[None, :]
        out[..., channel] = fft.idctn(spectrum, type=2, axes=(0, 1), norm="ortho", overwrite_x=True)
        del spectrum
    del groups
    _trim_heap()  # before the caller's colour conversion
    return out


_ROWS = 256  # rows per block of the DCT denominator


def _supported_edges(groups, has, source, reference, support, strongest, contrast, floor):
    """Horizontal and vertical neighbour pairs (see :func:`seamless_copy`) copied from the
    same exemplar whose copied step is an edge (``contrast`` times either side's own
    gradient and at least ``floor``) that the reference shows too.

    ``strongest``: per direction, the larger summed square of the two sides' own
    gradients. This runs on a large map's memory peak: float32 accumulators, one
    direction at a time (the copy is remade per direction rather than six
    accumulators kept)."""
    e = source[..., 0]
    pairs = []
    for axis in (1, 0):
        ahead, behind = _along(axis, slice(1, None)), _along(axis, slice(None, -1))
        terms = [np.zeros(e[ahead].shape, np.float32) for _ in range(3)]  # step.span, span², step²
        for channel in range(reference.shape[2]):
            ref = reference[..., channel]
            copy = _copy_channel(groups, has, ref.astype(np.float64), channel)
            step = np.subtract(copy[ahead], copy[behind], dtype=np.float32)
            del copy
            # The reference's change from the pixel before the pair to the one after it:
            # the voted map's edges are a few pixels wide.
            padded = np.pad(ref, [(1, 1) if a == axis else (0, 0) for a in (0, 1)], mode="edge")
            far, near = _along(axis, slice(3, None)), _along(axis, slice(None, -3))
            span = np.subtract(padded[far], padded[near], dtype=np.float32)
            del padded
            terms[0] += step * span
            terms[1] += np.square(span, out=span)
            terms[2] += np.square(step, out=step)
            del step, span
        dot, span2, step2 = terms
        keep = has[ahead] & has[behind] & (e[ahead] == e[behind]) & (dot > 0)
        keep &= span2 >= np.float32(support**2) * step2
        keep &= step2 >= np.float32(contrast**2) * strongest[1 - axis]
        keep &= step2 >= np.float32(floor**2)
        pairs.append(keep)
        del terms, dot, span2, step2
    return pairs[0], pairs[1]


def _along(axis: int, part: slice) -> tuple[slice, slice]:
    """The index of ``part`` along ``axis`` (0 or 1) of a 2-D array, all of the other."""
    return (part, slice(None)) if axis == 0 else (slice(None), part)


def _copy_channel(groups, has, ref, channel, dy=0, dx=0) -> np.ndarray:
    """One channel of :func:`copy_through` shifted by (dy, dx); ``ref`` (the reference's
    channel, float64) where no source.

    ``groups``: per exemplar, (exemplar, flat pixel indices, their source y and x)."""
    h, w = has.shape
    out = np.zeros(h * w, dtype=np.float32)
    for exemplar, pixels, sy, sx in groups:
        eh, ew = exemplar.shape[:2]
        out[pixels] = exemplar[np.clip(sy + dy, 0, eh - 1), np.clip(sx + dx, 0, ew - 1), channel]
    return np.where(has, out.reshape(h, w), ref)


def _source_groups(exemplars, source):
    """Per exemplar: (exemplar, flat indices of the pixels copied from it, source y, x)."""
    e = source[..., 0].ravel()
    groups = []
    for k, exemplar in enumerate(exemplars):
        pixels = np.flatnonzero(e == k).astype(np.int32)
        groups.append(
            (exemplar, pixels, source[..., 1].ravel()[pixels], source[..., 2].ravel()[pixels])
        )
    return groups


def _side_gradients(groups, has, ref, channel):
    """Per channel, one at a time (a generator: the caller frees each before the next is
    made): the horizontal gradient by the left pixel's source and by the right pixel's,
    then the vertical one by the upper and by the lower pixel's source."""
    copy = _copy_channel(groups, has, ref, channel)
    right = _copy_channel(groups, has, ref, channel, 0, 1)[:, :-1]
    yield np.subtract(right, copy[:, :-1], out=right)
    del right
    left = _copy_channel(groups, has, ref, channel, 0, -1)[:, 1:]
    yield np.subtract(copy[:, 1:], left, out=left)
    del left
    down = _copy_channel(groups, has, ref, channel, 1, 0)[:-1]
    yield np.subtract(down, copy[:-1], out=down)
    del down
    up = _copy_channel(groups, has, ref, channel, -1, 0)[1:]
    yield np.subtract(copy[1:], up, out=up)
