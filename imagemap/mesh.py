"""Meshes in, textured meshes out: views, depth rendering, UVs, baking and export.

A mesh (anything trimesh loads: OBJ, PLY, GLB/glTF, STL, OFF) is seen from a
:class:`View` (azimuth and elevation in degrees; the front, ``0,0``, looks along -z
as ``data_gen`` does) by the project's one orthographic ray caster
(:mod:`imagemap.raycast`): :func:`render_mesh` gives the depth map (planar,
larger = nearer, background 0), and per pixel the hit face and its barycentric
coordinates.

**Framing.** The mesh, rotated into the view, is fitted into the picture with a
margin (``margin`` of each side, default 8 %), centred; depth is
``0.1 + 0.9 (z - z_min) / L`` with ``L`` the largest of the rotated bounding box's
three extents, so x, y and depth share one scale and proportions are kept.
Every mesh (query or example) is framed the same way, so examples rendered from
meshes match queries rendered from meshes.

**One view** (:func:`project_texture`): the UVs are the orthographic projection of
the vertices into the picture, and the synthesized map is the texture. Fallback for
what the view does not see: every face takes the colour of the visible texel it
projects onto (the nearest visible texel in the picture plane), so a hidden flank
shows the visible one mirrored and an occluded part the surface in front of it;
faces at the silhouette whose projection falls between pixel centres find the
texture's background filled with the nearest foreground colour, never black.

**Several views** (:func:`bake_views`): the mesh's own UVs, or an atlas made with
``xatlas`` when it has none. Each texel is a surface point; every view that sees
it (its depth within two pixels of the rendered surface) contributes its colour
with weight ``cos^2`` of the angle between the surface normal and the view
direction, times a feather that falls to zero within four pixels of the view's
silhouette and depth discontinuities, so views blend smoothly where they overlap.
Texels no view sees take the colour of the nearest seen texel in 3-D. Texels
outside every chart are filled with the nearest chart texel, so bilinear
filtering at chart seams never samples black.

Examples
--------
>>> import trimesh
>>> mesh = trimesh.creation.icosphere(subdivisions=2)
>>> render = render_mesh(mesh, parse_view("front"), size=(40, 30))
>>> render.depth.shape, bool(render.mask[15, 20]), bool(render.mask[0, 0])
((30, 40), True, False)
"""

from __future__ import annotations

import hashlib
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

from imagemap.database import Database, Example
from imagemap.io import InputError, atomic_path, read_npz, write_npz

__all__ = [
    "MESH_SUFFIXES",
    "MeshExample",
    "MeshRender",
    "MeshResult",
    "View",
    "bake_views",
    "check_textured",
    "colorize_mesh",
    "database_at_view",
    "export_textured",
    "fill_from_nearest",
    "is_mesh_path",
    "load_mesh",
    "mesh_examples",
    "parse_view",
    "parse_views",
    "prepare_database",
    "project_texture",
    "rasterize_uv",
    "render_colours",
    "render_mesh",
    "render_textured",
    "sample_image",
    "surface_colours",
    "textured_mesh",
    "uv_atlas",
]

#: Suffixes read as meshes (anything trimesh loads that holds triangles).
MESH_SUFFIXES = (".obj", ".ply", ".glb", ".gltf", ".stl", ".off")
#: Suffixes written as textured meshes.
TEXTURED_SUFFIXES = (".glb", ".obj")
#: Bumped whenever rendering changes, so cached renders of examples are redone.
RENDER_VERSION = 1
DEFAULT_SIZE = (200, 150)
DEFAULT_MARGIN = 0.08


# --------------------------------------------------------------------------- views


@dataclass(frozen=True)
class View:
    """A direction to look from: azimuth about +y, then elevation towards +y (degrees).

    ``View(0, 0)`` is the front (camera on +z looking along -z, as ``data_gen``);
    ``View(90, 0)`` looks from +x, ``View(0, 90)`` from above.
    """

    azimuth: float = 0.0
    elevation: float = 0.0

    def rotation(self) -> np.ndarray:
        """3x3 rotation taking world coordinates into the view frame (camera on +z)."""
        az, el = np.radians(self.azimuth), np.radians(self.elevation)
        ry = np.array([[np.cos(az), 0, -np.sin(az)], [0, 1, 0], [np.sin(az), 0, np.cos(az)]])
        rx = np.array([[1, 0, 0], [0, np.cos(el), -np.sin(el)], [0, np.sin(el), np.cos(el)]])
        return rx @ ry

    @property
    def direction(self) -> np.ndarray:
        """Unit vector from the object towards the camera, in world coordinates."""
        return self.rotation()[2]

    @property
    def label(self) -> str:
        """``"az30_el-10"``: a file-name-safe name of the view."""
        return f"az{self.azimuth:g}_el{self.elevation:g}"

    def __str__(self) -> str:
        return f"{self.azimuth:g},{self.elevation:g}"


