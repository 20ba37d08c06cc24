"""Textured heads that share one UV layout: a generated stand-in for registered face scans.

Every head of :func:`shared_layout_heads` is the same latitude/longitude grid (the same
faces, the same UVs), deformed into its own head shape (skull, jaw, chin, nose, brows,
ears, neck) and painted with its own texture (skin tone, eyes, brows, lips, hair on top
and at the back): "several people" in one template's layout, as registered face scans
are (FFHQ-UV's HiFi3D++ heads, which the tests used before; their licence did not allow
committing them, see docs/real_data.md). The UV layout is the grid's own: one chart,
longitude along u (the face at u = 0.5, the seam at the back of the head, so the
layout is cut there: the chart's left and right borders are the same points of the
surface), latitude along v (the crown at the top, the neck's open end at the bottom),
inside a margin of unused texels.

Everything is made from the seed by NumPy at call time: no file is committed. Two heads
take about 0.2 s, written as GLB files included.

Example
-------
>>> from data_gen.heads import shared_layout_heads
>>> first, second = shared_layout_heads(2, seed=0)
>>> bool((first.faces == second.faces).all() and (first.visual.uv == second.visual.uv).all())
True
>>> bool(np.abs(first.vertices - second.vertices).max() > 0.05)  # two shapes
True
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from data_gen.core import smoothstep
from data_gen.procedural import fbm

__all__ = ["HEAD_HEIGHT", "shared_layout_heads", "write_shared_layout_heads"]

#: Rows (crown to neck) and columns (around the head) of the grid: 42 x 49 - 1 = 2,057
#: vertices (a column more than cells: the seam's two sides are separate UV vertices; the
#: crown's row has one fewer) and 3,888 triangles.
GRID = (42, 48)
#: Unused texels around the chart, as a fraction of the atlas side on each border: the
#: atlas has padding, as a real one has (about 0.87 of a 64^2 atlas is used).
UV_MARGIN = 0.035
#: Latitude of the rows (radians): the crown's pole at the top, down to this at the bottom
#: of the head; the rows below it are the neck.
LOWEST_LATITUDE = -0.9
#: Fraction of the rows that are neck (below the jaw).
NECK_ROWS = 0.2
#: The skull's height (its ellipsoid's, crown to bottom; world units) before a head's own
#: ``size``. With the lower face and the neck a head is about 3 units tall (2.8 and 3.1
#: for seed 0's two), near the 3.3-unit bounding box of the FFHQ-UV heads the tests used
#: before: the texel density of a 0.01-unit view pixel asks for a 1024^2 atlas (814 and
#: 907 texels across), much larger than the heads' own texture.
HEAD_HEIGHT = 2.4
#: Skin tones from pale to dark (RGB in [0, 1]); a head's tone is a point on this ramp.
SKIN_RAMP = ((0.95, 0.80, 0.70), (0.84, 0.63, 0.50), (0.66, 0.46, 0.33), (0.48, 0.32, 0.22))
#: Hair colours: black, dark brown, auburn, blond, grey, chestnut.
HAIR = (
    (0.07, 0.06, 0.06),
    (0.25, 0.16, 0.10),
    (0.55, 0.24, 0.12),
    (0.80, 0.66, 0.40),
    (0.62, 0.61, 0.60),
    (0.40, 0.25, 0.14),
)
#: Iris colours: brown, blue, green, grey.
IRIS = ((0.35, 0.20, 0.10), (0.25, 0.45, 0.70), (0.30, 0.50, 0.30), (0.50, 0.55, 0.58))
#: Lip colours: rose, red, brownish, pale pink.
LIPS = ((0.78, 0.42, 0.45), (0.70, 0.22, 0.25), (0.55, 0.30, 0.28), (0.86, 0.56, 0.56))
#: Golden-ratio step between heads along each proportion's range and the skin ramp.
_GOLDEN = 0.6180339887498949


def _grid_angles(rows: int) -> tuple[np.ndarray, np.ndarray]:
    """(latitude (rows,), neck weight (rows,)) of the grid's rows, crown first."""
    t = np.linspace(0.0, 1.0, rows)
    head_rows = 1.0 - NECK_ROWS
    # The head's rows go from the crown's pole to LOWEST_LATITUDE, the neck's below stay
    # at that latitude and slide down the neck (their weight goes from 0 to 1).
    latitude = np.pi / 2 - (np.pi / 2 - LOWEST_LATITUDE) * np.clip(t / head_rows, 0.0, 1.0)
    neck = np.clip((t - head_rows) / NECK_ROWS, 0.0, 1.0)
    return latitude, neck


