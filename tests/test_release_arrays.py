"""A database opened for one query drops its examples' arrays once the synthesis has posed
them (``Database(keep_arrays=False)``, as ``imagemap synthesize`` opens it for one depth
map): the same bytes, less held through the synthesis (#44 item 3)."""

from __future__ import annotations

import numpy as np
from conftest import PALETTE, blob, painted

from imagemap import colorize
from imagemap.database import Database, Example
from imagemap.depth.config import resolve_config
from imagemap.io import write_image

SHAPE = (64, 96)


def _folder(tmp_path):
    for i, (cy, cx, ry, rx) in enumerate([(31, 47, 22, 36), (33, 49, 20, 34), (32, 46, 22, 37)]):
        depth = blob(SHAPE, centre=(cy, cx), radii=(ry, rx), bumps=0.02, seed=i)
        np.save(tmp_path / f"blob_{i}_depth.npy", depth.astype(np.float32))
        write_image(tmp_path / f"blob_{i}_image.png", painted(depth, PALETTE))
    return tmp_path


def test_one_query_drops_the_arrays_and_gives_the_same_bytes(tmp_path):
    folder = _folder(tmp_path)
    query = blob(SHAPE, centre=(32, 48), radii=(21, 35), bumps=0.02, seed=9)
    # Averaged by 4 (search size 20 px): the fine stage and the blend at full size run too.
    config = resolve_config("fish").replace_fields(search_size=20.0)
    kept = Database.from_directory(folder)
    dropped = Database.from_directory(folder, keep_arrays=False)
    a = colorize(query, kept, config, seed=0)
    b = colorize(query, dropped, config, seed=0)
    assert np.array_equal(a.image, b.image) and np.array_equal(a.source, b.source)
    assert next(r for r in b.stages if r.name == "working").changed.startswith("averaged")
    # The selection read every example's depth; one query holds none of them afterwards
    # (nor the images the fine stage read), a database kept for a batch holds them all.
    assert all("depth" in e.__dict__ for e in kept)
    assert not any("depth" in e.__dict__ or "image" in e.__dict__ for e in dropped)
    # Read again when asked for: the same values, and the size known without a read.
    assert all(e.shape == SHAPE for e in dropped)
    assert all(np.array_equal(d.depth, k.depth) for d, k in zip(dropped, kept, strict=True))
    # A database made from it (--exclude, a view) keeps the choice.
    assert dropped.without("blob_0").keep_arrays is False and kept.without("blob_0").keep_arrays


def test_examples_built_from_arrays_keep_theirs():
    depth = blob(SHAPE, bumps=0.02, seed=1)
    example = Example.from_arrays("a", depth, painted(depth, PALETTE))
    database = Database([example], keep_arrays=False)
    assert database.release_arrays() == 0
    assert example.depth is example._arrays["depth"]
