"""Procedural solid textures: gradient (Perlin) noise, fractal sums, marble, wood, stripes, spots.

The classic tools of texture mapping (lecture notes "More Texture Mapping"):
a lattice of seeded random unit gradients interpolated with a smooth fade (Perlin
noise), sums of octaves whose frequency grows by ``lacunarity`` and whose amplitude
shrinks by ``persistence`` (fbm, turbulence), marble ``sin(k . p + A * noise(p))``,
wood rings of the distance to an axis perturbed by noise, and stripes and spots.

Every function takes ``points`` of shape ``(..., 2)`` or ``(..., 3)`` (any leading
shape: a pixel grid, a list of mesh hit points) and returns float32 values of shape
``points.shape[:-1]``, so colour can be a function of the 3-D surface point and moves
with the shape. Randomness comes only from ``seed``: an int, or a
``numpy.random.Generator`` from which the lattice tables are drawn. The same seed gives
the same bytes.

The BTF experiment's procedural materials (:mod:`imagemap.btf.materials`) are made of
them, which is why they live in ``imagemap``; :mod:`data_gen.procedural` re-exports them for
the example classes (data_gen uses imagemap, never the reverse).

Value ranges
------------
``perlin``, ``fbm``: [-1, 1] (scaled so the bound is exact; typical std about 0.2-0.3).
``turbulence``, ``marble``, ``wood``, ``stripes``, ``spots``: [0, 1].

Example
-------
>>> import numpy as np
>>> from imagemap.btf.procedural import fbm, marble, color_ramp
>>> yy, xx = np.mgrid[0:64, 0:64] / 64.0
>>> points = np.stack([xx, yy], axis=-1)
>>> fbm(points, octaves=5, seed=1, frequency=4.0).shape
(64, 64)
>>> colors = color_ramp(marble(points, seed=1), [(0.9, 0.9, 0.85), (0.3, 0.3, 0.35)])
>>> colors.shape
(64, 64, 3)
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from imagemap.io import InputError

__all__ = [
    "Seed",
    "color_ramp",
    "fbm",
    "marble",
    "perlin",
    "spots",
    "stripes",
    "turbulence",
    "wood",
    "worley",
]

Seed = int | np.random.Generator

#: Size of the lattice hash (coordinates wrap with this period).
_TABLE_SIZE = 256

#: Offsets that move each octave off the lattice of the previous one, so the octaves do
#: not all vanish together at integer points (gradient noise is 0 on its lattice).
_OCTAVE_SHIFT = np.array([0.3183099, 0.7071068, 0.5772157], dtype=np.float32)


def _generator(seed: Seed) -> np.random.Generator:
    if isinstance(seed, np.random.Generator):
        return seed
    return np.random.default_rng(int(seed))


def _as_points(points: np.ndarray) -> np.ndarray:
    points = np.asarray(points, dtype=np.float32)
    if points.ndim < 1 or points.shape[-1] not in (2, 3):
        raise InputError(
            f"points: expected an array of shape (..., 2) or (..., 3), got {points.shape}"
        )
    return points


class _Lattice:
    """Seeded permutation table with a unit gradient and a jitter point per hash value."""

    def __init__(self, seed: Seed, dims: int):
        rng = _generator(seed)
        permutation = rng.permutation(_TABLE_SIZE).astype(np.int64)
        self.permutation = np.concatenate([permutation, permutation])
        gradients = rng.standard_normal((_TABLE_SIZE, dims))
        self.gradients = (gradients / np.linalg.norm(gradients, axis=1, keepdims=True)).astype(
            np.float32
        )
        self.jitter = rng.random((_TABLE_SIZE, dims)).astype(np.float32)

    def hash(self, cells: np.ndarray) -> np.ndarray:
        """Hash integer lattice cells (N, D) to [0, 256) as perm[perm[x] + y] (+ z)."""
        wrapped = cells & (_TABLE_SIZE - 1)
        code = self.permutation[wrapped[:, 0]]
        for axis in range(1, cells.shape[1]):
            code = self.permutation[code + wrapped[:, axis]]
        return code


def _fade(t: np.ndarray) -> np.ndarray:
    # Perlin's quintic 6t^5 - 15t^4 + 10t^3 rather than the lecture's cubic: its second
    # derivative is continuous too, so bump-mapped normals show no lattice creases.
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


def _gradient_noise(flat: np.ndarray, lattice: _Lattice) -> np.ndarray:
    """Gradient noise at points (N, D), bounded by sqrt(D)/2 before scaling to [-1, 1]."""
    dims = flat.shape[1]
    base = np.floor(flat)
    frac = (flat - base).astype(np.float32)
    cells = base.astype(np.int64)
    weights = _fade(frac)
    total = np.zeros(flat.shape[0], dtype=np.float32)
    # Loop over the 2^D corners of the cell (4 or 8), not over points.
    for corner in np.ndindex(*(2,) * dims):
        offset = np.array(corner, dtype=np.int64)
        gradient = lattice.gradients[lattice.hash(cells + offset)]
        dot = np.einsum("nd,nd->n", gradient, frac - offset.astype(np.float32))
        weight = np.prod(np.where(offset == 1, weights, 1.0 - weights), axis=1)
        total += weight * dot
    return np.clip(total * np.float32(2.0 / np.sqrt(dims)), -1.0, 1.0)


def perlin(points: np.ndarray, seed: Seed = 0, frequency: float = 1.0) -> np.ndarray:
    """Gradient (Perlin) noise at 2-D or 3-D points.

    Parameters
    ----------
    points : ndarray, shape (..., 2) or (..., 3)
        Coordinates; the lattice spacing is ``1 / frequency``.
    seed : int or numpy.random.Generator, optional
        Chooses the permutation table and gradients.
    frequency : float, optional
        Lattice cells per unit length.

    Returns
    -------
    noise : ndarray of float32, shape ``points.shape[:-1]``
        Smooth noise in [-1, 1], zero on the lattice points.

    Example
    -------
    >>> perlin(np.array([[0.5, 0.5, 0.5], [1.0, 2.0, 3.0]]), seed=3).shape
    (2,)
    """
    points = _as_points(points)
    lattice = _Lattice(seed, points.shape[-1])
    flat = points.reshape(-1, points.shape[-1]) * np.float32(frequency)
    return _gradient_noise(flat, lattice).reshape(points.shape[:-1])


def _octaves(
    points: np.ndarray,
    octaves: int,
    persistence: float,
    lacunarity: float,
    seed: Seed,
    frequency: float,
    absolute: bool,
) -> np.ndarray:
    points = _as_points(points)
    if octaves < 1:
        raise InputError(f"octaves: must be at least 1, got {octaves}")
    dims = points.shape[-1]
    lattice = _Lattice(seed, dims)
    flat = points.reshape(-1, dims)
    total = np.zeros(flat.shape[0], dtype=np.float32)
    amplitude_sum = 0.0
    for octave in range(octaves):
        scale = np.float32(frequency * lacunarity**octave)
        amplitude = persistence**octave
        noise = _gradient_noise(flat * scale + octave * _OCTAVE_SHIFT[:dims], lattice)
        total += np.float32(amplitude) * (np.abs(noise) if absolute else noise)
        amplitude_sum += amplitude
    return (total / np.float32(amplitude_sum)).reshape(points.shape[:-1])


def fbm(
    points: np.ndarray,
    octaves: int = 4,
    persistence: float = 0.5,
    lacunarity: float = 2.0,
    seed: Seed = 0,
    frequency: float = 1.0,
) -> np.ndarray:
    """Fractal sum of Perlin noise: sum_k persistence^k * perlin(lacunarity^k * f * p).

    Parameters
    ----------
    points : ndarray, shape (..., 2) or (..., 3)
    octaves : int, optional
        Number of noise layers.
    persistence : float, optional
        Amplitude ratio between successive octaves (smaller = smoother).
    lacunarity : float, optional
        Frequency ratio between successive octaves.
    seed : int or numpy.random.Generator, optional
    frequency : float, optional
        Frequency of the first octave.

    Returns
    -------
    noise : ndarray of float32, shape ``points.shape[:-1]``, in [-1, 1]
        Normalised by the sum of the amplitudes.

    Example
    -------
    >>> fbm(np.zeros((4, 4, 3)), octaves=3, seed=0).shape
    (4, 4)
    """
    return _octaves(points, octaves, persistence, lacunarity, seed, frequency, absolute=False)


def turbulence(
    points: np.ndarray,
    octaves: int = 4,
    persistence: float = 0.5,
    lacunarity: float = 2.0,
    seed: Seed = 0,
    frequency: float = 1.0,
) -> np.ndarray:
    """Perlin's turbulence: the fractal sum of ``|perlin|``, in [0, 1].

    Same parameters as :func:`fbm`; the absolute value gives sharp creases (the veins
    of marble, the licks of fire).

    Example
    -------
    >>> float(turbulence(np.random.default_rng(0).random((100, 3)), seed=0).min()) >= 0
    True
    """
    return _octaves(points, octaves, persistence, lacunarity, seed, frequency, absolute=True)


def _unit_vector(components: Sequence[float], dims: int, name: str) -> np.ndarray:
    vector = np.asarray(components, dtype=np.float32)[:dims]
    if vector.shape != (dims,):
        raise InputError(f"{name}: expected {dims} components, got {vector.shape}")
    norm = float(np.linalg.norm(vector))
    if norm == 0:
        raise InputError(f"{name}: must not be the zero vector")
    return vector / np.float32(norm)


def marble(
    points: np.ndarray,
    direction: Sequence[float] = (1.0, 0.0, 0.0),
    frequency: float = 2.0,
    amplitude: float = 4.0,
    octaves: int = 4,
    persistence: float = 0.5,
    noise_frequency: float = 2.0,
    seed: Seed = 0,
) -> np.ndarray:
    """Marble: ``0.5 + 0.5 sin(2 pi f (d . p) + A turbulence(p))``, in [0, 1].

    Parameters
    ----------
    points : ndarray, shape (..., 2) or (..., 3)
    direction : sequence of float, optional
        Direction across the layers (normalised; the first 2 components in 2-D).
    frequency : float, optional
        Layers per unit length along ``direction``.
    amplitude : float, optional
        ``A``: how far the turbulence bends the layers (radians).
    octaves, persistence : optional
        Of the turbulence.
    noise_frequency : float, optional
        First-octave frequency of the turbulence.
    seed : int or numpy.random.Generator, optional

    Returns
    -------
    layer : ndarray of float32 in [0, 1]
        Feed it to :func:`color_ramp` for the layer colours.

    Example
    -------
    >>> layer = marble(np.random.default_rng(0).random((500, 3)), seed=0)
    >>> bool(layer.min() >= 0.0 and layer.max() <= 1.0)
    True
    """
    points = _as_points(points)
    axis = _unit_vector(direction, points.shape[-1], "direction")
    noise = turbulence(
        points, octaves=octaves, persistence=persistence, seed=seed, frequency=noise_frequency
    )
    phase = np.float32(2 * np.pi * frequency) * (points @ axis) + np.float32(amplitude) * noise
    return (0.5 + 0.5 * np.sin(phase)).astype(np.float32)


def wood(
    points: np.ndarray,
    axis: Sequence[float] = (0.0, 0.0, 1.0),
    center: Sequence[float] = (0.0, 0.0, 0.0),
    ring_frequency: float = 8.0,
    amplitude: float = 0.15,
    octaves: int = 3,
    persistence: float = 0.5,
    noise_frequency: float = 2.0,
    seed: Seed = 0,
) -> np.ndarray:
    """Wood rings: the fractional part of ``f * R + A * fbm(p)``, R the distance to an axis.

    The lecture's cylindrical coordinates: a tree trunk along ``axis`` through
    ``center``; rings are surfaces of equal distance R, wobbled by noise.

    Parameters
    ----------
    points : ndarray, shape (..., 2) or (..., 3)
        In 2-D the "axis" is the point ``center`` and rings are circles around it.
    axis : sequence of float, optional
        Trunk direction (3-D only; normalised).
    center : sequence of float, optional
        A point on the trunk axis.
    ring_frequency : float, optional
        Rings per unit of radius.
    amplitude : float, optional
        Ring wobble in units of ring spacing.
    octaves, persistence, noise_frequency : optional
        Of the fbm wobble.
    seed : int or numpy.random.Generator, optional

    Returns
    -------
    ring_phase : ndarray of float32 in [0, 1)
        0 at the start of a ring (early wood), rising towards the next.

    Example
    -------
    >>> wood(np.array([[0.0, 0.0, 0.0]]), amplitude=0.0).tolist()
    [0.0]
    """
    points = _as_points(points)
    dims = points.shape[-1]
    relative = points - np.asarray(center, dtype=np.float32)[:dims]
    if dims == 3:
        trunk = _unit_vector(axis, 3, "axis")
        relative = relative - (relative @ trunk)[..., None] * trunk
    radius = np.linalg.norm(relative, axis=-1)
    noise = fbm(
        points, octaves=octaves, persistence=persistence, seed=seed, frequency=noise_frequency
    )
    rings = np.float32(ring_frequency) * radius + np.float32(amplitude) * noise
    return (rings - np.floor(rings)).astype(np.float32)


def stripes(
    points: np.ndarray,
    direction: Sequence[float] = (1.0, 0.0, 0.0),
    frequency: float = 4.0,
    sharpness: float = 4.0,
    warp: float = 0.0,
    noise_frequency: float = 2.0,
    seed: Seed = 0,
) -> np.ndarray:
    """Parallel stripes along ``direction``, optionally warped by fbm, in [0, 1].

    Parameters
    ----------
    points : ndarray, shape (..., 2) or (..., 3)
    direction : sequence of float, optional
        Normal of the stripe planes.
    frequency : float, optional
        Stripes per unit length.
    sharpness : float, optional
        1 gives a sine; larger values give flatter stripes with crisper edges.
    warp : float, optional
        Displacement of the stripes by fbm, in stripe periods.
    noise_frequency : float, optional
    seed : int or numpy.random.Generator, optional

    Returns
    -------
    stripe : ndarray of float32 in [0, 1]
        1 in the middle of a stripe, 0 between stripes.

    Example
    -------
    >>> stripes(np.array([[0.125, 0.0]]), frequency=2.0).round(3).tolist()
    [1.0]
    """
    points = _as_points(points)
    axis = _unit_vector(direction, points.shape[-1], "direction")
    phase = np.float32(frequency) * (points @ axis)
    if warp:
        phase = phase + np.float32(warp) * fbm(points, seed=seed, frequency=noise_frequency)
    wave = np.sin(np.float32(2 * np.pi) * phase)
    stripe = 0.5 + 0.5 * np.tanh(sharpness * wave) / np.tanh(sharpness)
    return np.clip(stripe, 0.0, 1.0).astype(np.float32)


def worley(points: np.ndarray, seed: Seed = 0, frequency: float = 1.0) -> np.ndarray:
    """Cellular (Worley) noise: distance to the nearest jittered lattice feature point.

    One feature point per lattice cell, at a seeded position inside it; distances are
    in lattice cells (``frequency`` cells per unit length).

    Returns
    -------
    distance : ndarray of float32, shape ``points.shape[:-1]``, >= 0
        At most sqrt(D) (never further than the own cell's feature point).

    Example
    -------
    >>> float(worley(np.zeros((1, 2)), seed=0)[0]) >= 0
    True
    """
    points = _as_points(points)
    dims = points.shape[-1]
    lattice = _Lattice(seed, dims)
    flat = points.reshape(-1, dims) * np.float32(frequency)
    cells = np.floor(flat).astype(np.int64)
    nearest = np.full(flat.shape[0], np.inf, dtype=np.float32)
    # Loop over the 3^D neighbouring cells (9 or 27), not over points.
    for offset in np.ndindex(*(3,) * dims):
        neighbour = cells + (np.array(offset, dtype=np.int64) - 1)
        feature = neighbour + lattice.jitter[lattice.hash(neighbour)]
        distance = np.linalg.norm(flat - feature.astype(np.float32), axis=1)
        np.minimum(nearest, distance, out=nearest)
    return nearest.reshape(points.shape[:-1])


def spots(
    points: np.ndarray,
    frequency: float = 4.0,
    radius: float = 0.3,
    softness: float = 0.05,
    seed: Seed = 0,
) -> np.ndarray:
    """Round spots at jittered lattice points (one per cell), 1 inside, 0 outside.

    Parameters
    ----------
    points : ndarray, shape (..., 2) or (..., 3)
    frequency : float, optional
        Spots per unit length (about).
    radius : float, optional
        Spot radius in cell units (0.5 makes neighbouring spots touch at times).
    softness : float, optional
        Width of the edge ramp in cell units.
    seed : int or numpy.random.Generator, optional

    Returns
    -------
    coverage : ndarray of float32 in [0, 1]

    Example
    -------
    >>> s = spots(np.random.default_rng(0).random((1000, 3)), frequency=3.0, seed=2)
    >>> 0.0 < float(s.mean()) < 1.0
    True
    """
    distance = worley(points, seed=seed, frequency=frequency)
    edge = max(float(softness), 1e-6)
    return np.clip((radius - distance) / np.float32(edge) + 0.5, 0.0, 1.0).astype(np.float32)


def color_ramp(
    values: np.ndarray,
    colors: Sequence[Sequence[float]] | np.ndarray,
    positions: Sequence[float] | None = None,
) -> np.ndarray:
    """Map values in [0, 1] to colours by piecewise-linear interpolation ("LayerColor").

    Parameters
    ----------
    values : ndarray
        Any shape; clipped to [0, 1].
    colors : array-like, shape (K, C)
        Colours of the K stops.
    positions : sequence of float, optional
        Increasing stop positions in [0, 1]; evenly spaced by default.

    Returns
    -------
    colored : ndarray of float32, shape ``values.shape + (C,)``

    Example
    -------
    >>> color_ramp(np.array([0.0, 0.5, 1.0]), [(0, 0, 0), (1, 1, 1)])[:, 0].tolist()
    [0.0, 0.5, 1.0]
    """
    colors = np.asarray(colors, dtype=np.float32)
    if colors.ndim != 2 or colors.shape[0] < 2:
        raise InputError(f"colors: expected at least 2 colour stops (K, C), got {colors.shape}")
    if positions is None:
        stops = np.linspace(0.0, 1.0, colors.shape[0])
    else:
        stops = np.asarray(positions, dtype=np.float64)
        if stops.shape != (colors.shape[0],) or np.any(np.diff(stops) < 0):
            raise InputError("positions: expected one increasing position per colour stop")
    values = np.clip(np.asarray(values, dtype=np.float32), 0.0, 1.0)
    channels = [np.interp(values, stops, colors[:, c]) for c in range(colors.shape[1])]
    return np.stack(channels, axis=-1).astype(np.float32)
