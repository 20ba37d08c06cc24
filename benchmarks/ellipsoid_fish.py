"""#10's outside task, rebuilt: an ellipsoid "fish" with stripes and an eye ring.

Two examples and a query, made here (not by ``data_gen``): the depth is the height of an
ellipsoid, the map vertical crisp stripes (their phase and period differ per object, as
no depth can show) with grain, and near the head a white disc with a blue ring and a
black pupil, painted only (no relief). Each size is synthesised with the fish preset
(m = 2) and any method options given; the driver (``outside.py``) prints per size, for
ours, a bounding-box copy of the nearest example, EbSynth (when ``EBSYNTH`` names its
binary) and the truth: PSNR on the object, continuity and mid-tone share of the striped
back against the truth's (``imagemap.metrics``), fragments of our source map, the eye's
ring contrast (grey levels of the white rim minus the blue ring, best over shifts of up
to 3 px; the truth's is about 173) and whether the eye is drawn (the metrics' feature
test: L* correlation with the truth's eye disc >= 0.5). Pictures: truth | ours | bbox
copy [| EbSynth] and an eye close-up per size.

    python benchmarks/ellipsoid_fish.py [--sizes 200x150,512x512,1024x1024] [--quick]
        [--out DIR] [--json FILE] [--vote mean --appearance-pyramid laplacian ...]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy import ndimage
from skimage import color

sys.path.insert(0, str(Path(__file__).resolve().parent))  # outside.py beside this script

#: The eye's centre in object units (u right, v down) and its radii in units of the
#: object's half height: pupil, inner and outer edge of the ring, the white disc.
EYE = (0.62, -0.2)
PUPIL, RING_INNER, RING_OUTER, DISC = 0.04, 0.09, 0.16, 0.21
#: The striped back excludes the eye out to this many disc radii (the ring's own
#: edges are not stripes; a map's eye may sit a few pixels off).
EYE_MARGIN = 1.3

EXAMPLES = [
    dict(a=0.40, b=0.30, cx=0.50, cy=0.50, phase=0.0, periods=3.0, seed=1,
         body=(0.85, 0.6, 0.2), stripe=(0.35, 0.2, 0.1), ring=(0.1, 0.3, 0.6)),
    dict(a=0.42, b=0.26, cx=0.50, cy=0.52, phase=0.3, periods=3.5, seed=2,
         body=(0.75, 0.65, 0.3), stripe=(0.3, 0.25, 0.15), ring=(0.15, 0.25, 0.55)),
]  # fmt: skip
QUERY = dict(a=0.38, b=0.33, cx=0.48, cy=0.50, phase=0.15, periods=3.2, seed=3,
             body=(0.8, 0.62, 0.25), stripe=(0.33, 0.22, 0.12),
             ring=(0.12, 0.28, 0.58))  # fmt: skip


def ellipsoid_fish(width, height, *, a, b, cx, cy, phase, periods, seed, body, stripe, ring):
    """Depth (0 outside), RGB map and the eye's centre (x, y) and radius unit in pixels."""
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float64)
    u, v = (xx - cx * width) / (a * width), (yy - cy * height) / (b * height)
    inside = u**2 + v**2 < 1
    depth = np.where(inside, np.sqrt(np.clip(1 - u**2 - v**2, 0, 1)), 0.0)
    bars = 0.5 + 0.5 * np.sin(2 * np.pi * (periods * u + phase))
    bars = 1 / (1 + np.exp(-12 * (bars - 0.5)))[..., None]  # crisp stripes
    image = np.asarray(body) * (1 - bars) + np.asarray(stripe) * bars
    image = image + 0.03 * np.random.default_rng(seed).standard_normal((height, width, 1))
    unit = b * height
    ex, ey = cx * width + EYE[0] * a * width, cy * height + EYE[1] * b * height
    d = np.hypot(xx - ex, yy - ey) / unit
    image[d < DISC] = (0.95, 0.95, 0.9)
    image[(d < RING_OUTER) & (d >= RING_INNER)] = ring
    image[d < PUPIL] = (0.05, 0.05, 0.05)
    return depth, np.clip(image, 0, 1) * inside[..., None], (ex, ey, unit)


def ring_contrast(image, mask, eye, shift=3):
    """Grey levels (0-255) of the white rim minus the blue ring, best over shifts."""
    ex, ey, unit = eye
    grey = color.rgb2gray(np.clip(image, 0, 1)) * 255
    yy, xx = np.mgrid[0 : mask.shape[0], 0 : mask.shape[1]]
    best = -np.inf
    for sy in range(-shift, shift + 1):
        for sx in range(-shift, shift + 1):
            d = np.hypot(xx - ex - sx, yy - ey - sy) / unit
            rim = (d >= RING_OUTER) & (d < DISC) & mask
            ring = (d >= RING_INNER) & (d < RING_OUTER) & mask
            best = max(best, grey[rim].mean() - grey[ring].mean())
    return float(best)


def make_task(width, height):
    """The two examples and the query at one size, with the striped back and the eye."""
    from outside import Task

    import imagemap
    from imagemap.metrics import FEATURE_NCC, feature_correlation

    examples = []
    for i, spec in enumerate(EXAMPLES):
        depth, image, _ = ellipsoid_fish(width, height, **spec)
        examples.append(imagemap.Example.from_arrays(f"ellipsoid_{i}", depth, image))
    depth, truth, eye = ellipsoid_fish(width, height, **QUERY)
    mask = depth > 0
    ex, ey, unit = eye
    yy, xx = np.mgrid[0:height, 0:width]
    distance = np.hypot(xx - ex, yy - ey) / unit
    # The striped back: the object less its outline's 3 px and the eye with a margin.
    region = ndimage.binary_erosion(mask, iterations=3) & (distance > EYE_MARGIN * DISC)
    disc = (distance < DISC) & mask

    def features(image, object_mask):
        ncc = feature_correlation(image, truth, disc, mask=object_mask)
        return {
            "ring_contrast": ring_contrast(image, object_mask, eye),
            "eye_ncc": ncc,
            "eye_drawn": bool(ncc >= FEATURE_NCC),
        }

    r = int(2.5 * DISC * unit)
    rows, left = slice(max(int(ey) - r, 0), int(ey) + r), max(int(ex) - r, 0)
    return Task(
        examples, depth, truth, region, features, {"eye": (rows, slice(left, left + 2 * r))}
    )


def main(argv=None):
    """Print the table (ours, the bounding-box copy, EbSynth if EBSYNTH is set, the truth)."""
    import outside

    return outside.main(
        argv,
        description="ellipsoid fish (two examples, straight stripes, an eye ring)",
        make_task=make_task,
        default_sizes="200x150,512x512,1024x1024",
        quick_size="120x90",
        default_out="ellipsoid_fish",
    )


if __name__ == "__main__":
    main()
