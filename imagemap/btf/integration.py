"""Heights from a normal field: Frankot-Chellappa over the frame, or least squares on a mask.

A photometric-stereo normal field n gives the slopes p = dz/dx = -n_x / n_z and
q = dz/drow = n_y / n_z (image frame of :mod:`imagemap.render`: x along the columns, y up
the screen, z out of the surface). Two integrations:

* :func:`frankot_chellappa` projects (p, q) onto integrable fields in Fourier space over the
  whole frame (Frankot & Chellappa 1988). Where only part of the frame is the object, the
  background's slopes are integrated with it and bend the object's relief; with ``mask``
  they are set to 0 (a flat background), which removes most of that.
* :func:`poisson_integration` solves the least-squares problem on the mask only: for every
  pair of horizontally or vertically adjacent mask pixels, z[j] - z[i] equals the mean of
  their two slopes. Pixels outside the mask take no part; each connected part of the mask
  gets its own zero mean (the offset between parts is not observable). The normal
  equations are a sparse graph Laplacian, solved directly (scipy.sparse's SuperLU): about
  1 s for the 37,000 pixels of a 108 px sphere, but it grows faster than the pixel count
  (on a loaded 2-core machine a 512^2 frame took 14 s; 1024^2 almost 3 minutes with the
  default ordering). A multigrid solver (pyamg) would scale; not a dependency yet.

:func:`integrate_normals` chooses between them. Heights are in pixels.

Example
-------
>>> import numpy as np
>>> from imagemap.render import normals_from_height
>>> ramp = np.add.outer(np.zeros(12), 0.5 * np.arange(12))
>>> height = poisson_integration(normals_from_height(ramp), mask=np.ones((12, 12), bool))
>>> round(float(np.median(np.diff(height, axis=1))), 3)
0.5
"""

from __future__ import annotations

import numpy as np

from imagemap.io import InputError

__all__ = ["frankot_chellappa", "integrate_normals", "poisson_integration", "slopes"]

#: n_z is clamped to at least this before dividing: a near-vertical normal (a sphere's rim,
#: noise at grazing angles) would otherwise give an unbounded slope. 0.05 bounds the slope
#: at 20 (87 degrees), which keeps the grey sphere's rim (psm "gray" set, tests/data) from
#: dominating the solve.
MIN_NZ = 0.05

#: Tikhonov weight that makes the Laplacian of a masked solve invertible (its constant
#: vectors are its null space); 1e-9 changes the heights by less than 1e-6 px on 256^2.
POISSON_RIDGE = 1e-9

#: The integrations :func:`integrate_normals` knows.
INTEGRATIONS = ("poisson", "frankot_chellappa")


def _normals(normals) -> np.ndarray:
    normals = np.asarray(normals, dtype=np.float64)
    if normals.ndim != 3 or normals.shape[2] != 3 or min(normals.shape[:2]) < 1:
        raise InputError(f"normals: expected (H, W, 3), got {normals.shape}")
    if not np.all(np.isfinite(normals)):
        raise InputError("normals: have NaN or infinite values")
    return normals


def _mask(mask, shape) -> np.ndarray:
    mask = np.asarray(mask)
    if mask.shape != tuple(shape):
        raise InputError(f"mask: shape {mask.shape} differs from the normals' {tuple(shape)}")
    mask = mask.astype(bool)
    if not mask.any():
        raise InputError("mask: selects no pixel")
    return mask


def slopes(normals: np.ndarray, *, min_nz: float = MIN_NZ) -> tuple[np.ndarray, np.ndarray]:
    """(dz/dx, dz/drow) of a normal field, n_z clamped to ``min_nz``.

    Example
    -------
    >>> p, q = slopes(np.array([[[0.6, 0.0, 0.8]]]))
    >>> round(float(p[0, 0]), 6), float(q[0, 0])
    (-0.75, 0.0)
    """
    normals = _normals(normals)
    nz = np.maximum(normals[..., 2], min_nz)
    return -normals[..., 0] / nz, normals[..., 1] / nz


def frankot_chellappa(
    normals: np.ndarray,
    *,
    mask: np.ndarray | None = None,
    mirror: bool = True,
    min_nz: float = MIN_NZ,
) -> np.ndarray:
    """Integrate a normal field into a height map (Frankot-Chellappa, 1988).

    The gradients p = dz/dx = -n_x / n_z and q = dz/dy = -n_y / n_z are projected in Fourier
    space onto the nearest integrable field, Z = -i (w_x P + w_y Q) / (w_x^2 + w_y^2).

    Parameters
    ----------
    normals : ndarray, shape (H, W, 3)
        Unit normals in the image frame (x right, y up, z out).
    mask : ndarray of bool, shape (H, W), optional
        The object: slopes outside it are set to 0 (a flat background) before the
        projection, and the heights' mean is taken over it.
    mirror : bool
        Integrate the even (mirror) extension of the gradients, so that a sample that is not
        periodic gets no wrap-around bending; False treats the field as periodic.
    min_nz : float
        n_z is clamped to at least this, bounding the slope of near-vertical normals.

    Returns
    -------
    height : ndarray of float32, shape (H, W)
        Heights in pixels, zero mean over the mask (or the frame).

    Examples
    --------
    >>> from imagemap.render import normals_from_height
    >>> ramp = np.add.outer(np.zeros(16), 0.3 * np.arange(16))
    >>> height = frankot_chellappa(normals_from_height(ramp))
    >>> round(float(np.median(np.diff(height, axis=1))), 1)
    0.3
    """
    d_col, d_row = slopes(normals, min_nz=min_nz)
    height, width = d_col.shape
    if mask is not None:
        mask = _mask(mask, (height, width))
        d_col = np.where(mask, d_col, 0.0)
        d_row = np.where(mask, d_row, 0.0)
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
    z -= z[mask].mean() if mask is not None else z.mean()
    return z.astype(np.float32)


