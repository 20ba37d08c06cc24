"""The copy's seams, placed by graph cuts: :func:`place_seams`.

The labels of a copy (exemplar and offset per pixel) are chosen again by
alpha-expansion (Boykov, Veksler & Zabih 2001) on Kwatra et al.'s seam cost (2003,
"Graphcut textures"), each move one minimum cut (Boykov & Kolmogorov's max-flow in numba,
:func:`imagemap.core.flow.grid_cut`); the terms of a move are a numba kernel
(:func:`imagemap.core.kernels.expansion_terms`). The seams left are
blended by :func:`imagemap.core.poisson.seamless_copy`.

One module for one job: one solve (the full one and its coarse-to-fine form share the
move loop, the terms and the cost bookkeeping, so they stay together).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from scipy import ndimage

__all__ = ["place_seams", "with_channels"]


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
    coarse_above: int | None = None,
    band: int = 4,
    weights: np.ndarray | None = None,
    exemplar_channels: list[list[tuple[float, np.ndarray | None]]] | None = None,
) -> np.ndarray:
    """A source map with fewer, cheaper seams, placed where the sources agree.

    Every pixel's source is an exemplar and an offset: a *label*. The labels are
    chosen again, among those the map already uses, to minimise the squared
    distance of each copied colour to ``reference`` plus ``smoothness`` times the
    seam costs: zero between equal labels, else the two sources' colour gap on both
    pixels (Kwatra et al. 2003, "Graphcut textures"). The minimisation is Boykov,
    Veksler & Zabih's alpha-expansion (2001): each label in turn, largest first, may
    take over any set of pixels near where it is used (``spread``), chosen by one
    minimum cut (Boykov & Kolmogorov 2004, :mod:`imagemap.core.flow`). Unlike
    pixel-by-pixel moves, a whole fragment can give way to its neighbour's copy at
    once, so a few large copies replace many small ones and the boundaries between
    them run where they show the same colours.
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
    coarse_above : int, optional
        Above this many pixels the labelling is solved coarse to fine (Lombaert et al.
        2005, "A multilevel banded graph cuts method"): on the grid of 2x2 blocks
        (each block's most common label, the exemplars block-averaged in the block's
        phase, so that every coarse label is one fine label), recursively, then at
        full resolution only within ``band`` pixels of the coarse seams, every other
        label fixed. Default: always at full resolution.
    band : int
        Half-width, in pixels, of the band around the upsampled seams that is solved
        again at each finer level (with ``coarse_above``).
    weights : ndarray, (H, W), optional
        Per pixel, a factor on ``smoothness``: a seam between two pixels costs the mean
        of their two factors times as much (default: 1 everywhere). Where a seam should
        be cheaper (say, where the voted map follows the query's own relief rather than
        one copy), the copies stay smaller there.
    exemplar_channels : list of lists of (scale, values), optional
        More channels of each exemplar, after its own (``reference`` has them all):
        ``scale * values`` (values (H_e, W_e)) or, with values None, the constant
        ``scale`` (:func:`with_channels`). They are added once the exemplars are cut to
        what the labels can read: the full-size exemplars with them are never made.

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
    # Each level of the coarse-to-fine form holds its own copy of the exemplars (block-
    # averaged), and every solve packs them into one array: only the part the labels can
    # read is kept, as views (no copy): an example no pixel copies is dropped, and a large
    # example is cut to its object (the labelling's costs are unchanged, :func:`_crops`).
    corners, exemplars, exemplar_masks = _crops(exemplars, exemplar_masks, source, mask)
    if exemplar_channels is not None:
        exemplars = [
            with_channels(
                crop, [(scale, _crop_like(values, crop, corner)) for scale, values in planes]
            )
            for crop, corner, planes in zip(exemplars, corners, exemplar_channels, strict=True)
        ]
    if coarse_above is not None and source.shape[0] * source.shape[1] > coarse_above:
        placed = _coarse_to_fine(
            exemplars,
            _shifted(source, -corners),  # handed over: freed there once the band is known
            reference,
            smoothness=smoothness,
            spread=spread,
            sweeps=sweeps,
            mask=mask,
            exemplar_masks=exemplar_masks,
            groups=groups,
            coarse_above=coarse_above,
            band=band,
            weights=weights,
        )
    else:
        placed = _solve(
            exemplars,
            _shifted(source, -corners),  # handed over: freed there once the labels are made
            reference,
            smoothness,
            spread,
            sweeps,
            mask,
            exemplar_masks,
            groups,
            weights=weights,
        )
    return _shifted(placed, corners)


