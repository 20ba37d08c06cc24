"""Procedural ground-truth BTFs after the cross-device paper's six samples.

The material sources of ``imagemap btf experiment`` (:mod:`imagemap.btf.experiment`);
:mod:`data_gen.materials` re-exports this module and :mod:`imagemap.btf.rendering` for
the data generator.

Each material is a height field (in pixel units) with an albedo (linear RGB), a
glossy strength and a Blinn-Phong exponent per texel.
:func:`~imagemap.btf.rendering.render_btf_matrix` renders it under every (light, view)
pair of a hemisphere sampling.

**Easy materials** (cloth, leather, wallpaper, wood; the control set) are shaded
in place:

    radiance = albedo * (ambient * occlusion + cos(n, l) * shadow)
               + gloss * shadow * cos(n, h) ** shininess * (cos(n, l) > 0)

where ``shadow`` is the cast shadow of the height field along the light (found
by marching towards the light and comparing shifted heights, one whole image
per step) and ``occlusion`` a local ambient occlusion (how far a texel lies
below its blurred surroundings). Views change the glossy term only: the texels
stay registered on the reference plane (no parallax). On these, each texel's
whole BTF follows from its albedo, normal and gloss, which the four flatbed
scans nearly reveal.

**Hard materials** (:data:`HARD_MATERIALS`: velvet, lacquered_leather, cobbles)
add what the scans cannot see (see :func:`~imagemap.btf.rendering.render_btf_matrix`):

* parallax and self-occlusion: for every view, the ray through each texel of
  the reference plane (z = 0, the mean height) is marched down the height
  field, and the texel shows the surface point it hits first;
* cast shadows per light, looked up at that hit point;
* spatially varying roughness, with the glossy strength set so that the
  highlight at the scans' half vector (11 deg from the normal) does not depend
  on it: rough and polished texels scan alike and differ elsewhere;
* a second layer: a clear varnish with its own sharp lobe on a levelled
  surface (invisible where the half vector is 11 deg off), or fibres standing
  over the base, seen edge-on only from oblique views (none from the top).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from imagemap.btf.procedural import color_ramp, fbm, stripes, worley
from imagemap.btf.procedural import wood as wood_rings
from imagemap.io import InputError

__all__ = [
    "EASY_MATERIALS",
    "HARD_MATERIALS",
    "MATERIALS",
    "Material",
    "make_material",
    "scan_configuration",
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
    margin : int
        Texels of extra surface on every side of the rendered region (hard
        materials: rays of oblique views and shadows reach beyond the region).
        All fields have the padded shape; the render is (H - 2 margin)^2.
    parallax : bool
        Render by ray marching each view (parallax, self-occlusion), not in place.
    varnish : (H, W) float32 or None
        Strength of a clear coat with a sharp lobe (exponent
        :data:`VARNISH_SHININESS`) on a levelled surface (tilt at most
        :data:`VARNISH_MAX_TILT` degrees).
    fibres : (H, W) float32 or None
        Density of fibres standing over the base, seen edge-on from oblique views
        only: coverage 1 - exp(-FIBRE_COVER * density * tan(theta_view)).
    fibre_albedo : (H, W, 3) float32 or None
    """

    height: np.ndarray
    albedo: np.ndarray
    gloss: np.ndarray
    shininess: np.ndarray
    name: str = ""
    margin: int = 0
    parallax: bool = False
    varnish: np.ndarray | None = None
    fibres: np.ndarray | None = None
    fibre_albedo: np.ndarray | None = None

    @property
    def hard(self) -> bool:
        """True when :func:`render_btf_matrix` uses the layered, ray-marched renderer."""
        return bool(
            self.parallax or self.margin or self.varnish is not None or self.fibres is not None
        )


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


#: The control set: each texel's BTF follows from what the scans show.
EASY_MATERIALS = {"cloth": _cloth, "leather": _leather, "wallpaper": _wallpaper, "wood": _wood}


# ------------------------------------------------------------------ hard materials
#: Padding of the hard materials (texels each side): rays of the 60 deg views travel
#: |height| * tan(60 deg) across the reference plane, shadows further.
HARD_MARGIN = 32
#: Blinn-Phong exponent of the varnish lobe and the largest tilt of its levelled
#: surface: at the scans' half vector (11 deg off the normal) cos(10 deg)^400 < 0.003.
VARNISH_SHININESS = 400.0
VARNISH_MAX_TILT = 1.0
#: Fibre coverage per density per tan(theta_view).
FIBRE_COVER = 1.5


def scan_configuration() -> tuple[tuple[float, float], list[tuple[float, float]]]:
    """The flatbed scans' view (theta, phi) and four lights: top view, theta 22 deg."""
    return (0.0, 0.0), [(22.0, phi) for phi in (0.0, 90.0, 180.0, 270.0)]


