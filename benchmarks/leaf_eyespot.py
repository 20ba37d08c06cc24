"""Outside task: leaves with veins and a painted eyespot near the tip.

Two examples and a query, made here: a leaf lying along x (base left, tip right) whose
depth is a dome raised along the midrib, with the lateral veins pressed in slightly (the
veins are in the relief, as on a real leaf); the map is a green blade with light veins
(their spacing and phase differ per leaf, as no depth can say exactly), grain, and near
the tip a painted eyespot (no relief): a black disc, a yellow ring, a black pupil. Each
size is synthesised with the fish preset (m = 2) and any method options given; the
driver (``outside.py``) prints per size, for ours, a bounding-box copy of the nearest
example, EbSynth (when ``EBSYNTH`` names its binary) and the truth: PSNR on the leaf,
continuity and mid-tones of the veined blade against the truth's, fragments of our
source map, and whether the eyespot is drawn: the metrics' feature test (L* correlation
with the truth's eyespot >= 0.5, best over shifts of 3 px) and its ring contrast (L* of
the yellow ring minus the black disc around it, best over shifts of 3 px; the truth's is
about 60). Pictures: truth | ours | bbox copy [| EbSynth] and an eyespot close-up.

    python benchmarks/leaf_eyespot.py [--sizes 200x150,512x384] [--quick] [--out DIR]
        [--json FILE] [--vote mean --appearance-pyramid laplacian ...]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy import ndimage
from skimage import color

sys.path.insert(0, str(Path(__file__).resolve().parent))  # outside.py beside this script

#: The eyespot's place along the leaf (0 base, 1 tip) and across it (share of the
#: half-width, + below the midrib), and its radii in units of the leaf's largest
#: half-width: pupil, inner and outer edge of the yellow ring, the black disc.
SPOT_ALONG, SPOT_ACROSS = 0.78, 0.35
PUPIL, RING_INNER, RING_OUTER, DISC = 0.06, 0.11, 0.19, 0.27
#: The veined blade excludes the eyespot out to this many disc radii.
SPOT_MARGIN = 1.3

EXAMPLES = [
    dict(length=0.76, breadth=0.28, veins=7.0, phase=0.0, seed=1,
         blade=(0.22, 0.48, 0.16), vein=(0.62, 0.78, 0.35)),
    dict(length=0.72, breadth=0.25, veins=8.0, phase=0.4, seed=2,
         blade=(0.18, 0.42, 0.14), vein=(0.58, 0.74, 0.3)),
]  # fmt: skip
QUERY = dict(length=0.74, breadth=0.26, veins=7.5, phase=0.2, seed=3,
             blade=(0.2, 0.45, 0.15), vein=(0.6, 0.76, 0.33))  # fmt: skip


def leaf(width, height, *, length, breadth, veins, phase, seed, blade, vein):
    """Depth (0 outside), RGB map and the eyespot's centre (x, y) and radius unit (px).

    ``length`` is the leaf's share of the image width, ``breadth`` its largest
    half-width as a share of the image height, ``veins`` the lateral veins per side.
    """
    half = breadth * height
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float64)
    base = (1 - length) / 2 * width
    t = (xx - base) / (length * width)  # 0 at the base, 1 at the tip
    outline = half * np.sin(np.pi * np.clip(t, 0, 1)) ** 0.7 * (1 - 0.35 * np.clip(t, 0, 1))
    across = (yy - height / 2) / np.maximum(outline, 1e-9)  # -1..1 inside
    inside = (t > 0) & (t < 1) & (np.abs(across) < 1)
    # Lateral veins run from the midrib towards the tip at about 50 degrees.
    vein_phase = veins * (t - 0.45 * np.abs(across) * half / (length * width)) + phase
    vein_line = np.abs(vein_phase - np.round(vein_phase)) * (length * width) / veins
    vein_width = 0.012 * height
    lateral = np.exp(-0.5 * (vein_line / vein_width) ** 2) * (np.abs(across) < 0.92)
    midrib = np.exp(-0.5 * ((yy - height / 2) / (1.6 * vein_width)) ** 2)
    lines = np.clip(np.maximum(lateral, midrib), 0, 1)
    dome = np.sqrt(np.clip(1 - across**2, 0, 1)) * np.sin(np.pi * np.clip(t, 0, 1)) ** 0.5
    depth = np.where(inside, 0.35 + 0.5 * dome + 0.08 * midrib - 0.04 * lateral, 0.0)
    image = np.asarray(blade) * (1 - lines[..., None]) + np.asarray(vein) * lines[..., None]
    image = image * (0.85 + 0.15 * dome[..., None])
    image = image + 0.025 * np.random.default_rng(seed).standard_normal((height, width, 1))
    sx = base + SPOT_ALONG * length * width
    local = half * np.sin(np.pi * SPOT_ALONG) ** 0.7 * (1 - 0.35 * SPOT_ALONG)
    sy = height / 2 + SPOT_ACROSS * local
    d = np.hypot(xx - sx, yy - sy) / half
    image[d < DISC] = (0.05, 0.04, 0.03)
    image[(d < RING_OUTER) & (d >= RING_INNER)] = (0.95, 0.8, 0.15)
    image[d < PUPIL] = (0.02, 0.02, 0.02)
    return depth, np.clip(image, 0, 1) * inside[..., None], (sx, sy, half)


def ring_contrast(image, mask, spot, shift=3):
    """L* of the yellow ring minus the black disc around it, best over shifts of the spot."""
    sx, sy, unit = spot
    reach = int(np.ceil(DISC * unit)) + shift + 1
    rows = slice(max(int(sy) - reach, 0), int(sy) + reach + 1)
    columns = slice(max(int(sx) - reach, 0), int(sx) + reach + 1)
    lightness = color.rgb2lab(np.clip(image[rows, columns], 0, 1))[..., 0]
    inside = mask[rows, columns]
    yy, xx = np.mgrid[rows, columns]
    best = -np.inf
    for dy in range(-shift, shift + 1):
        for dx in range(-shift, shift + 1):
            d = np.hypot(xx - sx - dx, yy - sy - dy) / unit
            ring = (d >= RING_INNER) & (d < RING_OUTER) & inside
            disc = (d >= RING_OUTER) & (d < DISC) & inside
            if ring.any() and disc.any():
                best = max(best, float(lightness[ring].mean() - lightness[disc].mean()))
    return best


def make_task(width, height):
    """The two examples and the query at one size, with the veined blade and the eyespot."""
    from outside import Task

    import imagemap
    from imagemap.metrics import FEATURE_NCC, feature_correlation

    examples = []
    for i, spec in enumerate(EXAMPLES):
        depth, image, _ = leaf(width, height, **spec)
        examples.append(imagemap.Example.from_arrays(f"leaf_{i}", depth, image))
    depth, truth, spot = leaf(width, height, **QUERY)
    mask = depth > 0
    sx, sy, unit = spot
    yy, xx = np.mgrid[0:height, 0:width]
    distance = np.hypot(xx - sx, yy - sy) / unit
    region = ndimage.binary_erosion(mask, iterations=3) & (distance > SPOT_MARGIN * DISC)
    disc = (distance < DISC) & mask

    def features(image, object_mask):
        ncc = feature_correlation(image, truth, disc, mask=object_mask)
        return {
            "spot_contrast": ring_contrast(image, object_mask, spot),
            "spot_ncc": ncc,
            "spot_drawn": bool(ncc >= FEATURE_NCC),
        }

    r = int(2.5 * DISC * unit)
    rows, left = slice(max(int(sy) - r, 0), int(sy) + r), max(int(sx) - r, 0)
    return Task(
        examples, depth, truth, region, features, {"spot": (rows, slice(left, left + 2 * r))}
    )


def main(argv=None):
    """Print the table (ours, the bounding-box copy, EbSynth if EBSYNTH is set, the truth)."""
    import outside

    return outside.main(
        argv,
        description="leaf eyespot (two examples, veins in the relief, a painted eyespot)",
        make_task=make_task,
        default_sizes="200x150,512x384",
        quick_size="120x90",
        default_out="leaf_eyespot",
    )


if __name__ == "__main__":
    main()
