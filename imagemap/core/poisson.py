"""Seamless copying: exemplar pixels copied through a source map, seams blended.

A map whose every pixel is copied from an exemplar pixel keeps the exemplars'
detail (eyes, stripes, edges) exactly where the source map is coherent, and
shows hard seams where two sources meet. :func:`seamless_copy` keeps the
copy's gradients inside coherent regions and takes the gradients of a smooth
reference (the voted result) across seams, then solves the screened Poisson
equation that also holds the result near the reference at large scales
(gradient-domain blending, Pérez, Gangnet & Blake 2003, "Poisson image
editing"). It is one DCT solve per channel: O(N log N), no iterations. The seams
it blends are placed first by :mod:`imagemap.core.seams`.

Examples
--------
The left half copied from a dark exemplar, the right half from a bright one,
both with the same texture: the step between the palettes is spread out, the
texture kept.

>>> from scipy import ndimage
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
from scipy import fft

__all__ = ["seamless_copy"]


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
    out: np.ndarray | None = None,
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
    out : ndarray, (H, W, C) float32, optional
        Where to write the result: it may be ``reference`` itself (each channel of the
        reference is read before that channel is written), which saves the result's
        allocation on a large map's peak.

    Returns
    -------
    ndarray, (H, W, C) float32
        ``out`` when given.
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
    copies = _Copies(exemplars, source, reference)
    # One channel at a time (a third of the memory of all at once), and within a channel
    # one side's gradient at a time; the reference is made float64 a channel at a time.
    # Only the choice of the stronger gradient across a seam couples the channels (it
    # compares their summed squares), so a first pass sums those squares, one direction
    # at a time: two full-size float64 sums held, not four (each channel's copy is made
    # once per direction).
    wins, strongest = [], []
    for axis in (1, 0):
        shape = (h, w - 1) if axis == 1 else (h - 1, w)
        ahead, behind = np.zeros(shape), np.zeros(shape)
        for channel in range(n_channels):
            ref = reference[..., channel].astype(np.float64)
            sides = _side_gradients(copies, ref, channel, (axis,))
            del ref
            for norm in (ahead, behind):
                difference = next(sides)
                norm += np.square(difference, out=difference)
                # Freed before the next side's copy is made (a zip over the sides held
                # it until then: a full-size float64 array more at the blend's peak).
                del difference
            del sides
        wins.append(ahead >= behind)
        if edge_support > 0:  # the sides are chosen: the stronger side's sum, in place
            strongest.append(np.maximum(ahead, behind, out=ahead))
        del ahead, behind
    right_wins, down_wins = wins
    edges = None
    if strongest:
        edges = _supported_edges(
            copies,
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
    if out is None:
        out = np.empty((h, w, n_channels), dtype=np.float32)
    elif out.shape != reference.shape or out.dtype != np.float32:
        raise ValueError(f"out {out.shape} {out.dtype}: not float32 of the reference's shape")
    for channel in range(n_channels):
        ref = reference[..., channel].astype(np.float64)
        gradients = _side_gradients(copies, ref, channel)
        # Each side's own exemplar gradient (equal where the copy is coherent); across a
        # seam the stronger of the two, so an edge or stripe that meets the seam goes on
        # at full contrast instead of an average of two unrelated textures.
        gx = next(gradients)
        np.copyto(gx, next(gradients), where=~right_wins)
        gy = next(gradients)
        np.copyto(gy, next(gradients), where=~down_wins)
        gradients.close()
        if edges is not None:  # the copy's own step across the supported edges
            copy = copies(ref, channel)
            np.subtract(copy[:, 1:], copy[:, :-1], out=gx, where=edges[0])
            np.subtract(copy[1:], copy[:-1], out=gy, where=edges[1])
            del copy
        copies.drop(channel)
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
    del copies
    _trim_heap()  # before the caller's colour conversion
    return out


_ROWS = 256  # rows per block of the DCT denominator


def _supported_edges(copies, has, source, reference, support, strongest, contrast, floor):
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
            copy = copies(ref, channel)  # float64 from the float32
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


def _copy_channel(groups, ref, channel, dy=0, dx=0) -> np.ndarray:
    """One channel of :func:`copy_through` shifted by (dy, dx); ``ref`` (the reference's
    channel, any float type: the copy is float64) where no source.

    ``groups``: per exemplar, (exemplar, flat pixel indices, their source y and x)."""
    # The reference's values, then every pixel with a source its exemplar's: the pixels
    # of the groups are those with a source. Each source read from the exemplar's flat
    # values (one index per pixel: row, column, channel), not by three index arrays:
    # the same values, a quarter of the time. The indices are made as intp (np.take
    # converts any other to a whole intp copy), a piece of the group at a time.
    out = np.array(ref, dtype=np.float64, order="C")  # one copy, not a float64 one and its copy
    flat_out = out.reshape(-1)
    for exemplar, pixels, sy, sx in groups:
        eh, ew, channels = exemplar.shape
        flat = exemplar.reshape(-1)
        for start in range(0, len(pixels), _PIECE):
            piece = slice(start, start + _PIECE)
            index = sy[piece].astype(np.intp)
            index += dy
            np.clip(index, 0, eh - 1, out=index)  # clipped as copy_through: any source
            index *= ew
            index += np.clip(sx[piece] + dx, 0, ew - 1)
            index *= channels
            index += channel
            flat_out[pixels[piece]] = flat.take(index)
    return out


#: Pixels of a group read at a time by :func:`_copy_channel`: its temporaries (the intp
#: indices, the values) were whole groups, most of the frame, about two float64 frames
#: beside the blend's peak at 4096^2; a piece of 2^20 keeps them at 8 MB (the take's
#: own time per pixel is the same).
_PIECE = 2**20


#: Frames up to this many pixels (724 x 724) keep each channel's five shifted copies
#: through the blend once gathered (60 bytes a pixel for three float32 channels: 14 MB at
#: the 512^2 fish's 459 x 509 frame, 31 MB at most): 15 gathers instead of 42, each a
#: full-size float64 copy of the reference and a take per exemplar (about half the
#: blend's time at 512^2). Larger frames gather again: the blend is the 4096^2 peak.
KEEP_COPIES_PIXELS = 2**19


class _Copies:
    """:func:`_copy_channel` of one blend's exemplars and source map: ``copies(ref,
    channel, dy, dx)``, ``ref`` always the reference's own ``channel`` (any float type: the
    same float64 values), a new float64 array each call. On frames up to
    :data:`KEEP_COPIES_PIXELS` each is gathered once and kept in the inputs' type (float32
    when the exemplars and the reference are: the copied values are theirs, the same
    values), until :meth:`drop`."""

    def __init__(self, exemplars, source, reference) -> None:
        self.groups = _source_groups(exemplars, source)
        height, width = source.shape[:2]
        self.kept: dict[tuple[int, int, int], np.ndarray] | None = (
            {} if height * width <= KEEP_COPIES_PIXELS else None
        )
        dtypes = {np.dtype(reference.dtype), *(np.dtype(e.dtype) for e in exemplars)}
        self.dtype = np.float32 if dtypes == {np.dtype(np.float32)} else np.float64

    def __call__(self, ref, channel: int, dy: int = 0, dx: int = 0) -> np.ndarray:
        if self.kept is None:
            return _copy_channel(self.groups, ref, channel, dy, dx)
        kept = self.kept.get((channel, dy, dx))
        if kept is not None:
            return kept.astype(np.float64)
        copy = _copy_channel(self.groups, ref, channel, dy, dx)
        self.kept[(channel, dy, dx)] = copy.astype(self.dtype)
        return copy

    def drop(self, channel: int) -> None:
        """Forget ``channel``'s copies (its solve has read them)."""
        if self.kept is not None:
            for key in [key for key in self.kept if key[0] == channel]:
                del self.kept[key]


