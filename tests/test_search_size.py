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


def _phases(result, factor: int) -> int:
    """How many different (y - source y, x - source x) mod ``factor`` the object's pixels
    have."""
    ys, xs = np.nonzero(result.mask)
    source = result.source[ys, xs]
    phase = np.stack([(ys - source[:, 1]) % factor, (xs - source[:, 2]) % factor], axis=1)
    return len(np.unique(phase, axis=0))


def test_a_large_query_is_copied_by_blocks_from_the_full_size_examples():
    capped = _run(search_size=20.0)  # 48 px: averaged by 4 (12 px across)
    working = next(record for record in capped.stages if record.name == "working")
    assert working.changed.startswith("averaged by 4")
    # The configuration as it ran: the pyramid of the averaged object (12 px: 2 levels).
    assert capped.config.pyramid.levels < _run(search_size=0.0).config.pyramid.levels
    assert capped.image.shape == (*SHAPE, 3) and capped.source.shape == (*SHAPE, 3)
    assert np.array_equal(capped.mask, blob(SHAPE, (32, 48), RADII, 0.02, 9) > 0)
    # Every pixel copies the pixel at its own place in its source's 4x4 block: one phase
    # for the whole map (the frame's shift), where the full-size synthesis has many.
    assert _phases(capped, 4) == 1
    assert _phases(_run(search_size=0.0), 4) > 4  # (the cap off: the test can fail)
    # The colours are the full-size examples' (copied, then blended): the map keeps the
    # painted palette's three colours apart, not averaged into each other.
    top, bottom = capped.image[20, 48], capped.image[44, 48]
    assert top[0] > top[2] + 0.3 and bottom[1] > 0.6


def test_a_query_within_the_search_size_gives_the_same_bytes():
    within, off = _run(search_size=60.0), _run(search_size=0.0)
    assert np.array_equal(within.image, off.image)
    assert np.array_equal(within.source, off.source)
