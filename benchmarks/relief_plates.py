"""#42's relief task: a domed shell divided into plates by grooves, the plates painted.

Two examples and a query, made here (not by ``data_gen``). The depth is a dome over an
ellipse, carved by grooves along the borders of Voronoi plates whose seeds lie in other
places in every object; each plate is painted with growth rings and rays around its own
seed in the object's palette, and the grooves are dark seams. So the query's seams can
only come from its own grooves: an example's layout, however well bent onto the query,
draws them in the wrong places.

Measured per size (``outside.py`` prints the table; ours, the bounding-box copy, EbSynth
when ``EBSYNTH`` names its binary, and the truth):

- **seam recall / precision / F1**: a pixel is dark when its luminance is below the
  midpoint between the truth's seam and plate luminance; recall is the share of the
  query's groove-centre pixels with a dark output pixel within 1 px, precision the share
  of dark output pixels within ``max(2, width / 160)`` px of a groove centre;
- **palette share** (ours): the share of the plated area copied from the example that
  copies most of it (the two examples have different palettes: below 1 means plates
  from both);
- PSNR on the object, continuity and mid-tone share of the plates (the driver's).

    python benchmarks/relief_plates.py [--sizes 320x240,768x576] [--quick]
        [--out DIR] [--json FILE] [--finish paper ...]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy import ndimage
from skimage import color

sys.path.insert(0, str(Path(__file__).resolve().parent))  # outside.py beside this script

#: Groove half-width and depth, as fractions of the object's half height and of the dome.
GROOVE_WIDTH = 0.017
GROOVE_DEPTH = 0.08
#: Plate seeds: a hexagonal grid of this spacing (object half heights), each seed moved
#: by up to this share of the spacing.
PLATE_SPACING = 0.55
PLATE_JITTER = 0.25

EXAMPLES = [
    dict(a=0.42, b=0.38, cx=0.50, cy=0.50, seed=11,
         plate=((0.78, 0.62, 0.38), (0.62, 0.44, 0.24)), seam=(0.16, 0.10, 0.06)),
    dict(a=0.40, b=0.40, cx=0.51, cy=0.49, seed=12,
         plate=((0.60, 0.70, 0.40), (0.40, 0.52, 0.26)), seam=(0.10, 0.14, 0.08)),
]  # fmt: skip
QUERY = dict(a=0.41, b=0.37, cx=0.49, cy=0.51, seed=13,
             plate=((0.76, 0.60, 0.36), (0.60, 0.42, 0.22)), seam=(0.15, 0.10, 0.06))  # fmt: skip


def shell(width, height, *, a, b, cx, cy, seed, plate, seam):
    """Depth (0 outside), RGB map and the groove-centre pixels of one plated shell."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float64)
    unit = b * height  # the object's half height in pixels
    u, v = (xx - cx * width) / (a * width), (yy - cy * height) / unit
    inside = u**2 + v**2 < 1
    dome = np.sqrt(np.clip(1 - u**2 - v**2, 0, 1))
    # Plate seeds: a jittered hexagonal grid over the ellipse (object units, x scaled by
    # the aspect so that plates are about round in the image), its phase per object.
    aspect = a * width / unit
    spacing = PLATE_SPACING
    rows = np.arange(-3, 4) * spacing * np.sqrt(3) / 2
    grid = np.array(
        [(x + (0.5 * spacing if k % 2 else 0.0), y) for k, y in enumerate(rows)
         for x in np.arange(-4, 5) * spacing]
    ) + rng.uniform(-0.5, 0.5, 2) * spacing  # fmt: skip
    grid = grid + rng.uniform(-PLATE_JITTER, PLATE_JITTER, grid.shape) * spacing
    grid[:, 0] /= aspect
    seeds = grid[np.hypot(grid[:, 0], grid[:, 1]) < 0.92]
    plates = len(seeds)
    # Distance to each seed in pixels (isotropic in the image, so grooves have one width).
    px = cx * width + seeds[:, 0] * a * width
    py = cy * height + seeds[:, 1] * unit
    distances = np.hypot(xx[None] - px[:, None, None], yy[None] - py[:, None, None])
    order = np.argsort(distances, axis=0)
    nearest = order[0]
    d1 = np.take_along_axis(distances, order[:1], 0)[0]
    d2 = np.take_along_axis(distances, order[1:2], 0)[0]
    border = (d2 - d1) / 2  # distance to the Voronoi border, in pixels
    half = GROOVE_WIDTH * unit
    groove = np.exp(-0.5 * (border / half) ** 2)
    depth = np.where(inside, 0.35 + 0.5 * dome - GROOVE_DEPTH * 0.5 * groove, 0.0)
    # Paint: rings and rays around each plate's own seed, the plate's tone alternating.
    dy, dx = yy - py[nearest], xx - px[nearest]
    r = np.hypot(dy, dx) / unit
    theta = np.arctan2(dy, dx)
    phase = rng.uniform(0, 2 * np.pi, plates)[nearest]
    rings = 0.5 + 0.5 * np.cos(2 * np.pi * r / 0.12)
    rays = 0.5 + 0.5 * np.cos(10 * theta + phase)
    mix = np.clip(0.55 * rings + 0.45 * rays, 0, 1)[..., None]
    light, dark = np.asarray(plate[0]), np.asarray(plate[1])
    tone = np.where((nearest % 2 == 0)[..., None], 1.0, 0.93)
    image = tone * (light * (1 - mix) + dark * mix)
    seams = groove > 0.5  # within about 1.2 half-widths of the border
    image[seams] = seam
    image = image + 0.015 * rng.standard_normal((height, width, 1))
    centre = inside & (border < 0.75) & (ndimage.distance_transform_edt(inside) > 2)
    return depth, np.clip(image, 0, 1) * inside[..., None], centre, seams & inside


