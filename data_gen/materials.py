"""Procedural ground-truth BTFs after the cross-device paper's six samples.

Each material is a height field (in pixel units) with an albedo (linear RGB), a
glossy strength and a Blinn-Phong exponent per texel. :func:`render_btf_matrix`
renders it under every (light, view) pair of a hemisphere sampling with

    radiance = albedo * (ambient * occlusion + cos(n, l) * shadow)
               + gloss * shadow * cos(n, h) ** shininess * (cos(n, l) > 0)

where ``shadow`` is the cast shadow of the height field along the light (found
by marching towards the light and comparing shifted heights, one whole image
per step) and ``occlusion`` a local ambient occlusion (how far a texel lies
below its blurred surroundings): the non-local shading that makes a BTF's
apparent BRDFs differ from a plain SVBRDF. Views change the glossy term only:
the texels stay registered on the reference plane (no parallax), as in a
rectified BTF.

Sampling (:func:`default_sampling`), directions as (theta, phi) in degrees,
theta the polar angle from the normal (the paper's theta_i):

* 33 lights: theta 0 (1), and 8 azimuths (0, 45, .., 315) at each of
  theta 22, 45, 60 and 75; so theta 22 at phi 0, 90, 180, 270 is there, the
  paper's constraint images;
* 9 views: top (0, 0), theta 30 at phi 0, 90, 180, 270 and theta 60 at phi 45,
  135, 225, 315;
* RGB: 33 x 9 x 3 = 891 rows.

Example
-------
>>> from data_gen.materials import make_material, default_sampling, render_btf_matrix
>>> material = make_material("leather", size=64, seed=0)
>>> lights, views = default_sampling()
>>> S = render_btf_matrix(material, lights, views)
>>> S.shape
(891, 4096)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from imagemap.io import InputError
from imagemap.procedural import color_ramp, fbm, stripes, worley
from imagemap.procedural import wood as wood_rings

__all__ = [
    "MATERIALS",
    "Material",
    "default_sampling",
    "make_material",
    "render_btf_matrix",
    "shadow_mask",
]

#: Pixels per unit of the procedural patterns: the pattern scale does not change
#: with the image size (a 64x64 render is a crop-sized piece of the same material).
PIXELS_PER_UNIT = 128.0


@dataclass
class Material:
    """A height-field material.

    Attributes
    ----------
    height : (H, W) float32, pixel units (1 = one texel width).
    albedo : (H, W, 3) float32 linear RGB.
    gloss : (H, W) float32 glossy strength.
    shininess : (H, W) float32 Blinn-Phong exponent.
    name : str
    """

    height: np.ndarray
    albedo: np.ndarray
    gloss: np.ndarray
    shininess: np.ndarray
    name: str = ""


def default_sampling() -> tuple[np.ndarray, np.ndarray]:
    """The hemisphere sampling: 33 light and 9 view directions, (theta, phi) degrees.

    Example
    -------
    >>> lights, views = default_sampling()
    >>> lights.shape, views.shape
    ((33, 2), (9, 2))
    """
    lights = [(0.0, 0.0)]
    for theta in (22.0, 45.0, 60.0, 75.0):
        lights += [(theta, phi) for phi in np.arange(0.0, 360.0, 45.0)]
    views = [(0.0, 0.0)]
    views += [(30.0, phi) for phi in (0.0, 90.0, 180.0, 270.0)]
    views += [(60.0, phi) for phi in (45.0, 135.0, 225.0, 315.0)]
    return np.array(lights, dtype=np.float32), np.array(views, dtype=np.float32)


def _grid(size: int) -> np.ndarray:
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float32) / np.float32(PIXELS_PER_UNIT)
    return np.stack([xx, yy], axis=-1)


def _cloth(size: int, rng: np.random.Generator) -> Material:
    """Plain weave with a plaid of thread colours; warp and weft alternate over/under."""
    period = 8  # pixels per thread
    yy, xx = np.mgrid[0:size, 0:size]
    column, row = xx // period, yy // period
    u = (xx % period + 0.5) / period * 2 - 1  # across a warp thread
    v = (yy % period + 0.5) / period * 2 - 1  # across a weft thread
    warp_profile = np.sqrt(np.clip(1 - u**2, 0, 1))
    weft_profile = np.sqrt(np.clip(1 - v**2, 0, 1))
    warp_over = (column + row) % 2 == 0
    height = np.where(warp_over, 1.0 + warp_profile, 1.0 + weft_profile) * 1.6
    points = _grid(size)
    fibres = fbm(points * np.array([1.0, 6.0], np.float32), octaves=4, seed=rng, frequency=24.0)
    height = ndimage.gaussian_filter(height + 0.3 * fibres, 0.8)
    # Plaid: a repeating sequence of thread colours along warp and weft.
    palette = np.array(
        [[0.45, 0.06, 0.05], [0.45, 0.06, 0.05], [0.05, 0.08, 0.25], [0.55, 0.50, 0.35]],
        dtype=np.float32,
    )
    warp_color = palette[(column // 3) % 4]
    weft_color = palette[(row // 4) % 4]
    albedo = np.where(warp_over[..., None], warp_color, weft_color)
    dye = 1.0 + 0.25 * fbm(points, octaves=3, seed=rng, frequency=3.0)
    albedo = albedo * dye[..., None] * (0.75 + 0.25 * (1.0 + fibres[..., None]) / 2)
    gloss = np.full((size, size), 0.15, np.float32)
    shininess = np.full((size, size), 12.0, np.float32)
    return Material(height, albedo, gloss, shininess, "cloth")


def _leather(size: int, rng: np.random.Generator) -> Material:
    """Grain cells (Worley F1): bulging cells, creases between them, blotchy dye."""
    points = _grid(size)
    cells = worley(points, seed=rng, frequency=6.0)
    fine = worley(points, seed=rng, frequency=20.0)
    height = 4.0 * (1.0 - np.clip(cells, 0, 1)) ** 1.5 + 0.8 * (1.0 - np.clip(fine, 0, 1))
    height = height + 0.4 * fbm(points, octaves=5, seed=rng, frequency=12.0)
    height = ndimage.gaussian_filter(height, 0.7)
    blotch = fbm(points, octaves=4, seed=rng, frequency=1.5)
    base = color_ramp(0.5 + blotch, [(0.12, 0.05, 0.02), (0.35, 0.17, 0.07), (0.55, 0.32, 0.15)])
    crease = np.clip(cells * 1.6 - 0.4, 0, 1)
    albedo = base * (1.0 - 0.55 * crease[..., None])
    gloss = (0.25 * (1.0 - 0.7 * crease)).astype(np.float32)
    shininess = np.full((size, size), 25.0, np.float32)
    return Material(height, albedo, gloss, shininess, "leather")


def _wallpaper(size: int, rng: np.random.Generator) -> Material:
    """Embossed print: a glossy raised motif (diamonds and dots) on matte paper grain."""
    points = _grid(size)
    diag_a = stripes(points, direction=(1.0, 1.0), frequency=3.0, sharpness=6.0)
    diag_b = stripes(points, direction=(1.0, -1.0), frequency=3.0, sharpness=6.0)
    lattice = np.clip(diag_a * diag_b * 2.0, 0, 1)
    motif = np.maximum(lattice, _dots(points, rng))
    motif = ndimage.gaussian_filter(motif, 0.8)
    grain = fbm(points, octaves=5, seed=rng, frequency=40.0)
    height = 2.5 * ndimage.gaussian_filter(motif, 1.5) + 0.25 * grain
    paper = np.array([0.55, 0.62, 0.50], np.float32) * (1 + 0.08 * grain[..., None])
    ink = np.array([0.60, 0.45, 0.12], np.float32)
    albedo = paper * (1 - motif[..., None]) + ink * motif[..., None]
    gloss = (0.03 + 0.6 * motif).astype(np.float32)
    shininess = (10.0 + 50.0 * motif).astype(np.float32)
    return Material(height, albedo, gloss, shininess, "wallpaper")


def _dots(points: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    # Dots at the centres of the diamonds, slightly irregular in size.
    shifted = points + np.float32(1.0 / 6.0)
    cells = np.abs(((shifted * 3.0) % 1.0) - 0.5).sum(axis=-1)
    wobble = 0.03 * fbm(points, octaves=2, seed=rng, frequency=2.0)
    return np.clip((0.18 + wobble - cells) / 0.03, 0, 1).astype(np.float32)


def _wood(size: int, rng: np.random.Generator) -> Material:
    """Finished wood: rings of a trunk far to the side (arcs), pores along the grain."""
    points = _grid(size)
    phase = wood_rings(
        points, center=(-2.5, 1.7), ring_frequency=3.5, amplitude=0.5, seed=rng, noise_frequency=1.5
    )
    late = np.clip((phase - 0.55) / 0.35, 0, 1) ** 0.7
    streak = fbm(points * np.array([8.0, 1.0], np.float32), octaves=4, seed=rng, frequency=6.0)
    pores = np.clip(
        worley(points * np.array([1.0, 6.0], np.float32), seed=rng, frequency=14.0), 0, 1
    )
    pore_mask = np.clip((0.12 - pores) / 0.06, 0, 1)
    albedo = color_ramp(
        np.clip(late + 0.15 * streak, 0, 1), [(0.62, 0.40, 0.20), (0.28, 0.13, 0.05)]
    )
    albedo = albedo * (1.0 - 0.4 * pore_mask[..., None])
    height = -1.2 * late - 1.5 * pore_mask + 0.15 * streak
    height = ndimage.gaussian_filter(height, 0.6)
    gloss = (0.45 * (1.0 - 0.8 * pore_mask)).astype(np.float32)
    shininess = np.full((size, size), 60.0, np.float32)
    return Material(height, albedo, gloss, shininess, "wood")


MATERIALS = {"cloth": _cloth, "leather": _leather, "wallpaper": _wallpaper, "wood": _wood}


def make_material(name: str, *, size: int = 512, seed: int = 0) -> Material:
    """Build one of :data:`MATERIALS` ("cloth", "leather", "wallpaper", "wood").

    Parameters
    ----------
    name : str
    size : int
        Side in texels (square).
    seed : int
        Seed of every random choice (same seed, same bytes).

    Returns
    -------
    Material
    """
    if name not in MATERIALS:
        raise InputError(f"material: {name!r} is not one of {sorted(MATERIALS)}")
    if size < 8:
        raise InputError(f"size: at least 8 texels, got {size}")
    material = MATERIALS[name](int(size), np.random.default_rng(seed))
    material.height = np.asarray(material.height, np.float32)
    material.albedo = np.clip(np.asarray(material.albedo, np.float32), 0.0, 1.0)
    material.gloss = np.asarray(material.gloss, np.float32)
    material.shininess = np.asarray(material.shininess, np.float32)
    return material


def _unit(theta: float, phi: float) -> np.ndarray:
    t, p = np.deg2rad(theta), np.deg2rad(phi)
    # x along image columns, y along image rows, z out of the surface.
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], np.float32)


def shadow_mask(
    height: np.ndarray, theta: float, phi: float, *, max_steps: int = 96, softness: float = 0.7
) -> np.ndarray:
    """Lit fraction (1 lit, 0 in cast shadow) of each texel for a light at (theta, phi).

    Marches towards the light one texel at a time: a texel is shadowed where the
    height field, shifted by s steps along the light's horizontal direction, rises
    above the ray's height h + s * cot(theta). Each step is one whole-image shift.

    Example
    -------
    >>> h = np.zeros((16, 16), np.float32); h[:, 8] = 10.0
    >>> bool(shadow_mask(h, 60.0, 0.0, softness=0)[4, 6] < 0.5)  # wall at x=8, light from +x
    True
    """
    height = np.asarray(height, dtype=np.float32)
    if theta <= 0.0:
        return np.ones_like(height)
    if theta >= 90.0:
        return np.zeros_like(height)
    direction = _unit(theta, phi)
    horizontal = direction[:2] / np.linalg.norm(direction[:2])
    rise = float(direction[2] / np.linalg.norm(direction[:2]))  # height per texel
    relief = float(height.max() - height.min())
    steps = int(min(max_steps, np.ceil(relief / max(rise, 1e-6))))
    blocked = np.zeros(height.shape, dtype=bool)
    for step in range(1, steps + 1):
        # The height at p + step * horizontal: shift the image by -step * horizontal.
        ahead = ndimage.shift(
            height, (-step * horizontal[1], -step * horizontal[0]), order=1, mode="nearest"
        )
        blocked |= ahead > height + step * rise
    lit = (~blocked).astype(np.float32)
    if softness > 0:
        lit = ndimage.gaussian_filter(lit, softness)  # a small penumbra, no aliasing
    return lit


def render_btf_matrix(
    material: Material,
    light_dirs: np.ndarray,
    view_dirs: np.ndarray,
    *,
    ambient: float = 0.08,
    intensity: float = 0.85,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """Render every (light, view) image into the BTF matrix S, (n_rows, H*W) float32.

    Rows in (light, view, channel) C order, as :class:`imagemap.btf.BTF` expects;
    written straight into ``out`` (or a new array) so no image stack is copied.

    Parameters
    ----------
    material : Material
    light_dirs, view_dirs : (n, 2) (theta, phi) degrees
    ambient : float
        Ambient light, scaled by the local occlusion.
    intensity : float
        Radiance of the directional light.
    out : ndarray, optional
        Preallocated (n_rows, H*W) float32.

    Returns
    -------
    S : ndarray (n_lights * n_views * 3, H*W) float32
    """
    light_dirs = np.asarray(light_dirs, np.float32).reshape(-1, 2)
    view_dirs = np.asarray(view_dirs, np.float32).reshape(-1, 2)
    height = material.height
    size_h, size_w = height.shape
    n_rows = len(light_dirs) * len(view_dirs) * 3
    if out is None:
        out = np.empty((n_rows, size_h * size_w), np.float32)
    elif out.shape != (n_rows, size_h * size_w) or out.dtype != np.float32:
        raise InputError(f"out: expected float32 {(n_rows, size_h * size_w)}, got {out.shape}")
    grad_y, grad_x = np.gradient(height.astype(np.float32))
    normals = np.stack([-grad_x, -grad_y, np.ones_like(grad_x)], axis=-1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    # Ambient occlusion: texels below their surroundings see less of the sky.
    cavity = ndimage.gaussian_filter(height, 4.0) - height
    occlusion = np.clip(1.0 - 0.25 * cavity, 0.2, 1.0).astype(np.float32)
    stack = out.reshape(len(light_dirs), len(view_dirs), 3, size_h, size_w)
    for li, (lt, lp) in enumerate(light_dirs):
        light = _unit(float(lt), float(lp))
        cos_light = normals @ light
        lit = shadow_mask(height, float(lt), float(lp)) * (cos_light > 0)
        diffuse = ambient * occlusion + intensity * np.clip(cos_light, 0, None) * lit
        for vi, (vt, vp) in enumerate(view_dirs):
            halfway = light + _unit(float(vt), float(vp))
            halfway /= np.linalg.norm(halfway)
            cos_half = np.clip(normals @ halfway, 0, None)
            specular = intensity * material.gloss * lit * cos_half**material.shininess
            radiance = material.albedo * diffuse[..., None] + specular[..., None]
            stack[li, vi] = np.moveaxis(radiance, 2, 0)
    return out
