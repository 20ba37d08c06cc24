"""The outside tasks' shared driver: synthesis, measures, baselines, EbSynth, pictures.

An *outside task* is a handful of examples and a query made procedurally by a script
(not by ``data_gen``), with a feature the generated classes do not test. Each script
(``ellipsoid_fish.py``, ``leaf_eyespot.py``) defines the task and calls :func:`main`,
which at every size

- synthesises the query through the public API,
  ``imagemap.colorize(depth, Database(examples), preset=..., seed=..., **options)``,
  with the method options given on the command line (``--vote mean
  --appearance-pyramid laplacian``, ``--finish paper``, ...);
- measures the map (:mod:`imagemap.metrics`): PSNR on the object, continuity and
  mid-tone share on the task's region (its structure, less the feature), the fragments
  of the source map, and the task's own feature figures;
- measures the same for a *bounding-box copy* of the nearest example (its map cropped
  to its object's box and stretched onto the query's box: the floor any method must
  beat), and for EbSynth when the ``EBSYNTH`` environment variable names its binary
  (one exemplar, the nearest, with a depth guide and a position guide);
- prints one table and writes ``SIZE.png`` (truth | ours | bbox copy [| EbSynth]),
  ``SIZE_fragments.png`` (ours | its fragments in random colours) and the task's
  close-ups, and with ``--json`` the figures.

EbSynth (https://github.com/jamriska/ebsynth, public domain) is not part of imagemap;
build it from source (``docs/measures.md``) and point ``EBSYNTH`` at the binary.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import ndimage
from skimage import io as skio
from skimage.transform import resize

#: EbSynth's guide weights (style weight, uniformity 3500 and patch 5 are its defaults).
#: The best PSNR of five pairs tried on the ellipsoid fish at 200x150 and 512^2:
#: (1, 4) gave 15.8 and 12.0 dB, (1, 1) 15.3 and 11.6, (0.5, 2) 15.1 and 11.8,
#: (2, 0.5) 15.0 and 11.5, (0.3, 0.3) 13.1 and 11.5.
EBSYNTH_DEPTH_WEIGHT = 1.0
EBSYNTH_POSITION_WEIGHT = 4.0
#: Object coordinates u, v in [-1, 1] (bounding-box normalised) are written to the
#: position guide as 0.1-0.9 of the grey range: background (0) stays apart from them.
POSITION_RANGE = (0.1, 0.9)


@dataclass
class Task:
    """One outside task at one size: what :func:`main` synthesises and measures.

    Attributes
    ----------
    examples : list of imagemap.Example
    depth, truth : ndarray
        The query's depth (0 outside) and true map.
    region : ndarray of bool
        Where continuity and mid-tones are measured (the structure, not the feature).
    features : callable
        ``features(image, mask) -> dict`` of the task's own figures (a feature drawn,
        its contrast), applied to the truth, ours and the baselines alike.
    closeups : dict of str to (slice, slice)
        Named crops written as truth | ours close-ups.
    provenance : callable, optional
        ``provenance(source, mask) -> dict`` of figures from our source map (which
        example each region came from).
    """

    examples: list
    depth: np.ndarray
    truth: np.ndarray
    region: np.ndarray
    features: Callable[[np.ndarray, np.ndarray], dict]
    closeups: dict = field(default_factory=dict)
    provenance: Callable[[np.ndarray, np.ndarray], dict] | None = None


def psnr(image: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> float:
    """PSNR (dB) of an RGB map against the truth over ``mask`` (values in [0, 1])."""
    error = np.mean((np.clip(image[mask], 0, 1) - truth[mask]) ** 2, dtype=np.float64)
    return math.inf if error == 0 else float(10 * np.log10(1.0 / error))


def _box(mask: np.ndarray) -> tuple[slice, slice]:
    ys, xs = np.nonzero(mask)
    return slice(ys.min(), ys.max() + 1), slice(xs.min(), xs.max() + 1)


def _filled(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The map with each background pixel given its nearest object pixel's colour."""
    _, (iy, ix) = ndimage.distance_transform_edt(~mask, return_indices=True)
    return image[iy, ix]


