"""The registration's match confidence: correct alignments against foreign scans.

For each control material (cloth, leather, wallpaper, wood) and three random perturbations
(the first scan's azimuth, the others' order, rotations up to 4 degrees, shifts up to 5 px;
112 px scans cut from 160 px renders, as tests/test_btf_registration.py makes them), the
four scans are registered and the three non-reference scans' confidences recorded
(correct). Then each scan in turn is replaced by the same view of every other material
(foreign) and of another piece of the same material (another seed); sets the turn search
refuses are counted. Prints the distributions (docs/btf.md, imagemap.btf.registration's
MIN_CONFIDENCE).

    python benchmarks/registration_confidence.py [--foreign-seed 11]
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from imagemap.btf.materials import MATERIALS, make_material  # noqa: E402
from imagemap.btf.registration import register_scans  # noqa: E402
from imagemap.btf.rendering import render_btf_matrix  # noqa: E402
from imagemap.errors import InputError  # noqa: E402

SIZE, CROP = 160, 112
CONTROL = ("cloth", "leather", "wallpaper", "wood")


def constraint_images(name: str, seed: int) -> list[np.ndarray]:
    """Top-view images under light theta 22 at azimuths 0, 90, 180, 270."""
    lights = np.array([[22.0, a] for a in (0, 90, 180, 270)], np.float32)
    matrix = render_btf_matrix(
        make_material(name, size=SIZE, seed=seed), lights, np.array([[0.0, 0.0]], np.float32)
    )
    return [matrix[3 * i : 3 * i + 3].reshape(3, SIZE, SIZE).transpose(1, 2, 0) for i in range(4)]


def scans_of(images, order, angles, shifts) -> list[np.ndarray]:
    """The sample turned by a quarter turn per azimuth step, rotated, shifted, cropped."""
    from scipy import ndimage
    from skimage.transform import rotate

    c = (SIZE - CROP) // 2
    out = []
    for azimuth, angle, shift in zip(order, angles, shifts, strict=True):
        image = rotate(np.rot90(images[azimuth], azimuth), angle, order=3, mode="reflect")
        image = ndimage.shift(image, (*shift, 0), order=3, mode="reflect")
        out.append(np.clip(0.9 * image[c : c + CROP, c : c + CROP], 0, 1).astype(np.float32))
    return out


def summary(label: str, values) -> str:
    values = np.asarray(values, dtype=float)
    return (
        f"{label}: {len(values)} scans, confidence {values.min():.1f}-{values.max():.1f} "
        f"(median {np.median(values):.1f})"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--foreign-seed", type=int, default=2, help="noise seed of the others")
    args = parser.parse_args()
    logging.getLogger("imagemap").setLevel(logging.ERROR)
    rng = np.random.default_rng(1)
    own = {m: constraint_images(m, 2) for m in CONTROL}
    foreign_images = {m: constraint_images(m, args.foreign_seed) for m in MATERIALS}
    piece = {m: constraint_images(m, 7) for m in CONTROL}
    correct, foreign, pieces = [], [], []
    refused = {"correct": 0, "foreign": 0, "piece": 0}
    for name in CONTROL:
        for _ in range(3):
            order = [0, *rng.permutation([1, 2, 3])]
            order = list((np.array(order) + rng.integers(4)) % 4)
            angles = [0.0, *rng.uniform(-4, 4, 3)]
            shifts = [(0.0, 0.0)] + [tuple(rng.uniform(-5, 5, 2)) for _ in range(3)]
            scans = scans_of(own[name], order, angles, shifts)
            try:
                correct += list(register_scans(scans).confidences[1:])
            except InputError:
                refused["correct"] += 1
            for k in (1, 2, 3):
                others = [(foreign_images[o], foreign, "foreign") for o in MATERIALS if o != name]
                for images, bucket, kind in [*others, (piece[name], pieces, "piece")]:
                    mixed = list(scans)
                    mixed[k] = scans_of(images, order, angles, shifts)[k]
                    try:
                        bucket.append(register_scans(mixed).confidences[k])
                    except InputError:
                        refused[kind] += 1
    print(summary("correct alignments", correct))
    print(summary(f"another material (seed {args.foreign_seed})", foreign))
    print(summary("another piece of the same material", pieces))
    print(f"refused by the turn search: {refused}")


if __name__ == "__main__":
    main()