def _scan_balanced_gloss(strength: np.ndarray, shininess: np.ndarray) -> np.ndarray:
    """Glossy strength whose highlight at the scans' half vector is ``strength``.

    Top view, light at theta 22: the half vector is 11 deg off a flat texel's
    normal, so gloss * cos(11 deg)^shininess is what a scan sees. Dividing by
    cos(11 deg)^shininess makes rough and polished texels scan alike; they differ
    at every other half vector.
    """
    return (strength / np.cos(np.deg2rad(11.0)) ** shininess).astype(np.float32)


def _cells(
    points: np.ndarray, rng: np.random.Generator, frequency: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Jittered-grid Voronoi cells: distances F1, F2 (cell units) and the nearest cell's id."""
    table = 4096
    jitter = rng.random((table, 2)).astype(np.float32)
    flat = points.reshape(-1, 2) * np.float32(frequency)
    base = np.floor(flat).astype(np.int64)
    f1 = np.full(len(flat), np.inf, np.float32)
    f2 = np.full(len(flat), np.inf, np.float32)
    ident = np.zeros(len(flat), np.int64)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            cell = base + np.array([dx, dy])
            key = (cell[:, 0] * 73856093 ^ cell[:, 1] * 19349663) % table
            distance = np.linalg.norm(flat - (cell + jitter[key]), axis=1).astype(np.float32)
            closer = distance < f1
            f2 = np.where(closer, f1, np.minimum(f2, distance))
            ident = np.where(closer, key, ident)
            f1 = np.where(closer, distance, f1)
    shape = points.shape[:-1]
    return f1.reshape(shape), f2.reshape(shape), ident.reshape(shape)


def _velvet(size: int, rng: np.random.Generator) -> Material:
    """Crushed velvet: a woven base with a pile of fibres whose density the scans cannot see.

    From the top the pile is seen end-on (no coverage), so the four scans show the
    dyed base only; from 30 and 60 deg the fibres (lighter, with a forward sheen)
    cover the base by the local density, an fbm of its own (crushed patches).
    """
    full = size + 2 * HARD_MARGIN
    points = _grid(full)
    period = 6
    yy, xx = np.mgrid[0:full, 0:full]
    column, row = xx // period, yy // period
    u = (xx % period + 0.5) / period * 2 - 1
    v = (yy % period + 0.5) / period * 2 - 1
    warp_over = (column + row) % 2 == 0
    profile = np.where(
        warp_over, np.sqrt(np.clip(1 - u**2, 0, 1)), np.sqrt(np.clip(1 - v**2, 0, 1))
    )
    height = ndimage.gaussian_filter(
        2.5 * profile + 0.4 * fbm(points, seed=rng, frequency=20.0), 0.7
    )
    motif = stripes(points, direction=(1.0, 0.4), frequency=2.0, sharpness=4.0)
    base = color_ramp(motif, [(0.30, 0.03, 0.06), (0.55, 0.10, 0.12)])
    dye = 1.0 + 0.2 * fbm(points, octaves=3, seed=rng, frequency=3.0)
    albedo = base * dye[..., None] * np.where(warp_over, 1.0, 0.85)[..., None]
    shininess = np.full((full, full), 15.0, np.float32)
    gloss = _scan_balanced_gloss(np.full((full, full), 0.05, np.float32), shininess)
    crushed = fbm(points, octaves=4, seed=rng, frequency=2.5)
    fibres = np.clip(0.55 + 1.2 * crushed, 0.0, 1.0).astype(np.float32)
    fibre_albedo = np.clip(0.55 * albedo + np.array([0.28, 0.12, 0.16], np.float32), 0, 1)
    return Material(
        height,
        albedo,
        gloss,
        shininess,
        "velvet",
        margin=HARD_MARGIN,
        parallax=True,
        fibres=fibres,
        fibre_albedo=fibre_albedo.astype(np.float32),
    )


def _lacquered_leather(size: int, rng: np.random.Generator) -> Material:
    """Deep-grained leather, polished in patches, with a varnish that the scans miss.

    Relief about 9 texels (parallax of up to 8 texels at 60 deg, cast shadows);
    roughness varies on its own (an fbm independent of the dye) with the glossy
    strength balanced so that the scans' highlight does not show it; a clear
    varnish (sharp lobe, levelled surface) lies in patches of its own.
    """
    full = size + 2 * HARD_MARGIN
    points = _grid(full)
    cells = worley(points, seed=rng, frequency=5.0)
    fine = worley(points, seed=rng, frequency=18.0)
    height = 7.0 * (1.0 - np.clip(cells, 0, 1)) ** 1.5 + 1.2 * (1.0 - np.clip(fine, 0, 1))
    height = ndimage.gaussian_filter(height + 0.4 * fbm(points, seed=rng, frequency=12.0), 0.8)
    blotch = fbm(points, octaves=4, seed=rng, frequency=1.5)
    base = color_ramp(0.5 + blotch, [(0.10, 0.05, 0.03), (0.30, 0.16, 0.08), (0.50, 0.30, 0.16)])
    crease = np.clip(cells * 1.6 - 0.4, 0, 1)
    albedo = base * (1.0 - 0.5 * crease[..., None])
    rough = np.clip(0.5 + 1.1 * fbm(points, octaves=3, seed=rng, frequency=2.0), 0, 1)
    shininess = (8.0 * 2.0 ** (3.5 * rough)).astype(np.float32)  # 8 .. 90
    gloss = _scan_balanced_gloss((0.12 * (1.0 - 0.6 * crease)).astype(np.float32), shininess)
    polish = fbm(points, octaves=3, seed=rng, frequency=1.8)
    varnish = (0.6 * np.clip((polish + 0.05) / 0.15, 0, 1)).astype(np.float32)
    return Material(
        height,
        albedo,
        gloss,
        shininess,
        "lacquered_leather",
        margin=HARD_MARGIN,
        parallax=True,
        varnish=varnish,
    )


def _cobbles(size: int, rng: np.random.Generator) -> Material:
    """Rounded stones of several colours set in grout: tall relief, long shadows.

    Stones stand 6-12 texels above the grout (parallax up to ~10 texels at 60 deg,
    whole stones hiding grout); each stone is polished or matte independently of
    its colour, balanced so the scans' highlight is the same; a wet film (varnish)
    lies in patches.
    """
    full = size + 2 * HARD_MARGIN
    points = _grid(full)
    f1, f2, ident = _cells(points, rng, frequency=6.0)
    table = 4096
    stone_height = rng.uniform(6.0, 12.0, table).astype(np.float32)
    palette = np.array(
        [[0.35, 0.34, 0.32], [0.45, 0.33, 0.20], [0.30, 0.16, 0.10], [0.20, 0.22, 0.26]],
        np.float32,
    )
    stone_colour = palette[rng.integers(0, len(palette), table)] * rng.uniform(0.8, 1.2, (table, 1))
    stone_shininess = np.where(rng.random(table) < 0.5, 10.0, 120.0).astype(np.float32)
    edge = np.clip((f2 - f1) / 0.45, 0, 1)  # 0 at the joints, 1 inside a stone
    dome = np.sqrt(1.0 - (1.0 - edge) ** 2)
    speckle = fbm(points, octaves=4, seed=rng, frequency=30.0)
    height = stone_height[ident] * dome + 0.5 * speckle
    height = ndimage.gaussian_filter(height, 0.8)
    stone = (edge > 0.08)[..., None]
    grout = np.array([0.50, 0.48, 0.44], np.float32) * (1 + 0.1 * speckle[..., None])
    albedo = np.where(stone, stone_colour[ident] * (1 + 0.15 * speckle[..., None]), grout)
    shininess = np.where(stone[..., 0], stone_shininess[ident], 5.0).astype(np.float32)
    gloss = _scan_balanced_gloss(np.where(stone[..., 0], 0.10, 0.02).astype(np.float32), shininess)
    wet = fbm(points, octaves=3, seed=rng, frequency=1.5)
    varnish = (0.5 * np.clip((wet - 0.1) / 0.15, 0, 1)).astype(np.float32)
    return Material(
        height,
        albedo,
        gloss,
        shininess,
        "cobbles",
        margin=HARD_MARGIN,
        parallax=True,
        varnish=varnish,
    )


#: Materials whose scans are ambiguous by construction (hidden layer, balanced
#: roughness) and whose views show parallax, self-occlusion and cast shadows.
HARD_MATERIALS = {"velvet": _velvet, "lacquered_leather": _lacquered_leather, "cobbles": _cobbles}
MATERIALS = {**EASY_MATERIALS, **HARD_MATERIALS}


def make_material(name: str, *, size: int = 512, seed: int = 0) -> Material:
    """Build one of :data:`MATERIALS`: the easy "cloth", "leather", "wallpaper", "wood"
    or the hard "velvet", "lacquered_leather", "cobbles".

    Hard materials carry a margin of :data:`HARD_MARGIN` texels on every side
    (their fields are (size + 2 margin)^2); the render is size x size.

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
    if material.hard:
        # Heights relative to the reference plane z = 0 at the mean height: the
        # plane the BTF's texels are registered on.
        material.height = material.height - np.float32(material.height.mean())
    return material
