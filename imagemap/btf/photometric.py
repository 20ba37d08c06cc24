"""Range maps of BTF materials by over-determined photometric stereo (section 2.1 of the
moving-average BTF paper, papers/moving-average-btf-model.txt).

One module for one job: photometric stereo and the range map it gives (check, solve, enlarge).

All images of one fixed view (the top view of a BTF) under all its lights give, per texel,
an over-determined Lambertian system I_i = rho (n . l_i): least squares gives the scaled
normal g = rho n (Woodham), whose direction is the normal and whose length the albedo. The
normal field is integrated into heights by the Frankot-Chellappa projection onto integrable
surfaces (in Fourier space). The range map is enlarged to any size by *seamless periodic
tiling* (:func:`enlarge_range_map`): the sample is cross-faded with its half-shifted copy
into a tile whose heights and slopes wrap continuously, standing in for the paper's roller
method, which also repeats a seam-free toroidal tile of the sample.

Vectors use the image frame of :mod:`imagemap.render`: x along the columns, y up the screen
(against the row index), z out of the surface; heights come out in pixels.
"""

from __future__ import annotations

import logging

import numpy as np

from imagemap.btf.core import directions_to_vectors
from imagemap.btf.integration import frankot_chellappa  # re-exported: its former home
from imagemap.io import InputError

__all__ = [
    "LIGHT_RANK_TOLERANCE",
    "MAX_LIGHT_CONDITION",
    "btf_direction_vectors",
    "check_light_matrix",
    "flat_where_left_out",
    "crossfade_tile",
    "enlarge_range_map",
    "frankot_chellappa",
    "periodic_component",
    "photometric_stereo",
    "range_map_from_btf",
    "solvable_pixels",
    "split_alpha",
    "usable_samples",
]

log = logging.getLogger("imagemap")

#: Rec. 709 luminance weights: the normals are fitted on luminance, the albedo per channel.
LUMINANCE = (0.2126, 0.7152, 0.0722)

#: Shadow cut-off of photographs (fraction of full scale): samples at or below it are
#: sensor black, not shading, and are dropped. On psmImages' real grey sphere (quarter size,
#: 12 lights; benchmarks/photometric_sphere.py --psm DIR) the mean error is 5.50 degrees at
#: 2/255, 5.63 at 0, 5.65 at 5/255, 5.91 at 10/255.
SHADOW_LEVEL = 2.0 / 255.0

#: Saturation cut-off of photographs (fraction of full scale): a sample with a channel at or
#: above it may be clipped, reads too dark, and tilts the normal away from its light. Cameras
#: roll off a little below full scale. With 15 % of the grey sphere's samples clipped by
#: overexposure, the clipped pixels' error is 6.76 degrees (7.06 kept, 5.29 before
#: clipping; a Lambertian sphere under the same lights: 2.64, 4.52, 0.22); with 5 % clipped
#: the real sphere loses (5.30 against 4.62 kept).
SATURATION_LEVEL = 0.99

#: Clipped samples of a pixel are dropped only while at least this fraction of its lights
#: (and 3) remain: with few lights left the fit extrapolates from one side. On the grey
#: sphere (12 lights within 40 degrees of the view) dropping helped where up to 4 of 12
#: samples clipped and cost up to 14 degrees where 9 did; 15 % clipped, clipped pixels:
#: 6.86 degrees at 0.5, 6.80 at 2/3, 7.06 kept; the Lambertian sphere: 2.97, 3.63, 4.52
#: (measured with the cut at 250/255).
MIN_KEPT_FRACTION = 0.5


#: A light matrix (unit vectors towards the lights, one row each) whose smallest singular
#: value is below this fraction of its largest spans fewer than 3 directions: its lights
#: are one direction or one plane through the camera (rank < 3), and no normal follows
#: from them. The fraction is what a lights file's 5-6 significant digits move a coplanar
#: set off its plane (about 1e-6), with room: such a set is coplanar as written.
LIGHT_RANK_TOLERANCE = 1e-4

