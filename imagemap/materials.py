"""PBR material sets: maps beside an example's colour, carried through the colour's source map.

A database example may hold more maps than its colour, each beside
``NAME_image.png`` as ``NAME_KIND.png`` for a KIND of :data:`MAP_KINDS`:

- ``normal``: tangent-space normals, OpenGL convention (x right, y up, z out of the
  surface), encoded ``(n + 1) / 2`` in RGB;
- ``roughness``, ``metallic``, ``height``, ``ao`` (ambient occlusion): grey, in [0, 1].

A synthesis makes each output pixel a copy of one example pixel: the source map
of :class:`~imagemap.depth.pipeline.ColorizeResult` (example, y, x). Every map is
written through **the same source map** (:func:`transfer_maps`): a pixel's roughness
is its source pixel's roughness. Tangent-space normals copy as they are on the
picture route: the tangent frame of an image-map is the picture's x and y on the
surface at both ends, and the synthesis copies windows without rotating them, so a
copied normal says the same thing about the query's surface. On the mesh route the
frames differ (picture axes against the UV atlas' axes) and the normals are turned
into the atlas' tangent frame (:func:`view_normals_to_atlas`).

An example without a map that others have contributes the map's neutral value
(:data:`NEUTRAL`), so a half-equipped database still gives whole maps.

Examples
--------
>>> import numpy as np
>>> from imagemap.example import Example
>>> depth = np.pad(np.full((8, 8), 0.5), 1)
>>> example = with_maps(Example.from_arrays("a", depth, np.zeros((10, 10, 3))),
...                     roughness=np.linspace(0, 1, 100).reshape(10, 10))
>>> sorted(example_maps(example))
['roughness']
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from imagemap.core.blend import copy_through
from imagemap.errors import InputError
from imagemap.io import _load_raw
from imagemap.tangents import corner_tangents, tangent_frames

__all__ = [
    "MAP_KINDS",
    "NEUTRAL",
    "SIDE_MAPS",
    "atlas_normals_to_view",
    "companion_path",
    "database_map_kinds",
    "decode_normals",
    "encode_normals",
    "example_maps",
    "map_kinds",
    "map_paths",
    "picture_normals_to_world",
    "transfer_maps",
    "uv_frames",
    "view_normals_to_atlas",
    "with_maps",
]

#: The maps a material set may hold, with their channel counts.
#: The maps a glTF material has no slot for: on the mesh route they are written beside
#: the mesh as ``STEM_KIND.png`` (:func:`imagemap.mesh.route.mesh_writers`), not in it.
SIDE_MAPS: tuple[str, ...] = ("height",)

MAP_KINDS: dict[str, int] = {"normal": 3, "roughness": 1, "metallic": 1, "height": 1, "ao": 1}
#: What a map says where it says nothing: a flat normal, the export's default
#: roughness (:data:`imagemap.scene.files.DEFAULT_ROUGHNESS`), no metal, mid height,
#: nothing occluded.
NEUTRAL: dict[str, tuple[float, ...]] = {
    "normal": (0.5, 0.5, 1.0),
    "roughness": (0.6,),
    "metallic": (0.0,),
    "height": (0.5,),
    "ao": (1.0,),
}


#: Baked tangent-space normals with a smaller z (over ~72 degrees from the surface's)
#: are taken as flat: on the fish, such texels were those filled from another surface
#: (a fin's hidden side from its visible one), not relief.
MIN_NORMAL_Z = 0.3
#: Rows of a copied normal map re-encoded at a time (bounded float temporaries).
_ROWS = 256


def encode_normals(normals: np.ndarray) -> np.ndarray:
    """Unit vectors (..., 3) -> RGB in [0, 1] (``(n + 1) / 2``)."""
    return np.clip((np.asarray(normals, dtype=np.float32) + 1.0) / 2.0, 0.0, 1.0)


def decode_normals(rgb: np.ndarray) -> np.ndarray:
    """RGB in [0, 1] (..., 3) -> unit vectors (a zero vector becomes +z).

    Examples
    --------
    >>> decode_normals(np.array([0.5, 0.5, 1.0])).tolist()
    [0.0, 0.0, 1.0]
    """
    vectors = np.asarray(rgb, dtype=np.float32) * 2.0 - 1.0
    length = np.linalg.norm(vectors, axis=-1, keepdims=True)
    flat = np.zeros_like(vectors)
    flat[..., 2] = 1.0
    return np.where(length > 1e-6, vectors / np.maximum(length, 1e-6), flat)


def _as_map(kind: str, array: np.ndarray, shape: tuple[int, int], what: str) -> np.ndarray:
    """A map checked for its kind: (H, W, 3) for normals, (H, W) for the rest, in [0, 1]."""
    if kind not in MAP_KINDS:
        raise InputError(f"{what}: unknown map {kind!r} (use {', '.join(MAP_KINDS)})")
    array = np.asarray(array)
    if array.dtype == np.uint8:
        array = array / 255.0
    elif array.dtype == np.uint16:
        array = array / 65535.0
    array = np.asarray(array, dtype=np.float32)
    if MAP_KINDS[kind] == 1 and array.ndim == 3:
        if array.shape[2] not in (1, 3, 4) or (
            array.shape[2] >= 3 and np.ptp(array[..., :3], axis=2).max(initial=0.0) > 1 / 255
        ):
            raise InputError(f"{what}: a {kind} map is grey (one channel), got {array.shape}")
        array = array[..., 0]
    if MAP_KINDS[kind] == 3 and (array.ndim != 3 or array.shape[2] < 3):
        raise InputError(f"{what}: a normal map is RGB (H, W, 3), got {array.shape}")
    if MAP_KINDS[kind] == 3:
        array = array[..., :3]
    if array.shape[:2] != tuple(shape):
        raise InputError(
            f"{what}: {kind} map is {array.shape[1]}x{array.shape[0]}, "
            f"its example is {shape[1]}x{shape[0]}"
        )
    if not np.all(np.isfinite(array)) or array.min(initial=0) < 0 or array.max(initial=0) > 1:
        raise InputError(f"{what}: {kind} map values must be finite and in [0, 1]")
    return array


def map_paths(image_path: str | os.PathLike, name: str) -> dict[str, Path]:
    """The map files beside an example's image-map that exist: ``{kind: NAME_KIND.png}``."""
    folder = Path(image_path).parent
    found = {}
    for kind in MAP_KINDS:
        path = folder / f"{name}_{kind}.png"
        if path.is_file():
            found[kind] = path
    return found