def _source_groups(exemplars, source):
    """Per exemplar: (exemplar (H, W, C), C-contiguous, flat indices of the pixels copied
    from it, source y, x)."""
    e = source[..., 0].ravel()
    groups = []
    for k, exemplar in enumerate(exemplars):
        pixels = np.flatnonzero(e == k).astype(np.int32)
        bands = np.ascontiguousarray(exemplar)
        bands = bands.reshape(bands.shape[:2] + (-1,))  # (H, W) as one channel
        groups.append(
            (bands, pixels, source[..., 1].ravel()[pixels], source[..., 2].ravel()[pixels])
        )
    return groups


def _side_gradients(copies, ref, channel, axes=(1, 0)):
    """Per channel, one at a time (a generator: the caller frees each before the next is
    made), along each of ``axes`` (1: horizontal pairs, 0: vertical): the horizontal
    gradient by the left pixel's source and by the right pixel's, the vertical one by the
    upper and by the lower pixel's source."""
    copy = copies(ref, channel)
    if 1 in axes:
        right = copies(ref, channel, 0, 1)[:, :-1]
        yield np.subtract(right, copy[:, :-1], out=right)
        del right
        left = copies(ref, channel, 0, -1)[:, 1:]
        yield np.subtract(copy[:, 1:], left, out=left)
        del left
    if 0 in axes:
        down = copies(ref, channel, 1, 0)[:-1]
        yield np.subtract(down, copy[:-1], out=down)
        del down
        up = copies(ref, channel, -1, 0)[1:]
        yield np.subtract(copy[1:], up, out=up)
