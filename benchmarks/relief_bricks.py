"""#42's relief task: a brick wall on a gently domed slab, the mortar in grooves.

Two examples and a query, made here (not by ``data_gen``). The object is a slab with a
rounded outline (a superellipse), gently domed, whose depth is carved by mortar grooves
between brick courses: bed joints between the courses and head joints between the
bricks of a course. The course heights, the bricks' length and the stagger from course
to course (running bond, a third, a quarter) differ per object, and so does the courses'
phase, so the query's mortar lines lie elsewhere than any example's and can only come
from its own grooves. Each brick is painted in the object's palette with its own tone
and a speckle; the mortar is light (every brick tone lies below the threshold).

Measured per size (``outside.py`` prints the table; ours, ``warp_nearest``, the
bounding-box copy, EbSynth when ``EBSYNTH`` names its binary, and the truth):

- **mortar recall / precision / F1**, as ``relief_plates.py``'s seam scores with light
  for dark: a pixel is mortar-coloured when its luminance is above the midpoint between
  the truth's mortar and brick luminance; recall is the share of the query's
  mortar-centre pixels with a mortar-coloured output pixel within 1 px, precision the
  share of mortar-coloured output pixels within ``max(2, width / 160)`` px of a mortar
  centre;
- **palette share** (ours, ``warp_nearest``): the share of the bricks' area copied from
  the example that copies most of it, and that example (``palette_from``: 0 has the
  query's red bricks, 1 blue-grey ones; a share below 1 means bricks from both);
- PSNR on the object, continuity and mid-tone share of the bricks (the driver's).

    python benchmarks/relief_bricks.py [--sizes 320x240,768x576] [--quick]
        [--out DIR] [--json FILE] [--finish paper ...]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy import ndimage
from skimage import color

sys.path.insert(0, str(Path(__file__).resolve().parent))  # outside.py beside this script

#: Mortar groove half-width and depth, as fractions of the object's half height and of
#: the slab's relief (the painted mortar, about 1.2 half-widths either side of the
#: joint, stays within the precision's reach at 320 and 768 px wide).
GROOVE_WIDTH = 0.016
GROOVE_DEPTH = 0.08
#: Each course's height varies by up to this share of the object's course height, each
#: head joint's place by up to this share of the brick length.
COURSE_JITTER = 0.08
JOINT_JITTER = 0.06
#: Per-brick tone factors, and the speckle: cells of this size (object half heights),
#: this share of them dark, this share light, and their tone factors.
BRICK_TONE = (0.82, 1.08)
SPECKLE_CELL = 0.014
SPECKLE_DARK, SPECKLE_LIGHT = 0.12, 0.06
SPECKLE_TONES = (0.62, 1.18)

EXAMPLES = [
    dict(a=0.40, b=0.36, cx=0.50, cy=0.50, course=0.17, brick=2.0, stagger=0.5, seed=21,
         brick_colour=(0.62, 0.25, 0.17), mortar=(0.86, 0.83, 0.76)),
    dict(a=0.41, b=0.37, cx=0.51, cy=0.49, course=0.21, brick=2.4, stagger=0.25, seed=22,
         brick_colour=(0.36, 0.39, 0.46), mortar=(0.80, 0.79, 0.72)),
]  # fmt: skip
QUERY = dict(a=0.41, b=0.35, cx=0.49, cy=0.51, course=0.19, brick=2.2, stagger=1 / 3, seed=23,
             brick_colour=(0.60, 0.26, 0.18), mortar=(0.85, 0.82, 0.75))  # fmt: skip


def wall(width, height, *, a, b, cx, cy, course, brick, stagger, seed, brick_colour, mortar):
    """Depth (0 outside), RGB map, mortar-centre pixels and painted mortar of one wall.

    ``a``, ``b`` are the slab's half-width and half-height as shares of the image's,
    ``course`` the course height in object half heights, ``brick`` the brick length in
    course heights, ``stagger`` the head joints' shift from one course to the next as a
    share of the brick length.
    """
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float64)
    unit = b * height  # the object's half height in pixels
    u, v = (xx - cx * width) / (a * width), (yy - cy * height) / unit
    rho = np.abs(u) ** 4 + np.abs(v) ** 4  # a rounded rectangle
    inside = rho < 1
    rim = np.clip(1 - rho, 0, 1) ** 0.25  # steep at the outline, flat on the face
    dome = 1 - 0.5 * (u**2 + v**2)
    # Courses, in object units (half heights, so that every size draws the same wall):
    # bed joints from above the object down, each course's height jittered, the first
    # joint's phase per object.
    ox = (xx[0] - cx * width) / unit
    oy = v[:, 0]
    top = -1 - rng.uniform(0, 1) * course
    beds = top + np.concatenate(
        [[0.0], np.cumsum(course * (1 + rng.uniform(-1, 1, 64) * COURSE_JITTER))]
    )
    index = np.clip(np.searchsorted(beds, oy, side="right") - 1, 0, len(beds) - 2)
    to_bed = np.minimum(oy - beds[index], beds[index + 1] - oy)
    # Head joints: every brick length, shifted by the stagger from course to course,
    # each joint moved a little.
    length = brick * course
    phase = rng.uniform(0, length)
    start = -np.ceil(a * width / unit) - 2 * length  # left of the object
    per_course = int((2 * -start) / length) + 2
    to_head = np.empty((height, width))
    brick_id = np.empty((height, width), np.int64)
    for k in range(len(beds) - 1):
        joints = start + (phase + k * stagger * length) % length + length * np.arange(per_course)
        joints = joints + rng.uniform(-JOINT_JITTER, JOINT_JITTER, per_course) * length
        rows = index == k
        if rows.any():
            to_head[rows] = np.abs(ox[:, None] - joints[None]).min(axis=1)
            brick_id[rows] = k * (per_course + 1) + np.searchsorted(joints, ox)
    joint = np.minimum(to_bed[:, None], to_head) * unit  # distance to the nearest joint, px
    half = GROOVE_WIDTH * unit
    groove = np.exp(-0.5 * (joint / half) ** 2)
    depth = np.where(inside, 0.3 + 0.35 * rim + 0.15 * dome - GROOVE_DEPTH * 0.5 * groove, 0.0)
    # Paint: each brick its own tone, a speckle fixed to the object's coordinates.
    tones = rng.uniform(*BRICK_TONE, brick_id.max() + 1)
    image = np.asarray(brick_colour) * tones[brick_id][..., None]
    reach = a * width / unit  # the object's half-width in half heights
    column = ((xx - cx * width) / unit + reach) / SPECKLE_CELL
    row = (v + 1) / SPECKLE_CELL
    field = rng.uniform(0, 1, (int(2 / SPECKLE_CELL) + 2, int(2 * reach / SPECKLE_CELL) + 2))
    speck = field[
        np.clip(row.astype(int), 0, field.shape[0] - 1),
        np.clip(column.astype(int), 0, field.shape[1] - 1),
    ]
    dark, light = SPECKLE_TONES
    speckle = np.where(speck < SPECKLE_DARK, dark, np.where(speck > 1 - SPECKLE_LIGHT, light, 1))
    image = image * speckle[..., None]
    painted = groove > 0.5  # within about 1.2 half-widths of the joint
    image[painted] = mortar
    image = image + 0.015 * rng.standard_normal((height, width, 1))
    centre = inside & (joint < 0.75) & (ndimage.distance_transform_edt(inside) > 2)
    return depth, np.clip(image, 0, 1) * inside[..., None], centre, painted & inside


def mortar_scores(image, mask, centres, light_level, width):
    """Mortar recall, precision and F1 of a map (see the module notes).

    ``relief_plates.seam_scores`` with light for dark: the same recall (1 px) and the
    same precision reach (``max(2, width / 160)`` px).
    """
    from relief_plates import line_scores

    light = (color.rgb2gray(np.clip(image, 0, 1)) > light_level) & mask
    recall, precision, f1 = line_scores(light, centres, width)
    return {"mortar_recall": recall, "mortar_precision": precision, "mortar_f1": f1}


def make_task(width, height):
    """The two examples and the query at one size."""
    from outside import Task

    import imagemap

    examples = []
    for i, spec in enumerate(EXAMPLES):
        depth, image, _, _ = wall(width, height, **spec)
        examples.append(imagemap.Example.from_arrays(f"wall_{i}", depth, image))
    depth, truth, centres, mortar = wall(width, height, **QUERY)
    mask = depth > 0
    luma = color.rgb2gray(truth)
    bricks = mask & ~ndimage.binary_dilation(mortar, iterations=2)
    bricks &= ndimage.binary_erosion(mask, iterations=3)
    light_level = 0.5 * (float(np.median(luma[mortar])) + float(np.median(luma[bricks])))

    def features(image, object_mask):
        return mortar_scores(image, object_mask, centres, light_level, width)

    def provenance(source, object_mask):
        index = source[..., 0][bricks]
        counts = np.bincount(index[index >= 0], minlength=len(examples))
        share = float(counts.max() / max(counts.sum(), 1))
        return {"palette_share": share, "palette_from": int(counts.argmax())}

    quarter = (slice(height // 4, height // 2), slice(width // 4, width // 2))
    return Task(
        examples, depth, truth, bricks, features, {"bricks": quarter}, provenance=provenance
    )


def main(argv=None):
    """Print the table (ours, warp_nearest, the bounding-box copy, EbSynth if EBSYNTH is
    set, the truth)."""
    import outside

    return outside.main(
        argv,
        description="relief bricks (two examples, mortar grooves of other courses and bonds)",
        make_task=make_task,
        default_sizes="320x240,768x576",
        quick_size="160x120",
        default_out="relief_bricks",
    )


if __name__ == "__main__":
    main()
