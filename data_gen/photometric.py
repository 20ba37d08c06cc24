"""A grey sphere photographed under 12 known lights: a generated photometric-stereo set.

The stand-in for psmImages' "gray" set (S. Seitz), which the tests used before and which
has no licence (docs/real_data.md). The sphere is computed analytically in the world
frame the lights file uses (x right, y up, z towards the camera; an orthographic camera
looking down -z), independently of :mod:`imagemap.btf.photometric`, with what real
captures have and the Lambertian model that photometric stereo assumes does not:

- a Blinn-Phong specular lobe (the grey sphere is glossy), whose peak clips at full scale
  in some images;
- attached shadows (the far side of the sphere from each light is black but for the
  ambient light);
- an ambient and interreflected light (a constant plus light bounced from below);
- lights of slightly unequal strength (the lights file says only their directions);
- partial pixels on the rim (each pixel averages 4 x 4 samples);
- surroundings, as psmImages' photographs have: a grey backdrop, a dark folded cloth and
  the post the sphere stands on, with the sphere's cast shadow moving over them from
  light to light (photometric stereo over the whole frame reads slopes from them, which
  bend the sphere's heights when the whole frame is integrated);
- a black level, sensor noise (read noise and shot noise) and 8-bit quantization.

Example
-------
>>> from data_gen.photometric import grey_sphere
>>> sphere = grey_sphere(seed=0)
>>> sphere.images.shape, sphere.lights.shape, int(sphere.mask.sum())
((12, 85, 128), (12, 3), 2293)
>>> bool((sphere.images * 255 == np.round(sphere.images * 255)).all())  # 8-bit levels
True
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["LIGHT_ANGLES", "GreySphere", "grey_sphere", "light_directions", "write_grey_sphere"]

#: The 12 lights: (angle from the view axis, azimuth in the image plane: 0 = right, 90 =
#: up), degrees. Within 40 degrees of the view axis, as psmImages' (6-39 degrees), but
#: all around the axis where those came mostly from above.
LIGHT_ANGLES = (
    (7, 50),
    (12, 200),
    (16, 310),
    (20, 95),
    (23, 160),
    (26, 20),
    (29, 250),
    (31, 130),
    (34, 340),
    (36, 60),
    (38, 280),
    (40, 190),
)
#: Picture size (width, height) and the sphere's centre (x, y, pixels from the top-left
#: corner of the picture) and radius: near those of the quarter-size psmImages copy the
#: tests used before (128 x 85, the centre at (61.2, 36.2), radius 27.1).
SIZE = (128, 85)
CENTRE = (63.4, 42.3)
RADIUS = 27.0
#: Samples per pixel along each axis (the rim's pixels are partly sphere).
SUPERSAMPLING = 4
#: Reflectance: diffuse albedo, specular strength and Blinn-Phong exponent. The peaks of
#: the brightest lights' highlights are over full scale: clipped.
ALBEDO = 0.72
SPECULAR = 0.28
SHININESS = 60.0
#: Light that reaches every point (a fraction of full scale), and light bounced from the
#: cloth below the sphere (largest on the sphere's underside).
AMBIENT = 0.008
BOUNCE = 0.02
#: The lights' strengths vary by up to this fraction (unknown to the solver).
STRENGTH_SPREAD = 0.04
#: The scene behind the sphere, as psmImages' is: a grey backdrop above this row, a dark
#: folded cloth below it, both a plane this many radii behind the sphere's centre (the
#: sphere casts its shadow on them), and the sphere's stand, a post down from its bottom.
HORIZON_ROW = 38.0
BACKDROP_DEPTH = 2.5
BACKDROP_ALBEDO = 0.06
CLOTH_ALBEDO = 0.01
POST_RADIUS = 0.2  # in sphere radii
POST_ALBEDO = 0.12
#: The sensor's black level (a fraction of full scale).
BLACK = 0.002
#: Sensor noise: read noise (standard deviation) and shot noise (variance per unit of
#: signal), full scale = 1: about 2.5/255 at mid-grey.
READ_NOISE = 0.6 / 255
SHOT_NOISE = 0.05 / 255


@dataclass
class GreySphere:
    """A photometric-stereo set and its truth.

    Attributes
    ----------
    images : (12, H, W) float32
        Grey images in [0, 1], on 8-bit levels, in the order of ``lights``.
    lights : (12, 3) float64
        Unit vectors towards the lights (x right, y up, z towards the camera).
    mask : (H, W) bool
        Pixels at least half covered by the sphere.
    normals : (H, W, 3) float64
        True unit normals at the pixel centres ((0, 0, 1) off the sphere).
    heights : (H, W) float64
        True heights in pixels (the sphere's z above its rim's plane; 0 off it).
    """

    images: np.ndarray
    lights: np.ndarray
    mask: np.ndarray
    normals: np.ndarray
    heights: np.ndarray


def light_directions() -> np.ndarray:
    """The unit vectors (12, 3) of :data:`LIGHT_ANGLES`.

    Examples
    --------
    >>> lights = light_directions()
    >>> bool(np.allclose(np.linalg.norm(lights, axis=1), 1.0)), round(float(lights[:, 2].min()), 3)
    (True, 0.766)
    """
    polar, azimuth = np.radians(np.asarray(LIGHT_ANGLES, dtype=np.float64)).T
    return np.stack(
        [np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar)],
        axis=1,
    )


def _sphere_normals(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(normals (..., 3), inside (...)) at picture points (pixel units, y down)."""
    x, y = np.broadcast_arrays(x, y)
    nx = (x - CENTRE[0]) / RADIUS
    ny = -(y - CENTRE[1]) / RADIUS  # the picture's rows go down, the world's y up
    inside = nx**2 + ny**2 < 1.0
    nz = np.sqrt(np.clip(1.0 - nx**2 - ny**2, 0.0, None))
    return np.stack([nx, ny, nz], axis=-1), inside


