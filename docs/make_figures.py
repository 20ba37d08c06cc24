"""Regenerate the README's pictures: ``python docs/make_figures.py [--out docs/images]``.

- ``results.png``: per class (fish, busts, humans; generated, seed 0) the query
  depth, the examples selected, the synthesized map, its provenance and the
  held-out truth.
- ``crops.png``: close-ups (3x) of a fish's eye and a stripe boundary and a bust's
  face: truth, the paper's method (``--finish paper``), 0.1.0's default (no
  registration), the default, and the nearest example's map pasted over.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from data_gen import make_instance
from imagemap import Database, Example, colorize
from imagemap.depth.config import FINISHES, PRESETS
from imagemap.evaluation import _copy_nearest
from imagemap.io import write_image

BACKDROP = 0.85


def _on_backdrop(image, mask):
    return np.where(mask[..., None], image, BACKDROP).astype(np.float32)


def _database(cls: str, count: int, seed: int = 0) -> tuple[Database, Example]:
    examples = []
    for i in range(count):
        inst = make_instance(cls, i, seed=seed)
        examples.append(
            Example.from_arrays(f"{cls}_{i:03d}", inst.depth, inst.image, labels=inst.labels)
        )
    return Database(examples[:-1]), examples[-1]


def _caption(tile: np.ndarray, text: str) -> np.ndarray:
    picture = Image.fromarray(np.round(np.clip(tile, 0, 1) * 255).astype(np.uint8))
    canvas = Image.new("RGB", (picture.width, picture.height + 14), (255, 255, 255))
    canvas.paste(picture, (0, 14))
    ImageDraw.Draw(canvas).text((2, 1), text, fill=(0, 0, 0))
    return np.asarray(canvas, dtype=np.float32) / 255.0


def _row(tiles: list[np.ndarray], gap: int = 4) -> np.ndarray:
    h = max(t.shape[0] for t in tiles)
    padded = [np.pad(t, ((0, h - t.shape[0]), (0, gap), (0, 0)), constant_values=1) for t in tiles]
    return np.concatenate(padded, axis=1)


def _stack(rows: list[np.ndarray], gap: int = 6) -> np.ndarray:
    w = max(r.shape[1] for r in rows)
    padded = [np.pad(r, ((0, gap), (0, w - r.shape[1]), (0, 0)), constant_values=1) for r in rows]
    return np.concatenate(padded, axis=0)


def results_figure(count: int = 12) -> np.ndarray:
    rows = []
    for cls in ("fish", "busts", "humans"):
        db, query = _database(cls, count)
        result = colorize(query.depth, db, cls, seed=0)
        mask = query.mask
        depth = query.depth
        grey = np.where(mask, 0.15 + 0.85 * (depth - depth[mask].min()) / np.ptp(depth[mask]), 1)
        tiles = [_caption(np.repeat(grey[..., None], 3, axis=2), "query depth")]
        for name in result.example_names:
            tiles.append(_caption(_on_backdrop(db[name].image, db[name].mask), name))
        tiles.append(_caption(_on_backdrop(result.image, mask), "synthesized"))
        tiles.append(_caption(result.provenance, "provenance"))
        tiles.append(_caption(_on_backdrop(query.image, mask), "truth (held out)"))
        rows.append(_row(tiles))
    return _stack(rows)


#: 0.1.0's default matching: positions relative to each object's centroid, the example
#: preference at the coarser levels only (as in make_coherence_figures.py).
BEFORE = dict(registration=False, example_preference=0.3, preference_at_finest=False)


def _crop(image, box, zoom=3):
    y0, y1, x0, x1 = box
    return np.kron(image[y0:y1, x0:x1], np.ones((zoom, zoom, 1))).astype(np.float32)


def crops_figure(count: int = 12) -> np.ndarray:
    rows = []
    for cls, name_boxes in (("fish", ("eye", "stripes")), ("busts", ("face",))):
        db, query = _database(cls, count)
        mask = query.mask
        paper = colorize(query.depth, db, PRESETS[cls].replace_fields(**FINISHES["paper"]), seed=0)
        before = colorize(query.depth, db, PRESETS[cls].replace_fields(**BEFORE), seed=0)
        default = colorize(query.depth, db, cls, seed=0)
        pasted, _, _ = _copy_nearest(query.depth, db)
        labels = query.labels
        ys, xs = np.nonzero(mask)
        for what in name_boxes:
            if what in ("eye", "face"):
                part = 5 if cls == "fish" else 4  # fish eye; bust eyes
                py, px = np.nonzero(labels == part)
                cy, cx = int(py.mean()), int(px.mean())
                half = 18 if cls == "fish" else 24
            else:  # a stripe boundary on the fish's flank
                cy, cx = int(ys.mean()), int(xs.min() + 0.45 * np.ptp(xs))
                half = 18
            box = (max(cy - half, 0), cy + half, max(cx - half, 0), cx + half)
            tiles = [
                _caption(_crop(_on_backdrop(query.image, mask), box), f"{cls} {what}: truth"),
                _caption(_crop(_on_backdrop(paper.image, mask), box), "--finish paper"),
                _caption(_crop(_on_backdrop(before.image, mask), box), "0.1.0 default"),
                _caption(_crop(_on_backdrop(default.image, mask), box), "default (this version)"),
                _caption(_crop(_on_backdrop(pasted, mask), box), "nearest pasted"),
            ]
            rows.append(_row(tiles))
    return _stack(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(Path(__file__).parent / "images"))
    args = parser.parse_args()
    out = Path(args.out)
    with tempfile.TemporaryDirectory():
        write_image(out / "results.png", results_figure())
        write_image(out / "crops.png", crops_figure())
    print(f"wrote {out / 'results.png'} and {out / 'crops.png'}")


if __name__ == "__main__":
    main()