def with_channels(values: np.ndarray, planes: list[tuple[float, np.ndarray | None]]) -> np.ndarray:
    """``values`` (H, W, C) with one more channel per plane, ``(scale, plane)``: ``scale *
    plane`` ((H, W)) or, with plane None, the constant ``scale``; float32, as
    ``np.concatenate`` of them would be, in one allocation (no copy per channel added).

    Examples
    --------
    >>> out = with_channels(np.zeros((2, 3, 3), np.float32), [(2.0, np.ones((2, 3))), (0.5, None)])
    >>> out.shape, out[0, 0].tolist()
    ((2, 3, 5), [0.0, 0.0, 0.0, 2.0, 0.5])
    """
    own = values.shape[2]
    out = np.empty(values.shape[:2] + (own + len(planes),), np.float32)
    out[..., :own] = values
    for index, (scale, plane) in enumerate(planes):
        out[..., own + index] = scale if plane is None else scale * plane
    return out


def _crop_like(values, crop, corner):
    """``values`` (an exemplar's (H_e, W_e) plane, or None) cut as ``crop`` was, from
    ``corner``."""
    if values is None:
        return None
    y0, x0 = int(corner[0]), int(corner[1])
    return values[y0 : y0 + crop.shape[0], x0 : x0 + crop.shape[1]]


#: Margin in pixels kept around what the labels read of each exemplar (:func:`_crops`):
#: a neighbour's label is read one pixel from its sources, and on the coarse grid a
#: block's label at its other pixels (up to 2^levels - 1 pixels from them).
_CROP_MARGIN = 8


def _crops(exemplars, exemplar_masks, source, mask):
    """Each exemplar cut to what a labelling can read: the box around the sources of
    the movable pixels and, as a pixel only takes a new label whose source lies inside
    the exemplar's object, around that object, plus ``_CROP_MARGIN``; empty where no
    movable pixel copies the exemplar (its labels are not in use, so never read).
    Reads past the box would lie outside the exemplar before too (the box is cut from
    it), so the labelling's costs are unchanged.

    Returns
    -------
    corners : ndarray of int, (n, 2)
        Each crop's top-left corner in its exemplar.
    exemplars, exemplar_masks : lists of views (masks None if not given)
    """
    label_e = source[..., 0]
    movable = _movable(label_e, mask)
    corners = np.zeros((len(exemplars), 2), np.int64)
    crops, crop_masks = [], []
    for k, exemplar in enumerate(exemplars):
        height, width = exemplar.shape[:2]
        copied = movable & (label_e == k)
        if not copied.any():
            crops.append(exemplar[:0, :0])
            crop_masks.append(None if exemplar_masks is None else exemplar_masks[k][:0, :0])
            continue
        ys, xs = source[..., 1][copied], source[..., 2][copied]
        box = [ys.min(), ys.max(), xs.min(), xs.max()]
        if exemplar_masks is None:
            box = [0, height - 1, 0, width - 1]
        elif exemplar_masks[k].any():
            rows = np.flatnonzero(exemplar_masks[k].any(axis=1))
            columns = np.flatnonzero(exemplar_masks[k].any(axis=0))
            box = [
                min(box[0], rows[0]),
                max(box[1], rows[-1]),
                min(box[2], columns[0]),
                max(box[3], columns[-1]),
            ]
        y0, x0 = max(int(box[0]) - _CROP_MARGIN, 0), max(int(box[2]) - _CROP_MARGIN, 0)
        y1 = min(max(int(box[1]) + _CROP_MARGIN + 1, y0), height)
        x1 = min(max(int(box[3]) + _CROP_MARGIN + 1, x0), width)
        corners[k] = y0, x0
        crops.append(exemplar[y0:y1, x0:x1])
        crop_masks.append(None if exemplar_masks is None else exemplar_masks[k][y0:y1, x0:x1])
    return corners, crops, None if exemplar_masks is None else crop_masks