def with_maps(example, **maps: np.ndarray):
    """``example`` (in memory or on disk) with maps given as arrays (checked), for the API."""
    checked = {
        kind: _as_map(kind, array, example.depth.shape, f"example {example.name!r}")
        for kind, array in maps.items()
    }
    example._arrays["maps"] = {**example_maps(example), **checked}
    return example


def example_maps(example) -> dict[str, np.ndarray]:
    """Every map an example carries (read on first use and cached), by kind.

    From arrays given with :func:`with_maps`, a mesh example's material
    (:meth:`~imagemap.scene.examples.MeshExample.maps`), or the files
    ``NAME_KIND.png`` beside ``NAME_image.png``.

    Raises
    ------
    InputError
        A map that cannot be read, is of the wrong size or has the wrong channels.
    """
    cached = example._arrays.get("maps")
    if cached is not None:
        return cached
    if hasattr(example, "rendered_maps"):
        maps = example.rendered_maps()
    elif getattr(example, "image_path", None) is not None:
        maps = {}
        for kind, path in map_paths(example.image_path, example.name).items():
            try:
                raw = _load_raw(path)
            except InputError:
                raise
            except Exception as exc:  # a decoder's failure is the file's fault
                raise InputError(f"{path}: cannot be read as an image ({exc})") from exc
            maps[kind] = _as_map(kind, raw, example.depth.shape, str(path))
    else:
        maps = {}
    example._arrays["maps"] = maps
    return maps


