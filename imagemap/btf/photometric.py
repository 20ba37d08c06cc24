"""Range maps of BTF materials by over-determined photometric stereo (section 2.1 of the
moving-average BTF paper, papers/moving-average-btf-model.txt).

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

import numpy as np

from imagemap.io import InputError

__all__ = [
    "btf_direction_vectors",
    "crossfade_tile",
    "enlarge_range_map",
    "frankot_chellappa",
    "periodic_component",
    "photometric_stereo",
    "range_map_from_btf",
]

#: Rec. 709 luminance weights: the normals are fitted on luminance, the albedo per channel.
LUMINANCE = (0.2126, 0.7152, 0.0722)


def photometric_stereo(
    images: np.ndarray,
    light_dirs: np.ndarray,
    *,
    min_intensity: float = 0.0,
    ridge: float = 1e-6,
) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares normals and albedo from N >= 3 images of one view under known lights.

    Parameters
    ----------
    images : ndarray, shape (N, H, W, C) or (N, H, W)
        Linear intensities, one image per light, all from the same (fixed) view.
    light_dirs : ndarray, shape (N, 3)
        Unit vectors towards each light, z up (lights below the horizon are ignored).
    min_intensity : float
        Samples of a texel at or below this (on luminance) are left out of its fit, so cast
        and attached shadows do not bend the normal; the default 0 drops black samples
        (attached shadows); a negative value keeps every sample above the horizon.
    ridge : float
        Tikhonov term that keeps texels with fewer than three usable lights solvable.

    Returns
    -------
    normals : ndarray of float32, shape (H, W, 3)
        Unit normals (z >= 0 is not enforced; it is what the data say).
    albedo : ndarray of float32, shape (H, W, C)
        Per-channel Lambertian albedo (C = 1 for grey input).

    Examples
    --------
    >>> lights = np.array([[0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8]], np.float32)
    >>> images = np.full((3, 4, 4), 0.5, np.float32) * lights[:, 2, None, None]
    >>> normals, albedo = photometric_stereo(images, lights)
    >>> normals[0, 0].round(3).tolist(), round(float(albedo[0, 0, 0]), 3)
    ([0.0, 0.0, 1.0], 0.5)
    """
    images = np.asarray(images, dtype=np.float32)
    if images.ndim == 3:
        images = images[..., None]
    if images.ndim != 4:
        raise InputError(f"images: expected (N, H, W[, C]), got shape {images.shape}")
    lights = np.asarray(light_dirs, dtype=np.float64)
    n, height, width, channels = images.shape
    if lights.shape != (n, 3):
        raise InputError(f"light_dirs: expected ({n}, 3) for {n} images, got {lights.shape}")
    norms = np.linalg.norm(lights, axis=1)
    if np.any(norms == 0) or not np.all(np.isfinite(lights)):
        raise InputError("light_dirs: every light needs a finite non-zero direction")
    lights = lights / norms[:, None]
    above = lights[:, 2] > 0
    if above.sum() < 3:
        raise InputError(f"light_dirs: need at least 3 lights above the horizon, got {above.sum()}")
    if not np.all(np.isfinite(images)):
        raise InputError("images: have NaN or infinite values")

    if channels == 3:
        grey = images @ np.asarray(LUMINANCE, np.float32)
    else:
        grey = images.mean(axis=-1)
    intensity = grey.reshape(n, -1).astype(np.float64)  # (N, P)
    weights = (intensity > min_intensity) & above[:, None]
    if weights.all():
        # Every texel sees the same lights: one pseudo-inverse serves all (Woodham).
        scaled_normal = np.linalg.pinv(lights) @ intensity  # (3, P)
        scaled_normal = scaled_normal.T
    else:
        # Per-texel weighted normal equations, solved as a batch of 3x3 systems.
        w = weights.astype(np.float64)
        gram = np.einsum("np,ni,nj->pij", w, lights, lights)
        gram += ridge * np.eye(3)
        rhs = np.einsum("np,ni->pi", w * intensity, lights)
        scaled_normal = np.linalg.solve(gram, rhs[..., None])[..., 0]
    length = np.linalg.norm(scaled_normal, axis=1, keepdims=True)
    normals = np.where(length > 0, scaled_normal / np.maximum(length, 1e-12), [0.0, 0.0, 1.0])

    # Per-channel albedo: least squares of I_c = rho_c * shading over the used samples.
    shading = np.clip(lights @ normals.T, 0.0, None) * weights  # (N, P)
    colour = images.reshape(n, -1, channels).astype(np.float64)
    numerator = np.einsum("np,npc->pc", shading, colour)
    denominator = np.einsum("np,np->p", shading, shading)[:, None]
    albedo = numerator / np.maximum(denominator, 1e-12)
    return (
        normals.reshape(height, width, 3).astype(np.float32),
        albedo.reshape(height, width, channels).astype(np.float32),
    )


