"""The pictures of maps tailored to the query's own shape (#42), for the README and docs.

- ``relief.jpg``: the three relief tasks of ``benchmarks/`` (plates between grooves,
  brick courses, scales on bumps) at 320x240: truth | before (the method of 0.2.0, when
  ``--before DIR`` holds its maps as ``TASK_before_320.npy``) | now | the paper's method
  (``--finish paper``);
- ``pose.png``: a held-out generated fish and bust: the upright query's map, the map of
  the query mirrored, and of the query turned 30 degrees and scaled 0.7 (each made from
  the moved query, the database untouched).

    python docs/make_shape_figures.py [OUT_DIR] [--before DIR]

The "before" maps were made with the library at commit 0a29e77 (``imagemap.colorize``
on each task at 320x240, seed 0, preset fish), saved with ``numpy.save``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import imagemap  # noqa: E402
from imagemap.depth.config import FINISHES  # noqa: E402

TASKS = ("relief_plates", "relief_bricks", "relief_scales")


def _label(image: np.ndarray, text: str) -> np.ndarray:
    picture = Image.fromarray(np.round(np.clip(image, 0, 1) * 255).astype(np.uint8))
    ImageDraw.Draw(picture).text((4, 2), text, fill=(255, 255, 255))
    return np.asarray(picture, np.float32) / 255


def _on_black(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    return np.where(mask[..., None], np.clip(image, 0, 1), 0.0).astype(np.float32)


def relief(out: Path, before: Path | None) -> None:
    rows = []
    for name in TASKS:
        task = __import__(name).make_task(320, 240)
        database = imagemap.Database(task.examples)
        mask = task.depth > 0
        now = imagemap.colorize(task.depth, database, "fish", seed=0)
        paper = imagemap.colorize(
            task.depth, database, imagemap.DepthConfig().replace_fields(**FINISHES["paper"])
        )
        cells = [_label(_on_black(task.truth, mask), f"{name[7:]}: truth")]
        saved = before / f"{name}_before_320.npy" if before else None
        if saved is not None and saved.is_file():
            cells.append(_label(_on_black(np.load(saved), mask), "before (0.2.0)"))
        cells.append(_label(_on_black(now.image, mask), "now"))
        cells.append(_label(_on_black(paper.image, mask), "paper"))
        rows.append(np.concatenate(cells, axis=1))
    # JPEG: the textures' grain makes a PNG of this figure almost 1 MB.
    picture = np.round(np.concatenate(rows, axis=0) * 255).astype(np.uint8)
    Image.fromarray(picture).save(out / "relief.jpg", quality=88)


def pose(out: Path) -> None:
    from skimage.transform import AffineTransform, warp

    from data_gen.dataset import write_class

    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for name, size in (("fish", (240, 180)), ("busts", (180, 240))):
            root = Path(folder) / name
            write_class(name, root, count=9, seed=0, size=size, holdout=1, quiet=True)
            database = imagemap.Database.from_directory(root)
            query = imagemap.read_depth(next((root / "holdout").glob("*_depth.png")))
            height, width = query.shape
            depth = np.zeros((2 * height, 2 * width), np.float32)
            depth[height // 2 : height // 2 + height, width // 2 : width // 2 + width] = query
            centre = np.array([(2 * width - 1) / 2, (2 * height - 1) / 2])
            theta = np.deg2rad(-30.0)
            linear = 0.7 * np.array(
                [[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]]
            )
            matrix = np.eye(3)
            matrix[:2, :2], matrix[:2, 2] = linear, centre - linear @ centre
            moved = AffineTransform(matrix=matrix)
            turned = warp(depth, moved.inverse, order=1, preserve_range=True)
            inside = warp((depth > 0).astype(float), moved.inverse, order=1) > 0.5
            queries = {
                "upright": depth,
                "mirrored": np.ascontiguousarray(depth[:, ::-1]),
                "turned 30, x0.7": np.where(inside, turned, 0).astype(np.float32),
            }
            made = {
                label: imagemap.colorize(moved_depth, database, name, seed=0)
                for label, moved_depth in queries.items()
            }
            # Each map cropped to the box of the three objects (and a margin).
            union = np.any([m.mask for m in made.values()], axis=0)
            ys, xs = np.nonzero(union)
            box = (
                slice(max(ys.min() - 8, 0), ys.max() + 9),
                slice(max(xs.min() - 8, 0), xs.max() + 9),
            )
            cells = [
                _label(_on_black(m.image, m.mask)[box], f"{name}: {label}")
                for label, m in made.items()
            ]
            rows.append(np.concatenate(cells, axis=1))
    width = max(row.shape[1] for row in rows)
    rows = [np.pad(r, ((0, 0), (0, width - r.shape[1]), (0, 0))) for r in rows]
    imagemap.write_image(out / "pose.png", np.concatenate(rows, axis=0))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", type=Path, default=ROOT / "docs" / "images")
    parser.add_argument("--before", type=Path, help="folder of the 0.2.0 maps (.npy)")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    relief(args.out, args.before)
    pose(args.out)


if __name__ == "__main__":
    main()
