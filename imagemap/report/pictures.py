"""The report's pictures: depth, truth and each method on a grey backdrop, strips, the overview."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from imagemap.evaluation import Evaluation, ObjectEvaluation


#: Grey behind the objects in report pictures, so that black object pixels
#: (holes of copy_nearest) stand out from the background.
_BACKDROP = 0.82


def _on_backdrop(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    return np.where(mask[..., None], image, _BACKDROP).astype(np.float32)


def _depth_picture(depth: np.ndarray) -> np.ndarray:
    mask = depth > 0
    lo, hi = float(depth[mask].min()), float(depth[mask].max())
    grey = 0.15 + 0.85 * (depth - lo) / max(hi - lo, 1e-6)
    return np.where(mask, grey, _BACKDROP).astype(np.float32)


def _comparison_strip(obj: ObjectEvaluation, methods: tuple[str, ...], gap: int = 4) -> np.ndarray:
    """depth | truth | each method | provenance of full, side by side."""
    tiles = [
        _depth_picture(obj.depth)[..., None].repeat(3, axis=2),
        _on_backdrop(obj.truth, obj.mask),
    ]
    tiles += [_on_backdrop(obj.results[m].image, obj.mask) for m in methods]
    provenance = next(
        (p for p in (obj.results[m].provenance for m in methods) if p is not None), None
    )
    if provenance is not None:
        tiles.append(provenance)
    h, w = obj.depth.shape
    strip = np.ones((h, len(tiles) * (w + gap) - gap, 3), dtype=np.float32)
    for k, tile in enumerate(tiles):
        strip[:, k * (w + gap) : k * (w + gap) + w] = tile
    return strip


def _strip_captions(methods: tuple[str, ...], has_provenance: bool) -> list[str]:
    return ["depth", "truth", *methods] + (["provenance"] if has_provenance else [])


def _captioned_sheet(evaluation: Evaluation, gap: int = 4, caption_height: int = 16) -> np.ndarray:
    """All objects' strips stacked under one caption row (an overview picture)."""
    from PIL import Image, ImageDraw  # deferred: the overview picture only

    if not evaluation.objects:  # every object failed: a blank picture keeps the link valid
        return np.ones((caption_height, 200, 3), np.float32)
    strips = [_comparison_strip(obj, evaluation.methods, gap) for obj in evaluation.objects]
    width = max(s.shape[1] for s in strips)
    h, w = evaluation.objects[0].depth.shape
    sheet = np.ones((caption_height + sum(s.shape[0] + gap for s in strips), width, 3), np.float32)
    top = caption_height
    for strip in strips:
        sheet[top : top + strip.shape[0], : strip.shape[1]] = strip
        top += strip.shape[0] + gap
    picture = Image.fromarray(np.round(sheet * 255).astype(np.uint8))
    draw = ImageDraw.Draw(picture)
    has_provenance = any(r.provenance is not None for r in evaluation.objects[0].results.values())
    for k, text in enumerate(_strip_captions(evaluation.methods, has_provenance)):
        draw.text((k * (w + gap) + 2, 2), text, fill=(0, 0, 0))
    return np.asarray(picture, dtype=np.float32) / 255.0