NAMED_VIEWS = {
    "front": View(0.0, 0.0),
    "back": View(180.0, 0.0),
    "right": View(90.0, 0.0),
    "left": View(-90.0, 0.0),
    "top": View(0.0, 90.0),
    "bottom": View(0.0, -90.0),
}
FRONT = NAMED_VIEWS["front"]


def parse_views(text: str) -> list[View]:
    """``"front,back"``, ``"30,10"``, ``"0,0;180,0"`` or ``"front,90,20"`` -> views.

    Tokens are separated by commas, semicolons or spaces; a name (front, back, left,
    right, top, bottom) is one view, two numbers in a row are azimuth and elevation.
    """
    tokens = [t for t in re.split(r"[,;\s]+", text.strip()) if t]
    views, i = [], 0
    while i < len(tokens):
        token = tokens[i].lower()
        if token in NAMED_VIEWS:
            views.append(NAMED_VIEWS[token])
            i += 1
            continue
        try:
            azimuth = float(tokens[i])
            elevation = float(tokens[i + 1])
        except (ValueError, IndexError):
            raise InputError(
                f"view {text!r}: expected AZ,EL in degrees or one of "
                f"{', '.join(NAMED_VIEWS)} (got {tokens[i]!r})"
            ) from None
        if not (np.isfinite(azimuth) and np.isfinite(elevation)) or abs(elevation) > 90:
            raise InputError(f"view {text!r}: elevation must be within [-90, 90]")
        views.append(View(azimuth, elevation))
        i += 2
    if not views:
        raise InputError(f"view {text!r}: no view given")
    return views


def parse_view(text: str | View | None) -> View:
    """One view (see :func:`parse_views`); None is the front."""
    if text is None:
        return FRONT
    if isinstance(text, View):
        return text
    views = parse_views(text)
    if len(views) != 1:
        raise InputError(f"view {text!r}: expected one view, got {len(views)}")
    return views[0]


# ---------------------------------------------------------------------- loading


def is_mesh_path(path: str | os.PathLike) -> bool:
    return Path(path).suffix.lower() in MESH_SUFFIXES


def load_mesh(path: str | os.PathLike):
    """Read a mesh as one ``trimesh.Trimesh`` (a scene's geometries concatenated).

    Raises
    ------
    InputError
        Missing file, unknown format, unreadable, or no triangles.
    """
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: mesh file not found")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise InputError(
            f"{path}: unsupported mesh format {path.suffix!r} (use {', '.join(MESH_SUFFIXES)})"
        )
    try:
        loaded = trimesh.load(path, force="mesh")
    except Exception as exc:  # any decoder failure is the file's fault here
        raise InputError(f"{path}: cannot be read as a mesh ({exc})") from exc
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise InputError(f"{path}: holds no triangles")
    if not np.all(np.isfinite(loaded.vertices)):
        raise InputError(f"{path}: vertices have NaN or infinite coordinates")
    if np.ptp(loaded.vertices, axis=0).max() <= 0:
        raise InputError(f"{path}: all vertices coincide")
    return loaded


def file_digest(path: str | os.PathLike) -> str:
    """SHA-256 of a file's content (hex)."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


# --------------------------------------------------------------------- rendering


@dataclass
class MeshRender:
    """A mesh seen from a view: the depth map and what every pixel hit.

    Attributes
    ----------
    depth : (H, W) float32, larger = nearer, background 0
    mask : (H, W) bool
    face : (H, W) int64, the hit face (-1 on background)
    barycentric : (H, W, 3) float32, the hit's barycentric coordinates in its face
    z : (H, W) float64, the hit's z in the view frame (NaN on background)
    view, center, pixel_size, size : the framing (view-frame x, y of the picture's
        centre, world units per pixel, (W, H))
    """

    depth: np.ndarray
    mask: np.ndarray
    face: np.ndarray
    barycentric: np.ndarray
    z: np.ndarray
    view: View
    center: tuple[float, float]
    pixel_size: float
    size: tuple[int, int]

    def to_pixels(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World points (N, 3) -> (column, row, view z); pixel j's centre is at j."""
        local = np.asarray(points, dtype=np.float64) @ self.view.rotation().T
        width, height = self.size
        col = (local[:, 0] - self.center[0]) / self.pixel_size + width / 2 - 0.5
        row = (self.center[1] - local[:, 1]) / self.pixel_size + height / 2 - 0.5
        return col, row, local[:, 2]

    def projection_uv(self, points: np.ndarray) -> np.ndarray:
        """World points -> texture coordinates of the picture (u right, v up, GL style)."""
        col, row, _ = self.to_pixels(points)
        width, height = self.size
        return np.stack([(col + 0.5) / width, 1.0 - (row + 0.5) / height], axis=1)