def map_kinds(example) -> list[str]:
    """The kinds of map an example has, without reading them (files by name; a mesh
    example's material; arrays given with :func:`with_maps`)."""
    cached = example._arrays.get("maps")
    if cached is not None:
        return [k for k in MAP_KINDS if k in cached]
    if hasattr(example, "map_kinds"):
        return list(example.map_kinds())
    if getattr(example, "image_path", None) is not None:
        return list(map_paths(example.image_path, example.name))
    return []


def database_map_kinds(database, names: list[str] | None = None) -> list[str]:
    """The kinds of map at least one example (of ``names``, or all) has, in
    :data:`MAP_KINDS` order: what a synthesis from this database will write."""
    wanted = None if names is None else set(names)
    found = set()
    for example in database:
        if wanted is None or example.name in wanted:
            found.update(map_kinds(example))
    return [k for k in MAP_KINDS if k in found]


def transfer_maps(
    result, database, kinds: list[str] | tuple[str, ...] | None = None
) -> dict[str, np.ndarray]:
    """The examples' maps copied through the colour's source map, pixel for pixel.

    Parameters
    ----------
    result : ColorizeResult
        Its ``source`` (H, W, 3: example index, y, x) and ``example_names``.
    database : Database or list of Example
        Where the examples named in ``result`` are found.
    kinds : sequence of str, optional
        The maps to make; by default every kind at least one used example has.

    Returns
    -------
    dict
        ``{kind: (H, W) or (H, W, 3) float32}``; background pixels hold the
        kind's neutral value. Normals are unit vectors, encoded.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> from imagemap.example import Example
    >>> depth = np.pad(np.full((8, 8), 0.5), 1)
    >>> rough = np.arange(100, dtype=float).reshape(10, 10) / 100
    >>> ex = with_maps(Example.from_arrays("a", depth, np.zeros((10, 10, 3))), roughness=rough)
    >>> source = np.zeros((1, 2, 3), np.int32); source[0, :, 1:] = [[1, 2], [2, 1]]
    >>> result = SimpleNamespace(source=source, example_names=["a"], mask=np.ones((1, 2), bool))
    >>> [round(float(v), 2) for v in transfer_maps(result, [ex])["roughness"][0]]
    [0.12, 0.21]
    """

    by_name = {e.name: e for e in database}
    used = [by_name[name] for name in result.example_names]
    maps = [example_maps(e) for e in used]
    if kinds is None:
        kinds = [k for k in MAP_KINDS if any(k in m for m in maps)]
    mask = np.asarray(result.mask, dtype=bool)
    out = {}
    for kind in kinds:
        if kind not in MAP_KINDS:
            raise InputError(f"maps: unknown map {kind!r} (use {', '.join(MAP_KINDS)})")
        neutral = np.asarray(NEUTRAL[kind], dtype=np.float32)
        exemplars = []
        for example, have in zip(used, maps, strict=True):
            shape = example.depth.shape + ((3,) if MAP_KINDS[kind] == 3 else ())
            exemplar = have.get(kind)
            if exemplar is None:
                exemplar = np.broadcast_to(
                    neutral.reshape((-1,) if len(neutral) == 3 else ()), shape
                )
            exemplars.append(np.asarray(exemplar, dtype=np.float32))
        # float32 maps copied as float32 (the values float64 held), a block of rows at a
        # time, normals re-encoded so too (per pixel: the same bytes as the whole map's,
        # without its full-size float64 copy and gathers).
        source = np.asarray(result.source)
        copied = np.empty((*source.shape[:2], *exemplars[0].shape[2:]), dtype=np.float32)
        for y0 in range(0, copied.shape[0], _ROWS):
            rows = copied[y0 : y0 + _ROWS]
            rows[...] = copy_through(exemplars, source[y0 : y0 + _ROWS], dtype=np.float32)
            if kind == "normal":
                rows[...] = encode_normals(decode_normals(rows))
        copied[~mask] = neutral if MAP_KINDS[kind] == 3 else neutral[0]
        out[kind] = copied
    return out


