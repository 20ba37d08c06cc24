"""The depth-map front end: selection, units, background, presets."""

import numpy as np
import pytest

from imagemap import Database, Example, colorize, select_examples
from imagemap.depth.config import PRESETS
from imagemap.depth.guides import to_rgb, to_ycbcr
from imagemap.io import InputError


def test_select_examples_prefers_the_shifted_twin(blob_database, query_blob):
    depth, image = query_blob
    twin = np.roll(depth, (3, -4), axis=(0, 1))  # same object, elsewhere in the frame
    db = Database([*blob_database.examples, Example.from_arrays("twin", twin, image)])
    assert db.names[select_examples(depth, db, m=1)[0]] == "twin"
    assert len(select_examples(depth, db, m=3)) == 3


def test_depth_units_do_not_matter(blob_database, query_blob):
    depth, _ = query_blob
    scaled = Database([Example.from_arrays(e.name, e.depth * 1000, e.image) for e in blob_database])
    a = colorize(depth, blob_database, "busts", seed=1)
    b = colorize(depth * 1000, scaled, "busts", seed=1)
    assert a.example_names == b.example_names
    assert np.abs(a.image - b.image).max() < 1e-3


def test_background_is_transparent_and_untouched(blob_database, query_blob):
    depth, _ = query_blob
    result = colorize(depth, blob_database, "fish")
    assert np.all(result.rgba[..., 3][depth == 0] == 0)
    assert np.all(result.rgba[..., 3][depth > 0] == 1)
    assert np.all(result.image[depth == 0] == 0)
    white = result.on_background((1, 1, 1))
    assert np.all(white[depth == 0] == 1)
    # Provenance: one tint per example, inside the object only.
    assert result.provenance.shape == depth.shape + (3,)
    assert set(np.unique(result.source[..., 0][depth > 0])) <= {0, 1}


def test_database_of_one_and_manual_examples(blob_database, query_blob):
    depth, _ = query_blob
    single = Database([blob_database[0]])
    result = colorize(depth, single, "busts", m=2)  # m larger than the database: uses all
    assert result.example_names == ["blob_0"]
    chosen = colorize(depth, blob_database, "busts", examples=["blob_3", "blob_1"])
    assert chosen.example_names == ["blob_3", "blob_1"]
    with pytest.raises(InputError, match="nope"):
        colorize(depth, blob_database, "busts", examples=["nope"])
    with pytest.raises(InputError, match="unknown preset"):
        colorize(depth, blob_database, "cats")


def test_ycbcr_round_trip_and_presets_follow_table_1():
    rgb = np.random.default_rng(0).random((8, 8, 3)).astype(np.float32)
    np.testing.assert_allclose(to_rgb(to_ycbcr(rgb)), rgb, atol=1e-5)
    assert PRESETS["humans"].selection.m == 1
    assert PRESETS["humans"].pyramid.patch_sizes == (7, 9, 9)
    assert PRESETS["fish"].selection.m == 2
    assert PRESETS["fish"].pyramid.patch_sizes == (7, 11, 9)
    assert PRESETS["fish"].guides.position_weight < PRESETS["busts"].guides.position_weight


def test_pyramid_depth_follows_object_size():
    """Three levels where the coarsest still sees the object 1.25 windows across."""
    from imagemap.depth.guides import pyramid_levels

    def square(side):
        mask = np.zeros((400, 400), bool)
        mask[:side, :side] = True
        return mask

    sizes = (7, 11, 9)
    assert pyramid_levels(square(47), sizes) == 3
    assert pyramid_levels(square(44), sizes) == 2
    assert pyramid_levels(square(27), sizes) == 1