def _layout(rows: int, cols: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(faces (F, 3), UVs (V, 2), (row, column) of each vertex (V, 2)) of the shared grid.

    Row 0 is the crown's pole: its vertices sit at the middle of their column in UV (so
    the fan's triangles have an area in the atlas), and the triangles that would join
    two of them (no area on the surface) are left out, as is its last, unused vertex.
    """
    row, col = np.mgrid[0:rows, 0 : cols + 1]
    u = col + np.where(row == 0, 0.5, 0.0)
    span = 1.0 - 2 * UV_MARGIN
    uv = np.stack(
        [UV_MARGIN + span * u / cols, 1.0 - UV_MARGIN - span * row / (rows - 1)], axis=-1
    ).reshape(-1, 2)
    index = np.arange(rows * (cols + 1)).reshape(rows, cols + 1)
    a, b = index[:-1, :-1], index[:-1, 1:]
    c, d = index[1:, :-1], index[1:, 1:]
    # Counter-clockwise seen from outside: u grows to the viewer's right on the face and
    # v upwards, the same turn as x right and y up seen from the front.
    lower = np.stack([a, c, d], axis=-1)
    upper = np.stack([a, d, b], axis=-1)
    faces = np.concatenate([lower.reshape(-1, 3), upper[1:].reshape(-1, 3)])
    keep = np.setdiff1d(np.arange(rows * (cols + 1)), [cols])  # row 0's last vertex
    remap = np.full(rows * (cols + 1), -1)
    remap[keep] = np.arange(len(keep))
    grid = np.stack([row.ravel(), col.ravel()], axis=1)
    return remap[faces], uv[keep], grid[keep]


#: Each proportion's range (fractions of the skull's height unless said). The skull's are
#: narrow: heads in one registered layout differ little once scaled (the layout test's
#: median distance between two heads is at most 0.02 for seeds 0-11; FFHQ-UV's two heads
#: gave 0.005), while their sizes, which that test normalises away, vary more.
SHAPE_RANGES = {
    "size": (0.92, 1.08),  # the whole head's scale
    "width": (0.35, 0.37),  # half-width of the skull (its half-height is 0.5)
    "depth": (0.43, 0.45),  # half-depth, front to back
    "face": (0.24, 0.28),  # the lower face's length
    "back": (0.06, 0.09),  # the back of the skull bulging backwards
    "jaw": (0.24, 0.3),  # narrowing of the lower face
    "chin": (0.05, 0.09),
    "nose": (0.09, 0.14),
    "brow": (0.015, 0.03),
    "cheek": (0.0, 0.025),
    "ears": (0.05, 0.08),
    "neck": (0.18, 0.21),  # the neck's radius
}


def _spread(index: int, offset: float) -> float:
    """Head ``index``'s point in [0, 1) on a golden-ratio sequence from ``offset``.

    Any two of the first three heads are at least 0.24 apart on it (the first two 0.38),
    so a class's heads never come out nearly alike, whatever the seed.
    """
    return (offset + index * _GOLDEN) % 1.0


def _shape(index: int, offsets: np.ndarray) -> dict[str, float]:
    """Head ``index``'s proportions: each its own offset on :func:`_spread`'s sequence."""
    return {
        name: low + _spread(index, offset) * (high - low)
        for (name, (low, high)), offset in zip(SHAPE_RANGES.items(), offsets, strict=True)
    }


def _bump(lat: np.ndarray, lon: np.ndarray, lat0: float, lon0: float, s_lat: float, s_lon: float):
    return np.exp(-(((lat - lat0) / s_lat) ** 2) - ((lon - lon0) / s_lon) ** 2)


def _positions(grid: np.ndarray, rows: int, cols: int, shape: dict[str, float]) -> np.ndarray:
    """Vertex positions (V, 3) of one head: y up, the face towards +z, the crown at the top."""
    latitude, neck = _grid_angles(rows)
    lat = latitude[grid[:, 0]]
    lon = -np.pi + 2 * np.pi * grid[:, 1] / cols
    # The seam's two columns are one set of points: the same angle (cos and sin of -pi and
    # pi differ in the last bit), so a welded mesh is closed across it.
    lon = np.where(grid[:, 1] == cols, -np.pi, lon)
    front = np.cos(lon)
    # The pole's row is one point (cos(pi / 2) is 6e-17, not 0).
    across = np.where(grid[:, 0] == 0, 0.0, np.cos(lat))
    # The radius along each direction: 1 on an ellipsoid, the features as bumps on it.
    eyes = _bump(lat, lon, 0.1, 0.33, 0.07, 0.12) + _bump(lat, lon, 0.1, -0.33, 0.07, 0.12)
    cheeks = _bump(lat, lon, -0.25, 0.5, 0.2, 0.2) + _bump(lat, lon, -0.25, -0.5, 0.2, 0.2)
    ears = _bump(lat, lon, 0.0, np.pi / 2, 0.16, 0.09) + _bump(
        lat, lon, 0.0, -np.pi / 2, 0.16, 0.09
    )
    radius = (
        1.0
        + shape["back"] * smoothstep(0.0, -0.8, front) * np.exp(-((lat - 0.3) ** 2) / 0.3)
        + shape["nose"] * _bump(lat, lon, -0.12, 0.0, 0.2, 0.13)
        + shape["brow"] * _bump(lat, lon, 0.22, 0.0, 0.06, 0.5)
        + shape["cheek"] * cheeks
        - 0.03 * eyes  # the sockets
        + shape["chin"] * _bump(lat, lon, -0.85, 0.0, 0.2, 0.35)
        + shape["ears"] * ears
    )
    radius = np.where(grid[:, 0] == 0, 1.0, radius)  # (the bulge reaches the pole at 0.005)
    jaw = 1.0 - shape["jaw"] * smoothstep(-0.1, -1.0, lat) * smoothstep(-0.5, 0.5, front)
    head = np.stack(
        [
            radius * across * np.sin(lon) * shape["width"] * jaw,
            radius * np.sin(lat) * 0.5 * (1 + shape["face"] * smoothstep(0.0, -0.9, lat)),
            radius * across * np.cos(lon) * shape["depth"],
        ],
        axis=1,
    )
    # The neck: a cylinder under the jaw, a little behind the face's centre, that the
    # lowest rows slide down; the rows just above blend into it.
    w = neck[grid[:, 0]]
    cylinder = np.stack(
        [
            shape["neck"] * np.sin(lon),
            0.5 * np.sin(LOWEST_LATITUDE) * (1 + shape["face"]) - 0.22 * w,
            1.1 * shape["neck"] * np.cos(lon) - 0.06,
        ],
        axis=1,
    )
    blend = smoothstep(0.0, 0.5, w)[:, None]
    return HEAD_HEIGHT * shape["size"] * ((1 - blend) * head + blend * cylinder)


def _palette(index: int, offset: float, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Head ``index``'s colours: skin from the ramp, hair, irises and lips from the lists."""
    # Heads step along the skin ramp (:func:`_spread`): two heads of one seed are never of
    # one tone.
    t = _spread(index, offset) * (len(SKIN_RAMP) - 1)
    low = min(int(t), len(SKIN_RAMP) - 2)
    ramp = np.asarray(SKIN_RAMP)
    skin = ramp[low] + (t - low) * (ramp[low + 1] - ramp[low])
    return {
        "skin": skin,
        "hair": np.asarray(HAIR[int(rng.integers(len(HAIR)))]),
        "iris": np.asarray(IRIS[int(rng.integers(len(IRIS)))]),
        "lips": np.asarray(LIPS[int(rng.integers(len(LIPS)))]),
    }


def _paint(size: int, rows: int, palette: dict[str, np.ndarray], seed: int) -> np.ndarray:
    """The head's texture (size, size, 3) float32, painted at every texel's surface angles."""
    # Each texel centre's (latitude, longitude): the layout's own mapping inverted; texels
    # outside the chart get the angles of its nearest border (the padding continues it).
    span = 1.0 - 2 * UV_MARGIN
    centres = (np.arange(size) + 0.5) / size
    u, v = np.meshgrid(centres, 1.0 - centres)
    lon = (np.clip((u - UV_MARGIN) / span, 0.0, 1.0) - 0.5) * 2 * np.pi
    row = np.clip((1.0 - UV_MARGIN - v) / span, 0.0, 1.0) * (rows - 1)
    latitude, neck = _grid_angles(rows)
    lat = np.interp(row, np.arange(rows), latitude)
    # Below the head's rows the neck continues downwards: a latitude-like coordinate.
    lat = lat - 0.6 * np.interp(row, np.arange(rows), neck)
    point = np.stack([np.cos(lat) * np.sin(lon), np.sin(lat), np.cos(lat) * np.cos(lon)], -1)
    skin = (
        palette["skin"] * (1.0 + 0.06 * fbm(point, octaves=3, seed=seed, frequency=3.0))[..., None]
    )
    # Cheeks a little redder, the neck a little darker.
    blush = _bump(lat, np.abs(lon), -0.22, 0.5, 0.15, 0.18)[..., None]
    skin = skin + 0.08 * blush * (np.array([0.9, 0.3, 0.3]) - skin)
    skin = skin * (1.0 - 0.12 * smoothstep(-0.85, -1.2, lat))[..., None]
    colour = skin
    # Eyes: a white almond with the iris and the pupil, a dark upper lid line.
    for side in (-1.0, 1.0):
        d_lon, d_lat = (lon - side * 0.33) / 0.15, (lat - 0.1) / 0.055
        almond = smoothstep(1.0, 0.8, d_lon**2 + d_lat**2)[..., None]
        iris = smoothstep(0.42, 0.32, np.hypot(d_lon * 0.15, d_lat * 0.055) / 0.11)[..., None]
        pupil = smoothstep(0.16, 0.1, np.hypot(d_lon * 0.15, d_lat * 0.055) / 0.11)[..., None]
        eye = np.array([0.93, 0.92, 0.9]) * (1 - iris) + palette["iris"] * iris
        eye = eye * (1 - pupil) + 0.05 * pupil
        colour = colour * (1 - almond) + eye * almond
        lid = smoothstep(0.35, 0.1, np.abs(d_lat - 0.9)) * smoothstep(1.15, 0.9, np.abs(d_lon))
        colour = colour * (1 - 0.7 * lid[..., None])
        brow_arch = 0.21 + 0.02 * (1 - d_lon**2)
        brow = smoothstep(0.022, 0.012, np.abs(lat - brow_arch)) * smoothstep(
            1.3, 1.0, np.abs(d_lon)
        )
        colour = colour + brow[..., None] * (0.8 * palette["hair"] + 0.05 - colour)
    # Lips: an ellipse under the nose, the mouth line darker across its middle.
    d_lon, d_lat = lon / 0.26, (lat + 0.5) / 0.06
    lips = smoothstep(1.0, 0.75, d_lon**2 + d_lat**2)[..., None]
    colour = colour * (1 - lips) + palette["lips"] * lips
    mouth = smoothstep(0.25, 0.05, np.abs(d_lat)) * smoothstep(1.0, 0.8, np.abs(d_lon))
    colour = colour * (1 - 0.6 * mouth[..., None])
    # Ears: a ring a little redder than the skin round a shadowed hollow.
    ear = np.hypot((np.abs(lon) - np.pi / 2) / 0.09, lat / 0.16)
    rim = (smoothstep(1.1, 0.9, ear) * smoothstep(0.5, 0.7, ear))[..., None]
    hollow = smoothstep(0.6, 0.3, ear)[..., None]
    colour = colour + 0.25 * rim * (np.array([0.85, 0.45, 0.4]) - colour)
    colour = colour * (1 - 0.35 * hollow)
    # Nostrils.
    nostrils = _bump(lat, np.abs(lon), -0.28, 0.05, 0.02, 0.025)[..., None]
    colour = colour * (1 - 0.6 * nostrils)
    # Hair: above a hairline high on the forehead that drops towards the ears and the nape;
    # strands run down the head (noise stretched along the latitude).
    hairline = 0.62 - 1.2 * (1 - np.cos(lon)) / 2 + 0.05 * fbm(point, seed=seed + 1, frequency=4.0)
    hair = smoothstep(hairline - 0.04, hairline + 0.04, lat)[..., None]
    strands = fbm(np.stack([lon * 12.0, lat * 1.5], -1), octaves=3, seed=seed + 2, frequency=2.0)
    hair_colour = palette["hair"] * (1.0 + 0.35 * strands)[..., None]
    colour = colour * (1 - hair) + hair_colour * hair
    return np.clip(colour, 0.0, 1.0).astype(np.float32)


def shared_layout_heads(
    count: int = 2, seed: int = 0, texture_size: int = 128, grid: tuple[int, int] = GRID
) -> list:
    """``count`` textured heads in one UV layout: the same faces and UVs, own shapes and textures.

    Parameters
    ----------
    count : int, optional
        Number of heads ("people").
    seed : int, optional
        The run's seed: the same seed gives the same heads (the same bytes when written);
        head ``i`` does not depend on ``count``.
    texture_size : int, optional
        Side of each head's square texture (texels).
    grid : (int, int), optional
        Rows (crown to neck) and columns (around the head) of the latitude/longitude grid;
        the default gives 2,057 vertices and 3,888 triangles.

    Returns
    -------
    list of trimesh.Trimesh
        Textured meshes (:func:`imagemap.scene.textured_mesh`), y up, the face towards +z,
        about 1.3 :data:`HEAD_HEIGHT` tall with the neck.

    Examples
    --------
    >>> from imagemap.scene.views import texture_image
    >>> heads = shared_layout_heads(2, seed=0, texture_size=64)
    >>> [len(h.vertices) for h in heads], texture_image(heads[0]).shape
    ([2057, 2057], (64, 64, 3))
    >>> bool((heads[0].visual.uv == heads[1].visual.uv).all())
    True
    """
    from imagemap.scene import textured_mesh

    rows, cols = (int(n) for n in grid)
    if rows < 4 or cols < 8 or count < 0 or texture_size < 8:
        raise ValueError(f"shared_layout_heads: count {count}, grid {grid}, texture_size "
                         f"{texture_size}: at least a 4 x 8 grid and 8 texels")  # fmt: skip
    faces, uv, cells = _layout(rows, cols)
    # Where the class starts on each proportion's and the skin's sequence: per seed.
    offsets = np.random.default_rng([int(seed), 0]).random(len(SHAPE_RANGES) + 1)
    heads = []
    for index in range(count):
        rng = np.random.default_rng([int(seed), 1, index])  # colours and texture noise
        shape = _shape(index, offsets[1:])
        palette = _palette(index, float(offsets[0]), rng)
        texture = _paint(texture_size, rows, palette, int(rng.integers(2**31)))
        heads.append(textured_mesh(_positions(cells, rows, cols, shape), faces, uv, texture))
    return heads


def write_shared_layout_heads(
    folder: str | os.PathLike, count: int = 2, seed: int = 0, texture_size: int = 128,
    grid: tuple[int, int] = GRID,
) -> list[Path]:  # fmt: skip
    """Write :func:`shared_layout_heads` as ``head_00.glb``, ``head_01.glb``... in ``folder``.

    The folder is an imagemap database of textured meshes (``imagemap synthesize MESH
    --db FOLDER``). Returns the paths, in name order.

    Examples
    --------
    >>> import tempfile
    >>> paths = write_shared_layout_heads(tempfile.mkdtemp(), count=2, seed=0)
    >>> [p.name for p in paths]
    ['head_00.glb', 'head_01.glb']
    """
    from imagemap.scene.files import export_textured

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for index, head in enumerate(shared_layout_heads(count, seed, texture_size, grid)):
        paths += export_textured(head, folder / f"head_{index:02d}.glb")
    return paths
