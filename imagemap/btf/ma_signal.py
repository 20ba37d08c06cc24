"""Signal blocks of the moving-average BTF model (Havlicek & Haindl).

The image-processing steps :mod:`imagemap.btf.moving_average` chains together, each
usable alone: the Karhunen-Loeve spectral decorrelation, the collapse of a periodic
(seamlessly tiling) Laplacian pyramid, the random-decrement signature and the MA
kernel made from it, the synthesis of one band by convolving white noise with a
kernel (circular FFT, so the band tiles), and the segmentation of BTF images into
subspaces by K-means in CIELAB.
"""

from __future__ import annotations

import numpy as np

from imagemap.io import InputError

__all__ = [
    "collapse_periodic",
    "inverse_karhunen_loeve",
    "karhunen_loeve",
    "ma_kernel_from_signature",
    "random_decrement_signature",
    "segment_subspaces",
    "synthesize_band",
]


# --------------------------------------------------------------------------- K-L transform
def karhunen_loeve(image: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Spectral decorrelation: project the channels on the eigenvectors of their covariance.

    Parameters
    ----------
    image : ndarray, shape (H, W, C)

    Returns
    -------
    bands : ndarray (H, W, C) float32
        Decorrelated bands, strongest first (their covariance is diagonal).
    mean : ndarray (C,)
        Channel means.
    basis : ndarray (C, C)
        Rows are the eigenvectors: ``bands = (image - mean) @ basis.T``.

    Examples
    --------
    >>> x = np.random.default_rng(0).random((8, 8, 3))
    >>> bands, mean, basis = karhunen_loeve(x)
    >>> bool(np.allclose(inverse_karhunen_loeve(bands, mean, basis), x, atol=1e-5))
    True
    """
    image = np.asarray(image, dtype=np.float64)
    if image.ndim != 3:
        raise InputError(f"image: expected (H, W, C), got shape {image.shape}")
    pixels = image.reshape(-1, image.shape[2])
    mean = pixels.mean(axis=0)
    covariance = np.cov(pixels - mean, rowvar=False).reshape(image.shape[2], image.shape[2])
    eigenvalues, eigenvectors = np.linalg.eigh(covariance)
    basis = eigenvectors[:, np.argsort(eigenvalues)[::-1]].T
    # Fix each eigenvector's sign (largest entry positive): same data, same model bytes.
    basis *= np.sign(basis[np.arange(len(basis)), np.argmax(np.abs(basis), axis=1)])[:, None]
    bands = (image - mean) @ basis.T
    return bands.astype(np.float32), mean.astype(np.float32), basis.astype(np.float32)


def inverse_karhunen_loeve(bands: np.ndarray, mean: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """Inverse of :func:`karhunen_loeve`: ``bands @ basis + mean`` (the basis is orthonormal)."""
    return (np.asarray(bands, np.float32) @ np.asarray(basis, np.float32) + mean).astype(np.float32)


# ------------------------------------------------------------------ periodic pyramid collapse
def _expand_wrap(image: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Bilinear 2x upsampling like :func:`imagemap.core.pyramid.expand`, wrapping at the borders.

    Synthetic factors are periodic; wrapping keeps the collapsed texture tileable.
    """
    height, width = shape
    ys = np.arange(height, dtype=np.float32) / 2
    xs = np.arange(width, dtype=np.float32) / 2
    y0, x0 = np.floor(ys).astype(np.intp), np.floor(xs).astype(np.intp)
    fy = (ys - y0)[:, None]
    fx = (xs - x0)[None, :]
    y0, y1 = y0 % image.shape[0], (y0 + 1) % image.shape[0]
    x0, x1 = x0 % image.shape[1], (x0 + 1) % image.shape[1]
    top = image[y0][:, x0] * (1 - fx) + image[y0][:, x1] * fx
    bottom = image[y1][:, x0] * (1 - fx) + image[y1][:, x1] * fx
    return (top * (1 - fy) + bottom * fy).astype(np.float32)


def collapse_periodic(pyramid: list[np.ndarray]) -> np.ndarray:
    """Collapse a Laplacian pyramid of periodic 2-D factors with wrapping expansion.

    Examples
    --------
    >>> flat = [np.zeros((8, 8)), np.zeros((4, 4)), np.ones((2, 2))]
    >>> float(collapse_periodic(flat).mean())
    1.0
    """
    image = np.asarray(pyramid[-1], dtype=np.float32)
    for band in reversed(pyramid[:-1]):
        image = np.asarray(band, np.float32) + _expand_wrap(image, band.shape[:2])
    return image


# ------------------------------------------------------------------ random decrement, MA kernel
def random_decrement_signature(
    factor: np.ndarray, *, support: int = 13, threshold: float = 0.5
) -> tuple[np.ndarray, int]:
    """Random-decrement average of the windows around threshold crossings (Eq. 2).

    The factor is centred; gamma = ``threshold`` * sigma. Pixel r is a crossing when
    Y_r >= gamma while at least one of its left/right neighbours and one of its up/down
    neighbours are below gamma. Only crossings whose whole window lies inside are used.
    The sum over crossings is one FFT cross-correlation of the crossing indicator with Y.

    Parameters
    ----------
    factor : ndarray (H, W)
        A mono-spectral band-limited factor.
    support : int
        Odd window width.
    threshold : float
        gamma in units of sigma.

    Returns
    -------
    signature : ndarray (support, support) float32
        Mean window, centred on the crossing (zeros when there is no crossing).
    count : int
        Number of crossings, cardinality of Gamma.

    Examples
    --------
    >>> y = np.random.default_rng(0).standard_normal((64, 64))
    >>> signature, count = random_decrement_signature(y, support=5)
    >>> signature.shape, count > 100
    ((5, 5), True)
    """
    y = np.asarray(factor, dtype=np.float64)
    if y.ndim != 2:
        raise InputError(f"factor: expected a 2-D band, got shape {y.shape}")
    radius = support // 2
    y = y - y.mean()
    gamma = threshold * y.std()
    above = y >= gamma
    below = ~above
    row_neighbour_below = np.zeros_like(above)
    row_neighbour_below[:, 1:-1] = below[:, :-2] | below[:, 2:]
    column_neighbour_below = np.zeros_like(above)
    column_neighbour_below[1:-1, :] = below[:-2, :] | below[2:, :]
    crossing = above & row_neighbour_below & column_neighbour_below
    interior = np.zeros_like(crossing)
    interior[radius : y.shape[0] - radius, radius : y.shape[1] - radius] = True
    crossing &= interior
    count = int(crossing.sum())
    if count == 0:
        return np.zeros((support, support), np.float32), 0
    # sum_r M_r Y_{r+s} = circular cross-correlation; no wrap for |s| <= radius (interior).
    correlation = np.real(np.fft.ifft2(np.conj(np.fft.fft2(crossing)) * np.fft.fft2(y)))
    offsets = np.arange(-radius, radius + 1)
    window = correlation[np.ix_(offsets % y.shape[0], offsets % y.shape[1])]
    return (window / count).astype(np.float32), count


def ma_kernel_from_signature(
    signature: np.ndarray, variance: float, *, kernel: str = "signature"
) -> np.ndarray:
    """Turn a random-decrement signature into an MA filter with the factor's variance.

    Parameters
    ----------
    signature : ndarray (s, s)
        From :func:`random_decrement_signature`.
    variance : float
        Variance of the factor; the filter's energy sum(h^2) is set to it, so white noise
        of unit variance convolved with it has this variance.
    kernel : {"spectral_root", "signature"}
        "spectral_root": the zero-phase filter whose autocorrelation is the symmetrized
        signature (its power spectrum is clipped at 0 and square-rooted); "signature": the
        averaged windows themselves.

    Returns
    -------
    kernel : ndarray (s, s) float32, centred

    Examples
    --------
    >>> delta = np.zeros((5, 5)); delta[2, 2] = 1.0
    >>> ma_kernel_from_signature(delta, 4.0, kernel="spectral_root")[2, 2].round(3)
    np.float32(2.0)
    """
    signature = np.asarray(signature, dtype=np.float64)
    size = signature.shape[0]
    if kernel == "signature":
        filt = signature
    elif kernel == "spectral_root":
        symmetric = 0.5 * (signature + signature[::-1, ::-1])
        fft_size = 4 * size
        padded = np.zeros((fft_size, fft_size))
        offsets = np.arange(size) - size // 2
        padded[np.ix_(offsets % fft_size, offsets % fft_size)] = symmetric
        power = np.clip(np.real(np.fft.fft2(padded)), 0.0, None)
        root = np.real(np.fft.ifft2(np.sqrt(power)))
        filt = root[np.ix_(offsets % fft_size, offsets % fft_size)]
    else:
        raise InputError(f"kernel: expected 'spectral_root' or 'signature', got {kernel!r}")
    energy = float(np.sum(filt**2))
    if energy <= 0 or not np.isfinite(energy):
        filt = np.zeros_like(filt)
        filt[size // 2, size // 2] = 1.0
        energy = 1.0
    return (filt * np.sqrt(max(variance, 0.0) / energy)).astype(np.float32)


def synthesize_band(
    kernel: np.ndarray,
    shape: tuple[int, int],
    *,
    noise: np.ndarray | None = None,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """White noise circularly convolved with an MA kernel (Eq. 1), any size, seamless.

    Parameters
    ----------
    kernel : ndarray (s, s), centred
    shape : (H, W)
    noise : ndarray (H, W), optional
        The uncorrelated input e_r; default standard normal from ``rng``.
    rng : numpy.random.Generator, optional
        Needed when ``noise`` is not given.

    Returns
    -------
    band : ndarray (H, W) float32, periodic

    Examples
    --------
    >>> k = np.zeros((3, 3)); k[1, 1] = 1.0
    >>> e = np.random.default_rng(0).standard_normal((8, 8))
    >>> bool(np.allclose(synthesize_band(k, (8, 8), noise=e), e, atol=1e-6))
    True
    """
    height, width = (int(s) for s in shape)
    if noise is None:
        if rng is None:
            raise InputError("synthesize_band: give noise or rng")
        noise = rng.standard_normal((height, width))
    kernel = np.asarray(kernel, dtype=np.float64)
    wrapped = np.zeros((height, width))
    rows = (np.arange(kernel.shape[0]) - kernel.shape[0] // 2) % height
    cols = (np.arange(kernel.shape[1]) - kernel.shape[1] // 2) % width
    # add.at: a kernel wider than a tiny coarse level folds onto itself (circular).
    np.add.at(wrapped, (rows[:, None], cols[None, :]), kernel)
    band = np.real(np.fft.ifft2(np.fft.fft2(noise) * np.fft.fft2(wrapped)))
    return band.astype(np.float32)


# ------------------------------------------------------------------------ subspaces (K-means)
def _lab_features(image: np.ndarray, scale: float) -> np.ndarray:
    from skimage.color import rgb2lab  # deferred: skimage.color, the features only

    lab = rgb2lab(np.clip(image / scale, 0.0, 1.0)).reshape(-1, 3)
    return np.concatenate([lab.mean(axis=0), lab.std(axis=0)])


def segment_subspaces(
    features: np.ndarray, n_subspaces: int, *, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """K-means segmentation of BTF images by their CIELAB features.

    Parameters
    ----------
    features : ndarray (N, F)
        Per image: mean and standard deviation of L*, a*, b*.
    n_subspaces : int
        Clusters (clipped to N).
    seed : int

    Returns
    -------
    labels : ndarray (N,) int
        Subspace of each image, renumbered 0..K-1 by first appearance.
    representatives : ndarray (K,) int
        Per subspace, the image nearest its centroid.

    Examples
    --------
    >>> f = np.array([[0.0], [0.1], [10.0], [10.2]])
    >>> segment_subspaces(f, 2)[0].tolist()
    [0, 0, 1, 1]
    """
    from scipy.cluster.vq import kmeans2  # deferred: scipy.cluster, segmentation only

    features = np.asarray(features, dtype=np.float64)
    n = features.shape[0]
    k = int(min(n_subspaces, n))
    if k == 1:
        centre = features.mean(axis=0)
        return np.zeros(n, np.intp), np.array([np.argmin(((features - centre) ** 2).sum(1))])
    spread = features.std(axis=0)
    whitened = features / np.where(spread > 0, spread, 1.0)
    centroids, labels = kmeans2(whitened, k, minit="++", rng=np.random.default_rng(seed))
    _, first = np.unique(labels, return_index=True)
    order = labels[np.sort(first)]
    renumber = np.full(k, -1)
    renumber[order] = np.arange(len(order))
    labels = renumber[labels]
    centroids = centroids[order]
    distances = ((whitened[:, None, :] - centroids[None]) ** 2).sum(-1)
    distances = np.where(labels[:, None] == np.arange(len(order)), distances, np.inf)
    return labels.astype(np.intp), np.argmin(distances, axis=0)