def _shifted(source, corners):
    """The source map with each exemplar's positions moved by its ``corners`` row (one
    gather from a table whose last row, no shift, is the one of label -1: no pass to mask
    the pixels without a source, 7 ms instead of 12 at 512^2)."""
    table = np.zeros((len(corners) + 1, 2), source.dtype)
    table[:-1] = corners
    moved = source.copy()
    moved[..., 1:] += table[np.maximum(source[..., 0], -1)]
    return moved


def _solve(
    exemplars,
    source,
    reference,
    smoothness,
    spread,
    sweeps,
    mask,
    exemplar_masks,
    groups,
    free=None,
    weights=None,
):
    """:func:`place_seams` at full resolution; with ``free`` (bool, (H, W)) only those
    pixels may change (the others are fixed, their seams with the free pixels weighed)."""
    packed, shapes = _packed(exemplars)
    inside = np.zeros(packed.shape[:3], bool)
    for k, exemplar in enumerate(exemplars):
        inside[k, : exemplar.shape[0], : exemplar.shape[1]] = (
            True if exemplar_masks is None else exemplar_masks[k]
        )
    from imagemap.core import kernels  # deferred: start-up (numba)

    height, width = source.shape[:2]
    yy, xx = np.ogrid[0:height, 0:width]
    # int32 labels (a source map's own type; offsets and indices < 2^31): the move's
    # kernel widens them as it reads them, and three int64 maps would be 24 bytes a pixel.
    label_e = source[..., 0].astype(np.int32)
    label_y = (source[..., 1] - yy).astype(np.int32)
    label_x = (source[..., 2] - xx).astype(np.int32)
    del source  # the labels are all it was needed for (freed where it was handed over)
    movable = _movable(label_e, mask)
    # The labels that may move: with a band, only those of its pixels (a label outside
    # it has nowhere to go), and their areas there set each move's reach.
    held = movable if free is None else movable & free
    reference = np.ascontiguousarray(reference, dtype=np.float32)
    weights = (
        np.ones((height, width), np.float32)
        if weights is None
        else np.ascontiguousarray(weights, dtype=np.float32)
    )
    moves = _Moves(
        (packed, shapes, inside),
        reference,
        (label_e, label_y, label_x),
        (movable, held, free, groups),
        smoothness,
        spread,
        weights,
    )
    for _ in range(sweeps):
        moves.sweep(paired=kernels.n_threads() >= 2)
    del moves, held
    # Written into the int32 map a channel at a time: no (H, W, 3) int64 stack beside it.
    placed = np.empty((height, width, 3), np.int32)
    placed[..., 0] = label_e
    placed[..., 1] = label_y
    placed[..., 1] += yy
    placed[..., 2] = label_x
    placed[..., 2] += xx
    return placed