def _radiance(normals: np.ndarray, light: np.ndarray, strength: float) -> np.ndarray:
    """Blinn-Phong radiance of the sphere at ``normals`` under one light, plus ambient."""
    cosine = normals @ light
    lit = cosine > 0.0  # attached shadow beyond the terminator
    half = light + np.array([0.0, 0.0, 1.0])
    half /= np.linalg.norm(half)
    specular = np.where(lit, np.clip(normals @ half, 0.0, None) ** SHININESS, 0.0)
    direct = strength * (ALBEDO * np.clip(cosine, 0.0, None) + SPECULAR * specular)
    bounce = BOUNCE * ALBEDO * np.clip(-normals[..., 1], 0.0, None)
    return direct + AMBIENT * ALBEDO + bounce


def _surroundings(x: np.ndarray, y: np.ndarray) -> dict[str, np.ndarray]:
    """What is around the sphere at picture points: normals, albedo, plane points, post."""
    x, y = np.broadcast_arrays(x, y)
    # World coordinates in sphere radii, the sphere's centre at the origin.
    wx, wy = (x - CENTRE[0]) / RADIUS, -(y - CENTRE[1]) / RADIUS
    # The cloth's folds: a height field of slanted waves, its normals from its slopes.
    wave = np.cos(1.3 * wx - 0.7 * wy)
    ridge = 0.5 * np.cos(1.7 * wx + 0.9 * wy + 0.8 * np.sin(1.3 * wx - 0.7 * wy))
    cloth = np.stack(
        [-ridge * (1.7 + 1.04 * wave), -ridge * (0.9 - 0.56 * wave), np.ones_like(wx)], axis=-1
    )
    cloth /= np.linalg.norm(cloth, axis=-1, keepdims=True)
    upper = y < HORIZON_ROW
    normal = np.where(upper[..., None], np.array([0.0, 0.0, 1.0]), cloth)
    albedo = np.where(upper, BACKDROP_ALBEDO, CLOTH_ALBEDO)
    # The post: a vertical cylinder below the sphere, in front of the planes.
    post = (np.abs(wx) < POST_RADIUS) & (wy < 0.0)
    across = np.clip(wx / POST_RADIUS, -1.0, 1.0)
    post_normal = np.stack([across, np.zeros_like(across), np.sqrt(1.0 - across**2)], -1)
    return {
        "normal": np.where(post[..., None], post_normal, normal),
        "albedo": np.where(post, POST_ALBEDO, albedo),
        "plane_point": np.stack([wx, wy, np.full_like(wx, -BACKDROP_DEPTH)], axis=-1),
        "post": post,
    }


