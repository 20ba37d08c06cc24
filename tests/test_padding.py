"""Padding by the surface itself (#46 item 1): the atlas' padding beside a chart seam
continues onto the chart across the seam, for the guides and the examples' appearance."""

from __future__ import annotations

import numpy as np

from imagemap.core.blend import fill_background
from imagemap.mesh.padding import surface_padding, walk
from imagemap.mesh.uvspace import surface_maps

#: The atlas' side: 0.1 of it (the gap between the two charts in u) is 8 whole texels, so a
#: padding texel's mate across the seam is a texel centre of the other chart.
SIZE = 80
#: Segments of the cylinder's circumference (16 per chart) and rows along its axis.
SEGMENTS, ROWS = 32, 4
#: Largest guide difference (position in RMS radii, unit normal) of a padding texel from
#: its mate across the seam: both are the same surface point (the walk is exact on the
#: facets; bilinear reads at a texel centre); measured 0.0.
SAME_POINT = 0.02
#: The nearest-texel padding repeats the border: it is off its mate by at least this
#: (measured 0.10, 0.20, 0.29 at 1, 2, 3 texels past the seam).
REPEATED = 0.05


def _cylinder(mirrored: bool = False):
    """An open cylinder (radius 1, height 2) in two charts: angles 0-180° at u 0.05-0.45,
    180-360° at u 0.55-0.95 (seams at 0° and 180°), v 0.05 up, both at one scale.
    ``mirrored``: the second chart laid out mirrored (180° at u 0.95, 360° at 0.55), as
    an atlas packer may lay a chart (a quarter of the generated fish's faces)."""
    theta = np.linspace(0.0, 2.0 * np.pi, SEGMENTS + 1)
    z = np.linspace(0.0, 2.0, ROWS + 1)
    vertices, uv, faces = [], [], []
    half = SEGMENTS // 2
    for chart in (0, 1):
        start = len(vertices)
        columns = range(chart * half, chart * half + half + 1)
        for k in columns:
            for zz in z:
                angle = theta[k % SEGMENTS]  # 360° is 0°, bit for bit (welded)
                vertices.append((np.cos(angle), np.sin(angle), zz))
                u = 0.05 + 0.5 * chart + 0.4 * (k - chart * half) / half
                if mirrored and chart:
                    u = 1.5 - u  # 0.55 <-> 0.95
                uv.append((u, 0.05 + zz * 0.4 / np.pi))
        for i in range(half):
            for j in range(ROWS):
                a = start + i * (ROWS + 1) + j
                b = a + ROWS + 1
                faces += [(a, b, b + 1), (a, b + 1, a + 1)]
    return np.array(vertices), np.array(faces), np.array(uv)


def test_padding_beside_a_seam_takes_the_other_charts_guides():
    vertices, faces, uv = _cylinder()
    maps = surface_maps(vertices, faces, uv, SIZE)
    guides = maps.guides()[..., :6]  # position and normal
    pad = surface_padding(vertices, faces, uv, SIZE, reach=4)
    padded = pad.apply(guides, maps.mask)
    nearest = fill_background(guides, maps.mask)
    rows = np.arange(58, 74)  # inside the charts' height (not beside the caps' boundary)
    # Chart 0 spans columns 4-35, chart 1 columns 44-75: a padding texel right of chart 0
    # (column 36 + k, past 180°) is the point of chart 1's column 44 + k; left of chart 0
    # (column 3 - k, before 0°, i.e. below 360°) chart 1's column 75 - k.
    assert maps.mask[rows][:, [4, 35, 44, 75]].all() and not maps.mask[rows][:, [3, 36]].any()
    for pad_column, mate in [(36 + k, 44 + k) for k in range(3)] + [
        (3 - k, 75 - k) for k in range(3)
    ]:
        error = np.abs(padded[rows, pad_column] - guides[rows, mate]).max()
        repeated = np.abs(nearest[rows, pad_column] - guides[rows, mate]).max()
        assert error < SAME_POINT, (pad_column, error)
        assert repeated > REPEATED, (pad_column, repeated)
    # Beyond the reach: the nearest placed texel's values (no padding texel left unset).
    assert np.isfinite(padded).all()
    assert np.array_equal(padded[maps.mask], guides[maps.mask])


def test_padding_beside_a_mirrored_chart_takes_its_guides_at_the_same_point():
    # #46: identity.py's generated fish changed where the padding of thin charts was
    # placed; a quarter of their faces lie in charts the packer mirrored. The UV offset
    # turned into a step through the start face's own UV -> 3-D map, and the walk on the
    # welded surface, must land on the same surface point whichever way the chart across
    # the seam is laid: here chart 1 mirrored, so the mates run the other way.
    vertices, faces, uv = _cylinder(mirrored=True)
    maps = surface_maps(vertices, faces, uv, SIZE)
    guides = maps.guides()[..., :6]
    padded = surface_padding(vertices, faces, uv, SIZE, reach=4).apply(guides, maps.mask)
    rows = np.arange(58, 74)
    # Right of chart 0 (past 180°): 180° is chart 1's right side now, column 75 - k;
    # left of chart 0 (below 360°): chart 1's left side, column 44 + k.
    for pad_column, mate in [(36 + k, 75 - k) for k in range(3)] + [
        (3 - k, 44 + k) for k in range(3)
    ]:
        error = np.abs(padded[rows, pad_column] - guides[rows, mate]).max()
        assert error < SAME_POINT, (pad_column, error)
    # Chart 1's own padding continues onto chart 0 the same way: right of column 75 (past
    # 180° backwards, i.e. below 180°) is chart 0's column 35 - k.
    for k in range(3):
        error = np.abs(padded[rows, 76 + k] - guides[rows, 35 - k]).max()
        assert error < SAME_POINT, (76 + k, error)