def render_mesh(
    mesh,
    view: View | str | None = None,
    size: tuple[int, int] = DEFAULT_SIZE,
    margin: float = DEFAULT_MARGIN,
) -> MeshRender:
    """Depth, mask, hit face and barycentrics of ``mesh`` seen orthographically from ``view``.

    Parameters
    ----------
    mesh : trimesh.Trimesh
    view : View or str, optional
        The front (``0,0``) by default.
    size : (int, int)
        Picture (width, height).
    margin : float
        Free border of each side, as a fraction of the picture.

    Examples
    --------
    >>> import trimesh
    >>> box = trimesh.creation.box(extents=(2.0, 1.0, 0.5))
    >>> render = render_mesh(box, "front", size=(80, 60))
    >>> round(float(render.depth[30, 40]), 3)  # front face: 0.1 + 0.9 * 0.5 / 2
    0.325
    """
    import trimesh

    from imagemap.raycast import OrthographicView, cast_orthographic

    view = parse_view(view)
    width, height = (int(v) for v in size)
    if width < 8 or height < 8:
        raise InputError(f"size {width}x{height} is too small (at least 8x8)")
    if not 0 <= margin < 0.5:
        raise InputError(f"margin {margin} must be in [0, 0.5)")
    rotation = view.rotation()
    posed = trimesh.Trimesh(
        np.asarray(mesh.vertices, dtype=np.float64) @ rotation.T, mesh.faces, process=False
    )
    low, high = posed.bounds
    extent = high - low
    usable = 1.0 - 2.0 * margin
    pixel_size = float(max(extent[0] / (width * usable), extent[1] / (height * usable)))
    if pixel_size <= 0:
        raise InputError("mesh has no extent across the view")
    center = (float(low[0] + high[0]) / 2.0, float(low[1] + high[1]) / 2.0)
    hits = cast_orthographic(posed, OrthographicView(center, pixel_size, (width, height)))
    scale = float(extent.max())
    depth = np.zeros((height, width), dtype=np.float32)
    depth.flat[hits.pixels] = 0.1 + 0.9 * (hits.points[:, 2] - low[2]) / scale
    face = np.full((height, width), -1, dtype=np.int64)
    face.flat[hits.pixels] = hits.faces
    barycentric = np.zeros((height, width, 3), dtype=np.float32)
    if hits.pixels.size:
        bary = trimesh.triangles.points_to_barycentric(posed.triangles[hits.faces], hits.points)
        barycentric.reshape(-1, 3)[hits.pixels] = np.clip(bary, 0.0, 1.0)
    return MeshRender(
        depth=depth,
        mask=hits.hit,
        face=face,
        barycentric=barycentric,
        z=hits.z,
        view=view,
        center=center,
        pixel_size=pixel_size,
        size=(width, height),
    )


# ------------------------------------------------------------------- textures


