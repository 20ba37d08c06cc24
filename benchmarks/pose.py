"""#42's pose task: does a query's pose change its map? (equivariance error per pose)

Held-out generated objects (``data_gen``; fish and busts) are put in a frame twice their
size and moved there (rotated, scaled, shifted, mirrored); each moved query is
synthesized from the untouched database. The **equivariance error** of a pose is the
mean CIEDE2000 between the moved query's map and the upright query's map moved the same
way, over the moved object's mask eroded by 2 px (0: the pose does not matter). The
table also says whether the moved query chose the upright query's examples.

    python benchmarks/pose.py [--classes fish,busts] [--objects 2] [--size 320x240]
        [--poses rot20,rot-35,...] [--out DIR] [--json FILE] [--finish paper ...]

Pictures: ``DIR/CLASS_OBJECT.png``, per pose: the upright map moved | the moved
query's map (one row per pose).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import ndimage
from skimage import color
from skimage import io as skio
from skimage.transform import AffineTransform, warp

#: The poses: name -> (rotation degrees counter-clockwise, scale, shift (x, y) as a
#: share of the frame, mirrored left-right).
POSES = {
    "rot20": (20.0, 1.0, (0.0, 0.0), False),
    "rot-35": (-35.0, 1.0, (0.0, 0.0), False),
    "rot45": (45.0, 1.0, (0.0, 0.0), False),
    "scale0.6": (0.0, 0.6, (0.0, 0.0), False),
    "scale0.5": (0.0, 0.5, (0.0, 0.0), False),
    "scale2": (0.0, 2.0, (0.0, 0.0), False),
    "scale0.8+shift": (0.0, 0.8, (0.12, -0.1), False),
    "mirror": (0.0, 1.0, (0.0, 0.0), True),
    "mirror+rot20": (20.0, 1.0, (0.0, 0.0), True),
}
#: The moved map is compared inside the moved object eroded by this many pixels (its
#: outline is resampled in both).
ERODE = 2


def pose_transform(shape: tuple[int, int], pose) -> AffineTransform:
    """The map from the upright frame's (x, y) to the moved frame's, about its centre."""
    angle, scale, (sx, sy), mirrored = pose
    height, width = shape
    centre = np.array([(width - 1) / 2, (height - 1) / 2])
    flip = np.diag([-1.0, 1.0]) if mirrored else np.eye(2)
    theta = np.deg2rad(-angle)  # image y points down: counter-clockwise on screen
    rotation = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    linear = scale * rotation @ flip
    offset = centre + np.array([sx * width, sy * height]) - linear @ centre
    matrix = np.eye(3)
    matrix[:2, :2], matrix[:2, 2] = linear, offset
    return AffineTransform(matrix=matrix)


def move_depth(depth: np.ndarray, transform: AffineTransform) -> np.ndarray:
    """The depth moved: values interpolated inside the object, background 0 outside."""
    mask = depth > 0
    _, (iy, ix) = ndimage.distance_transform_edt(~mask, return_indices=True)
    filled = depth[iy, ix]  # the background continued from the object: no mix with 0
    inverse = transform.inverse
    moved = warp(filled, inverse, order=1, preserve_range=True)
    moved_mask = warp(mask.astype(np.float64), inverse, order=1, preserve_range=True) > 0.5
    return np.where(moved_mask, moved, 0.0).astype(np.float32)


def move_image(image: np.ndarray, transform: AffineTransform) -> np.ndarray:
    return warp(image, transform.inverse, order=1, preserve_range=True).astype(np.float32)


def equivariance_error(moved_map, map_moved, mask) -> float:
    """Mean CIEDE2000 over ``mask`` eroded by :data:`ERODE` px."""
    inner = ndimage.binary_erosion(mask, iterations=ERODE)
    lab_a = color.rgb2lab(np.clip(moved_map, 0, 1))
    lab_b = color.rgb2lab(np.clip(map_moved, 0, 1))
    return float(color.deltaE_ciede2000(lab_a, lab_b)[inner].mean())


def padded(depth: np.ndarray) -> np.ndarray:
    """The depth in a frame twice its size, centred (room for scale 2 and shifts)."""
    height, width = depth.shape
    frame = np.zeros((2 * height, 2 * width), np.float32)
    frame[height // 2 : height // 2 + height, width // 2 : width // 2 + width] = depth
    return frame


def main(argv=None) -> list[dict]:
    from imagemap.cli.options import add_config_options, config_options

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--classes", default="fish,busts")
    parser.add_argument("--objects", type=int, default=2, help="held-out objects per class")
    parser.add_argument("--size", default="320x240", help="the classes' WIDTHxHEIGHT")
    parser.add_argument("--poses", default=",".join(POSES))
    parser.add_argument("--out", type=Path, default=Path("pose"))
    parser.add_argument("--json", type=Path)
    parser.add_argument("--data", type=Path, help="make the classes here (kept)")
    add_config_options(parser)
    args = parser.parse_args(argv)
    options = config_options(args)
    width, height = (int(v) for v in args.size.split("x"))
    poses = {name: POSES[name] for name in args.poses.split(",")}
    import imagemap
    from data_gen.dataset import write_class

    args.out.mkdir(parents=True, exist_ok=True)
    scratch = args.data or Path(tempfile.mkdtemp(prefix="pose_"))
    rows = []
    for name in args.classes.split(","):
        folder = scratch / name
        size = (width, height) if name == "fish" else (height, width)
        if not folder.exists():
            write_class(name, folder, count=8 + args.objects, seed=0, size=size,
                        holdout=args.objects, quiet=True)  # fmt: skip
        database = imagemap.Database.from_directory(folder)
        for query in sorted((folder / "holdout").glob("*_depth.png")):
            stem = query.name[: -len("_depth.png")]
            depth = padded(imagemap.read_depth(query))
            upright = imagemap.colorize(depth, database, preset=name, seed=args.seed, **options)
            tiles = []
            for pose_name, pose in poses.items():
                transform = pose_transform(depth.shape, pose)
                moved_depth = move_depth(depth, transform)
                start = time.perf_counter()
                moved = imagemap.colorize(
                    moved_depth, database, preset=name, seed=args.seed, **options
                )
                seconds = time.perf_counter() - start
                expected = move_image(upright.image, transform)
                error = equivariance_error(moved.image, expected, moved_depth > 0)
                rows.append({
                    "class": name, "object": stem, "pose": pose_name, "de00": error,
                    "same_examples": moved.example_names == upright.example_names,
                    "examples": ",".join(moved.example_names), "seconds": seconds,
                })  # fmt: skip
                tiles.append(np.concatenate([expected, moved.image], axis=1))
            picture = np.concatenate(tiles, axis=0)
            skio.imsave(args.out / f"{name}_{stem}.png",
                        np.round(np.clip(picture, 0, 1) * 255).astype(np.uint8),
                        check_contrast=False)  # fmt: skip
    label = " ".join(f"--{k.replace('_', '-')} {v}" for k, v in options.items()) or "defaults"
    print(f"pose equivariance ({label}, seed {args.seed}; ΔE00 of the moved query's map "
          "against the upright map moved)")  # fmt: skip
    print("| class | object | pose | ΔE00 | same examples | examples | s |")
    print("|---|---|---|---:|---|---|---:|")
    for row in rows:
        print(f"| {row['class']} | {row['object']} | {row['pose']} | {row['de00']:.1f} | "
              f"{'yes' if row['same_examples'] else 'no'} | {row['examples']} | "
              f"{row['seconds']:.1f} |")  # fmt: skip
    worst = max((row["de00"] for row in rows), default=math.nan)
    print(f"worst ΔE00: {worst:.1f}")
    if args.json:
        args.json.write_text(json.dumps({"options": options, "rows": rows}, indent=1) + "\n")
    return rows


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