def poisson_integration(
    normals: np.ndarray, *, mask: np.ndarray, min_nz: float = MIN_NZ
) -> np.ndarray:
    """Least-squares heights on ``mask`` only (see the module docstring).

    Parameters
    ----------
    normals : ndarray, shape (H, W, 3)
        Unit normals in the image frame (x right, y up, z out).
    mask : ndarray of bool, shape (H, W)
        Pixels whose heights are solved; the others are NaN.
    min_nz : float
        n_z is clamped to at least this, bounding the slopes.

    Returns
    -------
    height : ndarray of float32, shape (H, W)
        Heights in pixels, zero mean on each connected part of the mask, NaN outside.

    Examples
    --------
    >>> from imagemap.render import normals_from_height
    >>> bump = np.add.outer(np.arange(6.0), np.zeros(6))  # rises down the rows
    >>> mask = np.zeros((6, 6), bool)
    >>> mask[1:5, 1:5] = True
    >>> height = poisson_integration(normals_from_height(bump), mask=mask)
    >>> np.round(height[1:5, 2], 3).tolist(), bool(np.isnan(height[0, 0]))
    ([-1.5, -0.5, 0.5, 1.5], True)
    """
    from scipy import ndimage, sparse  # deferred: scipy.sparse, the masked solve only
    from scipy.sparse.linalg import spsolve  # deferred: scipy.sparse, the masked solve only

    d_col, d_row = slopes(normals, min_nz=min_nz)
    mask = _mask(mask, d_col.shape)
    index = np.full(mask.shape, -1, np.int64)
    index[mask] = np.arange(int(mask.sum()))
    starts, ends, targets = [], [], []
    # Horizontal pairs (slope along x), then vertical pairs (slope along the rows).
    for slope, a, b in (
        (d_col, (slice(None), slice(None, -1)), (slice(None), slice(1, None))),
        (d_row, (slice(None, -1), slice(None)), (slice(1, None), slice(None))),
    ):
        both = mask[a] & mask[b]
        starts.append(index[a][both])
        ends.append(index[b][both])
        targets.append(0.5 * (slope[a][both] + slope[b][both]))
    start, end, target = (np.concatenate(v) for v in (starts, ends, targets))
    n_pixels, n_pairs = int(mask.sum()), len(start)
    rows = np.repeat(np.arange(n_pairs), 2)
    columns = np.stack([end, start], axis=1).ravel()
    values = np.tile([1.0, -1.0], n_pairs)
    difference = sparse.csr_matrix((values, (rows, columns)), shape=(n_pairs, n_pixels))
    laplacian = (difference.T @ difference + POISSON_RIDGE * sparse.identity(n_pixels)).tocsc()
    # A symmetric matrix: the minimum-degree ordering of A^T + A fills in less than the
    # default COLAMD (512^2 frame: 13.8 s against 22.2 s on a loaded 2-core machine).
    solution = spsolve(laplacian, difference.T @ target, permc_spec="MMD_AT_PLUS_A")
    # Each connected part floats on its own: give each a zero mean.
    labels, count = ndimage.label(mask)
    part = labels[mask] - 1
    means = np.bincount(part, weights=solution, minlength=count) / np.bincount(part)
    height = np.full(mask.shape, np.nan)
    height[mask] = solution - means[part]
    return height.astype(np.float32)


def integrate_normals(
    normals: np.ndarray,
    *,
    mask: np.ndarray | None = None,
    method: str = "poisson",
    min_nz: float = MIN_NZ,
) -> np.ndarray:
    """Heights of a normal field: :func:`poisson_integration` on ``mask`` (NaN outside), or
    :func:`frankot_chellappa` (``mask`` sets the background flat).

    Without a mask the whole frame is the object (Poisson then solves every pixel).

    Example
    -------
    >>> integrate_normals(np.dstack([np.zeros((3, 3, 2)), np.ones((3, 3))])).tolist()[0]
    [0.0, 0.0, 0.0]
    """
    if method not in INTEGRATIONS:
        raise InputError(f"method: {method!r} is not one of {INTEGRATIONS}")
    if method == "frankot_chellappa":
        return frankot_chellappa(normals, mask=mask, min_nz=min_nz)
    if mask is None:
        mask = np.ones(np.shape(normals)[:2], bool)
    return poisson_integration(normals, mask=mask, min_nz=min_nz)