def bbox_copy(example_image: np.ndarray, example_mask: np.ndarray, mask: np.ndarray):
    """The example's map in its object's box, stretched onto the query's box (0 outside)."""
    rows, columns = _box(example_mask)
    crop = _filled(example_image, example_mask)[rows, columns]
    target_rows, target_columns = _box(mask)
    shape = (target_rows.stop - target_rows.start, target_columns.stop - target_columns.start)
    out = np.zeros(mask.shape + (3,), np.float32)
    out[target_rows, target_columns] = resize(crop, shape + (3,), order=1, anti_aliasing=True)
    out[~mask] = 0
    return out


def position_guide(mask: np.ndarray) -> np.ndarray:
    """RGB guide of bounding-box-normalised object coordinates (u in R, v in G)."""
    rows, columns = _box(mask)
    yy, xx = np.indices(mask.shape, dtype=np.float64)
    u = (xx - (columns.start + columns.stop - 1) / 2) / max((columns.stop - columns.start) / 2, 1)
    v = (yy - (rows.start + rows.stop - 1) / 2) / max((rows.stop - rows.start) / 2, 1)
    low, high = POSITION_RANGE
    guide = np.zeros(mask.shape + (3,))
    guide[..., 0] = low + (high - low) * (np.clip(u, -1, 1) + 1) / 2
    guide[..., 1] = low + (high - low) * (np.clip(v, -1, 1) + 1) / 2
    guide[~mask] = 0
    return guide


def _png(path: Path, image: np.ndarray) -> None:
    skio.imsave(path, np.round(np.clip(image, 0, 1) * 255).astype(np.uint8), check_contrast=False)


def run_ebsynth(binary: str, example, depth: np.ndarray) -> np.ndarray:
    """EbSynth's map of ``depth`` from one example (style = its map, guides: depth, position).

    Parameters
    ----------
    binary : str
        The ebsynth executable.
    example : imagemap.Example
    depth : ndarray
        The query's depth (0 outside).

    Returns
    -------
    ndarray, (H, W, 3) float32, 0 outside the query's object.
    """
    mask = depth > 0
    with tempfile.TemporaryDirectory() as folder:
        work = Path(folder)
        _png(work / "style.png", _filled(example.image, example.mask))
        _png(work / "depth_s.png", np.clip(example.depth, 0, 1))
        _png(work / "depth_t.png", np.clip(depth, 0, 1))
        _png(work / "pos_s.png", position_guide(example.mask))
        _png(work / "pos_t.png", position_guide(mask))
        command = [
            binary,
            "-style", str(work / "style.png"),
            "-guide", str(work / "depth_s.png"), str(work / "depth_t.png"),
            "-weight", str(EBSYNTH_DEPTH_WEIGHT),
            "-guide", str(work / "pos_s.png"), str(work / "pos_t.png"),
            "-weight", str(EBSYNTH_POSITION_WEIGHT),
            "-output", str(work / "out.png"),
        ]  # fmt: skip
        subprocess.run(command, check=True, capture_output=True)
        out = skio.imread(work / "out.png")[..., :3].astype(np.float32) / 255
    out[~mask] = 0
    return out


def measure(image, task: Task, mask, source=None) -> dict:
    """The figures of one map: PSNR, continuity, mid-tones, fragments, the task's own."""
    from imagemap.metrics import fragments, midtone_share, structure_continuity

    figures = {
        "psnr": psnr(image, task.truth, mask),
        "continuity": structure_continuity(image, task.truth, task.region),
        "midtones": midtone_share(image, task.truth, task.region),
    }
    if source is not None:
        split = fragments(source, mask)
        figures["fragments_90"], figures["fragment_share"] = split.count_90, split.mean_share
        if task.provenance is not None:
            figures.update(task.provenance(source, mask))
    figures.update(task.features(image, mask))
    return figures