def seam_scores(image, mask, centres, dark_level, width):
    """Seam recall, precision and F1 of a map (see the module notes)."""
    dark = (color.rgb2gray(np.clip(image, 0, 1)) < dark_level) & mask
    recall, precision, f1 = line_scores(dark, centres, width)
    return {"seam_recall": recall, "seam_precision": precision, "seam_f1": f1}


def line_scores(marked, centres, width):
    """Recall (the share of ``centres`` with a ``marked`` pixel within 1 px), precision
    (the share of ``marked`` pixels within ``max(2, width / 160)`` px of a centre) and
    their F1: the seams' scores here, the mortar's in ``relief_bricks.py``."""
    near = ndimage.binary_dilation(marked, np.ones((3, 3), bool))
    recall = float(near[centres].mean()) if centres.any() else float("nan")
    reach = max(2.0, width / 160.0)
    to_centre = ndimage.distance_transform_edt(~centres)
    precision = float((to_centre[marked] <= reach).mean()) if marked.any() else 0.0
    f1 = 2 * recall * precision / (recall + precision) if recall + precision > 0 else 0.0
    return recall, precision, f1


def make_task(width, height):
    """The two examples and the query at one size."""
    from outside import Task

    import imagemap

    examples = []
    for i, spec in enumerate(EXAMPLES):
        depth, image, _, _ = shell(width, height, **spec)
        examples.append(imagemap.Example.from_arrays(f"shell_{i}", depth, image))
    depth, truth, centres, seams = shell(width, height, **QUERY)
    mask = depth > 0
    luma = color.rgb2gray(truth)
    plates = mask & ~ndimage.binary_dilation(seams, iterations=2)
    plates &= ndimage.binary_erosion(mask, iterations=3)
    dark_level = 0.5 * (float(np.median(luma[seams])) + float(np.median(luma[plates])))

    def features(image, object_mask):
        return seam_scores(image, object_mask, centres, dark_level, width)

    def provenance(source, object_mask):
        index = source[..., 0][plates]
        counts = np.bincount(index[index >= 0], minlength=len(examples))
        return {"palette_share": float(counts.max() / max(counts.sum(), 1))}

    quarter = (slice(height // 4, height // 2), slice(width // 4, width // 2))
    return Task(
        examples, depth, truth, plates, features, {"plates": quarter}, provenance=provenance
    )


def main(argv=None):
    """Print the table (ours, the bounding-box copy, EbSynth if EBSYNTH is set, the truth)."""
    import outside

    return outside.main(
        argv,
        description="relief plates (two examples, plates between grooves elsewhere in each)",
        make_task=make_task,
        default_sizes="320x240,768x576",
        quick_size="160x120",
        default_out="relief_plates",
    )


if __name__ == "__main__":
    main()