def frankot_chellappa(
    normals: np.ndarray, *, mirror: bool = True, min_nz: float = 0.05
) -> np.ndarray:
    """Integrate a normal field into a height map (Frankot-Chellappa, 1988).

    The gradients p = dz/dx = -n_x / n_z and q = dz/dy = -n_y / n_z are projected in Fourier
    space onto the nearest integrable field, Z = -i (w_x P + w_y Q) / (w_x^2 + w_y^2).

    Parameters
    ----------
    normals : ndarray, shape (H, W, 3)
        Unit normals in the image frame (x right, y up, z out).
    mirror : bool
        Integrate the even (mirror) extension of the gradients, so that a sample that is not
        periodic gets no wrap-around bending; False treats the field as periodic.
    min_nz : float
        n_z is clamped to at least this, bounding the slope of near-vertical normals.

    Returns
    -------
    height : ndarray of float32, shape (H, W)
        Heights in pixels, zero mean (the offset is not observable).

    Examples
    --------
    >>> from imagemap.render import normals_from_height
    >>> ramp = np.add.outer(np.zeros(16), 0.3 * np.arange(16))
    >>> height = frankot_chellappa(normals_from_height(ramp))
    >>> round(float(np.median(np.diff(height, axis=1))), 1)
    0.3
    """
    normals = np.asarray(normals, dtype=np.float64)
    if normals.ndim != 3 or normals.shape[2] != 3:
        raise InputError(f"normals: expected (H, W, 3), got {normals.shape}")
    nz = np.maximum(normals[..., 2], min_nz)
    d_col = -normals[..., 0] / nz  # dz/dx
    d_row = normals[..., 1] / nz  # dz/drow = -dz/dy, y being up the screen
    height, width = d_col.shape
    if mirror:
        # Even extension of z: dz/dx flips sign in the left-right mirror, dz/drow in the
        # up-down mirror.
        d_col = np.block([[d_col, -d_col[:, ::-1]], [d_col[::-1], -d_col[::-1, ::-1]]])
        d_row = np.block([[d_row, d_row[:, ::-1]], [-d_row[::-1], -d_row[::-1, ::-1]]])
    rows, cols = d_col.shape
    w_row = 2.0 * np.pi * np.fft.fftfreq(rows)[:, None]
    w_col = 2.0 * np.pi * np.fft.fftfreq(cols)[None, :]
    denominator = w_row**2 + w_col**2
    denominator[0, 0] = 1.0
    spectrum = (-1j * w_col * np.fft.fft2(d_col) - 1j * w_row * np.fft.fft2(d_row)) / denominator
    spectrum[0, 0] = 0.0
    z = np.real(np.fft.ifft2(spectrum))[:height, :width]
    return (z - z.mean()).astype(np.float32)


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
    from imagemap.btf.core import directions_to_vectors

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
    return frankot_chellappa(normals, mirror=mirror), normals, albedo