def fragment_picture(image: np.ndarray, source: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The map beside its fragments, each in a colour of its own (white background)."""
    from imagemap.metrics import fragment_labels

    labels = fragment_labels(source, mask)
    colours = np.random.default_rng(0).uniform(0.15, 1.0, (labels.max() + 1, 3))
    colours[0] = 1.0
    return np.concatenate([image, colours[labels]], axis=1)


def _cell(value) -> str:
    if isinstance(value, str):
        return value
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "–"
    return f"{value:.3f}" if abs(value) < 10 else f"{value:.1f}"


def _parse_sizes(text: str) -> list[tuple[int, int]]:
    sizes = []
    for item in text.split(","):
        try:
            width, height = (int(s) for s in item.lower().split("x"))
        except ValueError:
            raise SystemExit(f"--sizes: {item!r} is not WIDTHxHEIGHT") from None
        if width < 32 or height < 32:
            raise SystemExit(f"--sizes: {item!r} is too small (32x32 at least)")
        sizes.append((width, height))
    return sizes


def main(
    argv,
    *,
    description: str,
    make_task: Callable[[int, int], Task],
    default_sizes: str,
    quick_size: str,
    default_out: str,
    preset: str = "fish",
) -> list[dict]:
    """Run an outside task at each size; print the table, write pictures (and JSON).

    Returns
    -------
    list of dict
        One row per size and method (``ours``, ``bbox copy``, ``ebsynth``).
    """
    from imagemap.cli.options import add_config_options, config_options

    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--sizes", default=default_sizes, help="WIDTHxHEIGHT,...")
    parser.add_argument("--quick", action="store_true", help=f"one small size ({quick_size})")
    parser.add_argument("--out", type=Path, default=Path(default_out), help="picture folder")
    parser.add_argument("--json", type=Path, help="write the figures here")
    parser.add_argument("--preset", default=preset, help=f"class preset (default {preset})")
    add_config_options(parser)  # --vote, --appearance-pyramid, --finish, ..., --seed
    args = parser.parse_args(argv)
    options = config_options(args)
    import imagemap

    sizes = _parse_sizes(quick_size if args.quick else args.sizes)
    ebsynth = os.environ.get("EBSYNTH")
    if ebsynth and not Path(ebsynth).is_file():
        raise SystemExit(f"EBSYNTH={ebsynth}: no such file")
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for width, height in sizes:
        size = f"{width}x{height}"
        task = make_task(width, height)
        database = imagemap.Database(task.examples)
        mask = task.depth > 0
        start = time.perf_counter()
        result = imagemap.colorize(
            task.depth, database, preset=args.preset, seed=args.seed, quiet=True, **options
        )
        seconds = time.perf_counter() - start
        ours = np.clip(result.image, 0, 1)
        nearest = database[imagemap.select_examples(task.depth, database, 1)[0]]
        copied = bbox_copy(nearest.image, nearest.mask, mask)
        from imagemap.depth.pipeline import warp_nearest

        start = time.perf_counter()
        warped = warp_nearest(task.depth, database, preset=args.preset, seed=args.seed, **options)
        maps = {
            "ours": (ours, result.source, seconds),
            "warp_nearest": (np.clip(warped.image, 0, 1), warped.source,
                             time.perf_counter() - start),
            "bbox copy": (copied, None, 0.0),
        }  # fmt: skip
        if ebsynth:
            start = time.perf_counter()
            maps["ebsynth"] = (run_ebsynth(ebsynth, nearest, task.depth), None, 0.0)
            maps["ebsynth"] = maps["ebsynth"][:2] + (time.perf_counter() - start,)
        truth_figures = task.features(task.truth, mask)
        for method, (image, source, took) in maps.items():
            row = {"size": size, "method": method, "seconds": took}
            row.update(measure(image, task, mask, source))
            rows.append(row)
        rows.append({"size": size, "method": "truth", **truth_figures})
        pictures = [task.truth] + [image for image, _, _ in maps.values()]
        _png(args.out / f"{size}.png", np.concatenate(pictures, axis=1))
        _png(args.out / f"{size}_fragments.png", fragment_picture(ours, result.source, mask))
        for name, (ys, xs) in task.closeups.items():
            close = np.concatenate([task.truth[ys, xs], ours[ys, xs]], axis=1)
            zoom = max(1, 240 // max(close.shape[0], 1))
            _png(args.out / f"{size}_{name}.png", close.repeat(zoom, 0).repeat(zoom, 1))
    columns = ["size", "method"] + [
        key
        for key in dict.fromkeys(k for row in rows for k in row)
        if key not in ("size", "method")
    ]
    label = " ".join(f"--{k.replace('_', '-')} {v}" for k, v in options.items()) or "defaults"
    print(f"{description} (preset {args.preset}, {label}, seed {args.seed})")
    print("| " + " | ".join(columns) + " |")
    print("|" + "---|" * len(columns))
    for row in rows:
        print("| " + " | ".join(_cell(row.get(c)) for c in columns) + " |")
    if args.json:
        args.json.write_text(
            json.dumps({"options": options, "seed": args.seed, "rows": rows}, indent=1) + "\n"
        )
    return rows