def maps_written(
    result, database, kinds: list[str] | tuple[str, ...]
) -> tuple[dict[str, np.ndarray], list[str]]:
    """The maps a synthesis writes beside its image-map, and the kinds it leaves out.

    Of ``kinds`` (the kinds planned: :func:`database_map_kinds`), those that at least one
    example used has are copied through the source map (:func:`transfer_maps`); a kind
    none of them has would be its neutral value everywhere, a constant that says
    nothing: left out (returned second, for a note to the user). One function for
    ``imagemap synthesize`` and ``imagemap batch``.
    """
    have = {kind for name in result.example_names for kind in map_kinds(database[name])}
    kept = [kind for kind in kinds if kind in have]
    missing = [kind for kind in kinds if kind not in have]
    return transfer_maps(result, database, kinds=kept), missing


def companion_path(output: str | os.PathLike, kind: str) -> Path:
    """``out.png`` -> ``out_KIND.png``: where a map is written beside the image-map.

    Examples
    --------
    >>> str(companion_path("maps/fish.png", "roughness"))
    'maps/fish_roughness.png'
    """
    output = Path(output)
    return output.with_name(f"{output.stem}_{kind}{output.suffix or '.png'}")


def _picture_frame(view_rotation: np.ndarray, normals: np.ndarray) -> tuple:
    """Tangent (picture x on the surface) and bitangent per surface normal (N, 3)."""
    right = view_rotation[0]  # the picture's x axis in world coordinates
    tangent = right - (normals @ right)[:, None] * normals
    length = np.linalg.norm(tangent, axis=1, keepdims=True)
    # Where the surface faces sideways to x, the picture's y stands in.
    up = view_rotation[1]
    fallback = up - (normals @ up)[:, None] * normals
    tangent = np.where(length > 1e-6, tangent, np.cross(fallback, normals))
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    return tangent, np.cross(normals, tangent)


def picture_normals_to_world(
    encoded: np.ndarray, view_rotation: np.ndarray, normals: np.ndarray
) -> np.ndarray:
    """Encoded tangent-space normals (N, 3) in a picture's frame, at surface points of
    unit ``normals`` (N, 3), as world directions (float64; unit where the picture's are).

    Examples
    --------
    >>> flat = encode_normals(np.array([[0.0, 0.0, 1.0]]))
    >>> up = np.array([[0.0, 1.0, 0.0]])
    >>> np.round(picture_normals_to_world(flat, np.eye(3), up), 3).tolist()
    [[0.0, 1.0, 0.0]]
    """
    local = decode_normals(encoded).astype(np.float64)
    tangent, bitangent = _picture_frame(view_rotation, normals)
    return local[:, :1] * tangent + local[:, 1:2] * bitangent + local[:, 2:] * normals


