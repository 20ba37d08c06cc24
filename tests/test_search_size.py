"""A query larger than the search size (``pyramid.search_size``): the synthesis runs on it
block-averaged, and every pixel is copied at full size from the same place in its source's
block (#44 item 5)."""

from __future__ import annotations

from functools import cache

import numpy as np
from conftest import PALETTE, blob, painted

from imagemap import colorize
from imagemap.database import Database, Example
from imagemap.depth.config import resolve_config
from imagemap.depth.pipeline import fine_source

#: The object of the test's query is about 48 px across (sqrt of its area).
SHAPE, RADII = (64, 96), (21, 35)


def _database() -> Database:
    examples = []
    for i, (cy, cx, ry, rx) in enumerate([(31, 47, 22, 36), (33, 49, 20, 34), (32, 46, 22, 37)]):
        depth = blob(SHAPE, centre=(cy, cx), radii=(ry, rx), bumps=0.02, seed=i)
        examples.append(Example.from_arrays(f"blob_{i}", depth, painted(depth, PALETTE)))
    return Database(examples)


@cache  # the cap-off run serves both tests
def _run(search_size: float):
    query = blob(SHAPE, centre=(32, 48), radii=RADII, bumps=0.02, seed=9)
    config = resolve_config("fish").replace_fields(mirror=False, search_size=search_size)
    return colorize(query, _database(), config, seed=0)


def _main_phase(result, factor: int) -> float:
    """The share of the object's pixels in the most common (y - source y, x - source x)
    mod ``factor``."""
    ys, xs = np.nonzero(result.mask)
    source = result.source[ys, xs]
    phase = np.stack([(ys - source[:, 1]) % factor, (xs - source[:, 2]) % factor], axis=1)
    return float(np.unique(phase, axis=0, return_counts=True)[1].max() / len(ys))


#: Where the averaged copies do not drift, every pixel copies the pixel at its own place
#: in its source's block: one phase (the frame's shift). The test's capped map has 88 % of
#: its object in it (the rest where a copy drifts by an averaged pixel and the offsets
#: step by one pixel at a time, FINE_DRIFT), the full-size synthesis 46 %.
ONE_PHASE_SHARE = 0.8


def test_a_large_query_is_copied_by_blocks_from_the_full_size_examples():
    capped = _run(search_size=20.0)  # 48 px: averaged by 4 (12 px across)
    working = next(record for record in capped.stages if record.name == "working")
    assert working.changed.startswith("averaged by 4")
    # The configuration as it ran: the pyramid of the averaged object (12 px: 2 levels).
    assert capped.config.pyramid.levels < _run(search_size=0.0).config.pyramid.levels
    assert capped.image.shape == (*SHAPE, 3) and capped.source.shape == (*SHAPE, 3)
    assert np.array_equal(capped.mask, blob(SHAPE, (32, 48), RADII, 0.02, 9) > 0)
    # The pixels copy the pixel at their own place in their source's 4x4 block: one
    # phase for most of the map, where the full-size synthesis has many.
    assert _main_phase(capped, 4) > ONE_PHASE_SHARE
    assert _main_phase(_run(search_size=0.0), 4) < ONE_PHASE_SHARE  # (the test can fail)
    # The colours are the full-size examples' (copied, then blended): the map keeps the
    # painted palette's three colours apart, not averaged into each other.
    top, bottom = capped.image[20, 48], capped.image[44, 48]
    assert top[0] > top[2] + 0.3 and bottom[1] > 0.6


def test_a_query_within_the_search_size_gives_the_same_bytes():
    within, off = _run(search_size=60.0), _run(search_size=0.0)
    assert np.array_equal(within.image, off.image)
    assert np.array_equal(within.source, off.source)


def test_the_fine_copy_steps_one_pixel_where_a_copy_drifts_and_keeps_its_seams():
    """fine_source: between blocks of one example whose offsets differ by one averaged
    pixel (FINE_DRIFT) the full-size offset steps by at most one pixel; another example or
    a larger jump stays a seam at the block's edge."""
    factor, cols = 4, 8
    bx = np.arange(cols)
    # One row of blocks: a copy drifting right by one block every two blocks, then (block
    # 5) a jump of 3 blocks, then (block 7) another example.
    offsets = np.array([0, 0, 1, 1, 2, 5, 5, 5])
    source = np.stack([np.zeros(cols, int), np.zeros(cols, int), bx + offsets], -1)
    source[7, 0] = 1
    fine = fine_source(source[None].astype(np.int32), factor, (factor, factor * cols),
                       [(8, 64), (8, 64)])  # fmt: skip
    x = np.arange(factor * cols)
    steps = np.diff(fine[0, :, 2] - x)
    drifting = x[1:] < 5 * factor  # steps within blocks 0-4, the drift
    assert np.abs(steps[drifting]).max() == 1
    assert np.count_nonzero(steps[drifting]) == 2 * factor  # 2 blocks' drift, 1 px a step
    # The jump of 3 blocks (12 px) between blocks 4 and 5, whole at the edge.
    assert np.diff(fine[0, 5 * factor - 1 : 5 * factor + 1, 2])[0] - 1 == 3 * factor
    assert (fine[0, x // factor == 7, 0] == 1).all() and (fine[0, x // factor < 7, 0] == 0).all()
    # Each block's own pixels: the source row is the block's, at the pixel's own row.
    assert np.array_equal(fine[:, 0, 1], np.arange(factor))