#: Condition numbers of the light matrix above this get a warning with the figure: the
#: normal's error grows about linearly with it. A Lambertian sphere under 12 lights on a
#: cone around the view, 8-bit images with 0.5 % noise (benchmarks/photometric_sphere.py,
#: ``condition_rows``): mean error 0.4 degrees at condition 1.7 (lights 40 degrees from
#: the view, as psmImages'; the generated grey sphere's are 2.8), 2.2 at 16, 5.5 at 40,
#: 10.8 at 81, 20.9 at 162. Above 40 the noise alone costs more than the whole error on
#: psmImages' real sphere (5.5 degrees).
MAX_LIGHT_CONDITION = 40.0
#: The mean normal error per unit of condition number at 0.5 % noise (the slope of the
#: figures above: 5.5 / 40.5, 10.8 / 81, 20.9 / 162): the warning's estimate.
DEGREES_PER_CONDITION = 0.135


def _singular_spread(gram: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(smallest / largest singular value, condition number) of light matrices from their
    (..., 3, 3) Gram matrices L^T L (singular values are the eigenvalues' roots)."""
    eigen = np.clip(np.linalg.eigvalsh(gram), 0.0, None)
    ratio = np.sqrt(eigen[..., 0] / np.maximum(eigen[..., -1], 1e-300))
    return ratio, np.where(ratio > 0, 1.0 / np.maximum(ratio, 1e-300), np.inf)


def check_light_matrix(
    light_dirs: np.ndarray, what: str = "light_dirs", *, warn: bool = True
) -> float:
    """The condition number of the lights above the horizon; rank < 3 is refused.

    Parameters
    ----------
    light_dirs : ndarray, shape (N, 3)
        Vectors towards the lights (normalized here).
    what : str
        What the lights are called in the messages (``"--lights lights.txt"``).
    warn : bool
        Log a warning with the figure when the condition number is over
        :data:`MAX_LIGHT_CONDITION`.

    Returns
    -------
    float
        The condition number (largest over smallest singular value).

    Raises
    ------
    InputError
        Fewer than 3 lights above the horizon, or lights spanning fewer than 3
        directions (identical, opposite or in one plane through the camera:
        :data:`LIGHT_RANK_TOLERANCE`), naming ``what``.

    Examples
    --------
    >>> round(check_light_matrix(np.array([[0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8]])), 2)
    4.16
    >>> check_light_matrix(np.array([[0, 0, 1.0]] * 4))  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    imagemap.errors.InputError: light_dirs: the 4 lights span 1 direction (rank 1 < 3: ...
    """
    lights = np.asarray(light_dirs, dtype=np.float64)
    lights = lights / np.maximum(np.linalg.norm(lights, axis=1, keepdims=True), 1e-300)
    above = lights[lights[:, 2] > 0]
    if len(above) < 3:
        raise InputError(f"{what}: need at least 3 lights above the horizon, got {len(above)}")
    singular = np.linalg.svd(above, compute_uv=False)
    rank = int(np.sum(singular > LIGHT_RANK_TOLERANCE * singular[0]))
    if rank < 3:
        shape = "one direction" if rank == 1 else "one plane through the camera"
        raise InputError(
            f"{what}: the {len(above)} lights span {rank} direction{'s' if rank > 1 else ''} "
            f"(rank {rank} < 3: they lie in {shape}); a normal needs lights from 3 "
            "directions not in one plane"
        )
    condition = float(singular[0] / singular[-1])
    if warn and condition > MAX_LIGHT_CONDITION:
        log.warning(
            "%s: the light matrix' condition number is %.1f (over %g): the lights are "
            "close to one plane or direction, and the normals' error grows with it (about "
            "%.0f degrees at 0.5 %% noise)",
            what,
            condition,
            MAX_LIGHT_CONDITION,
            DEGREES_PER_CONDITION * condition,
        )
    return condition


def solvable_pixels(used: np.ndarray, lights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which pixels' samples decide a normal, and their lights' condition numbers.

    Parameters
    ----------
    used : ndarray of bool, shape (N, P)
        The samples that enter each pixel's fit (:func:`usable_samples`, clipped ones
        left out).
    lights : ndarray, shape (N, 3)
        Unit vectors towards the lights.

    Returns
    -------
    solvable : ndarray of bool, shape (P,)
        At least 3 samples whose lights span 3 directions (:data:`LIGHT_RANK_TOLERANCE`).
    condition : ndarray of float, shape (P,)
        The condition number of each pixel's lights (inf where not solvable).

    Pixels that use the same lights share one computation: the usage patterns are few.

    Examples
    --------
    >>> lights = np.array([[0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8], [0, 0, 1.0]])
    >>> used = np.array([[1, 1], [1, 0], [1, 0], [0, 1]], bool)  # pixel 1: one direction
    >>> solvable, condition = solvable_pixels(used, lights)
    >>> solvable.tolist(), condition.round(2).tolist()
    ([True, False], [4.16, inf])
    """
    used = np.asarray(used, dtype=bool)
    packed = np.packbits(used, axis=0).T.copy()  # (P, ceil(N / 8)): one row per pattern
    patterns, index = np.unique(packed, axis=0, return_inverse=True)
    pattern_used = np.unpackbits(patterns, axis=1, count=used.shape[0]).astype(np.float64)
    lights = np.asarray(lights, dtype=np.float64)
    gram = np.einsum("kn,ni,nj->kij", pattern_used, lights, lights)
    ratio, condition = _singular_spread(gram)
    solvable = (pattern_used.sum(axis=1) >= 3) & (ratio > LIGHT_RANK_TOLERANCE)
    index = np.asarray(index).ravel()
    return solvable[index], np.where(solvable, condition, np.inf)[index]


def split_alpha(images: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """Colour and alpha of an (N, H, W, C) stack: alpha is the last of 2 or 4 channels.

    Returns the (N, H, W, C - 1) colour and a (H, W) mask where every image's alpha is
    at least half (None when C is 1 or 3: no alpha). Alpha is coverage, not light: it
    must never be averaged into the intensity.

    Examples
    --------
    >>> rgba = np.ones((3, 2, 2, 4), np.float32)
    >>> rgba[1, 0, 0, 3] = 0.0
    >>> colour, mask = split_alpha(rgba)
    >>> colour.shape, mask.tolist()
    ((3, 2, 2, 3), [[False, True], [True, True]])
    """
    images = np.asarray(images)
    if images.ndim != 4:
        raise InputError(f"images: expected (N, H, W, C), got shape {images.shape}")
    if images.shape[3] not in (2, 4):
        return images, None
    return images[..., :-1], np.all(images[..., -1] >= 0.5, axis=0)


def _intensity(images: np.ndarray) -> np.ndarray:
    """Luminance (N, H, W) of (N, H, W, C) linear images, C = 1 or 3."""
    if images.shape[3] == 3:
        return images @ np.asarray(LUMINANCE, np.float32)
    return images[..., 0]


def usable_samples(
    images: np.ndarray,
    light_dirs: np.ndarray,
    *,
    mask: np.ndarray | None = None,
    min_intensity: float = 0.0,
    max_intensity: float | None = None,
    min_kept_fraction: float = MIN_KEPT_FRACTION,
) -> np.ndarray:
    """Which samples enter each pixel's fit, (N, H, W) bool, of (N, H, W[, C]) images.

    A sample is used when its light is above the horizon, its pixel in ``mask``, its
    luminance above ``min_intensity`` (shadowed samples break the Lambertian model) and
    every channel below ``max_intensity`` (clipped samples read too dark: the normal
    leans away from that light). A pixel's clipped samples are dropped only while at least
    ``min_kept_fraction`` of its other usable samples, and 3, remain (see
    :data:`MIN_KEPT_FRACTION`); otherwise they are kept.

    Example
    -------
    >>> images = np.array([0.0, 0.5, 1.0, 0.4, 0.3], np.float32).reshape(5, 1, 1, 1)
    >>> lights = np.array([[0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8], [0.6, 0.6, 0.5], [0, 0, 1]])
    >>> usable_samples(images, lights, max_intensity=0.98).ravel().tolist()
    [False, True, False, True, True]
    """
    images = np.asarray(images, dtype=np.float32)
    if images.ndim == 3:
        images = images[..., None]
    lights = np.asarray(light_dirs, dtype=np.float64)
    used = (lights[:, 2] > 0)[:, None, None] & (_intensity(images) > min_intensity)
    if max_intensity is not None:
        unclipped = images.max(axis=3) < max_intensity
        left = (used & unclipped).sum(axis=0)
        enough = (left >= np.ceil(min_kept_fraction * used.sum(axis=0))) & (left >= 3)
        used &= unclipped | ~enough[None]
    if mask is not None:
        used &= np.asarray(mask, bool)[None]
    return used


def photometric_stereo(
    images: np.ndarray,
    light_dirs: np.ndarray,
    *,
    mask: np.ndarray | None = None,
    min_intensity: float = 0.0,
    max_intensity: float | None = None,
    ridge: float = 1e-6,
    channel_axis: int | None = -1,
    lights_name: str = "light_dirs",
) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares normals and albedo from N >= 3 images of one view under known lights.

    Parameters
    ----------
    images : ndarray, shape (N, H, W, C) or (N, H, W)
        Linear intensities, one image per light, all from the same (fixed) view; C is 1
        (grey) or 3 (RGB). Two or four channels (grey or RGB with alpha) are refused: take
        the alpha off with :func:`split_alpha` and pass it as ``mask``.
    light_dirs : ndarray, shape (N, 3)
        Vectors towards each light in the image frame (x right, y up, z towards the
        viewer); normalized here. Lights below the horizon are ignored.
    mask : ndarray of bool, shape (H, W), optional
        Pixels to solve (the object); the others get the normal (0, 0, 1) and albedo 0.
    min_intensity : float
        Samples of a texel at or below this (on luminance) are left out of its fit, so cast
        and attached shadows do not bend the normal; the default 0 drops black samples
        (attached shadows); a negative value keeps every sample above the horizon.
    max_intensity : float, optional
        Samples with a channel at or above this are left out (clipped highlights or an
        overexposed sensor) where enough others remain (:func:`usable_samples`); None
        keeps them (linear data with no full scale). Photographs in [0, 1]:
        :data:`SATURATION_LEVEL`.
    ridge : float
        Tikhonov term that keeps the per-texel normal equations well posed in floating
        point (texels without 3 informative samples are left out, not regularized).
    channel_axis : int or None
        Axis of the channels in 4-D input (default last); None: ``images`` is (N, H, W).
    lights_name : str
        What the lights are called in messages (the command: ``"--lights FILE"``).

    Returns
    -------
    normals : ndarray of float32, shape (H, W, 3)
        Unit normals (z >= 0 is not enforced; it is what the data say). NaN where the
        samples decide no normal (:func:`solvable_pixels`: fewer than :data:`MIN_SAMPLES`
        lit, unclipped samples, or their lights in one plane): such texels are left out,
        with a warning giving their share, never filled in.
    albedo : ndarray of float32, shape (H, W, C)
        Per-channel Lambertian albedo (C = 1 for grey input); NaN where the normal is.

    Raises
    ------
    InputError
        Bad shapes or values; lights of rank < 3 (:func:`check_light_matrix`, which also
        warns about an ill-conditioned set); no texel with a normal to find.

    Examples
    --------
    >>> lights = np.array([[0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8]], np.float32)
    >>> images = np.full((3, 4, 4), 0.5, np.float32) * lights[:, 2, None, None]
    >>> normals, albedo = photometric_stereo(images, lights)
    >>> normals[0, 0].round(3).tolist(), round(float(albedo[0, 0, 0]), 3)
    ([0.0, 0.0, 1.0], 0.5)
    """
    images = np.asarray(images, dtype=np.float32)
    if images.ndim == 3 or channel_axis is None:
        images = images[..., None]
    elif images.ndim == 4:
        images = np.moveaxis(images, channel_axis, -1)
    if images.ndim != 4:
        raise InputError(f"images: expected (N, H, W[, C]), got shape {images.shape}")
    n, height, width, channels = images.shape
    if channels in (2, 4):
        raise InputError(
            f"images: {channels} channels ({'grey' if channels == 2 else 'RGB'} with alpha?); "
            "alpha is not light: take it off with split_alpha() and pass it as mask="
        )
    if channels not in (1, 3):
        raise InputError(f"images: expected 1 (grey) or 3 (RGB) channels, got {channels}")
    lights = np.asarray(light_dirs, dtype=np.float64)
    if lights.shape != (n, 3):
        raise InputError(f"light_dirs: expected ({n}, 3) for {n} images, got {lights.shape}")
    norms = np.linalg.norm(lights, axis=1)
    if np.any(norms == 0) or not np.all(np.isfinite(lights)):
        raise InputError("light_dirs: every light needs a finite non-zero direction")
    lights = lights / norms[:, None]
    overall = check_light_matrix(lights, lights_name)  # rank < 3 refused; else warned
    if not np.all(np.isfinite(images)):
        raise InputError("images: have NaN or infinite values")
    if mask is not None:
        mask = np.asarray(mask)
        if mask.shape != (height, width):
            raise InputError(f"mask: shape {mask.shape} differs from the images' {(height, width)}")
        mask = mask.astype(bool)
        if not mask.any():
            raise InputError("mask: selects no pixel")
    solved = np.ones((height, width), bool) if mask is None else mask

    used = usable_samples(images, lights, min_intensity=min_intensity, max_intensity=max_intensity)[
        :, solved
    ]  # (N, P)
    # What decides a normal: lit samples that are not clipped (a clipped sample may still
    # enter the fit where too few others remain, but it says little of the shading).
    informative = usable_samples(images, lights, min_intensity=min_intensity)[:, solved]
    if max_intensity is not None:
        informative &= (images.max(axis=3) < max_intensity)[:, solved]
    decided, condition = solvable_pixels(informative, lights)
    _report_left_out(decided, condition, informative, overall)
    solved = solved.copy()
    solved[solved] = decided
    used = used[:, decided]
    intensity = _intensity(images)[:, solved].astype(np.float64)
    if used.all():
        # Every texel sees the same lights: one pseudo-inverse serves all (Woodham).
        scaled_normal = (np.linalg.pinv(lights) @ intensity).T
    else:
        # Per-texel weighted normal equations, solved as a batch of 3x3 systems.
        w = used.astype(np.float64)
        gram = np.einsum("np,ni,nj->pij", w, lights, lights)
        gram += ridge * np.eye(3)
        rhs = np.einsum("np,ni->pi", w * intensity, lights)
        scaled_normal = np.linalg.solve(gram, rhs[..., None])[..., 0]
    length = np.linalg.norm(scaled_normal, axis=1, keepdims=True)
    found = np.where(length > 0, scaled_normal / np.maximum(length, 1e-12), [0.0, 0.0, 1.0])

    # Per-channel albedo: least squares of I_c = rho_c * shading over the used samples.
    shading = np.clip(lights @ found.T, 0.0, None) * used  # (N, P)
    colour = images[:, solved].astype(np.float64)  # (N, P, C)
    numerator = np.einsum("np,npc->pc", shading, colour)
    denominator = np.einsum("np,np->p", shading, shading)[:, None]
    normals = np.zeros((height, width, 3), np.float32)
    normals[..., 2] = 1.0
    albedo = np.zeros((height, width, channels), np.float32)
    if mask is not None:  # inside the mask, a texel left out has no normal
        normals[mask], albedo[mask] = np.nan, np.nan
    else:
        normals[:], albedo[:] = np.nan, np.nan
    normals[solved] = found
    albedo[solved] = numerator / np.maximum(denominator, 1e-12)
    return normals, albedo


#: The fewest informative samples that decide a texel's normal: the scaled normal has 3
#: unknowns (Woodham's least squares needs 3 independent equations).
MIN_SAMPLES = 3


def _report_left_out(
    decided: np.ndarray, condition: np.ndarray, informative: np.ndarray, overall: float
) -> None:
    """Warn, with the figures, about texels left out (no normal) and texels solved from
    ill-conditioned lights (unless all the lights are: :func:`check_light_matrix` said
    so); refuse when no texel is left to solve."""
    total = decided.size
    few = informative.sum(axis=0) < MIN_SAMPLES
    if not decided.any():
        raise InputError(
            f"images: no pixel has {MIN_SAMPLES} usable samples from lights in 3 directions "
            f"({int(few.sum())} of {total} have fewer than {MIN_SAMPLES} lit, unclipped "
            "samples: all shadowed, black or saturated?); no normal can be found"
        )
    left = int(total - decided.sum())
    if left:
        log.warning(
            "photometric stereo: %d of %d pixels (%.1f %%) left out of the normals (no "
            "normal, no height): %d with fewer than %d lit, unclipped samples (shadowed, "
            "saturated or lights behind), %d whose usable lights lie in one plane",
            left,
            total,
            100.0 * left / total,
            int(few.sum()),
            MIN_SAMPLES,
            left - int(few.sum()),
        )
    shaky = decided & (condition > MAX_LIGHT_CONDITION)
    if shaky.any() and overall <= MAX_LIGHT_CONDITION:
        log.warning(
            "photometric stereo: %d of %d pixels (%.1f %%) are solved from lights with a "
            "condition number over %g (up to %.1f): their normals are sensitive to noise",
            int(shaky.sum()),
            total,
            100.0 * shaky.sum() / total,
            MAX_LIGHT_CONDITION,
            float(condition[shaky].max()),
        )


def flat_where_left_out(normals: np.ndarray) -> np.ndarray:
    """``normals`` with the texels :func:`photometric_stereo` left out (NaN) taken flat.

    For what needs a whole field (a BTF's range map is integrated over the whole sample
    and tiled): a texel no light decides contributes no slope. The solver's warning has
    said how many there are.

    Examples
    --------
    >>> flat_where_left_out(np.array([[[np.nan, np.nan, np.nan], [0.6, 0.0, 0.8]]])).tolist()
    [[[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]]]
    """
    normals = np.asarray(normals)
    left_out = ~np.all(np.isfinite(normals), axis=-1, keepdims=True)
    return np.where(left_out, np.array([0.0, 0.0, 1.0], normals.dtype), normals)


def periodic_component(image: np.ndarray) -> np.ndarray:
    """Periodic part of Moisan's periodic-plus-smooth decomposition: it tiles without seams.

    The smooth part is the harmonic-like image whose Laplacian equals the jumps across the
    opposite borders; removing it leaves an image with the same content whose own borders
    match when tiled.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)

    Returns
    -------
    periodic : ndarray of float32, same shape (same mean)

    Examples
    --------
    >>> ramp = np.tile(np.arange(8.0), (8, 1))
    >>> p = periodic_component(ramp)
    >>> bool(abs(p[:, 0] - p[:, -1]).max() < abs(ramp[:, 0] - ramp[:, -1]).max())
    True
    """
    image = np.asarray(image, dtype=np.float64)
    if image.ndim not in (2, 3):
        raise InputError(f"image: expected (H, W) or (H, W, C), got shape {image.shape}")
    height, width = image.shape[:2]
    boundary = np.zeros_like(image)
    boundary[0] += image[-1] - image[0]
    boundary[-1] += image[0] - image[-1]
    boundary[:, 0] += image[:, -1] - image[:, 0]
    boundary[:, -1] += image[:, 0] - image[:, -1]
    cos_row = np.cos(2.0 * np.pi * np.arange(height) / height)[:, None]
    cos_col = np.cos(2.0 * np.pi * np.arange(width) / width)[None, :]
    denominator = 2.0 * cos_row + 2.0 * cos_col - 4.0
    denominator[0, 0] = 1.0
    if image.ndim == 3:
        denominator = denominator[..., None]
    smooth_spectrum = np.fft.fft2(boundary, axes=(0, 1)) / denominator
    smooth_spectrum[0, 0] = 0.0
    smooth = np.real(np.fft.ifft2(smooth_spectrum, axes=(0, 1)))
    return (image - smooth).astype(np.float32)


def crossfade_tile(image: np.ndarray, *, overlap: float = 0.25) -> np.ndarray:
    """A seamless periodic tile of ``image`` by cross-fading its opposite border strips.

    Along each axis in turn, the last ``o`` lines are faded into the first ``o`` (weights
    w = sin^2 ramp, 0 -> 1) and then dropped: the tile's first line continues its last one,
    so it wraps with continuous values *and* slopes, and no content repeats inside a tile.
    The deviation from the mean is divided by sqrt(w^2 + (1 - w)^2), which keeps the
    variance of an uncorrelated mix, so the fade does not flatten the relief.

    Parameters
    ----------
    image : ndarray, shape (H, W)
    overlap : float
        Fraction of each side faded (o = round(overlap * side)).

    Returns
    -------
    tile : ndarray of float32, shape (H - o_H, W - o_W), periodic

    Examples
    --------
    >>> ramp = np.tile(np.arange(16.0), (16, 1))
    >>> tile = crossfade_tile(ramp)
    >>> tile.shape, bool(abs(tile[:, 0] - tile[:, -1]).max() < 2.0)
    ((12, 12), True)
    """
    tile = np.asarray(image, dtype=np.float64)
    if tile.ndim != 2:
        raise InputError(f"image: expected a 2-D array, got shape {tile.shape}")
    if not 0.0 <= overlap < 0.5:
        raise InputError(f"overlap: expected a fraction in [0, 0.5), got {overlap}")
    mean = tile.mean()
    tile = tile - mean
    for axis in (0, 1):
        size = tile.shape[axis]
        strip = int(round(overlap * size))
        if strip < 1:
            continue
        tile = np.moveaxis(tile, axis, 0)
        weight = np.sin(0.5 * np.pi * (np.arange(strip) + 0.5) / strip)[:, None] ** 2
        head, tail = tile[:strip], tile[size - strip :]
        faded = (weight * head + (1 - weight) * tail) / np.sqrt(weight**2 + (1 - weight) ** 2)
        tile = np.moveaxis(np.concatenate([faded, tile[strip : size - strip]]), 0, axis)
    return (tile + mean).astype(np.float32)


def enlarge_range_map(
    height: np.ndarray,
    shape: tuple[int, int],
    *,
    method: str = "crossfade",
    seed: int | None = 0,
) -> np.ndarray:
    """Enlarge a range map to any ``shape`` by seamless tiling.

    Stands in for the roller method of the paper, which also repeats a seam-free toroidal
    tile of the sample: the tile is made periodic by :func:`crossfade_tile` (continuous
    heights and slopes across the wrap; default) or by :func:`periodic_component`
    (continuous heights, but slope creases at the tile borders show under grazing light),
    or taken as it is (``"wrap"``, for a tile that is already periodic); a seeded random
    cyclic shift chooses where the tiling starts.

    Parameters
    ----------
    height : ndarray, shape (h, w)
        Range map of the sample.
    shape : (int, int)
        Output (H, W), any size.
    method : {"crossfade", "periodic", "wrap"}
    seed : int or None
        Seed of the starting offset (None: no offset).

    Returns
    -------
    enlarged : ndarray of float32, shape ``shape``; periodic when ``shape`` is a multiple
    of the tile.

    Examples
    --------
    >>> enlarge_range_map(np.random.default_rng(0).random((8, 8)), (20, 12)).shape
    (20, 12)
    """
    height = np.asarray(height, dtype=np.float32)
    if height.ndim != 2:
        raise InputError(f"height: expected a 2-D range map, got shape {height.shape}")
    out_h, out_w = (int(s) for s in shape)
    if out_h < 1 or out_w < 1:
        raise InputError(f"shape: must be positive, got {shape}")
    if method == "crossfade":
        tile = crossfade_tile(height)
    elif method == "periodic":
        tile = periodic_component(height)
    elif method == "wrap":
        tile = height
    else:
        raise InputError(f"method: expected 'crossfade', 'periodic' or 'wrap', got {method!r}")
    if seed is not None:
        rng = np.random.default_rng(seed)
        offset = (int(rng.integers(tile.shape[0])), int(rng.integers(tile.shape[1])))
        tile = np.roll(tile, offset, (0, 1))
    repeats = (-(-out_h // tile.shape[0]), -(-out_w // tile.shape[1]))
    return np.tile(tile, repeats)[:out_h, :out_w].astype(np.float32)


def btf_direction_vectors(directions: np.ndarray) -> np.ndarray:
    """BTF (theta, phi) directions in degrees to unit vectors in the image frame used here.

    BTF azimuths (:mod:`imagemap.btf.core`, :mod:`imagemap.btf.materials`) count y along the
    image rows (down the screen); the image frame of :mod:`imagemap.render` has y up, so the
    y component changes sign.

    Examples
    --------
    >>> btf_direction_vectors(np.array([[90.0, 90.0]])).round(6).tolist()
    [[0.0, -1.0, 0.0]]
    """
    vectors = directions_to_vectors(directions)
    vectors[:, 1] *= -1.0
    return vectors + 0.0


def range_map_from_btf(
    btf, *, view: int | None = None, min_intensity: float = 0.0, mirror: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Range map, normals and albedo of a BTF from all its lights at one view.

    Parameters
    ----------
    btf : imagemap.btf.BTF
    view : int, optional
        View index; default the top view (smallest polar angle).
    min_intensity, mirror : see :func:`photometric_stereo` and :func:`frankot_chellappa`.

    Returns
    -------
    height : ndarray (H, W) float32, in pixels
    normals : ndarray (H, W, 3) float32
    albedo : ndarray (H, W, 3) float32

    Examples
    --------
    >>> height, normals, albedo = range_map_from_btf(sample)  # doctest: +SKIP
    """
    if view is None:
        view = int(np.argmin(btf.view_dirs[:, 0]))
    images = np.stack([btf.image(light, view) for light in range(btf.n_lights)])
    lights = btf_direction_vectors(btf.light_dirs)
    normals, albedo = photometric_stereo(images, lights, min_intensity=min_intensity)
    normals, albedo = flat_where_left_out(normals), np.nan_to_num(albedo)
    return frankot_chellappa(normals, mirror=mirror), normals, albedo