def view_normals_to_atlas(
    encoded: np.ndarray,
    normals: np.ndarray,
    view_rotation: np.ndarray,
    atlas_tangent: np.ndarray,
    atlas_bitangent: np.ndarray,
) -> np.ndarray:
    """Tangent-space normals of a picture re-expressed in a UV atlas' tangent frame.

    A picture's tangent frame at a surface point is the picture's x and y laid on
    the surface; an atlas' is the directions of increasing u and v there. Both
    share the surface normal, so this is a rotation about it.

    Parameters
    ----------
    encoded : ndarray, (N, 3)
        Encoded normals in the picture's frame.
    normals : ndarray, (N, 3)
        Unit surface normals (world) at the same points.
    view_rotation : ndarray, (3, 3)
        :meth:`imagemap.scene.View.rotation` of the picture's view.
    atlas_tangent, atlas_bitangent : ndarray, (N, 3)
        World directions of increasing u and v at the points.

    Returns
    -------
    ndarray, (N, 3): encoded normals in the atlas' frame.

    Examples
    --------
    >>> n = np.array([[0.0, 0.0, 1.0]])
    >>> tilted = encode_normals(np.array([[0.6, 0.0, 0.8]]))  # towards the picture's x
    >>> # an atlas whose u runs along the picture's y: the tilt is now along -v
    >>> out = view_normals_to_atlas(tilted, n, np.eye(3), np.array([[0.0, 1.0, 0.0]]),
    ...                             np.array([[-1.0, 0.0, 0.0]]))
    >>> [round(float(v), 3) for v in decode_normals(out)[0]]
    [0.0, -0.6, 0.8]
    """
    local = decode_normals(encoded).astype(np.float64)
    tangent, bitangent = _picture_frame(np.asarray(view_rotation, dtype=np.float64), normals)
    world = local[:, :1] * tangent + local[:, 1:2] * bitangent + local[:, 2:] * normals
    # The atlas frame, made orthonormal about the normal (as MikkTSpace does).
    t = atlas_tangent - np.einsum("ij,ij->i", atlas_tangent, normals)[:, None] * normals
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    handed = np.sign(np.einsum("ij,ij->i", np.cross(normals, t), atlas_bitangent))
    b = np.cross(normals, t) * np.where(handed == 0, 1.0, handed)[:, None]
    out = np.stack(
        [
            np.einsum("ij,ij->i", world, t),
            np.einsum("ij,ij->i", world, b),
            np.einsum("ij,ij->i", world, normals),
        ],
        axis=1,
    )
    return encode_normals(out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12))


def uv_frames(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray) -> tuple:
    """Per face, the world directions of increasing u and v (tangent, bitangent), (F, 3) each.

    Examples
    --------
    >>> t, b = uv_frames(np.eye(3), np.array([[0, 1, 2]]), np.array([[0, 0], [1, 0], [0, 1]]))
    >>> t.tolist(), b.tolist()
    ([[-1.0, 1.0, 0.0]], [[-1.0, 0.0, 1.0]])
    """
    corners = np.asarray(vertices, dtype=np.float64)[faces]
    corner_uv = np.asarray(uv, dtype=np.float64)[faces]
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    d1, d2 = corner_uv[:, 1] - corner_uv[:, 0], corner_uv[:, 2] - corner_uv[:, 0]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    inverse = np.where(np.abs(det) > 1e-12, 1.0 / np.where(det == 0, 1.0, det), 0.0)[:, None]
    tangent = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * inverse
    bitangent = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) * inverse
    return tangent, bitangent


def _surface_normals(mesh, faces: np.ndarray, bary: np.ndarray) -> np.ndarray:
    normals = np.einsum("nk,nkc->nc", bary, np.asarray(mesh.vertex_normals)[mesh.faces[faces]])
    return normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)


def atlas_normals_to_view(encoded: np.ndarray, mesh, faces: np.ndarray, bary: np.ndarray, view):
    """A mesh's UV tangent-space normals at surface points, in a picture's tangent frame.

    The inverse of :func:`view_normals_to_atlas` for a mesh's own UVs: ``faces``
    and ``bary`` name the points (as a render's hit faces and barycentrics). The
    atlas' frames are the mesh's MikkTSpace tangents (glTF's rule for a file without
    ``TANGENT``, and what :func:`~imagemap.scene.files.export_textured` writes).
    """
    tangents = corner_tangents(mesh.vertices, mesh.faces, mesh.vertex_normals, mesh.visual.uv)
    t, b, normals = tangent_frames(tangents, mesh.vertex_normals, mesh.faces, faces, bary)
    local = decode_normals(encoded).astype(np.float64)
    world = local[:, :1] * t + local[:, 1:2] * b + local[:, 2:] * normals
    p_t, p_b = _picture_frame(view.rotation(), normals)
    out = np.stack(
        [
            np.einsum("ij,ij->i", world, p_t),
            np.einsum("ij,ij->i", world, p_b),
            np.einsum("ij,ij->i", world, normals),
        ],
        axis=1,
    )
    return encode_normals(out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12))
