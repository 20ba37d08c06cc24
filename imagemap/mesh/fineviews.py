"""The views path's final copy at the texture's resolution (issue #46 item 2: no stair steps).

A view synthesized coarser than the texels it is baked into draws its pixels' steps into
the texture (the generated fish at 512²: one texel per view pixel needs 734x550, the
default views are capped at 317x238). Synthesizing at the finer size costs 2.3x the CPU
(docs/meshes.md). Here the synthesis stays at its size and each view's map is *copied*
again at ``k`` times it (:func:`fine_factor`: the smallest whole ``k`` at which a view
pixel covers no more of the surface than a texel), as the uv-space path copies its
texture at the output size:

- every fine pixel lies in one synthesized pixel; it copies from that pixel's example at
  the source position interpolated between the neighbouring pixels' sources that
  continue its copy (:func:`imagemap.core.finecopy.fine_positions`, the depth maps' and
  the uv-space textures' fine copy too: a turned or mirrored patch at its own turn), so
  an edge that runs across a copied patch is the example's own edge at the fine size,
  not the synthesized pixels' steps;
- from the example's picture at the fine size (a mesh example rendered at ``k`` times the
  view's size; a picture example at its own size, sampled between its pixels);
- plus the finish's smooth correction (blend minus plain copy) of the synthesized map,
  interpolated.

The PBR maps go through the same copy (:func:`fine_maps`: the same :class:`FineSource`,
every map of the example stacked and read at once), and one view's projection too
(:func:`fine_render` gives its normals the surface points of the fine pixels). Seams
between two examples, or two patches, stay where the synthesis put them, on its pixels'
grid.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from imagemap.core.blend import copy_through, fill_background
from imagemap.core.finecopy import copy_steps, fine_positions
from imagemap.materials import MAP_KINDS, NEUTRAL, decode_normals, encode_normals, example_maps
from imagemap.scene.bake import planar_barycentric, view_size_for
from imagemap.scene.views import sample_pixels

__all__ = [
    "FineSource",
    "copy_fine",
    "fine_factor",
    "fine_maps",
    "fine_render",
    "fine_source",
    "fine_view",
    "fine_view_maps",
    "fine_views",
]

#: The largest fine factor: the copy's pictures grow with its square (4: 16x the pixels).
MAX_FINE_FACTOR = 4


def fine_factor(mesh, views, size: tuple[int, int], texture_size: int | None) -> int:
    """The whole factor ``k`` (1 to :data:`MAX_FINE_FACTOR`) by which views of ``size``
    are copied so that one pixel covers no more of the surface than one texel
    (:func:`imagemap.scene.bake.view_size_for` without its cap); 1 without a texture size
    (the atlas is then sized from the views).

    Examples
    --------
    >>> import trimesh
    >>> plane = trimesh.creation.box(extents=(2.0, 2.0, 0.01))
    >>> plane.visual = trimesh.visual.TextureVisuals(uv=plane.vertices[:, :2] / 2 + 0.5)
    >>> [fine_factor(plane, ["front"], (200, 150), texels) for texels in (64, 512)]
    [1, 4]
    """
    width = int(size[0])
    wanted = view_size_for(mesh, views, texture_size, base=(width, int(size[1])),
                           max_pixels=2**62)  # fmt: skip
    return int(min(max(1, -(-wanted[0] // width)), MAX_FINE_FACTOR))


@dataclass
class FineSource:
    """Where every pixel of a view copied at ``factor`` times its size reads its examples.

    Attributes
    ----------
    index : (kH, kW) int array
        The example (in ``result.example_names`` order) of each fine pixel.
    y, x : (kH, kW) float64 arrays
        The position read in that example's picture, in its pixels at the view's size
        (scaled to a finer picture of the same example when it is read).
    inside : (kH, kW) bool array
        The fine pixels of the object (the synthesized mask's footprint).
    factor : int
    """

    index: np.ndarray
    y: np.ndarray
    x: np.ndarray
    inside: np.ndarray
    factor: int


def fine_source(result, factor: int) -> FineSource:
    """The fine copy's source positions of a view's synthesis (:class:`FineSource`).

    Every fine pixel lies in one synthesized pixel; it reads that pixel's example at the
    position interpolated between the neighbouring pixels' sources that continue its copy
    (:func:`imagemap.core.finecopy.fine_positions`, each example's pose as the map copies
    it, :func:`~imagemap.core.finecopy.copy_steps`: a turned or mirrored patch at its own
    turn, a seam kept on the pixels' edge). The colour and every PBR map are read at these
    positions (:func:`copy_fine`): one copy for all of them.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> source = np.zeros((1, 2, 3), np.int32)
    >>> source[0, :, 2] = [4, 5]
    >>> fine = fine_source(SimpleNamespace(source=source, mask=np.ones((1, 2), bool)), 2)
    >>> fine.x[0].tolist(), fine.y[:, 0].tolist()
    ([3.75, 4.25, 4.75, 5.25], [-0.25, 0.25])
    """
    source = np.asarray(result.source)
    mask = np.asarray(result.mask, dtype=bool)
    height, width = mask.shape
    k = int(factor)
    inside = np.repeat(np.repeat(mask, k, axis=0), k, axis=1)
    if not mask.any():
        empty = np.zeros(inside.shape)
        return FineSource(np.full(inside.shape, -1), empty, empty.copy(), inside, k)
    # Where the synthesis left no source, the nearest pixel's (the fine mask is the coarse
    # one's footprint).
    source = fill_background(source, mask & (source[..., 0] >= 0))
    source[~mask, 0] = -1  # outside the object: continues no copy
    # The examples' poses (turned, scaled, mirrored) as the map copies them.
    steps = copy_steps(source, max(int(source[..., 0].max()) + 1, 1))
    index, sy, sx = fine_positions(source, k, inside.shape, steps=steps)
    return FineSource(np.where(inside, index, -1), sy, sx, inside, k)


def copy_fine(fine: FineSource, shapes: list[tuple[int, ...]], pictures: list) -> np.ndarray:
    """Each example's picture read at the fine copy's positions (:func:`fine_source`).

    Parameters
    ----------
    fine : FineSource
    shapes : list of tuple
        Each example's picture's shape at the view's size (what the source map indexes).
    pictures : list of (H_k, W_k, C) arrays
        The pictures read, the same ``C`` for all: the example at the fine size (or at
        the view's, then sampled between its pixels); positions are scaled by
        ``H_k / shapes[k][0]`` and ``W_k / shapes[k][1]``.

    Returns
    -------
    (kH, kW, C) float32: 0 outside ``fine.inside``.
    """
    channels = int(np.shape(pictures[0])[2]) if pictures else 0
    out = np.zeros(fine.inside.shape + (channels,), dtype=np.float32)
    for index, (shape, large) in enumerate(zip(shapes, pictures, strict=True)):
        here = fine.index == index
        if not here.any():
            continue
        scale_y = large.shape[0] / shape[0]
        scale_x = large.shape[1] / shape[1]
        picture = np.asarray(large, dtype=np.float32)
        out[here] = sample_pixels(picture, (fine.x[here] + 0.5) * scale_x - 0.5,
                                  (fine.y[here] + 0.5) * scale_y - 0.5)  # fmt: skip
    return out


def fine_view(
    result,
    coarse: list[np.ndarray],
    fine: list[np.ndarray],
    factor: int,
    source: FineSource | None = None,
) -> np.ndarray:
    """A view's synthesized map copied again at ``factor`` times its size.

    Parameters
    ----------
    result : ColorizeResult
        The view's synthesis: ``image``, ``mask``, ``source`` (example, y, x in the
        example's picture at the view's size).
    coarse : list of (h_k, w_k, 3) arrays
        Each example's picture as the synthesis copied it (the order of
        ``result.example_names``).
    fine : list of (H_k, W_k, 3) arrays
        The same pictures at the fine size: a mesh example rendered at ``factor`` times,
        a picture example its own (then ``H_k = h_k``).
    factor : int
    source : FineSource, optional
        :func:`fine_source` of ``result`` at ``factor`` (made here when not given).

    Returns
    -------
    (factor H, factor W, 3) float32 in [0, 1]; 0 outside the synthesized map's object.

    Examples
    --------
    A diagonal edge copied from an example twice as fine keeps its fine steps:

    >>> yy, xx = np.mgrid[:8, :8]
    >>> example = np.repeat((xx > yy)[..., None], 3, axis=2).astype(np.float32)
    >>> small = example[::2, ::2]
    >>> source = np.zeros((4, 4, 3), np.int32)
    >>> source[..., 1], source[..., 2] = np.mgrid[:4, :4]
    >>> from types import SimpleNamespace
    >>> result = SimpleNamespace(image=small, mask=np.ones((4, 4), bool), source=source)
    >>> out = fine_view(result, [small], [example], 2)
    >>> bool(np.array_equal(out[..., 0] > 0.5, example[..., 0] > 0.5))
    True
    """
    mask = np.asarray(result.mask, dtype=bool)
    height, width = mask.shape
    k = int(factor)
    if source is None:
        source = fine_source(result, k)
    inside = source.inside
    if not mask.any():
        return np.zeros((height * k, width * k, 3), dtype=np.float32)
    plain = copy_through([np.asarray(c, dtype=np.float32)[..., :3] for c in coarse],
                         np.asarray(result.source))  # fmt: skip
    correction = fill_background(np.asarray(result.image, np.float32)[..., :3] - plain, mask)
    image = copy_fine(source, [np.shape(c) for c in coarse],
                      [np.asarray(f, dtype=np.float32)[..., :3] for f in fine])  # fmt: skip
    # The finish's smooth correction, between the synthesized pixels' centres.
    fy = (np.arange(height * k) + 0.5) / k - 0.5
    fx = (np.arange(width * k) + 0.5) / k - 0.5
    grid_y, grid_x = np.meshgrid(fy, fx, indexing="ij")
    smooth = sample_pixels(correction, grid_x[inside], grid_y[inside])
    image[inside] = np.clip(image[inside] + smooth, 0.0, 1.0)
    return image


def fine_maps(
    source: FineSource, shapes: list[tuple[int, ...]], maps: list[dict]
) -> dict[str, np.ndarray]:
    """The examples' PBR maps copied at the fine size through the colour's fine copy.

    Every fine pixel reads every map of the example its colour came from, at the same
    position (:func:`copy_fine`, one read of all maps stacked), as
    :func:`imagemap.materials.transfer_maps` does at the view's size.

    Parameters
    ----------
    source : FineSource
    shapes : list of tuple
        Each example's picture's shape at the view's size.
    maps : list of dict
        Each example's maps (``{kind: (H_k, W_k) or (H_k, W_k, 3)}``, the picture
        frame's normals), at the fine size or its own.

    Returns
    -------
    dict
        ``{kind: (kH, kW) or (kH, kW, 3) float32}`` for every kind an example has (an
        example without it: its neutral value); outside the object the neutral value;
        normals unit, encoded.
    """
    kinds = [k for k in MAP_KINDS if any(k in m for m in maps)]
    if not kinds:
        return {}
    stacks = []
    for shape, have in zip(shapes, maps, strict=True):
        size = next((np.shape(have[k])[:2] for k in kinds if k in have), tuple(shape[:2]))
        layers = []
        for kind in kinds:
            layer = have.get(kind)
            if layer is None:
                layer = np.broadcast_to(
                    np.asarray(NEUTRAL[kind], np.float32), size + (MAP_KINDS[kind],)
                )
            layers.append(np.asarray(layer, np.float32).reshape(size + (MAP_KINDS[kind],)))
        stacks.append(np.concatenate(layers, axis=2))
    stacked = copy_fine(source, shapes, stacks)
    out, start = {}, 0
    for kind in kinds:
        channels = MAP_KINDS[kind]
        layer = stacked[..., start : start + channels]
        start += channels
        if kind == "normal":
            layer = encode_normals(decode_normals(layer))
        layer[~source.inside] = NEUTRAL[kind]
        out[kind] = layer if channels == 3 else layer[..., 0]
    return out


def fine_views(
    examples, renders: list, results: list, databases: list, factor: int
) -> tuple[list[np.ndarray], list[FineSource]]:
    """Every view's map copied at ``factor`` times its size (:func:`fine_view`), each mesh
    example seen at that size, each picture example as it is; and each view's
    :class:`FineSource`, through which its PBR maps are copied (:func:`fine_view_maps`).

    Parameters
    ----------
    examples : ExampleSet
        The database (its mesh examples seen at the fine size,
        :meth:`~imagemap.mesh.library.ExampleSet.picture`).
    renders, results, databases : lists, one entry per view
        The views' renders, syntheses and the databases they were made from.
    factor : int
        :func:`fine_factor`.
    """
    images, sources = [], []
    for render, result, database in zip(renders, results, databases, strict=True):
        fine_size = _fine_size(render, factor)
        coarse, fine = [], []
        for name in result.example_names:
            picture = np.asarray(database[name].image, dtype=np.float32)
            coarse.append(picture)
            if name in examples.mesh_names:
                fine.append(examples.picture(name, render.view, fine_size))
            else:
                fine.append(picture)
        source = fine_source(result, factor)
        images.append(fine_view(result, coarse, fine, factor, source))
        sources.append(source)
    return images, sources


def fine_view_maps(
    examples, renders: list, results: list, databases: list, sources: list[FineSource]
) -> list[dict[str, np.ndarray]]:
    """Every view's PBR maps copied at the fine size through its colour's fine copy
    (:func:`fine_maps`): a mesh example's maps seen at the fine size
    (:meth:`~imagemap.mesh.library.ExampleSet.maps`), a picture example's its own."""
    out = []
    for render, result, database, source in zip(renders, results, databases, sources,
                                                strict=True):  # fmt: skip
        fine_size = _fine_size(render, source.factor)
        shapes, maps = [], []
        for name in result.example_names:
            shapes.append(np.shape(database[name].image))
            if name in examples.mesh_names:
                maps.append(examples.maps(name, render.view, fine_size))
            else:
                maps.append(example_maps(database[name]))
        out.append(fine_maps(source, shapes, maps))
    return out


def _fine_size(render, factor: int) -> tuple[int, int]:
    """A view's (width, height) at ``factor`` times its size."""
    width, height = render.size
    return (int(width) * int(factor), int(height) * int(factor))


def fine_render(mesh, render, factor: int):
    """``render`` at ``factor`` times its size without casting again: every fine pixel of
    a pixel that sees the mesh takes that pixel's face, at the barycentrics of the fine
    pixel's centre in the face's projection (clamped into the face where the centre falls
    outside it: the nearest point of the face, whose normal is its neighbour's at their
    shared edge). What the projection's normals need (its texels are the fine pixels),
    at a fraction of a render's memory at the fine size (fish_008 at 951x714: 638 MB).

    Examples
    --------
    >>> import trimesh
    >>> from imagemap.scene.views import render_mesh
    >>> sheet = trimesh.Trimesh([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0.0]],
    ...                         [[0, 1, 2], [0, 2, 3]], process=False)
    >>> coarse = render_mesh(sheet, "front", (8, 8))
    >>> fine = fine_render(sheet, coarse, 2)
    >>> exact = render_mesh(sheet, "front", (16, 16))  # cast at the fine size
    >>> same = exact.mask & fine.mask & (fine.face == exact.face)  # all but the diagonal's
    >>> int((exact.mask & fine.mask & ~same).sum())
    6
    >>> bool(np.allclose(fine.barycentric[same], exact.barycentric[same], atol=1e-6))
    True
    """
    k = int(factor)
    height, width = render.depth.shape
    face = np.repeat(np.repeat(render.face, k, axis=0), k, axis=1)
    mask = face >= 0
    col, row, _ = render.to_pixels(np.asarray(mesh.vertices, dtype=np.float64))
    corners = np.asarray(mesh.faces, dtype=np.int64)[face[mask]]  # (N, 3)
    px = (col[corners] + 0.5) * k - 0.5
    py = (row[corners] + 0.5) * k - 0.5
    rows, cols = np.nonzero(mask)
    bary, ok = planar_barycentric(px, py, cols, rows)
    bary = np.clip(bary, 0.0, None)
    bary /= np.maximum(bary.sum(axis=1, keepdims=True), 1e-12)
    coarse = np.repeat(np.repeat(render.barycentric, k, axis=0), k, axis=1)[mask]
    flat = ~ok  # a face seen edge-on: the pixel's own hit
    bary[flat] = coarse[flat]
    barycentric = np.zeros((height * k, width * k, 3), dtype=np.float32)
    barycentric[mask] = bary
    return replace(
        render,
        depth=np.repeat(np.repeat(render.depth, k, axis=0), k, axis=1),
        mask=mask,
        face=face,
        barycentric=barycentric,
        z=np.repeat(np.repeat(render.z, k, axis=0), k, axis=1),
        pixel_size=render.pixel_size / k,
        size=(width * k, height * k),
    )