def sample_image(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear samples (N, C) of ``image`` (H, W, C) at GL texture coordinates (N, 2).

    u = 0 is the left edge of column 0, v = 0 the bottom edge of the last row;
    coordinates are clamped to the image.
    """
    image = np.asarray(image, dtype=np.float32)
    height, width = image.shape[:2]
    x = np.clip(np.asarray(uv[:, 0], dtype=np.float64) * width - 0.5, 0, width - 1)
    y = np.clip((1.0 - np.asarray(uv[:, 1], dtype=np.float64)) * height - 0.5, 0, height - 1)
    return sample_pixels(image, x, y)


def sample_pixels(image: np.ndarray, col: np.ndarray, row: np.ndarray) -> np.ndarray:
    """Bilinear samples at continuous pixel coordinates (pixel j's centre at j), clamped."""
    height, width = image.shape[:2]
    x = np.clip(col, 0, width - 1)
    y = np.clip(row, 0, height - 1)
    x0 = np.minimum(np.floor(x).astype(np.int64), width - 2 if width > 1 else 0)
    y0 = np.minimum(np.floor(y).astype(np.int64), height - 2 if height > 1 else 0)
    x1, y1 = np.minimum(x0 + 1, width - 1), np.minimum(y0 + 1, height - 1)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    top = image[y0, x0] * (1 - fx) + image[y0, x1] * fx
    bottom = image[y1, x0] * (1 - fx) + image[y1, x1] * fx
    return (top * (1 - fy) + bottom * fy).astype(np.float32)


def fill_from_nearest(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``image`` with every pixel outside ``mask`` set to the nearest pixel inside it."""
    if mask.all() or not mask.any():
        return image.copy()
    _, (ny, nx) = ndimage.distance_transform_edt(~mask, return_indices=True)
    return image[ny, nx]


def _texture_image(mesh) -> np.ndarray | None:
    """A textured mesh's base-colour image as float32 (H, W, 3), or None."""
    material = getattr(mesh.visual, "material", None)
    if material is None:
        return None
    image = getattr(material, "image", None)
    if image is None:
        image = getattr(material, "baseColorTexture", None)
    if image is None:
        return None
    array = np.asarray(image.convert("RGB"), dtype=np.float32) / 255.0
    return array


def surface_colours(mesh, faces: np.ndarray, barycentric: np.ndarray) -> np.ndarray:
    """RGB (N, 3) in [0, 1] of surface points given by face and barycentrics.

    From the texture at the interpolated UVs, else interpolated vertex colours, else
    face colours. Raises :class:`InputError` for a mesh with no colour at all.
    """
    visual = mesh.visual
    uv = getattr(visual, "uv", None)
    texture = _texture_image(mesh) if uv is not None else None
    if texture is not None:
        corner_uv = np.asarray(uv, dtype=np.float64)[mesh.faces[faces]]
        point_uv = np.einsum("nk,nkc->nc", barycentric, corner_uv)
        point_uv = point_uv - np.floor(point_uv)  # textures repeat
        return sample_image(texture, point_uv)
    kind = getattr(visual, "kind", None)
    if kind == "vertex":
        colours = np.asarray(visual.vertex_colors, dtype=np.float32)[:, :3] / 255.0
        return np.einsum("nk,nkc->nc", barycentric, colours[mesh.faces[faces]]).astype(np.float32)
    if kind == "face":
        return np.asarray(visual.face_colors, dtype=np.float32)[faces, :3] / 255.0
    raise InputError("mesh has no texture, vertex colours or face colours")


def render_colours(mesh, render: MeshRender) -> np.ndarray:
    """The mesh's own colours as seen in ``render`` (H, W, 3), background 0."""
    height, width = render.depth.shape
    image = np.zeros((height, width, 3), dtype=np.float32)
    pixels = np.flatnonzero(render.mask)
    if pixels.size:
        bary = render.barycentric.reshape(-1, 3)[pixels]
        image.reshape(-1, 3)[pixels] = surface_colours(mesh, render.face.flat[pixels], bary)
    return image


def _pil(image: np.ndarray):
    from PIL import Image

    array = np.round(np.clip(np.nan_to_num(image[..., :3]), 0, 1) * 255).astype(np.uint8)
    return Image.fromarray(array, mode="RGB")


def textured_mesh(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, image: np.ndarray):
    """A ``trimesh.Trimesh`` with per-vertex ``uv`` and ``image`` (H, W, 3) as its texture."""
    import trimesh
    from trimesh.visual.material import SimpleMaterial

    material = SimpleMaterial(image=_pil(image), diffuse=[255, 255, 255, 255])
    visual = trimesh.visual.TextureVisuals(uv=np.asarray(uv, dtype=np.float64), material=material)
    return trimesh.Trimesh(
        np.asarray(vertices, dtype=np.float64), np.asarray(faces), visual=visual, process=False
    )


def project_texture(mesh, render: MeshRender, image: np.ndarray):
    """The mesh textured with ``image`` seen from ``render``'s view (projection UVs).

    See the module notes for what hidden faces get.
    """
    image = np.asarray(image, dtype=np.float32)[..., :3]
    if image.shape[:2] != render.depth.shape:
        raise InputError(f"image {image.shape} does not match the render {render.depth.shape}")
    texture = fill_from_nearest(image, render.mask)
    uv = render.projection_uv(np.asarray(mesh.vertices))
    return textured_mesh(mesh.vertices, mesh.faces, uv, texture)


# ------------------------------------------------------------------- UV atlases


def uv_atlas(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, faces, uv, source vertex index): the mesh's own UVs, else an xatlas atlas.

    The source index maps each output vertex to the input vertex it copies (xatlas
    splits vertices along chart seams).
    """
    uv = getattr(mesh.visual, "uv", None)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if uv is not None and len(uv) == len(vertices):
        return vertices, faces, np.asarray(uv, dtype=np.float64), np.arange(len(vertices))
    try:
        import xatlas
    except ImportError as exc:
        raise InputError(
            "the mesh has no UV coordinates and xatlas is not installed "
            "(pip install xatlas, or give a mesh with UVs)"
        ) from exc
    vmapping, indices, uvs = xatlas.parametrize(
        vertices.astype(np.float32), faces.astype(np.uint32)
    )
    vmapping = vmapping.astype(np.int64)
    return vertices[vmapping], indices.astype(np.int64), uvs.astype(np.float64), vmapping


def rasterize_uv(
    uv: np.ndarray, faces: np.ndarray, texture_size: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Texels of a square texture covered by UV triangles.

    Returns (texel flat indices (N,), face (N,), barycentrics (N, 3)); a texel
    (row i, column j) is covered when its centre ((j + 0.5) / T, 1 - (i + 0.5) / T)
    lies in the triangle; where triangles overlap, the lowest face index wins.
    """
    size = int(texture_size)
    corners = np.asarray(uv, dtype=np.float64)[faces]  # (F, 3, 2)
    px = corners[..., 0] * size - 0.5  # continuous column (centre of j at j)
    py = (1.0 - corners[..., 1]) * size - 0.5
    col_lo = np.clip(np.ceil(px.min(axis=1)), 0, size - 1).astype(np.int64)
    col_hi = np.clip(np.floor(px.max(axis=1)), -1, size - 1).astype(np.int64)
    row_lo = np.clip(np.ceil(py.min(axis=1)), 0, size - 1).astype(np.int64)
    row_hi = np.clip(np.floor(py.max(axis=1)), -1, size - 1).astype(np.int64)
    n_cols = np.maximum(col_hi - col_lo + 1, 0)
    n_rows = np.maximum(row_hi - row_lo + 1, 0)
    counts = n_cols * n_rows
    face = np.repeat(np.arange(len(faces)), counts)
    start = np.cumsum(counts) - counts
    within = np.arange(counts.sum()) - np.repeat(start, counts)
    rows = row_lo[face] + within // np.maximum(n_cols[face], 1)
    cols = col_lo[face] + within % np.maximum(n_cols[face], 1)
    # Barycentrics of the texel centre in the face's UV triangle.
    ax, ay = px[face, 0], py[face, 0]
    v0x, v0y = px[face, 1] - ax, py[face, 1] - ay
    v1x, v1y = px[face, 2] - ax, py[face, 2] - ay
    qx, qy = cols - ax, rows - ay
    det = v0x * v1y - v1x * v0y
    ok = np.abs(det) > 1e-12
    safe = np.where(ok, det, 1.0)
    b1 = (qx * v1y - v1x * qy) / safe
    b2 = (v0x * qy - qx * v0y) / safe
    b0 = 1.0 - b1 - b2
    eps = 1e-9
    inside = ok & (b0 >= -eps) & (b1 >= -eps) & (b2 >= -eps)
    texel = rows[inside] * size + cols[inside]
    face, bary = face[inside], np.stack([b0, b1, b2], axis=1)[inside]
    order = np.lexsort((face, texel))
    first = order[np.r_[True, np.diff(texel[order]) != 0]] if order.size else order
    return texel[first], face[first], np.clip(bary[first], 0.0, 1.0)


#: A texel is seen by a view when it lies within this many pixels behind the
#: rendered surface.
VISIBILITY_PIXELS = 2.0
#: Weights fall to zero within this many pixels of a view's silhouette and
#: depth discontinuities.
FEATHER_PIXELS = 4.0


def _view_edges(render: MeshRender) -> np.ndarray:
    """Distance in pixels to the nearest silhouette or depth discontinuity of a view."""
    z = np.where(render.mask, render.z, np.nan)
    jump = 3.0 * render.pixel_size
    edge = ~render.mask
    dz_y = np.abs(np.diff(z, axis=0)) > jump
    dz_x = np.abs(np.diff(z, axis=1)) > jump
    edge[:-1] |= dz_y
    edge[1:] |= dz_y
    edge[:, :-1] |= dz_x
    edge[:, 1:] |= dz_x
    if not edge.any():
        return np.full(edge.shape, np.inf)
    return ndimage.distance_transform_edt(~edge)


def bake_views(
    mesh,
    renders: list[MeshRender],
    images: list[np.ndarray],
    texture_size: int = 512,
):
    """Bake several views' maps into one UV atlas (see the module notes).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Its own UVs are used when it has them, else an xatlas atlas is made.
    renders : list of MeshRender
        One per view (from :func:`render_mesh` of this mesh).
    images : list of (H, W, 3) arrays
        The map synthesized for each view.
    texture_size : int
        Width and height of the texture.

    Returns
    -------
    trimesh.Trimesh with the atlas UVs and the baked texture.
    """
    from scipy.spatial import cKDTree

    if len(renders) != len(images) or not renders:
        raise InputError("bake_views: one image per view is needed")
    vertices, faces, uv, source = uv_atlas(mesh)
    normals = np.asarray(mesh.vertex_normals, dtype=np.float64)[source]
    texel, face, bary = rasterize_uv(uv, faces, texture_size)
    if texel.size == 0:
        raise InputError("the mesh's UV atlas covers no texel")
    corners = faces[face]
    position = np.einsum("nk,nkc->nc", bary, vertices[corners])
    normal = np.einsum("nk,nkc->nc", bary, normals[corners])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    total = np.zeros((texel.size, 3), dtype=np.float64)
    weight = np.zeros(texel.size, dtype=np.float64)
    for render, image in zip(renders, images, strict=True):
        col, row, z = render.to_pixels(position)
        height, width = render.depth.shape
        ci = np.clip(np.round(col).astype(np.int64), 0, width - 1)
        ri = np.clip(np.round(row).astype(np.int64), 0, height - 1)
        inside = (col > -0.5) & (col < width - 0.5) & (row > -0.5) & (row < height - 0.5)
        surface = render.z[ri, ci]
        seen = inside & render.mask[ri, ci] & (z >= surface - VISIBILITY_PIXELS * render.pixel_size)
        facing = np.clip(normal @ render.view.direction, 0.0, 1.0) ** 2
        feather = np.clip(_view_edges(render)[ri, ci] / FEATHER_PIXELS, 1e-3, 1.0)
        w = np.where(seen, facing * feather, 0.0)
        filled = fill_from_nearest(np.asarray(image, dtype=np.float32)[..., :3], render.mask)
        colour = sample_pixels(filled, col, row)
        total += w[:, None] * colour
        weight += w
    seen = weight > 0
    colours = np.zeros((texel.size, 3), dtype=np.float64)
    colours[seen] = total[seen] / weight[seen, None]
    if seen.any() and not seen.all():
        # The documented fallback: the colour of the nearest seen texel in 3-D.
        _, nearest = cKDTree(position[seen]).query(position[~seen])
        colours[~seen] = colours[seen][nearest]
    texture = np.zeros((texture_size, texture_size, 3), dtype=np.float32)
    texture.reshape(-1, 3)[texel] = colours
    covered = np.zeros((texture_size, texture_size), dtype=bool)
    covered.flat[texel] = True
    texture = fill_from_nearest(texture, covered)
    return textured_mesh(vertices, faces, uv, texture)


# ------------------------------------------------------------------------ export


def export_textured(mesh, path: str | os.PathLike) -> list[Path]:
    """Write a textured mesh as ``.glb`` (one file) or ``.obj`` + ``.mtl`` + ``.png``.

    Every file is written atomically; for OBJ the ``.obj`` is written last, so its
    presence means the set is complete. Returns the paths written.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".glb":
        data = mesh.export(file_type="glb")
        with atomic_path(path) as tmp:
            tmp.write_bytes(data)
        return [path]
    if suffix == ".obj":
        from trimesh.exchange.obj import export_obj

        mesh = mesh.copy()
        material = getattr(mesh.visual, "material", None)
        if material is not None:
            material.name = path.stem  # the texture is then STEM.png, not material_0.png
        text, files = export_obj(
            mesh, include_texture=True, return_texture=True, mtl_name=f"{path.stem}.mtl"
        )
        written = []
        # Texture first, then the .mtl, then the .obj: the .obj's presence means complete.
        for name, data in sorted(files.items(), key=lambda item: item[0].endswith(".mtl")):
            target = path.parent / name
            with atomic_path(target) as tmp:
                tmp.write_bytes(data)
            written.append(target)
        with atomic_path(path) as tmp:
            tmp.write_text(text)
        return [*written, path]
    raise InputError(f"{path}: a textured mesh is written as .glb or .obj")


def check_textured(path: str | os.PathLike) -> bool:
    """True when ``path`` loads back as a mesh with UVs and a texture image."""
    try:
        mesh = load_mesh(path)
    except InputError:
        return False
    return getattr(mesh.visual, "uv", None) is not None and _texture_image(mesh) is not None


# ------------------------------------------------------- meshes as examples


def _default_cache() -> Path:
    root = os.environ.get("IMAGEMAP_CACHE")
    return Path(root) if root else Path.home() / ".cache" / "imagemap"


class MeshExample(Example):
    """An example whose depth and image-map are rendered from a textured mesh.

    Rendered on first use for its view and size, and cached on disk in
    ``cache_dir/meshes/`` under a key of the file's content hash, the view, the size,
    the margin and :data:`RENDER_VERSION`: a changed file or view renders anew.
    """

    def __init__(
        self,
        name: str,
        mesh_path: Path,
        view: View = FRONT,
        size: tuple[int, int] = DEFAULT_SIZE,
        cache_dir: str | os.PathLike | None = None,
        margin: float = DEFAULT_MARGIN,
    ) -> None:
        super().__init__(name=name)
        self.mesh_path = Path(mesh_path)
        self.view = view
        self.size = (int(size[0]), int(size[1]))
        self.margin = margin
        self.cache_dir = Path(cache_dir) if cache_dir is not None else _default_cache()

    def at_view(self, view: View, size: tuple[int, int] | None = None) -> MeshExample:
        """The same mesh rendered from another view (and size)."""
        return MeshExample(
            self.name, self.mesh_path, view, size or self.size, self.cache_dir, self.margin
        )

    def cache_path(self) -> Path:
        digest = file_digest(self.mesh_path)
        key = f"{digest}|{self.view}|{self.size}|{self.margin}|v{RENDER_VERSION}"
        short = hashlib.sha256(key.encode()).hexdigest()[:24]
        return self.cache_dir / "meshes" / f"{self.name}-{short}.npz"

    def _render(self) -> dict:
        if self._arrays:
            return self._arrays
        cached = self.cache_path()
        if cached.is_file():
            try:
                arrays = read_npz(cached, what="cached render")
                if {"depth", "image"} <= set(arrays):
                    self._arrays.update(arrays)
                    return self._arrays
            except InputError:
                pass  # a damaged cache entry is rendered anew
        mesh = load_mesh(self.mesh_path)
        render = render_mesh(mesh, self.view, self.size, self.margin)
        if not render.mask.any():
            raise InputError(f"{self.mesh_path}: nothing is visible from view {self.view}")
        try:
            image = render_colours(mesh, render)
        except InputError as exc:
            raise InputError(f"{self.mesh_path}: {exc} (an example needs colours)") from exc
        arrays = {"depth": render.depth, "image": image}
        try:
            write_npz(cached, **arrays)
        except OSError:
            pass  # a read-only cache only costs time
        self._arrays.update(arrays)
        return self._arrays

    @property
    def depth(self) -> np.ndarray:  # type: ignore[override]
        return self._render()["depth"]

    @property
    def image(self) -> np.ndarray:  # type: ignore[override]
        return self._render()["image"]

    @property
    def labels(self) -> np.ndarray | None:  # type: ignore[override]
        return None

    @property
    def info(self) -> dict:  # type: ignore[override]
        return {"mesh": str(self.mesh_path), "view": str(self.view)}

    def __repr__(self) -> str:
        return f"MeshExample({self.name!r}, {self.mesh_path.name!r}, view={self.view})"


def mesh_examples(
    root: str | os.PathLike,
    view: View | str | None = None,
    size: tuple[int, int] | None = None,
    taken: set[str] | frozenset = frozenset(),
    cache_dir: str | os.PathLike | None = None,
) -> tuple[list[MeshExample], list[str]]:
    """The meshes of a database directory as examples (rendered lazily, cached).

    Returns (examples, problems); a mesh whose name (file stem) is already an
    example's (``taken``) is a problem, not an example.
    """
    root = Path(root)
    view = parse_view(view)
    examples, problems = [], []
    if not root.is_dir():
        return examples, problems
    for entry in sorted(root.iterdir()):
        if not entry.is_file() or not is_mesh_path(entry):
            continue
        name = entry.stem
        if name in taken or any(e.name == name for e in examples):
            problems.append(f"{entry}: an example named {name!r} exists already")
            continue
        examples.append(MeshExample(name, entry, view, size or DEFAULT_SIZE, cache_dir))
    return examples, problems


def database_at_view(
    database: Database, view: View, size: tuple[int, int] | None = None
) -> Database:
    """The database with its mesh examples rendered from ``view`` (pictures unchanged)."""
    examples = [
        e.at_view(view, size) if isinstance(e, MeshExample) else e for e in database.examples
    ]
    return Database(examples, source=database.source)


def prepare_database(database: Database) -> Database:
    """Load every example's arrays now, so the database pickles with its data.

    Returns a database of in-memory examples (the same names and arrays): shipped
    to workers once, it is never read from disk or rendered again.
    """
    examples = []
    for example in database:
        prepared = Example.from_arrays(example.name, example.depth, example.image, example.labels)
        prepared.__dict__["info"] = dict(example.info)
        examples.append(prepared)
    return Database(examples, source=database.source)


# ------------------------------------------------------------- colorize a mesh


@dataclass
class MeshResult:
    """A textured mesh made from one or several views, and what made it."""

    mesh: object  # trimesh.Trimesh with UVs and texture
    renders: list[MeshRender]
    results: list  # one ColorizeResult per view

    @property
    def image(self) -> np.ndarray:
        """The first view's synthesized map (H, W, 3)."""
        return self.results[0].image


def colorize_mesh(
    mesh,
    database: Database,
    views: list[View] | str | None = None,
    *,
    size: tuple[int, int] = DEFAULT_SIZE,
    texture_size: int = 512,
    preset="busts",
    seed: int = 0,
    **colorize_options,
) -> MeshResult:
    """Synthesize image-maps for a mesh from one or several views and texture it.

    Each view is synthesized from the database's examples seen from the same view
    (mesh examples are rendered at that view; picture examples are used as they
    are). One view: projection UVs; several: baked into a UV atlas.

    Parameters
    ----------
    mesh : trimesh.Trimesh or path
    database : Database or dict
        The examples; or, prepared for each view (:func:`prepare_database`), a dict
        from ``str(view)`` (``"az,el"``) to Database.
    views : list of View or str, optional
        The front by default; e.g. ``"front,back,left,right"``.
    size : (int, int)
        (width, height) of each view's depth map.
    texture_size : int
        Atlas size when several views are baked.
    preset, seed, **colorize_options
        As :func:`imagemap.colorize`.
    """
    from imagemap.colorization import colorize

    if not hasattr(mesh, "faces"):
        mesh = load_mesh(mesh)
    if views is None:
        views = [FRONT]
    elif isinstance(views, str):
        views = parse_views(views)
    views = [parse_view(v) for v in views]
    renders, results = [], []
    for view in views:
        render = render_mesh(mesh, view, size)
        if not render.mask.any():
            raise InputError(f"nothing of the mesh is visible from view {view}")
        if isinstance(database, dict):
            examples = database[str(view)]
        else:
            examples = database_at_view(database, view, size)
        result = colorize(
            render.depth,
            examples,
            preset=preset,
            seed=seed,
            **colorize_options,
        )
        renders.append(render)
        results.append(result)
    if len(views) == 1:
        textured = project_texture(mesh, renders[0], results[0].image)
    else:
        textured = bake_views(mesh, renders, [r.image for r in results], texture_size)
    return MeshResult(mesh=textured, renders=renders, results=results)


def render_textured(
    mesh, view: View | str | None = None, size=DEFAULT_SIZE, background=1.0, shaded=False
):
    """A picture of a textured mesh from ``view``: the texture at each pixel's hit UVs.

    For looking at outputs. Unlit by default; ``shaded`` multiplies by a headlight
    Lambert term (0.45 + 0.55 cos) so the shape shows.
    """
    render = render_mesh(mesh, view, size)
    image = render_colours(mesh, render)
    if shaded and render.mask.any():
        normals = np.asarray(mesh.face_normals)[render.face[render.mask]]
        cosine = np.abs(normals @ render.view.direction)
        image[render.mask] *= (0.45 + 0.55 * cosine)[:, None].astype(np.float32)
    image[~render.mask] = background
    return image
