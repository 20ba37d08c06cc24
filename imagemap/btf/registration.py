"""Register the four flatbed scans: undo their quarter turns, small shifts and rotations.

The cross-device paper scans a material four times, turned by a quarter turn between
scans under the scanner's fixed lamp, and aligns the scans by hand. Here:

1. the turn of every scan relative to the reference (the first) is the quarter turn
   ``numpy.rot90(scan, -t)`` whose phase correlation with the reference leaves the
   smallest error (:func:`skimage.registration.phase_cross_correlation`);
2. a small rotation (within ``max_rotation`` degrees) is found by a search over the
   angle: coarse grid, finer grid, then a parabola through the three best; at each
   angle the shift is the phase correlation's (sub-pixel, ``upsample_factor``);
3. each scan is resampled once (rotation and shift together,
   :func:`scipy.ndimage.affine_transform`) into the reference's frame, and all four
   are cropped to the rectangle every scan covers.

Registration compares *descriptors*, not raw scans, for the four lamps shade the
relief differently: the log-chromaticity pattern (diffuse shading scales R, G, B alike)
and CIELAB L*, each minus its Gaussian blur. Each descriptor, with plain and with
phase-only correlation, proposes a turn, angle and shift; the proposal under which the
whitened descriptors agree best (largest |correlation coefficient|) is kept. The scan
lit opposite the reference is aligned last, to its prediction from the other three
(see ``pairs``).

Measured on the four procedural materials (112 px scans, shifts up to 5 px, rotations
up to 4 degrees, four random perturbations each, linear or 8-bit through the Table 1
response given as ``response``): quarter turns always right; angle within 0.8 degrees;
residual shift within 0.5 px for cloth, leather and (with ``response``) wood, within
1.5 px for wallpaper (a repeating print) and for wood from linear scans.

Light azimuths follow from the turns. With the lamp at azimuth 0 of the reference
scan's frame (x along columns, y along rows, as the BTF directions), a scan whose
content is ``numpy.rot90(reference_frame, t)`` was lit from azimuth 90 t (turning the
content by t quarter turns with ``rot90`` turns directions by -90 t degrees).
A scanner seen from the other side (a mirror) reverses that: ``turn_direction=-1``.
The result is ordered by azimuth 0, 90, 180, 270, which is what
:func:`imagemap.btf.extrapolate.extrapolate` expects.

Example
-------
>>> reg = register_scans([scan_a, scan_b, scan_c, scan_d])  # doctest: +SKIP
>>> reg.azimuths, reg.turns, reg.angles, reg.shifts  # doctest: +SKIP
>>> big = extrapolate(sample, reg.images)  # doctest: +SKIP
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from imagemap.btf.constraints import color_correct, lightness
from imagemap.io import InputError

__all__ = [
    "MIN_CONFIDENCE",
    "MIN_JUDGED_SIDE",
    "Registration",
    "match_confidence",
    "register_scans",
    "scan_descriptor",
]

log = logging.getLogger("imagemap")


@dataclass(frozen=True)
class Registration:
    """Four scans brought into the reference scan's frame, ordered by light azimuth.

    Attributes
    ----------
    images : list of four (H, W, 3) float32
        Registered scans for azimuths 0, 90, 180, 270, cropped to the common area.
    order : tuple of 4 int
        Index in the input of the scan used for each azimuth.
    turns : tuple of 4 int
        Quarter turns (``numpy.rot90``) of each *input* scan relative to the reference.
    angles : tuple of 4 float
        Rotation (degrees, clockwise as displayed with rows down) applied to each input
        scan, after undoing its turn, to bring it into the reference's frame.
    shifts : tuple of 4 (dy, dx)
        Shift (pixels) applied after that rotation.
    errors : tuple of 4 float
        1 - |correlation coefficient| of the best-agreeing descriptor after alignment
        (0 for the reference; near 1: the scan does not match).
    crop : (top, left, height, width)
        The common rectangle in the reference frame.
    confidences : tuple of 4 float
        How significant each registered scan's match with the reference is
        (:func:`match_confidence`; inf for the reference). Below :data:`MIN_CONFIDENCE`
        the scan does not fit: another material, another piece, or a failed alignment
        (nan: scans under :data:`MIN_JUDGED_SIDE` px are not judged).
    """

    images: list[np.ndarray]
    order: tuple[int, ...]
    turns: tuple[int, ...]
    angles: tuple[float, ...]
    shifts: tuple[tuple[float, float], ...]
    errors: tuple[float, ...]
    crop: tuple[int, int, int, int]
    confidences: tuple[float, ...] = ()

    @property
    def suspect(self) -> tuple[int, ...]:
        """Input indices of the scans whose confidence is below :data:`MIN_CONFIDENCE`
        (not judged, all nan, for scans under :data:`MIN_JUDGED_SIDE`)."""
        return tuple(i for i, c in enumerate(self.confidences) if c < MIN_CONFIDENCE)

    @property
    def azimuths(self) -> tuple[float, ...]:
        """Light azimuth (degrees) of each input scan."""
        out = [0.0] * 4
        for azimuth_index, scan in enumerate(self.order):
            out[scan] = 90.0 * azimuth_index
        return tuple(out)


#: A registered scan whose :func:`match_confidence` with the reference is below this does
#: not fit. Measured on 112 px scans (turned, rotated up to 4 degrees, shifted up to 5 px;
#: common areas 80-105 px) of cloth, leather, wallpaper and wood: correct alignments
#: 20.7-187 (median 63.5, 36 scans); a scan of another material put in their place, where
#: registration did not refuse it already: 1.6-13.5 (median 3.5, 47 scans; rendered with
#: the same noise seed, which shares structure) and 1.5-8.5 (62 scans, another seed).
MIN_CONFIDENCE = 17.0

#: The confidence of correct alignments grows with the scans' side, the foreign scans' does
#: not: scans whose shared square is under this side (px) are not judged (48 px scans:
#: correct alignments from 5.6, foreign up to 8.4; 64 px: from 9.0).
MIN_JUDGED_SIDE = 100


def match_confidence(reference: np.ndarray, image: np.ndarray, *, sigma: float = 6.0) -> float:
    """Significance of the match of two registered scans: the phase-correlation peak at
    zero shift against the rest of the correlation surface, in standard deviations.

    Both scans are turned into the registration's descriptors (colour pattern, lightness
    pattern) and whitened; the circular cross-correlation of aligned scans of one sample
    peaks at zero shift (within a pixel), far above its values elsewhere, while scans of
    different samples give a surface of noise whose largest values lie a few standard
    deviations out. Opposite lamps negate the shading: the peak's absolute value counts.
    The best of the two descriptors is returned.

    Example
    -------
    >>> rng = np.random.default_rng(0)
    >>> a, b = rng.random((2, 48, 48, 3)) * 0.5 + 0.25
    >>> bool(match_confidence(a, a) > 50), bool(match_confidence(a, b) < 8)
    (True, True)
    """
    best = 0.0
    for describe in (scan_descriptor, _lightness_descriptor):
        spectra = [
            np.fft.fft2(_whiten(describe(np.asarray(x, np.float64), sigma=sigma)))
            for x in (reference, image)
        ]
        surface = np.abs(np.fft.fftshift(np.real(np.fft.ifft2(spectra[0] * np.conj(spectra[1])))))
        cy, cx = surface.shape[0] // 2, surface.shape[1] // 2
        peak = surface[cy - 1 : cy + 2, cx - 1 : cx + 2].max()
        rest = np.ones(surface.shape, bool)
        rest[cy - 2 : cy + 3, cx - 2 : cx + 3] = False
        spread = float(surface[rest].std())
        if spread > 0:
            best = max(best, float((peak - surface[rest].mean()) / spread))
    return best


def scan_descriptor(
    scan: np.ndarray, *, sigma: float = 6.0, basis: np.ndarray | None = None
) -> np.ndarray:
    """The pattern the four lighting directions share, (H, W) float64.

    Diffuse shading scales R, G and B alike, so the log-chromaticities
    (log R/G, log B/G) keep the albedo's pattern and drop the shading that differs
    from lamp to lamp; they are projected on ``basis`` (2,) (default: their first
    principal direction in this scan) and the smooth part (a Gaussian blur of
    ``sigma``) is removed. Scans of a material without colour variation fall back
    to CIELAB L* minus its blur (see :func:`register_scans`).
    """
    from scipy.ndimage import gaussian_filter  # deferred: scipy.ndimage, when registering

    logs = np.log(np.clip(np.asarray(scan, dtype=np.float64), 1e-4, None))
    chroma = np.stack([logs[..., 0] - logs[..., 1], logs[..., 2] - logs[..., 1]], axis=-1)
    chroma -= gaussian_filter(chroma, (sigma, sigma, 0), mode="reflect")
    if basis is None:
        basis = _chroma_basis(chroma)
    return chroma @ basis


def _chroma_basis(chroma: np.ndarray) -> np.ndarray:
    flat = chroma.reshape(-1, 2)
    _, _, vt = np.linalg.svd(flat - flat.mean(axis=0), full_matrices=False)
    return vt[0]


def _lightness_descriptor(scan: np.ndarray, sigma: float = 6.0) -> np.ndarray:
    from scipy.ndimage import gaussian_filter  # deferred: scipy.ndimage, when registering

    lum = lightness(np.clip(scan, 0.0, None)).astype(np.float64)
    return lum - gaussian_filter(lum, sigma, mode="reflect")


def _check(scans: Sequence[np.ndarray]) -> list[np.ndarray]:
    if len(scans) != 4:
        raise InputError(f"scans: expected four scans, got {len(scans)}")
    out = []
    for i, scan in enumerate(scans):
        array = np.asarray(scan, dtype=np.float32)
        if array.ndim != 3 or array.shape[2] != 3:
            raise InputError(f"scans[{i}]: expected an (H, W, 3) image, got shape {array.shape}")
        if not np.all(np.isfinite(array)):
            raise InputError(f"scans[{i}]: has NaN or infinite values")
        if min(array.shape[:2]) < 32:
            raise InputError(f"scans[{i}]: {array.shape[0]}x{array.shape[1]} is too small (32)")
        out.append(array)
    return out


def _centre_crop(image: np.ndarray, side: int) -> np.ndarray:
    top, left = (image.shape[0] - side) // 2, (image.shape[1] - side) // 2
    return image[top : top + side, left : left + side]


def _rotation(angle: float) -> np.ndarray:
    """(row, col) matrix of a turn by ``angle`` degrees, clockwise as displayed (rows down)."""
    a = np.deg2rad(angle)
    return np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]])


def _warp(image: np.ndarray, angle: float, shift=(0.0, 0.0), order: int = 1) -> np.ndarray:
    """``image`` turned by ``angle`` about its centre, then shifted; one resampling.

    Output pixel o samples the input at c + R^-1 (o - shift - c).
    """
    from scipy.ndimage import affine_transform  # deferred: scipy.ndimage, when registering

    matrix = _rotation(angle).T  # the inverse of a rotation
    centre = (np.array(image.shape[:2]) - 1) / 2.0
    offset = centre - matrix @ (np.asarray(shift, dtype=np.float64) + centre)
    if image.ndim == 2:
        return affine_transform(image, matrix, offset=offset, order=order, mode="nearest")
    return np.stack(
        [
            affine_transform(image[..., c], matrix, offset=offset, order=order, mode="nearest")
            for c in range(image.shape[2])
        ],
        axis=2,
    )


def _correlate(reference, moving, window, upsample: int, normalization: str | None = "phase"):
    from skimage.registration import phase_cross_correlation  # deferred: skimage, when registering

    shift, error, _ = phase_cross_correlation(
        reference * window, moving * window, upsample_factor=upsample, normalization=normalization
    )
    return np.asarray(shift, dtype=np.float64), float(error)


def _best_angle(reference, moving, window, max_rotation: float, step: float, normalization):
    """Angle (degrees), shift and error aligning ``moving`` to ``reference``: grid, grid,
    parabola; with ``max_rotation`` 0 the shift alone (angle 0)."""
    if max_rotation <= 0:
        shift, error = _correlate(reference, moving, window, 20, normalization)
        return 0.0, shift, error
    margin = int(np.ceil(reference.shape[0] * (1 - np.cos(np.deg2rad(max_rotation))) / 2))
    inner = slice(margin, reference.shape[0] - margin)

    def score(angle: float) -> float:
        turned = _warp(moving, angle)
        return _correlate(reference[inner, inner], turned[inner, inner], window, 1, normalization)[
            1
        ]

    # Narrow the window of the inner crop to the crop's size.
    window = window[: reference.shape[0] - 2 * margin, : reference.shape[0] - 2 * margin]
    angles = np.arange(-max_rotation, max_rotation + 1e-9, step)
    errors = np.array([score(a) for a in angles])
    centre = float(angles[int(np.argmin(errors))])
    fine = centre + np.array([-0.75, -0.5, -0.25, 0.0, 0.25, 0.5, 0.75]) * step
    fine_errors = np.array([score(a) for a in fine])
    i = int(np.clip(np.argmin(fine_errors), 1, len(fine) - 2))
    e0, e1, e2 = fine_errors[i - 1 : i + 2]
    curvature = e0 - 2 * e1 + e2
    delta = 0.5 * (e0 - e2) / curvature if curvature > 0 else 0.0
    angle = float(fine[i] + np.clip(delta, -1, 1) * step * 0.25)
    shift, error = _correlate(
        reference[inner, inner], _warp(moving, angle)[inner, inner], window, 20, normalization
    )
    return angle, shift, error


def _whiten(image: np.ndarray) -> np.ndarray:
    """Unit Fourier magnitudes (phase only): fine structure counts as much as coarse."""
    spectrum = np.fft.rfft2(image - image.mean())
    return np.fft.irfft2(spectrum / np.maximum(np.abs(spectrum), 1e-12), s=image.shape)


def _agreement(references, movings, angle: float, shift, margin: int) -> float:
    """Largest |correlation coefficient| over the descriptors after the transform."""
    best = 0.0
    for reference, moving in zip(references, movings, strict=True):
        warped = _whiten(_warp(moving, angle, shift)[margin:-margin, margin:-margin])
        ref = _whiten(reference[margin:-margin, margin:-margin])
        best = max(best, abs(float(np.corrcoef(ref.ravel(), warped.ravel())[0, 1])))
    return best


def _align(references, movings, window, margin, max_rotation, step):
    """Best (agreement, angle, shift, label) aligning ``movings`` to ``references``.

    Both are lists over the descriptor kinds of upright, equally cropped images; each
    kind with plain and with phase-only correlation proposes an angle and a shift.
    """
    proposals = []
    for kind, reference, moving in zip(_KINDS, references, movings, strict=True):
        for normalization in ("phase", None):
            angle, shift, _ = _best_angle(
                reference, moving, window, max_rotation, step, normalization
            )
            score = _agreement(references, movings, angle, shift, margin)
            label = f"{kind}, {normalization or 'plain'}"
            proposals.append((score, angle, (float(shift[0]), float(shift[1])), label))
    return max(proposals, key=lambda p: p[0])


_KINDS = ("chroma", "lightness")


def register_scans(
    scans: Sequence[np.ndarray],
    *,
    max_rotation: float = 5.0,
    angle_step: float = 1.0,
    turn_direction: int = 1,
    sigma: float = 6.0,
    pairs: bool = True,
    response=None,
    names: Sequence[str] | None = None,
) -> Registration:
    """Find the quarter turns, rotations and shifts of four scans and undo them.

    Parameters
    ----------
    scans : four (H, W, 3) images in [0, 1], in any order; the first is the reference
        (its frame is the result's, its lamp direction azimuth 0). Sizes may differ
        (a turned scan is W x H); the common area is what the result keeps.
    max_rotation : float
        Largest rotation (degrees) besides the quarter turns; 0 searches shifts only.
    angle_step : float
        Step of the coarse angle grid (degrees).
    turn_direction : {1, -1}
        +1: the content turned by ``numpy.rot90(., t)`` was lit from azimuth 90 t;
        -1: from -90 t (a mirrored scanner).
    sigma : float
        Gaussian blur (pixels) removed from L* in the descriptor.
    pairs : bool
        Align the scan lit opposite the reference to its prediction from the other
        three, I90 + I270 - I0 (shading under opposite lamps is negated and biases a
        direct alignment, see the code); False aligns it to the reference directly.
    response : ScannerResponse, optional
        The scanner's response: descriptors are then computed from the linearized
        scans (:func:`imagemap.btf.constraints.color_correct`), where the prediction
        above holds. The returned images are the scans as given, only moved.
    names : sequence of 4 str, optional
        What to call the scans in warnings (file names); default "scan i".

    Returns
    -------
    Registration

    Raises
    ------
    InputError
        Not four colour images, or two scans would take the same azimuth (their turns
        are not four different quarter turns).
    """
    scans = _check(scans)
    if turn_direction not in (1, -1):
        raise InputError(f"turn_direction: 1 or -1, got {turn_direction!r}")
    if not 0 <= max_rotation <= 20 or not np.isfinite(max_rotation):
        raise InputError(f"max_rotation: between 0 and 20 degrees, got {max_rotation}")
    from skimage.filters import window as make_window  # deferred: skimage, when registering

    # Two descriptors (colour pattern, lightness pattern) and two correlations (plain,
    # phase-only: whitened, which favours fine structure): each pair proposes a turn,
    # an angle and a shift; the proposal under which the descriptors agree best wins.
    if response is not None:
        linear = [color_correct(s, response=response) for s in scans]
    else:
        linear = scans
    kinds = {
        "chroma": [scan_descriptor(s, sigma=sigma) for s in linear],
        "lightness": [_lightness_descriptor(s, sigma) for s in linear],
    }
    side = min(min(d.shape) for d in kinds["chroma"])
    window = make_window("hann", (side, side))
    margin = int(np.ceil(side * np.sin(np.deg2rad(max_rotation)))) + side // 16 + 1
    references = [_centre_crop(values[0], side) for values in kinds.values()]

    turns, angles, shifts, errors = [0], [0.0], [(0.0, 0.0)], [0.0]
    for i in range(1, 4):
        proposals = []
        for kind, values in kinds.items():
            reference = _centre_crop(values[0], side)
            for normalization in ("phase", None):
                by_turn = [
                    _correlate(
                        reference,
                        _centre_crop(np.rot90(values[i], -t), side),
                        window,
                        1,
                        normalization,
                    )[1]
                    for t in range(4)
                ]
                t = int(np.argmin(by_turn))
                moving = _centre_crop(np.rot90(values[i], -t), side)
                angle, shift, error = _best_angle(
                    reference, moving, window, max_rotation, angle_step, normalization
                )
                movings = [_centre_crop(np.rot90(v[i], -t), side) for v in kinds.values()]
                score = _agreement(references, movings, angle, shift, margin)
                proposals.append((score, t, angle, tuple(shift), error, kind, normalization))
        score, t, angle, shift, error, kind, normalization = max(proposals, key=lambda p: p[0])
        turns.append(t)
        angles.append(angle)
        shifts.append((float(shift[0]), float(shift[1])))
        errors.append(1.0 - score)
        log.info(
            "scan %d (%s, %s): %d quarter turns, %.2f deg, shift (%.2f, %.2f), agreement %.3f",
            i,
            kind,
            normalization or "plain",
            t,
            angle,
            shift[0],
            shift[1],
            score,
        )

    azimuth_index = [(turn_direction * t) % 4 for t in turns]
    if sorted(azimuth_index) != [0, 1, 2, 3]:
        raise InputError(
            f"scans: the quarter turns found ({turns}) are not four different ones; the "
            "four scans must show the sample turned by 0, 90, 180 and 270 degrees"
        )
    order = tuple(azimuth_index.index(a) for a in range(4))

    if pairs:
        # Under opposite lamps the relief's shading is negated while the albedo is not:
        # where the two are of similar strength their correlations cancel near the true
        # shift and the peak moves aside (measured: 1-2 px on leather and wood). Scans lit
        # 90 degrees apart do not suffer from it. For a Lambertian surface
        # I0 + I180 = I90 + I270, so the opposite scan is aligned to its prediction
        # I90 + I270 - I0 from the other three, already in the reference's frame.
        a, c, b, d = order  # inputs lit from 0, 90, 180, 270
        upright = [
            [_centre_crop(np.rot90(values[i], -turns[i]), side) for values in kinds.values()]
            for i in range(4)
        ]
        predicted = [
            _warp(mc, angles[c], shifts[c]) + _warp(md, angles[d], shifts[d]) - ma
            for ma, mc, md in zip(upright[a], upright[c], upright[d], strict=True)
        ]
        score, angle, shift, label = _align(
            predicted, upright[b], window, margin, max_rotation, angle_step
        )
        angles[b], shifts[b], errors[b] = angle, shift, 1.0 - score
        log.info(
            "scan %d (opposite) against its prediction (%s): %.2f deg, %s",
            b,
            label,
            angle,
            shift,
        )

    # Resample every scan once into the reference's (square, centred) frame and crop
    # the border that a rotation or shift leaves uncovered.
    warped = []
    for scan, t, angle, shift in zip(scans, turns, angles, shifts, strict=True):
        square = _centre_crop(np.rot90(scan, -t), side)
        warped.append(_warp(square, angle, shift, order=3).astype(np.float32))
    reach = max(abs(a) for a in angles)
    margin = int(
        np.ceil(side * np.sin(np.deg2rad(reach)) + max(np.abs(s).max() for s in shifts) + 1)
    )
    if side - 2 * margin < 16:
        raise InputError(
            f"scans: after registration only {side - 2 * margin} pixels are common; "
            "shifts or rotations are too large"
        )
    crop = (margin, margin, side - 2 * margin, side - 2 * margin)
    images = [
        np.clip(warped[i][margin : side - margin, margin : side - margin], 0.0, 1.0) for i in order
    ]
    confidences = [np.inf] * 4
    judged = side >= MIN_JUDGED_SIDE
    if not judged:
        log.info("scans not judged for fit: %d px is under %d px", side, MIN_JUDGED_SIDE)
    for position, i in enumerate(order):
        if i != 0:
            if not judged:
                confidences[i] = np.nan
                continue
            confidences[i] = match_confidence(images[0], images[position], sigma=sigma)
            if confidences[i] < MIN_CONFIDENCE:
                log.warning(
                    "%s does not fit %s (match confidence %.1f, below %.0f; correct "
                    "alignments measure 20 and more): a scan of another material or piece, "
                    "or a failed alignment",
                    names[i] if names else f"scan {i}",
                    names[0] if names else "the reference scan",
                    confidences[i],
                    MIN_CONFIDENCE,
                )
    return Registration(
        images=images,
        order=order,
        turns=tuple(turns),
        angles=tuple(angles),
        shifts=tuple(shifts),
        errors=tuple(errors),
        crop=crop,
        confidences=tuple(float(c) for c in confidences),
    )
