"""The README's coherence pictures (issue #32): python docs/make_coherence_figures.py [OUT_DIR]

- ``coherence.png``: the ellipsoid-fish outside task (``benchmarks/ellipsoid_fish.py``) at
  200x150, 512^2 and 1024^2, each row truth | 0.1.0's matching (positions relative to each
  object's centroid) | registered, without the seam stage | the default (registered, the
  copy rearranged by graph cuts), with their fragments for 90 % of the object;
- ``fish_2048.png``: a generated 2048x1536 fish from eight examples: truth | ours |
  provenance;
- ``mesh_four_angles.png``: a generated fish mesh textured by the mesh route, from four
  angles (truth above, ours below).

Everything is made here from procedural data (``data_gen`` and the outside task); seed 0.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import ellipsoid_fish  # noqa: E402  (the outside task, beside this script's repository)

import imagemap  # noqa: E402
from data_gen import make_instance  # noqa: E402
from imagemap import Database, Example  # noqa: E402
from imagemap.depth.config import PRESETS  # noqa: E402
from imagemap.metrics import fragments  # noqa: E402

#: 0.1.0's default matching: positions relative to each object's centroid, the example
#: preference at the coarser levels only.
BEFORE = dict(registration=False, example_preference=0.3, preference_at_finest=False)
BACKDROP = 1.0


def _label(image: np.ndarray, text: str) -> np.ndarray:
    picture = Image.fromarray((np.clip(image, 0, 1) * 255).astype(np.uint8))
    ImageDraw.Draw(picture).text((4, 2), text, fill=(0, 0, 0))
    return np.asarray(picture).astype(np.float32) / 255


def _on_white(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    return np.where(mask[..., None], image, BACKDROP).astype(np.float32)


def _fit(image: np.ndarray, height: int, width: int | None = None) -> np.ndarray:
    """``image`` scaled to ``height`` (and, with ``width``, centred on a white box)."""
    scale = height / image.shape[0]
    if width is not None:
        scale = min(scale, width / image.shape[1])
    size = (max(1, round(image.shape[1] * scale)), max(1, round(image.shape[0] * scale)))
    picture = Image.fromarray((np.clip(image, 0, 1) * 255).astype(np.uint8)).resize(
        size, Image.LANCZOS
    )
    fitted = np.asarray(picture).astype(np.float32) / 255
    if width is None:
        return fitted
    box = np.full((height, width, 3), BACKDROP, dtype=np.float32)
    y0, x0 = (height - fitted.shape[0]) // 2, (width - fitted.shape[1]) // 2
    box[y0 : y0 + fitted.shape[0], x0 : x0 + fitted.shape[1]] = fitted[..., :3]
    return box


def coherence(out: Path, sizes=((200, 150), (512, 512), (1024, 1024)), height: int = 220):
    rows = []
    for width, h in sizes:
        examples = []
        for i, spec in enumerate(ellipsoid_fish.EXAMPLES):
            depth, image, _ = ellipsoid_fish.ellipsoid_fish(width, h, **spec)
            examples.append(Example.from_arrays(f"ellipsoid_{i}", depth, image))
        depth, truth, _ = ellipsoid_fish.ellipsoid_fish(width, h, **ellipsoid_fish.QUERY)
        mask = depth > 0
        database = Database(examples)
        box = height * 4 // 3
        cells = [_label(_fit(_on_white(truth, mask), height, box), f"truth {width}x{h}")]
        for name, config in (
            ("centroid", PRESETS["fish"].replace_fields(**BEFORE)),
            ("no seams", PRESETS["fish"].replace_fields(seam_smoothness=0.0)),
            ("default", PRESETS["fish"]),
        ):
            result = imagemap.colorize(depth, database, config, seed=0)
            count = fragments(result.source, mask).count_90
            cells.append(
                _label(
                    _fit(_on_white(result.image, mask), height, box),
                    f"{name}: {count} fragments for 90 %",
                )
            )
        rows.append(np.concatenate(cells, axis=1))
    imagemap.write_image(out / "coherence.png", np.concatenate(rows, axis=0))


def fish_2048(out: Path, count: int = 9, height: int = 300):
    examples = []
    for i in range(count):
        instance = make_instance("fish", i, seed=0, size=(2048, 1536))
        examples.append(Example.from_arrays(f"fish_{i:03d}", instance.depth, instance.image))
    query = examples.pop()
    result = imagemap.colorize(query.depth, Database(examples), "fish", seed=0)
    mask = query.mask
    cells = [
        _label(_fit(_on_white(query.image, mask), height), "truth 2048x1536"),
        _label(_fit(_on_white(result.image, mask), height), "ours"),
        _label(_fit(result.provenance, height), "provenance"),
    ]
    imagemap.write_image(out / "fish_2048.png", np.concatenate(cells, axis=1))


def mesh_four_angles(out: Path, size: int = 240):
    from data_gen.dataset import write_class
    from imagemap.mesh import colorize_mesh
    from imagemap.scene import load_mesh, render_textured
    from imagemap.scene.coverage import choose_views

    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder) / "fish"
        write_class("fish", root, count=9, seed=0, holdout=1, meshes=True, quiet=True)
        truth = load_mesh(root / "holdout" / "meshes" / "fish_008.glb")
        database = Database.from_directory(root / "meshes")
        views = choose_views(truth)  # what the command line's default '--views auto' takes
        made = colorize_mesh(truth, database, views, preset="fish", seed=0)
        angles = ("0,0", "90,0", "180,0", "-40,25")
        rows = []
        for name, mesh in (("truth", truth), ("ours", made.mesh)):
            cells = [
                render_textured(mesh, angle, size=(size, size * 3 // 4), shaded=True)
                for angle in angles
            ]
            cells[0] = _label(cells[0], name)
            rows.append(np.concatenate(cells, axis=1))
    imagemap.write_image(out / "mesh_four_angles.png", np.concatenate(rows, axis=0))


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).parent / "images"
    target.mkdir(parents=True, exist_ok=True)
    coherence(target)
    fish_2048(target)
    mesh_four_angles(target)
