"""#42's relief task: an ellipsoid body covered with scales that are bumps in the depth.

Two examples and a query, made here (not by ``data_gen``). The depth is a dome over an
ellipse (an ellipsoid's front) carrying a scale on every cell of a jittered hexagonal
lattice: each scale is a dome over its Voronoi cell, highest at the cell's seed and down
to the body at the cell's border, so neighbouring scales meet in a crease. The lattice's
spacing, orientation and phase differ per object, so the query's scale borders lie
elsewhere than any example's and can only come from its own bumps. Each scale is painted
in the object's palette with a light centre shading to a mid-tone and a dark rim along
the bump's edge (its own tone per scale).

Measured per size (``outside.py`` prints the table; ours, ``warp_nearest``, the
bounding-box copy, EbSynth when ``EBSYNTH`` names its binary, and the truth):

- **rim recall / precision / F1**: ``relief_plates.py``'s seam scores on the scale
  borders: a pixel is dark when its luminance is below the midpoint between the truth's
  rim and scale luminance; recall is the share of the query's scale-border pixels with a
  dark output pixel within 1 px, precision the share of dark output pixels within
  ``max(2, width / 160)`` px of a scale border;
- **palette share** (ours, ``warp_nearest``): the share of the scales' area copied from
  the example that copies most of it, and that example (``palette_from``: 0 has the
  query's green scales, 1 copper ones; a share below 1 means scales from both);
- PSNR on the object, continuity and mid-tone share of the scales without their rims
  (the driver's).

    python benchmarks/relief_scales.py [--sizes 320x240,768x576] [--quick]
        [--out DIR] [--json FILE] [--finish paper ...]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree
from skimage import color

sys.path.insert(0, str(Path(__file__).resolve().parent))  # outside.py beside this script

#: A scale's height over the body, as a fraction of the body's relief.
SCALE_HEIGHT = 0.10
#: The dark rim's half-width (either side of a border) as a share of the lattice spacing:
#: within the precision's reach (``max(2, width / 160)`` px) at 320 and 768 px wide.
RIM_WIDTH = 0.065
#: Each lattice point moves by up to this share of the spacing.
LATTICE_JITTER = 0.18
#: Per-scale tone factors.
SCALE_TONE = (0.92, 1.05)

EXAMPLES = [
    dict(a=0.42, b=0.38, cx=0.50, cy=0.50, spacing=0.26, angle=0.0, seed=31,
         centre=(0.70, 0.80, 0.45), mid=(0.40, 0.55, 0.25), rim=(0.08, 0.16, 0.06)),
    dict(a=0.40, b=0.40, cx=0.51, cy=0.49, spacing=0.31, angle=25.0, seed=32,
         centre=(0.92, 0.66, 0.36), mid=(0.70, 0.40, 0.18), rim=(0.22, 0.09, 0.04)),
]  # fmt: skip
QUERY = dict(a=0.41, b=0.37, cx=0.49, cy=0.51, spacing=0.28, angle=12.0, seed=33,
             centre=(0.68, 0.80, 0.46), mid=(0.38, 0.54, 0.26), rim=(0.07, 0.15, 0.07))  # fmt: skip


def body(width, height, *, a, b, cx, cy, spacing, angle, seed, centre, mid, rim):
    """Depth (0 outside), RGB map, scale-border pixels and painted rims of one body.

    ``a``, ``b`` are the ellipse's half-axes as shares of the image's width and height,
    ``spacing`` the lattice spacing in object half heights, ``angle`` its orientation
    (degrees).
    """
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float64)
    unit = b * height  # the object's half height in pixels
    u, v = (xx - cx * width) / (a * width), (yy - cy * height) / unit
    inside = u**2 + v**2 < 1
    dome = np.sqrt(np.clip(1 - u**2 - v**2, 0, 1))
    # The lattice in object units (half heights, so that every size draws the same body):
    # a hexagonal grid turned by the angle, shifted by a phase, each point jittered; the
    # points whose cells can reach the ellipse are kept.
    turn = np.radians(angle)
    first = np.array([np.cos(turn), np.sin(turn)])
    second = np.array([np.cos(turn + np.pi / 3), np.sin(turn + np.pi / 3)])
    i, j = np.meshgrid(np.arange(-12, 13), np.arange(-12, 13))
    grid = (i.reshape(-1, 1) * first + j.reshape(-1, 1) * second) * spacing
    grid = grid + rng.uniform(-0.5, 0.5, 2) * spacing
    grid = grid + rng.uniform(-LATTICE_JITTER, LATTICE_JITTER, grid.shape) * spacing
    aspect = a * width / unit
    seeds = grid[np.hypot(grid[:, 0] / aspect, grid[:, 1]) < 1 + spacing]
    # The two nearest seeds of each pixel, in pixels (isotropic in the image).
    points = np.stack([cx * width + seeds[:, 0] * unit, cy * height + seeds[:, 1] * unit], 1)
    distances, nearest = cKDTree(points).query(np.stack([xx.ravel(), yy.ravel()], 1), k=2)
    d1 = distances[:, 0].reshape(height, width)
    d2 = distances[:, 1].reshape(height, width)
    cell = nearest[:, 0].reshape(height, width)
    border = (d2 - d1) / 2  # distance to the cell's border, in pixels
    t = d1 / np.maximum(d1 + border, 1e-9)  # 0 at the seed, 1 at the border
    bump = np.sqrt(np.clip(1 - t**2, 0, 1))
    depth = np.where(inside, 0.35 + 0.5 * dome + SCALE_HEIGHT * 0.5 * bump, 0.0)
    # Paint: a light centre shading to the mid-tone, a dark rim along the border.
    tones = rng.uniform(*SCALE_TONE, len(seeds))[cell][..., None]
    shade = (t**2)[..., None]
    image = tones * (np.asarray(centre) * (1 - shade) + np.asarray(mid) * shade)
    rims = border < RIM_WIDTH * spacing * unit
    image[rims] = np.asarray(rim) * tones[rims]
    image = image + 0.015 * rng.standard_normal((height, width, 1))
    borders = inside & (border < 0.75) & (ndimage.distance_transform_edt(inside) > 2)
    return depth, np.clip(image, 0, 1) * inside[..., None], borders, rims & inside


def make_task(width, height):
    """The two examples and the query at one size."""
    from outside import Task
    from relief_plates import seam_scores

    import imagemap

    examples = []
    for i, spec in enumerate(EXAMPLES):
        depth, image, _, _ = body(width, height, **spec)
        examples.append(imagemap.Example.from_arrays(f"scaled_{i}", depth, image))
    depth, truth, borders, rims = body(width, height, **QUERY)
    mask = depth > 0
    luma = color.rgb2gray(truth)
    scales = mask & ~ndimage.binary_dilation(rims, iterations=2)
    scales &= ndimage.binary_erosion(mask, iterations=3)
    dark_level = 0.5 * (float(np.median(luma[rims])) + float(np.median(luma[scales])))

    def features(image, object_mask):
        scores = seam_scores(image, object_mask, borders, dark_level, width)
        return {key.replace("seam", "rim"): value for key, value in scores.items()}

    def provenance(source, object_mask):
        index = source[..., 0][scales]
        counts = np.bincount(index[index >= 0], minlength=len(examples))
        share = float(counts.max() / max(counts.sum(), 1))
        return {"palette_share": share, "palette_from": int(counts.argmax())}

    quarter = (slice(height // 4, height // 2), slice(width // 4, width // 2))
    return Task(
        examples, depth, truth, scales, features, {"scales": quarter}, provenance=provenance
    )


def main(argv=None):
    """Print the table (ours, warp_nearest, the bounding-box copy, EbSynth if EBSYNTH is
    set, the truth)."""
    import outside

    return outside.main(
        argv,
        description="relief scales (two examples, scales on bumps of other lattices)",
        make_task=make_task,
        default_sizes="320x240,768x576",
        quick_size="160x120",
        default_out="relief_scales",
    )


if __name__ == "__main__":
    main()