class _Moves:
    """The alpha-expansion moves of one solve (:func:`_solve`), sweep by sweep, on its
    labels (label_e, label_y, label_x, changed in place).

    Each label in turn, largest first, may take over the pixels of its move's region: those
    within its reach (``spread`` times the square root of its area) of its pixels. A
    label's move is not repeated while nothing in or around its crop has changed since its
    last move (it would find the same cut), unless that move spread it: kept are the move
    after which each pixel last changed (``changed_at``) and each label's last move.

    Two moves run at once (each move's kernels release the GIL) where the second is the
    next one due and the crops are more than a pixel apart (:func:`_apart`): neither reads
    what the other writes, so the pair finds what the two moves in turn find, and their
    cuts are applied in turn, numbered in turn.
    """

    def __init__(self, exemplars, reference, labels, masks, smoothness, spread, weights):
        self.exemplars, self.reference, self.labels = exemplars, reference, labels
        self.movable, self.held, self.free, self.groups = masks
        self.smoothness, self.spread, self.weights = smoothness, spread, weights
        self.height, self.width = labels[0].shape
        # Each pixel's data cost of its own label, 0 until a move's terms gather it, and
        # again where a cut changes the label: not gathered again at every move. Zeros, so
        # that the pages no move reaches are never written (the band's solve at 4096^2).
        self.data_now = np.zeros((self.height, self.width))
        self.changed_at = np.zeros((self.height, self.width), np.int32)  # moves: < 2^31
        self.expanded_at: dict[tuple[int, ...], int] = {}
        self.count = 0  # moves made

    def sweep(self, paired):
        """One pass over the labels in use, largest first (ties in label order); with
        ``paired``, independent moves two at a time."""
        label_e, label_y, label_x = self.labels
        self.alphas, self.ids, self.areas, self.boxes = _label_table(
            label_e, label_y, label_x, self.held
        )
        self.in_groups = _group_labels(label_e, label_y, label_x, self.groups, self.held)
        order = np.argsort(-self.areas, kind="stable")
        position = 0
        ahead = None  # the next move due (crop, move), planned as a partner and not taken
        while position < len(order):
            if ahead is None:
                crop = self._crop(order[position])
                move = None if crop is None else self._planned(order[position], crop)
            else:
                (crop, move), ahead = ahead, None
            position += 1
            if move is None:
                continue
            # The next move due, if it can run beside this one: the labels passed over on
            # the way are passed over in turn too (this move changes nothing they read).
            partner, scan = None, position
            while paired and scan < len(order):
                other = self._crop(order[scan])
                if other is not None and not _apart(crop, other):
                    break
                partner = None if other is None else self._planned(order[scan], other)
                scan += 1
                if partner is not None:
                    if min(move[3].sum(), partner[3].sum()) < _PAIRED_PIXELS:
                        # not worth a hand-over: in turn, next, as planned (this move
                        # changes nothing its plan read); not planned again (a quarter of
                        # the plans at 512^2, each a maximum filter over its crop)
                        ahead, partner, position = (other, partner), None, scan - 1
                    break
            if partner is None:  # alone: a large one's cut is shared with the side thread
                self._apply(move, self._cut(move, _side_thread() if paired else None))
                continue
            position = scan
            beside = _side_thread().submit(self._cut, move)
            second = self._cut(partner)
            self._apply(move, beside.result())
            self._apply(partner, second)
        del self.ids  # (H, W) int32: rebuilt by the next sweep

    def _crop(self, k):
        """Label k's move's crop (rows, columns) and reach, or None where the label has
        no pixel left (taken over by the others' moves)."""
        if self.areas[k] == 0:
            return None
        # The boxes are from the start of the sweep: a label only ever loses pixels to
        # the others' moves, so its box still holds it.
        reach = int(np.ceil(self.spread * np.sqrt(self.areas[k])))
        box_rows, box_columns = self.boxes[k]
        rows = slice(max(box_rows.start - reach, 0), min(box_rows.stop + reach, self.height))
        columns = slice(
            max(box_columns.start - reach, 0), min(box_columns.stop + reach, self.width)
        )
        return rows, columns, reach

    def _planned(self, k, crop):
        """Label k's move (k, its key, crop and region), or None where it is not
        repeated."""
        rows, columns, reach = crop
        key = tuple(int(v) for v in self.alphas[k])
        around = self.changed_at[
            max(rows.start - 1, 0) : rows.stop + 1, max(columns.start - 1, 0) : columns.stop + 1
        ]
        if key in self.expanded_at and around.max() <= self.expanded_at[key]:
            return None
        region = ndimage.maximum_filter(self.ids[rows, columns] == k + 1, size=2 * reach + 1)
        if self.free is not None:
            region &= self.free[rows, columns]
        if self.groups is not None:  # a group's pixels only take its own labels
            grouped = self.groups[rows, columns]
            region &= (grouped == 0) | np.isin(grouped, self.in_groups.get(key, ()))
        return k, key, (rows, columns), region

    def _cut(self, move, beside=None):
        """:func:`_expand` of a planned move (reads the labels, writes nothing)."""
        k, _, crop, region = move
        return _expand(
            self.exemplars,
            self.reference,
            self.labels,
            self.movable,
            crop,
            region,
            self.alphas[k],
            self.smoothness,
            self.weights,
            self.data_now,
            beside,
        )

    def _apply(self, move, cut):
        """A move's cut written into the labels, as the next move made."""
        from imagemap.core import kernels  # deferred: start-up (numba)

        k, key, (rows, columns), _ = move
        self.count += 1
        if cut is None:
            self.expanded_at[key] = self.count
            return
        # it spread: its next move reaches further
        self.expanded_at[key] = self.count - 1
        node, takes = cut
        lost = np.zeros(len(self.areas), np.int64)
        self.areas[k] += kernels.expansion_apply(
            node,
            takes,
            self.labels,
            self.ids,
            self.changed_at,
            self.data_now,
            rows.start,
            columns.start,
            self.alphas[k],
            k + 1,
            self.count,
            lost,
        )
        self.areas -= lost