def test_a_walk_stops_at_the_surfaces_boundary():
    # A single triangle: a step out of it ends on its edge, not past it.
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    face, bary = walk(v, np.array([[0, 1, 2]]), np.array([0]), np.array([[0.6, 0.2, 0.2]]),
                      np.array([[5.0, 0.0, 0.0]]))  # fmt: skip
    point = bary @ v
    assert face.tolist() == [0]
    assert np.allclose(point, [[0.8, 0.2, 0.0]])


def test_an_examples_full_size_texture_is_padded_with_the_chart_across_the_seam(
    tmp_path, monkeypatch
):
    # The uv-space path copies full-size texels at sub-positions of used working texels;
    # one that falls in the example's padding reads the surface beyond the seam there.
    import trimesh

    monkeypatch.setenv("IMAGEMAP_CACHE", str(tmp_path))  # (the padding is cached)

    from imagemap.mesh.uvspace import UVExample, _surface_padded

    vertices, faces, uv = _cylinder()
    mesh = trimesh.Trimesh(vertices, faces, process=False,
                           visual=trimesh.visual.TextureVisuals(uv=uv))  # fmt: skip
    texture = np.zeros((SIZE, SIZE, 3), np.uint8)  # padding black
    texture[:, :40] = (200, 0, 0)  # chart 0 red (columns 4-35)
    texture[:, 40:] = (0, 0, 200)  # chart 1 blue (columns 44-75)
    padded, used = _surface_padded(UVExample("cylinder", mesh, texture), texture, SIZE // 4)
    rows = np.arange(58, 74)
    assert used is not None and used[rows][:, 4:36].all() and not used[rows][:, 36:44].any()
    # Right of chart 0 (past 180°) is chart 1's blue, left of chart 1 (before 180°) red.
    assert np.allclose(padded[rows][:, 36:40], (0, 0, 200 / 255))
    assert np.allclose(padded[rows][:, 40:44], (200 / 255, 0, 0))


def test_the_padding_on_the_maps_kept_rasterization_is_the_same():
    # SurfaceMaps keeps its atlas' rasterization; the padding made on it (no second
    # rasterization) places the same texels at the same points.
    vertices, faces, uv = _cylinder(mirrored=True)
    maps = surface_maps(vertices, faces, uv, SIZE)
    assert maps.raster is not None and maps.raster[0].size == maps.mask.sum()
    made = surface_padding(vertices, faces, uv, SIZE, reach=4)
    kept = surface_padding(vertices, faces, uv, SIZE, reach=4, raster=maps.raster)
    assert made.texel.size > 0
    for name in ("texel", "face", "bary", "source", "mask"):
        assert np.array_equal(getattr(made, name), getattr(kept, name)), name


def test_an_examples_padded_texture_is_cached_with_the_same_bytes(tmp_path, monkeypatch):
    # The full-size padding depends on the example alone: made once, then read from the
    # library's cache (keyed by the example's digest), the same bytes.
    import trimesh

    from imagemap.mesh.uvspace import UVExample, _surface_padded

    monkeypatch.setenv("IMAGEMAP_CACHE", str(tmp_path))
    vertices, faces, uv = _cylinder()
    mesh = trimesh.Trimesh(vertices, faces, process=False,
                           visual=trimesh.visual.TextureVisuals(uv=uv))  # fmt: skip
    texture = np.random.default_rng(0).integers(0, 256, (SIZE, SIZE, 3), dtype=np.uint8)
    example = UVExample("cylinder", mesh, texture)
    made, used = _surface_padded(example, texture, SIZE // 4)
    (entry,) = (tmp_path / "padded").glob("cylinder-*.npz")
    again, used_again = _surface_padded(example, texture, SIZE // 4)
    assert again.dtype == made.dtype and np.array_equal(again, made)
    assert used_again is not None and np.array_equal(used_again, used)
    # It is the entry that is read: one texel's value changed in it comes back.
    with np.load(entry) as data:
        texel, values, packed = data["texel"], data["values"].copy(), data["used"]
    assert texel.size > 0
    values[0] = 0.5
    np.savez_compressed(entry, texel=texel, values=values, used=packed)
    read, _ = _surface_padded(example, texture, SIZE // 4)
    assert np.allclose(read.reshape(-1, 3)[texel[0]], 0.5)
    # Another texture is another entry; a damaged entry is made anew.
    other = texture.copy()
    other[0, 0] = 1
    _surface_padded(UVExample("cylinder", mesh, other), other, SIZE // 4)
    assert len(list((tmp_path / "padded").glob("cylinder-*.npz"))) == 2
    entry.write_bytes(b"not an npz")
    assert np.array_equal(_surface_padded(example, texture, SIZE // 4)[0], made)