def _surroundings_radiance(scene: dict[str, np.ndarray], light: np.ndarray, strength: float):
    """Lambertian radiance of the surroundings under one light, the sphere's shadow cast."""
    # The ray from a plane's point towards the light meets the unit sphere: in its shadow
    # (the post stands in front of the planes: lit).
    point = scene["plane_point"]
    along = point @ light
    shadowed = (along**2 - (point**2).sum(-1) + 1.0 > 0.0) & (along < 0.0) & ~scene["post"]
    direct = scene["albedo"] * np.clip(scene["normal"] @ light, 0.0, None) * ~shadowed
    return strength * direct + AMBIENT * scene["albedo"]


def grey_sphere(seed: int = 0) -> GreySphere:
    """The grey sphere under :data:`LIGHT_ANGLES`, photographed (see the module notes).

    The same seed gives the same images (the noise and the lights' strengths are drawn
    from it); the geometry and the light directions do not depend on it.

    Examples
    --------
    >>> a, b = grey_sphere(seed=1), grey_sphere(seed=1)
    >>> bool((a.images == b.images).all()), bool((a.images == grey_sphere(2).images).all())
    (True, False)
    >>> int((a.images >= 1.0).any(axis=(1, 2)).sum())  # images with a clipped highlight
    2
    """
    rng = np.random.default_rng([int(seed), 2024])
    width, height = SIZE
    k = SUPERSAMPLING
    # Sub-pixel sample centres: pixel (row i, column j) covers [j, j + 1) x [i, i + 1).
    offsets = (np.arange(k) + 0.5) / k
    xs = (np.arange(width)[:, None] + offsets).ravel()
    ys = (np.arange(height)[:, None] + offsets).ravel()
    normals, inside = _sphere_normals(xs[None, :], ys[:, None])
    scene = _surroundings(xs[None, :], ys[:, None])
    lights = light_directions()
    strengths = 1.0 + rng.uniform(-STRENGTH_SPREAD, STRENGTH_SPREAD, len(lights))
    images = np.empty((len(lights), height, width), dtype=np.float32)
    for n, (light, strength) in enumerate(zip(lights, strengths, strict=True)):
        around = _surroundings_radiance(scene, light, strength)
        samples = np.where(inside, _radiance(normals, light, strength), around)
        pixels = BLACK + samples.reshape(height, k, width, k).mean(axis=(1, 3))
        noise = np.sqrt(READ_NOISE**2 + SHOT_NOISE * pixels) * rng.standard_normal(pixels.shape)
        images[n] = np.round(np.clip(pixels + noise, 0.0, 1.0) * 255.0) / 255.0
    coverage = inside.reshape(height, k, width, k).mean(axis=(1, 3))
    mask = coverage >= 0.5
    centre_normals, centre_inside = _sphere_normals(
        np.arange(width)[None, :] + 0.5, np.arange(height)[:, None] + 0.5
    )
    centre_normals[~centre_inside] = (0.0, 0.0, 1.0)
    heights = np.where(centre_inside, RADIUS * centre_normals[..., 2], 0.0)
    return GreySphere(images, lights, mask, centre_normals, heights)


def write_grey_sphere(folder: str | os.PathLike, seed: int = 0) -> list[Path]:
    """Write :func:`grey_sphere` as psmImages laid it out: ``gray.0.png`` .. ``gray.11.png``
    (8-bit grey), ``mask.png`` and ``lights.txt`` (the count, then one vector per line:
    the format ``imagemap btf photometric --lights`` reads). Returns the paths.

    Examples
    --------
    >>> import tempfile
    >>> paths = write_grey_sphere(tempfile.mkdtemp())
    >>> [p.name for p in paths[:2]], paths[-1].read_text().splitlines()[:2]
    (['gray.0.png', 'gray.1.png'], ['12', '0.078336 0.093357 0.992546'])
    """
    from imagemap.io import write_image

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    sphere = grey_sphere(seed)
    paths = []
    for n, image in enumerate(sphere.images):
        levels = np.round(image * 255.0).astype(np.uint8)  # exactly the 8-bit values
        paths.append(write_image(folder / f"gray.{n}.png", levels))
    paths.append(write_image(folder / "mask.png", sphere.mask.astype(np.uint8) * 255))
    lights = folder / "lights.txt"
    lines = [f"{len(sphere.lights)}"] + [" ".join(f"{c:.6f}" for c in v) for v in sphere.lights]
    lights.write_text("\n".join(lines) + "\n")
    paths.append(lights)
    return paths
