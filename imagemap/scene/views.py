"""Views of a mesh: how it is seen, rendered to depth, and coloured per pixel.

Meshes in, textured meshes out: views, depth rendering, UVs, baking and export.

A mesh (anything trimesh loads: OBJ, PLY, GLB/glTF, STL, OFF) is seen from a
:class:`View` (azimuth and elevation in degrees; the front, ``0,0``, looks along -z
as ``data_gen`` does) by the project's one orthographic ray caster
(:mod:`imagemap.scene.raycast`): :func:`render_mesh` gives the depth map (planar,
larger = nearer, background 0), and per pixel the hit face and its barycentric
coordinates.

**Framing.** The mesh, rotated into the view, is fitted into the picture with a
margin (``margin`` of each side, default 8 %), centred; depth is
``0.1 + 0.9 (z - z_min) / L`` with ``L`` the largest of the rotated bounding box's
three extents, so x, y and depth share one scale and proportions are kept.
Every mesh (query or example) is framed the same way, so examples rendered from
meshes match queries rendered from meshes.

Examples
--------
>>> import trimesh
>>> mesh = trimesh.creation.icosphere(subdivisions=2)
>>> render = render_mesh(mesh, parse_view("front"), size=(40, 30))
>>> render.depth.shape, bool(render.mask[15, 20]), bool(render.mask[0, 0])
((30, 40), True, False)
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from imagemap.io import InputError

__all__ = [
    "FRONT",
    "MeshRender",
    "NAMED_VIEWS",
    "View",
    "parse_view",
    "parse_views",
    "render_colours",
    "render_mesh",
    "render_textured",
    "sample_image",
    "sample_pixels",
    "surface_colours",
    "texture_image",
]

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
        if not np.isfinite(azimuth):
            raise InputError(f"view {text!r}: azimuth {tokens[i]!r} is not a finite number")
        if not np.isfinite(elevation) or abs(elevation) > 90:
            raise InputError(
                f"view {text!r}: elevation {tokens[i + 1]!r} must be a number within [-90, 90]"
            )
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
    import trimesh  # deferred: start-up (trimesh)

    from imagemap.scene.raycast import (  # deferred: start-up (trimesh)
        OrthographicView,
        cast_orthographic,
    )

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


def texture_image(mesh) -> np.ndarray | None:
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
    texture = texture_image(mesh) if uv is not None else None
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