def _apart(crop, other):
    """Whether two moves' crops ((rows, columns, reach)) are more than a pixel apart: a
    move writes labels only in its crop and reads them in its crop and one pixel around."""
    (rows, columns, _), (other_rows, other_columns, _) = crop, other
    return (
        rows.stop < other_rows.start
        or other_rows.stop < rows.start
        or columns.stop < other_columns.start
        or other_columns.stop < columns.start
    )


_SIDE_THREADS: dict[int, ThreadPoolExecutor] = {}


def _side_thread() -> ThreadPoolExecutor:
    """One thread of the process's own for the first move of a pair (not the kernels'
    pool: a solve called from one of its threads would wait on itself)."""
    pool = _SIDE_THREADS.get(os.getpid())  # per process: a forked child has no threads
    if pool is None:
        pool = _SIDE_THREADS[os.getpid()] = ThreadPoolExecutor(1, thread_name_prefix="seams")
    return pool


def _coarse_to_fine(
    exemplars,
    source,
    reference,
    *,
    smoothness,
    spread,
    sweeps,
    mask,
    exemplar_masks,
    groups,
    coarse_above,
    band,
    weights=None,
):
    """:func:`place_seams` solved on 2x2 blocks (recursively), then at full resolution in
    a band of ``band`` pixels around the seams the blocks left (Lombaert et al. 2005).

    A block's label is its pixels' most common one, offset (dy, dx) = 2 (DY, DX) +
    (py, px): on the coarse grid it is the label (4 e + 2 py + px, DY, DX) of the
    exemplar e block-averaged from row py, column px on (its *phase*), whose pixel at a
    block's coarse position plus (DY, DX) is the mean of the block's four fine sources.
    So every coarse label is exactly one fine label and the coarse copy shows the fine
    copy's colours, averaged. Blocks with a pixel that may not move (outside the object
    or ``mask``) are left out of the coarse solve and their movable pixels given to the
    band. The weight of the seams is halved on the coarse grid: a block's data cost
    stands for four pixels', a seam between blocks for two pixel pairs' (and the
    per-size weight of :func:`imagemap.depth.finish` halves with the object's size).
    """
    height, width = source.shape[:2]
    movable = _movable(source[..., 0], mask)
    yy, xx = np.ogrid[0:height, 0:width]
    keys = _key_map(source, movable)
    # Odd sizes: one row / column of padding, never movable (its pixels keep theirs).
    pad = ((0, height % 2), (0, width % 2))
    keys = np.pad(keys, pad, constant_values=-1)
    blocks = _blocks(keys)  # (H2, W2, 4)
    covered = (blocks >= 0).all(axis=-1)
    # The most common label of each block (the first of a tie, in raster order): counts
    # by comparing the four keys pairwise.
    counts = (blocks[..., :, None] == blocks[..., None, :]).sum(axis=-1)
    common = np.take_along_axis(blocks, counts.argmax(axis=-1)[..., None], axis=-1)[..., 0]
    e, dy, dx = _label_values(np.where(covered, common, 0).ravel()).T.reshape(3, *covered.shape)
    coarse_height, coarse_width = covered.shape
    rows, columns = np.ogrid[0:coarse_height, 0:coarse_width]
    coarse_source = np.stack(
        [np.where(covered, 4 * e + 2 * (dy % 2) + dx % 2, -1), rows + dy // 2, columns + dx // 2],
        axis=-1,
    )
    # The blocks' keys and counts (16 bytes a fine pixel) are not held through the coarse
    # and the fine solves below, where the stage's peak is.
    del keys, blocks, counts, common, e, dy, dx
    # Only the phases some block uses are averaged (a label never used at the start
    # never is); the others are empty, so that the labels keep their numbers.
    used = np.zeros(4 * len(exemplars), bool)
    used[coarse_source[..., 0][covered]] = True
    phases, phase_masks = [], []
    for k, exemplar in enumerate(exemplars):
        for py in (0, 1):
            for px in (0, 1):
                if not used[4 * k + 2 * py + px]:
                    phases.append(np.zeros((0, 0, exemplar.shape[2]), np.float32))
                    phase_masks.append(np.zeros((0, 0), bool))
                    continue
                phases.append(_block_mean(exemplar[py:, px:]))
                if exemplar_masks is not None:  # a block is inside where its 4 pixels are
                    phase_masks.append(_blocks(_even(exemplar_masks[k][py:, px:])).all(axis=2))
    coarse_reference = _block_mean(np.pad(reference, pad + ((0, 0),), mode="edge"))
    coarse_groups = None if groups is None else _blocks(np.pad(groups, pad)).max(axis=2)
    coarse_weights = (
        None
        if weights is None
        else _block_mean(np.pad(weights, pad, mode="edge")[..., None])[..., 0]
    )
    coarse = place_seams(
        phases,
        coarse_source,
        coarse_reference,
        smoothness=smoothness / 2.0,
        spread=spread,
        sweeps=sweeps,
        mask=covered,
        exemplar_masks=phase_masks if exemplar_masks is not None else None,
        groups=coarse_groups,
        coarse_above=coarse_above,
        band=band,
        weights=coarse_weights,
    )
    del phases, phase_masks, coarse_reference, coarse_source, coarse_groups, coarse_weights
    # Back to fine labels: phase p of exemplar e is label 4 e + p.
    phase = coarse[..., 0] % 4
    fine_e = coarse[..., 0] // 4
    fine_dy = 2 * (coarse[..., 1] - rows) + phase // 2
    fine_dx = 2 * (coarse[..., 2] - columns) + phase % 2
    up = np.ones((2, 2), bool)
    taken = np.kron(covered, up)[:height, :width]

    def _up(values):
        return np.repeat(np.repeat(values, 2, axis=0), 2, axis=1)[:height, :width]

    fine = source.astype(np.int32, copy=True)
    fine[..., 0][taken] = _up(fine_e)[taken]
    fine[..., 1][taken] = (_up(fine_dy) + yy)[taken]
    fine[..., 2][taken] = (_up(fine_dx) + xx)[taken]
    del coarse, phase, fine_e, fine_dy, fine_dx
    # A block's label reaches all its pixels; where it reads past the exemplar's object
    # at a pixel whose own label it was not (the full solve only ever gives a pixel a
    # new label that reads inside), the pixel keeps its own and is solved in the band.
    own = (fine == source).all(axis=-1)
    lost = taken & ~own & ~_reads_inside(exemplars, exemplar_masks, fine)
    fine[lost] = source[lost]
    del source  # (H, W, 3) int32: not held through the fine solve (place_seams hands it over)
    taken &= ~lost
    # The band: every pixel within ``band`` (Chebyshev) of a seam between movable
    # pixels or of a movable pixel the coarse grid left out.
    keys = _key_map(fine, movable)
    seeds = movable & ~taken
    across = (keys[1:] != keys[:-1]) & movable[1:] & movable[:-1]
    seeds[1:] |= across
    seeds[:-1] |= across
    across = (keys[:, 1:] != keys[:, :-1]) & movable[:, 1:] & movable[:, :-1]
    seeds[:, 1:] |= across
    seeds[:, :-1] |= across
    del keys, across
    free = ndimage.maximum_filter(seeds, size=2 * band + 1) & movable
    del seeds, own, lost, taken, covered, movable
    handed = [fine]  # the fine labels' only reference goes to _solve (it frees them)
    del fine
    return _solve(
        exemplars,
        handed.pop(),
        reference,
        smoothness,
        spread,
        sweeps,
        mask,
        exemplar_masks,
        groups,
        free,
        weights,
    )


def _reads_inside(exemplars, exemplar_masks, source):
    """Whether each pixel's source lies inside its exemplar (and its object), (H, W)."""
    label_e, ys, xs = source[..., 0], source[..., 1], source[..., 2]
    inside = np.zeros(label_e.shape, bool)
    for k, exemplar in enumerate(exemplars):
        height, width = exemplar.shape[:2]
        at = (label_e == k) & (ys >= 0) & (xs >= 0) & (ys < height) & (xs < width)
        inside[at] = True if exemplar_masks is None else exemplar_masks[k][ys[at], xs[at]]
    return inside


def _blocks(values):
    """The 2x2 blocks of an (H, W, ...) array of even H and W, as (H / 2, W / 2, 4, ...)."""
    height, width = values.shape[:2]
    rest = values.shape[2:]
    split = values.reshape(height // 2, 2, width // 2, 2, *rest).swapaxes(1, 2)
    return split.reshape(height // 2, width // 2, 4, *rest)


def _block_mean(values):
    """The float32 means of the 2x2 blocks of an (H, W, C) array (a last odd row or
    column dropped): four strided sums, not a reshaped copy of the whole array."""
    values = _even(values)
    total = values[0::2, 0::2].astype(np.float32)
    total += values[1::2, 0::2]
    total += values[0::2, 1::2]
    total += values[1::2, 1::2]
    total *= 0.25
    return total


def _even(values):
    """The array cropped to an even number of rows and columns."""
    return values[: values.shape[0] // 2 * 2, : values.shape[1] // 2 * 2]


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


def _movable(label_e, mask):
    """The pixels whose label may change: copied (label >= 0) and inside ``mask``."""
    return label_e >= 0 if mask is None else np.asarray(mask, bool) & (label_e >= 0)


def _key_map(source, movable):
    """(H, W) :func:`_label_keys` of a source map's labels at ``movable``, -1 elsewhere."""
    height, width = source.shape[:2]
    yy, xx = np.ogrid[0:height, 0:width]
    keys = np.full((height, width), -1, np.int64)
    keys[movable] = _label_keys(
        source[..., 0].astype(np.int64),
        (source[..., 1] - yy).astype(np.int64),
        (source[..., 2] - xx).astype(np.int64),
        movable,
    )
    return keys


def _label_keys(label_e, label_y, label_x, where):
    """One integer per label of the pixels ``where``: offsets fit in 20 bits whatever the
    image size (< 2^19 px)."""
    key = (label_e[where].astype(np.int64, copy=False) << 40) | (
        (label_y[where].astype(np.int64, copy=False) + (1 << 19)) << 20
    )
    return key | (label_x[where].astype(np.int64, copy=False) + (1 << 19))


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
    ids = np.zeros(movable.shape, np.int32)  # label numbers: far below 2^31
    ids[movable] = inverse.ravel() + 1
    alphas = _label_values(keys)
    return alphas, ids, areas.astype(np.int64), ndimage.find_objects(ids, max_label=len(keys))


#: Moves of this many nodes or more are cut in halves, then whole
#: (:func:`imagemap.core.flow.grid_cut_halved`), the halves on two threads where the
#: second is free (with one thread in turn: the same floats at any thread count): below it
#: the hand-over and the last pass over the whole graph cost more than half a move saves
#: (at 512^2, 30 of a call's ~97 moves, 82 % of its nodes).
_HALVED_NODES = 10_000
#: Two moves run at once only where both regions have this many pixels: a hand-over to
#: the side thread costs milliseconds on a busy machine, more than a small move.
_PAIRED_PIXELS = 5_000


def _expand(
    exemplars,
    reference,
    labels,
    movable,
    crop,
    region,
    alpha,
    smoothness,
    weights,
    data_now,
    beside=None,
):
    """One alpha-expansion move over ``region`` (inside ``crop``): its nodes' numbers in
    the crop and whether each takes ``alpha`` (for :func:`imagemap.core.kernels.
    expansion_apply`), or None where none does. The terms and the minimum cut are numba
    kernels (:func:`imagemap.core.flow.grid_cut`), run without the GIL; a large move's
    cut is in halves, on ``beside``'s thread too where given (an idle executor).
    ``data_now`` (H, W): each pixel's data cost of its own label where known, kept
    between moves (:func:`imagemap.core.kernels.expansion_terms`)."""
    from imagemap.core import flow, kernels  # deferred: start-up (numba)

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
        weights,
        data_now,
    )
    if len(cost0) == 0:
        return None
    if len(cost0) >= _HALVED_NODES:
        takes, _ = flow.grid_cut_halved(node, cost0, cost1, first, second, capacity, beside)
    else:
        takes, _ = flow.grid_cut(node, cost0, cost1, first, second, capacity)
    if not takes.any():
        return None
    return node, takes


def _packed(exemplars):
    """The exemplars in one zero-padded float32 array, and their (height, width)."""
    n_channels = exemplars[0].shape[2]
    heights = [e.shape[0] for e in exemplars]
    widths = [e.shape[1] for e in exemplars]
    packed = np.zeros((len(exemplars), max(heights), max(widths), n_channels), np.float32)
    for k, exemplar in enumerate(exemplars):
        packed[k, : exemplar.shape[0], : exemplar.shape[1]] = exemplar
    return packed, np.array([heights, widths], dtype=np.int64).T.copy()
