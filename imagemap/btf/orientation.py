"""Which lamp lit which scan: the registered scans turned to the sample's frame.

Registration (:mod:`imagemap.btf.registration`) knows the scans' azimuths only relative
to the first scan (and up to a mirror): the scanner's lamp may sit on any side of the
image, and the large sample may lie turned against the measured one.
:func:`orient_to_sample` tries every quarter turn and each of the eight labellings
(:data:`LABELLINGS`) against the sample BTF's own constraint images;
:func:`apply_orientation` turns and reorders images as it decided.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np

from imagemap.btf.constraints import constraint_bands, stack_neighbourhood
from imagemap.io import InputError

__all__ = ["LABELLINGS", "apply_orientation", "orient_to_sample"]

log = logging.getLogger("imagemap")


#: The eight ways four registered scans can map to azimuths 0, 90, 180, 270: the
#: reference's lamp at any of the four (the scanner's lamp side), mirrored or not.
LABELLINGS = tuple((start, mirrored) for mirrored in (False, True) for start in range(4))


def _relabel(images: Sequence[np.ndarray], start: int, mirrored: bool) -> list[np.ndarray]:
    """Images for azimuths 0..270 if input i was lit from 90 * (start +/- i)."""
    step = -1 if mirrored else 1
    out: list[np.ndarray | None] = [None] * 4
    for i, image in enumerate(images):
        out[(start + step * i) % 4] = image
    return out  # type: ignore[return-value]


def orient_to_sample(
    target_images: Sequence[np.ndarray],
    sample_images: Sequence[np.ndarray],
    *,
    radius: int = 1,
    ws: float = 1.0,
    wc: float = 10.0,
    n_texels: int = 4096,
    seed: int = 0,
) -> tuple[list[np.ndarray], tuple[int, int, bool], dict[tuple[int, int, bool], float]]:
    """Turn the registered scans to the sample's frame and tell which lamp lit which.

    Registration knows the scans' azimuths only relative to the first scan (and up to a
    mirror, ``turn_direction``): the scanner's lamp may sit on any side of the image,
    and the large sample may lie turned against the measured one. The sample BTF's own
    constraint images fix both: for each quarter turn q of the images (``rot90``, which
    turns light directions by -90 q) and each of the eight labellings
    (:data:`LABELLINGS`), the target's constraint vectors (Eq. 5 over a
    (2 radius + 1)^2 neighbourhood, so the relief's orientation counts) are matched to
    the sample's; the hypothesis with the smallest mean nearest-neighbour distance
    wins. A material that looks alike under every hypothesis (isotropic) gives costs
    that hardly differ, and then the choice matters little.

    Parameters
    ----------
    target_images : four (H, W, 3) linear images (colour-corrected, histogram-aligned
        scans), input i lit from 90 i degrees relative to input 0, square.
    sample_images : the sample BTF's four constraint images (azimuths 0..270).
    n_texels : int
        Target texels sampled for the cost.

    Returns
    -------
    images : the target images turned by q, for azimuths 0, 90, 180, 270
    hypothesis : (q, start, mirrored): turned by ``rot90(., q)``, input i lit from
        90 * (start +/- i) in the turned frame
    costs : hypothesis -> mean nearest-neighbour distance
    """
    from imagemap.core.search import make_index  # deferred: search backends, orient_to_sample only

    if len(target_images) != 4 or len(sample_images) != 4:
        raise InputError("target_images, sample_images: four images each")
    sample_c = stack_neighbourhood(constraint_bands(sample_images, ws=ws, wc=wc), radius=radius)
    index = make_index("pca_kdtree", sample_c.reshape(-1, sample_c.shape[2]))
    height, width = np.asarray(target_images[0]).shape[:2]
    rng = np.random.default_rng(seed)
    picks = rng.choice(height * width, size=min(n_texels, height * width), replace=False)
    ys, xs = np.unravel_index(picks, (height, width))
    costs = {}
    for q in range(4 if height == width else 1):
        turned = [np.ascontiguousarray(np.rot90(image, q)) for image in target_images]
        for start, mirrored in LABELLINGS:
            bands = constraint_bands(_relabel(turned, start, mirrored), ws=ws, wc=wc)
            _, distances = index.query(_neighbourhoods_at(bands, ys, xs, radius))
            costs[(q, start, mirrored)] = float(np.mean(np.sqrt(distances)))
    q, start, mirrored = min(costs, key=lambda hypothesis: costs[hypothesis])
    ranked = sorted(costs.values())
    log.info(
        "frame from the sample: turned %d quarter turns, input 0 lit from %d deg%s "
        "(cost %.3f, next %.3f)",
        q,
        90 * start,
        ", mirrored" if mirrored else "",
        ranked[0],
        ranked[1],
    )
    return apply_orientation(target_images, (q, start, mirrored)), (q, start, mirrored), costs


def _neighbourhoods_at(bands: np.ndarray, ys, xs, radius: int) -> np.ndarray:
    """Rows of :func:`~imagemap.btf.constraints.stack_neighbourhood` at texels (ys, xs) only."""
    padded = np.pad(bands, ((radius, radius), (radius, radius), (0, 0)), mode="reflect")
    offsets = range(2 * radius + 1)
    return np.concatenate(
        [padded[ys + dy, xs + dx] for dy in offsets for dx in offsets], axis=1
    ).astype(np.float32)


def apply_orientation(
    images: Sequence[np.ndarray], hypothesis: tuple[int, int, bool]
) -> list[np.ndarray]:
    """Turn and reorder four images as :func:`orient_to_sample` decided (e.g. the raw scans
    whose prepared versions it saw)."""
    q, start, mirrored = hypothesis
    turned = [np.ascontiguousarray(np.rot90(image, q)) for image in images]
    return _relabel(turned, start, mirrored)
