"""Real textured meshes: each held out in turn, synthesised by the mesh route, judged by render.

Issue #32, item 4. A folder of textured meshes (``.glb``; by default the prepared copy
under ``scratch/realdata/faces``) is the database, as ``imagemap`` reads it. Each mesh is
held out in turn and textured by the mesh route
(``imagemap.mesh.colorize_mesh(mesh, database.without(name), views, preset=..., seed=0)``,
what ``imagemap synthesize MESH --db DIR --views ... -o out.glb`` runs). The result and
the held-out mesh's own texture are rendered from several angles, at least one of them
not among the synthesis views, by the perspective z-buffer rasterizer below (written
here, independent of the library's orthographic ray caster: its own camera, its own
perspective-correct UV interpolation, its own texture sampling). Per object-view: mean
|RGB| error on the object's pixels (0-255), mean CIEDE2000, and crispness (the
finest-band energy, :func:`imagemap.metrics.fine_energy`, over the truth's). The same for
two baselines: pasting the first-choice example's own texture (the example the front
view's synthesis chose first; the meshes share one UV layout, so the paste is that
example's texture image on the query's UVs) and the best possible paste (the best
example for that object-view). Where the meshes share a UV layout the textures are also
compared texel by texel over the atlas' used texels (:func:`uv_errors`).

The data: ``prepare`` builds the class from a copy of the FFHQ-UV repository
(github.com/csbhr/FFHQ-UV) that the user fetches: four textured heads in the HiFi3D++ UV
layout, three with their own HiFi3D++ shapes, one on the FLAME head that the repository
gives HiFi3D UVs. The repository's code is MIT, but its textures derive from FFHQ (CC
BY-NC-SA 4.0) and its meshes from the research-only HiFi3D++ model: the prepared class
stays in the git-ignored ``scratch/`` and nothing of it is committed (docs/real_data.md).
The tests run the benchmark on generated heads in one layout instead
(:func:`data_gen.heads.write_shared_layout_heads`).

    python benchmarks/real_meshes.py prepare --source SRC [--out DIR]
    python benchmarks/real_meshes.py run [DIR] [--views front,left,right] [--preset busts]
        [--out OUT] [--only NAME,...]
"""

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: The prepared class (made by ``prepare``; git-ignored scratch, never committed: the
#: textures' and meshes' terms do not allow it, see docs/real_data.md).
DEFAULT_DIR = ROOT / "scratch" / "realdata" / "faces"
DEFAULT_OUT = ROOT / "scratch" / "realdata" / "out"

#: The synthesis views of the user's report in #32.
SYNTHESIS_VIEWS = "front,left,right"
#: Angles to judge from (azimuth, elevation in degrees, as imagemap.scene.View): the
#: front and a profile (synthesis views) and two raised three-quarter views that no
#: synthesis view sees straight on: where the per-view syntheses meet.
EVAL_VIEWS = ((0.0, 0.0), (-40.0, 15.0), (40.0, 15.0), (90.0, 0.0))
#: Side of the square judging renders (pixels): the face fills about 170 px, near the
#: 200x150 synthesis size.
RENDER_SIZE = 320
#: Vertical field of view of the judging camera (degrees); a portrait lens's.
FIELD_OF_VIEW = 30.0
#: Camera distance in bounding-sphere radii: far enough for a mild perspective.
CAMERA_DISTANCE = 3.0
#: Free border around the bounding sphere's image, as a fraction of the picture.
FRAME_MARGIN = 0.04
#: Side of the square atlas the UV-space measure compares at: the mesh route's atlas
#: size (``colorize_mesh(texture_size=512)``).
UV_SIZE = 512
#: A screen pixel is inside a triangle when its barycentrics are above this (shared
#: edges are drawn by both triangles; the depth test picks one).
INSIDE_EPS = 1e-9
#: The judging renders' background (white, as ``render_textured``).
BACKGROUND = 1.0

#: What ``prepare`` builds from a copy of the FFHQ-UV repository: name -> (mesh OBJ,
#: vertex positions OBJ or None, texture). The FLAME head (flame_head.obj, positions
#: only) takes its faces and HiFi3D UVs from FLAME_w_HIFI3D_UV.obj (same 5023 vertices).
FFHQ_UV_OBJECTS = {
    "ffhq_teaser1": ("demos/teaser_1/mesh_head.obj", None, "demos/teaser_1/tex_uv.png"),
    "ffhq_teaser2": ("demos/teaser_2/mesh_head.obj", None, "demos/teaser_2/tex_uv.png"),
    "ffhq_teaser3": ("demos/teaser_3/mesh_head.obj", None, "demos/teaser_3/tex_uv.png"),
    "ffhq_01223": (
        "FLAME_Apply_HIFI3D_UV/flame2hifi3d_assets/FLAME_w_HIFI3D_UV.obj",
        "examples/flame_apply_hifi3d_uv_examples/flame_head.obj",
        "examples/dataset_examples/unwrap_texture/01223/01223_final_uv.png",
    ),
}
FFHQ_UV_COMMIT = "223c129ddb4b6479bfa351c8e2bc3c359cae21f0"


# ------------------------------------------------------------------ reading OBJ


def read_obj(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(vertices (V, 3), vertex faces (F, 3), UVs (T, 2), UV faces (F, 3)) of an OBJ.

    Polygons are split into fans; a file without ``vt`` gives empty UVs and UV faces.

    Examples
    --------
    >>> import tempfile, os
    >>> text = "v 0 0 0\\nv 1 0 0\\nv 1 1 0\\nv 0 1 0\\nvt 0 0\\nvt 1 0\\nvt 1 1\\nvt 0 1\\n"
    >>> text += "f 1/1 2/2 3/3 4/4\\n"
    >>> path = os.path.join(tempfile.mkdtemp(), "quad.obj")
    >>> _ = open(path, "w").write(text)
    >>> v, f, t, ft = read_obj(path)
    >>> v.shape, f.tolist(), ft.tolist()
    ((4, 3), [[0, 1, 2], [0, 2, 3]], [[0, 1, 2], [0, 2, 3]])
    """
    vertices, uvs, faces, uv_faces = [], [], [], []
    with open(path) as handle:
        for line in handle:
            parts = line.split()
            if not parts:
                continue
            if parts[0] == "v":
                vertices.append([float(x) for x in parts[1:4]])
            elif parts[0] == "vt":
                uvs.append([float(x) for x in parts[1:3]])
            elif parts[0] == "f":
                corners = [p.split("/") for p in parts[1:]]
                vi = [int(c[0]) - 1 for c in corners]
                ti = [int(c[1]) - 1 if len(c) > 1 and c[1] else -1 for c in corners]
                for k in range(1, len(corners) - 1):
                    faces.append([vi[0], vi[k], vi[k + 1]])
                    uv_faces.append([ti[0], ti[k], ti[k + 1]])
    faces_array = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    uv_array = np.asarray(uvs, dtype=np.float64).reshape(-1, 2)
    uv_faces_array = np.asarray(uv_faces, dtype=np.int64).reshape(-1, 3)
    if not len(uv_array):
        uv_faces_array = np.zeros((0, 3), dtype=np.int64)
    return np.asarray(vertices, dtype=np.float64), faces_array, uv_array, uv_faces_array


def split_by_uv(
    vertices: np.ndarray, faces: np.ndarray, uvs: np.ndarray, uv_faces: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One vertex per distinct (position, UV) corner pair: (vertices, faces, per-vertex UVs).

    Examples
    --------
    >>> v = np.zeros((3, 3)); f = np.array([[0, 1, 2], [0, 2, 1]])
    >>> t = np.array([[0, 0], [1, 0], [0, 1], [1, 1]]); ft = np.array([[0, 1, 2], [3, 2, 1]])
    >>> out_v, out_f, out_uv = split_by_uv(v, f, t, ft)
    >>> len(out_v), out_f.tolist()
    (4, [[0, 2, 3], [1, 3, 2]])
    """
    pairs = np.stack([faces.ravel(), uv_faces.ravel()], axis=1)
    unique, inverse = np.unique(pairs, axis=0, return_inverse=True)
    return vertices[unique[:, 0]], inverse.reshape(-1, 3), uvs[unique[:, 1]]


def prepare(source: str | Path, out: str | Path = DEFAULT_DIR) -> list[Path]:
    """Build the face class as GLB files in ``out`` from a copy of the FFHQ-UV repository.

    ``source`` holds the repository's files at their paths (e.g. ``git archive`` of
    the snapshot, or only the files named in :data:`FFHQ_UV_OBJECTS`).
    """
    from PIL import Image

    from imagemap.io import InputError
    from imagemap.scene.files import export_textured, textured_mesh

    source, out = Path(source), Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, (mesh_file, positions_file, texture_file) in FFHQ_UV_OBJECTS.items():
        for part in (mesh_file, positions_file, texture_file):
            if part is not None and not (source / part).is_file():
                raise InputError(f"{source / part}: missing (a copy of FFHQ-UV is expected)")
        vertices, faces, uvs, uv_faces = read_obj(source / mesh_file)
        if positions_file is not None:
            positions = read_obj(source / positions_file)[0]
            if positions.shape != vertices.shape:
                raise InputError(f"{source / positions_file}: {len(positions)} vertices, "
                                 f"{len(vertices)} expected")  # fmt: skip
            vertices = positions
        vertices, faces, uv = split_by_uv(vertices, faces, uvs, uv_faces)
        texture = np.asarray(Image.open(source / texture_file).convert("RGB"), np.float32) / 255
        path = out / f"{name}.glb"
        export_textured(textured_mesh(vertices, faces, uv, texture), path)
        written.append(path)
    (out / SHARED_UV_MARKER).write_text(
        "All meshes here share the HiFi3D++ UV layout (FFHQ-UV); see SOURCE.txt.\n"
    )
    (out / "SOURCE.txt").write_text(
        f"Built by benchmarks/real_meshes.py prepare from github.com/csbhr/FFHQ-UV at commit "
        f"{FFHQ_UV_COMMIT} (code MIT, Copyright (c) 2022 Haoran Bai; the textures derive "
        "from FFHQ, CC BY-NC-SA 4.0, the meshes from HiFi3D++, research use only: do not "
        "redistribute).\n"
        + "".join(
            f"{n}: {' + '.join(p for p in parts if p)}\n" for n, parts in FFHQ_UV_OBJECTS.items()
        )  # fmt: skip
    )
    return written


# ----------------------------------------------------------------- rasterizer


@dataclass(frozen=True)
class Camera:
    """A pinhole camera: ``rotation`` rows are right, up, forward (world), ``position``."""

    rotation: np.ndarray
    position: np.ndarray
    focal: float  # pixels
    size: int  # the picture is size x size

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World points -> (column, row, distance along the view axis); pixel j at j."""
        local = (np.asarray(points, dtype=np.float64) - self.position) @ self.rotation.T
        z = local[:, 2]
        safe = np.where(z > 1e-12, z, 1e-12)
        col = self.size / 2 - 0.5 + self.focal * local[:, 0] / safe
        row = self.size / 2 - 0.5 - self.focal * local[:, 1] / safe
        return col, row, z


def look_at(
    azimuth: float,
    elevation: float,
    centre: np.ndarray,
    radius: float,
    size: int = RENDER_SIZE,
) -> Camera:
    """A camera on the ``(azimuth, elevation)`` direction looking at ``centre``.

    Directions as :class:`imagemap.scene.View` (azimuth about +y from +z, elevation
    towards +y); the bounding sphere (``centre``, ``radius``) fills the picture less
    :data:`FRAME_MARGIN`, or the field of view, whichever is tighter.

    Examples
    --------
    >>> cam = look_at(0, 0, np.zeros(3), 1.0, size=64)
    >>> col, row, z = cam.project(np.array([[0.0, 0.0, 0.0]]))
    >>> float(col[0]), float(row[0]), float(z[0])
    (31.5, 31.5, 3.0)
    """
    az, el = math.radians(azimuth), math.radians(elevation)
    towards_camera = np.array([math.sin(az) * math.cos(el), math.sin(el),
                               math.cos(az) * math.cos(el)])  # fmt: skip
    forward = -towards_camera
    world_up = np.array([0.0, 1.0, 0.0]) if abs(el) < 89.0 else np.array([0.0, 0.0, -1.0])
    right = np.cross(forward, world_up)
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    distance = CAMERA_DISTANCE * radius
    # The sphere's silhouette half-angle; the focal length fits it in the picture.
    half_angle = math.asin(min(1.0, radius / distance))
    fov_focal = (size / 2) / math.tan(math.radians(FIELD_OF_VIEW) / 2)
    fit_focal = (size / 2) * (1 - 2 * FRAME_MARGIN) / math.tan(half_angle)
    return Camera(
        rotation=np.stack([right, up, forward]),
        position=np.asarray(centre, dtype=np.float64) + distance * towards_camera,
        focal=float(min(fov_focal, fit_focal)),
        size=int(size),
    )


def _rasterize_kernel(col, row, z, faces, height, width):
    """Z-buffer: per pixel the nearest face and its perspective-correct barycentrics."""
    depth = np.full((height, width), np.inf)
    face_id = np.full((height, width), -1, dtype=np.int64)
    bary = np.zeros((height, width, 3))
    for f in range(faces.shape[0]):
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        z0, z1, z2 = z[i0], z[i1], z[i2]
        if z0 <= 0.0 or z1 <= 0.0 or z2 <= 0.0:
            continue  # behind the camera
        x0, y0, x1, y1, x2, y2 = col[i0], row[i0], col[i1], row[i1], col[i2], row[i2]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if abs(area) < 1e-12:
            continue
        x_lo = max(int(math.ceil(min(x0, x1, x2))), 0)
        x_hi = min(int(math.floor(max(x0, x1, x2))), width - 1)
        y_lo = max(int(math.ceil(min(y0, y1, y2))), 0)
        y_hi = min(int(math.floor(max(y0, y1, y2))), height - 1)
        for py in range(y_lo, y_hi + 1):
            for px in range(x_lo, x_hi + 1):
                w0 = ((x1 - px) * (y2 - py) - (x2 - px) * (y1 - py)) / area
                w1 = ((x2 - px) * (y0 - py) - (x0 - px) * (y2 - py)) / area
                w2 = 1.0 - w0 - w1
                if w0 < -INSIDE_EPS or w1 < -INSIDE_EPS or w2 < -INSIDE_EPS:
                    continue
                # 1/z is linear in screen space: the true depth and the surface's
                # barycentrics follow from it (perspective-correct interpolation).
                inverse = w0 / z0 + w1 / z1 + w2 / z2
                zp = 1.0 / inverse
                if zp < depth[py, px]:
                    depth[py, px] = zp
                    face_id[py, px] = f
                    bary[py, px, 0] = w0 / z0 * zp
                    bary[py, px, 1] = w1 / z1 * zp
                    bary[py, px, 2] = w2 / z2 * zp
    return face_id, bary, depth


_KERNEL = None


def _kernel():
    # A loop over triangles and their pixels cannot be vectorized with a z-buffer:
    # compiled with numba on first use (the pure-Python function is its reference).
    global _KERNEL
    if _KERNEL is None:
        import numba

        _KERNEL = numba.njit(cache=False)(_rasterize_kernel)
    return _KERNEL


def rasterize(
    col: np.ndarray, row: np.ndarray, z: np.ndarray, faces: np.ndarray, height: int, width: int
) -> tuple[np.ndarray, np.ndarray]:
    """(face per pixel (-1 outside), barycentrics (H, W, 3)) of triangles at screen points.

    Pixel (row i, column j) has its centre at (j, i). ``z`` is each vertex's distance
    along the view axis (all 1 for a flat layout such as a UV atlas).

    Examples
    --------
    >>> col = np.array([0.0, 4.0, 0.0]); row = np.array([0.0, 0.0, 4.0])
    >>> face, bary = rasterize(col, row, np.ones(3), np.array([[0, 1, 2]]), 5, 5)
    >>> int((face == 0).sum()), bary[0, 2].round(2).tolist()  # 15 centres on or inside
    (15, [0.5, 0.5, 0.0])
    """
    face, bary, _ = _kernel()(
        np.ascontiguousarray(col, dtype=np.float64),
        np.ascontiguousarray(row, dtype=np.float64),
        np.ascontiguousarray(z, dtype=np.float64),
        np.ascontiguousarray(faces, dtype=np.int64),
        int(height),
        int(width),
    )
    return face, bary


def sample_bilinear(texture: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear samples (N, 3) of ``texture`` at texture coordinates (u right, v up).

    Examples
    --------
    >>> tex = np.zeros((2, 2, 3)); tex[0, 1] = 1.0  # top-right texel white
    >>> sample_bilinear(tex, np.array([[0.75, 0.75], [0.5, 0.5]]))[:, 0].tolist()
    [1.0, 0.25]
    """
    texture = np.asarray(texture, dtype=np.float64)
    height, width = texture.shape[:2]
    # Textures repeat outside [0, 1]; 1.0 itself is the far edge, not the near one.
    u, v = (np.asarray(uv[:, k], dtype=np.float64) for k in (0, 1))
    u = np.where((u < 0) | (u > 1), np.mod(u, 1.0), u)
    v = np.where((v < 0) | (v > 1), np.mod(v, 1.0), v)
    x = np.clip(u * width - 0.5, 0, width - 1)
    y = np.clip((1.0 - v) * height - 0.5, 0, height - 1)
    x0 = np.minimum(np.floor(x).astype(np.int64), max(width - 2, 0))
    y0 = np.minimum(np.floor(y).astype(np.int64), max(height - 2, 0))
    x1, y1 = np.minimum(x0 + 1, width - 1), np.minimum(y0 + 1, height - 1)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    top = texture[y0, x0] * (1 - fx) + texture[y0, x1] * fx
    bottom = texture[y1, x0] * (1 - fx) + texture[y1, x1] * fx
    return top * (1 - fy) + bottom * fy


@dataclass
class TexturedArrays:
    """A textured mesh as arrays: per-vertex UVs and one base-colour texture in [0, 1]."""

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    texture: np.ndarray

    @classmethod
    def load(cls, path: str | Path) -> TexturedArrays:
        from imagemap.io import InputError
        from imagemap.scene.files import load_mesh
        from imagemap.scene.views import texture_image

        mesh = load_mesh(path)
        uv = getattr(mesh.visual, "uv", None)
        texture = texture_image(mesh)
        if uv is None or texture is None:
            raise InputError(f"{path}: not a textured mesh (UVs and a texture image needed)")
        return cls.from_mesh(mesh)

    @classmethod
    def from_mesh(cls, mesh) -> TexturedArrays:
        from imagemap.scene.views import texture_image

        return cls(
            np.asarray(mesh.vertices, dtype=np.float64),
            np.asarray(mesh.faces, dtype=np.int64),
            np.asarray(mesh.visual.uv, dtype=np.float64),
            np.asarray(texture_image(mesh), dtype=np.float32),
        )

    def with_texture(self, texture: np.ndarray) -> TexturedArrays:
        """The same mesh and UVs with another texture (a paste)."""
        return TexturedArrays(self.vertices, self.faces, self.uv, np.asarray(texture))

    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        low, high = self.vertices.min(axis=0), self.vertices.max(axis=0)
        centre = (low + high) / 2
        return centre, float(np.linalg.norm(self.vertices - centre, axis=1).max())


def render(
    mesh: TexturedArrays, camera: Camera, background: float = BACKGROUND
) -> tuple[np.ndarray, np.ndarray]:
    """(image (S, S, 3) float32, object mask) of a textured mesh, unlit, from ``camera``.

    Examples
    --------
    >>> quad = TexturedArrays(np.array([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]),
    ...     np.array([[0, 1, 2], [0, 2, 3]]), np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]]),
    ...     np.zeros((2, 2, 3), np.float32))
    >>> quad.texture[0, :, 0] = 1.0  # top row red
    >>> image, mask = render(quad, look_at(0, 0, np.zeros(3), 1.5, size=32))
    >>> image[8, 16].tolist(), image[24, 16].tolist(), bool(mask[0, 0])
    ([1.0, 0.0, 0.0], [0.0, 0.0, 0.0], False)
    """
    col, row, z = camera.project(mesh.vertices)
    face, bary = rasterize(col, row, z, mesh.faces, camera.size, camera.size)
    mask = face >= 0
    image = np.full((camera.size, camera.size, 3), background, dtype=np.float32)
    if mask.any():
        corner_uv = mesh.uv[mesh.faces[face[mask]]]  # (N, 3, 2)
        uv = np.einsum("nk,nkc->nc", bary[mask], corner_uv)
        image[mask] = sample_bilinear(mesh.texture, uv)
    return image, mask


# ------------------------------------------------------------------- measures


def image_errors(image: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> dict[str, float]:
    """Mean |RGB| (0-255), mean CIEDE2000 and crispness (fine-band energy ratio) on ``mask``.

    Examples
    --------
    >>> rng = np.random.default_rng(0); truth = rng.random((16, 16, 3))
    >>> mask = np.ones((16, 16), bool)
    >>> e = image_errors(truth, truth, mask)
    >>> e["rgb"], e["de00"], e["crisp"]
    (0.0, 0.0, 1.0)
    """
    from skimage import color

    from imagemap.metrics import fine_energy

    a = np.clip(np.asarray(image, dtype=np.float64), 0, 1)
    b = np.clip(np.asarray(truth, dtype=np.float64), 0, 1)
    rgb = float(np.mean(np.abs(a[mask] - b[mask])) * 255)
    lab_a = color.rgb2lab(a[mask][:, None, :])[:, 0]
    lab_b = color.rgb2lab(b[mask][:, None, :])[:, 0]
    de00 = float(np.mean(color.deltaE_ciede2000(lab_a, lab_b)))
    reference = fine_energy(b, mask)
    crisp = fine_energy(a, mask) / reference if reference > 0 else math.nan
    return {"rgb": rgb, "de00": de00, "crisp": float(crisp)}


def used_texels(uv: np.ndarray, faces: np.ndarray, size: int = UV_SIZE) -> np.ndarray:
    """(size, size) bool: atlas texels whose centre some UV triangle covers.

    Examples
    --------
    >>> uv = np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]])
    >>> int(used_texels(uv, np.array([[0, 1, 2]]), 4).sum())  # lower-right half, diagonal in
    10
    """
    col = np.asarray(uv[:, 0], dtype=np.float64) * size - 0.5
    row = (1.0 - np.asarray(uv[:, 1], dtype=np.float64)) * size - 0.5
    face, _ = rasterize(col, row, np.ones(len(uv)), faces, size, size)
    return face >= 0


def texture_at(texture: np.ndarray, size: int = UV_SIZE) -> np.ndarray:
    """``texture`` resampled to ``size`` x ``size`` (area averaging when shrinking)."""
    from skimage.transform import resize

    texture = np.asarray(texture, dtype=np.float64)[..., :3]
    if texture.shape[:2] == (size, size):
        return texture
    factor = texture.shape[0] // size
    if texture.shape[0] == texture.shape[1] == factor * size:
        return texture.reshape(size, factor, size, factor, 3).mean(axis=(1, 3))
    return resize(texture, (size, size), order=1, anti_aliasing=True)


def uv_errors(
    texture: np.ndarray,
    truth_texture: np.ndarray,
    uv: np.ndarray,
    faces: np.ndarray,
    size: int = UV_SIZE,
) -> dict[str, float]:
    """Texel-by-texel :func:`image_errors` of two textures of one UV layout, on used texels.

    Both are compared at ``size`` x ``size``; only texels some triangle of the layout
    covers count (the atlas' padding and unused corners do not).

    Examples
    --------
    >>> uv = np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]]); faces = np.array([[0, 1, 2]])
    >>> truth = np.zeros((8, 8, 3)); other = truth.copy(); other[0, 0] = 1.0  # unused texel
    >>> uv_errors(other, truth, uv, faces, 8)["rgb"]
    0.0
    """
    used = used_texels(uv, faces, size)
    return image_errors(texture_at(texture, size), texture_at(truth_texture, size), used)


#: A grid cell of :func:`small_copy` whose 3-D edge is longer than this many times the
#: median edge spans a gap between UV charts (measured on the FFHQ-UV heads at grid 48:
#: a triangle's longest edge is at most 3.2x the median on the HiFi3D++ heads and 3.9x on
#: the FLAME head within charts; the 3 cells across a seam on each HiFi3D++ head, 21x).
SEAM_EDGE_RATIO = 4.0


def small_copy(mesh: TexturedArrays, grid: int = 48, texture_size: int = 128) -> TexturedArrays:
    """A coarse remesh of ``mesh`` on a ``grid`` x ``grid`` lattice of its own UV layout.

    Each lattice node at a covered texel centre becomes a vertex at its surface point
    (keeping that UV), each lattice cell of four such nodes two triangles; cells that
    cross a gap between charts are dropped. Meshes that share a UV layout stay in one
    layout. The texture is shrunk to ``texture_size``. For small local test copies (none
    is committed: the tests use generated heads, :mod:`data_gen.heads`).

    Examples
    --------
    >>> quad = TexturedArrays(np.array([[0.0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0]]),
    ...     np.array([[0, 1, 2], [0, 2, 3]]), np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]]),
    ...     np.ones((8, 8, 3), np.float32))
    >>> small = small_copy(quad, grid=4, texture_size=4)
    >>> len(small.vertices), len(small.faces), small.vertices.max(axis=0).tolist()
    (16, 18, [1.75, 1.75, 0.0])
    """
    col = mesh.uv[:, 0] * grid - 0.5
    row = (1.0 - mesh.uv[:, 1]) * grid - 0.5
    face, bary = rasterize(col, row, np.ones(len(mesh.uv)), mesh.faces, grid, grid)
    valid = face >= 0
    index = np.full((grid, grid), -1, dtype=np.int64)
    index[valid] = np.arange(valid.sum())
    corners = mesh.faces[face[valid]]
    vertices = np.einsum("nk,nkc->nc", bary[valid], mesh.vertices[corners])
    rows, cols = np.nonzero(valid)
    uv = np.stack([(cols + 0.5) / grid, 1.0 - (rows + 0.5) / grid], axis=1)
    a, b = index[:-1, :-1], index[:-1, 1:]
    c, d = index[1:, :-1], index[1:, 1:]
    whole = (a >= 0) & (b >= 0) & (c >= 0) & (d >= 0)
    quads = np.stack([a[whole], b[whole], d[whole], c[whole]], axis=1)
    triangles = np.concatenate([quads[:, [0, 2, 1]], quads[:, [0, 3, 2]]])
    edges = np.linalg.norm(vertices[triangles] - vertices[np.roll(triangles, 1, axis=1)], axis=2)
    if len(edges):
        keep = edges.max(axis=1) <= SEAM_EDGE_RATIO * np.median(edges)
        triangles = triangles[keep]
    return TexturedArrays(vertices, triangles, uv, texture_at(mesh.texture, texture_size))


# ----------------------------------------------------------------- the benchmark


def mesh_files(folder: str | Path) -> list[Path]:
    """The textured meshes of a database folder, sorted by name (as the database sorts)."""
    from imagemap.scene.files import is_mesh_path

    return sorted(p for p in Path(folder).iterdir() if p.is_file() and is_mesh_path(p))


#: A file of this name in a folder declares that its meshes share one UV layout (written
#: by ``prepare``): meshes of different topologies (the FLAME head among HiFi3D++ heads)
#: can share a layout, and no test on the UVs alone tells (the HiFi3D++ layout covers 95 %
#: of the atlas: it overlaps its own mirror image at IoU 0.96, the FLAME head's at 0.96).
SHARED_UV_MARKER = "SHARED_UV_LAYOUT"


def shares_uv_layout(folder: str | Path, meshes: list[TexturedArrays]) -> bool:
    """True when the folder declares one UV layout, or all meshes have the same UVs and faces."""
    if (Path(folder) / SHARED_UV_MARKER).is_file():
        return True
    first = meshes[0]
    return all(
        np.array_equal(m.uv, first.uv) and np.array_equal(m.faces, first.faces) for m in meshes
    )


def first_choice(name: str, folder: Path, view: str = "front") -> str:
    """The example the mesh route's selection picks first for ``name`` held out, at ``view``."""
    from imagemap.database import Database, database_at_view
    from imagemap.depth.pipeline import select_examples
    from imagemap.scene.files import load_mesh
    from imagemap.scene.views import DEFAULT_SIZE, parse_view, render_mesh

    view = parse_view(view)
    database = database_at_view(Database.from_directory(folder).without(name), view, DEFAULT_SIZE)
    query = render_mesh(load_mesh(folder / f"{name}.glb"), view, DEFAULT_SIZE)
    return database.names[select_examples(query.depth, database, m=1)[0]]


#: ``run --path``: the mesh route's choice (auto), or one path forced (``uv_space``).
PATHS = {"auto": None, "uv-space": True, "views": False}


def synthesize(
    name: str,
    folder: Path,
    out: Path,
    views: str,
    preset: str,
    seed: int = 0,
    uv_space: bool | None = None,
):
    """Run the mesh route on ``name`` held out; write ``out/NAME.glb``; (path, MeshResult, s)."""
    from imagemap.database import Database
    from imagemap.mesh import colorize_mesh
    from imagemap.scene.files import export_textured, load_mesh

    database = Database.from_directory(folder).without(name)
    start = time.perf_counter()
    result = colorize_mesh(
        load_mesh(folder / f"{name}.glb"), database, views, preset=preset, seed=seed,
        uv_space=uv_space,
    )  # fmt: skip
    seconds = time.perf_counter() - start
    path = out / f"{name}_ours.glb"
    export_textured(result.mesh, path)
    return path, result, seconds


def evaluate(
    folder: Path,
    out: Path,
    views: str = SYNTHESIS_VIEWS,
    preset: str = "busts",
    only: list[str] | None = None,
    eval_views=EVAL_VIEWS,
    size: int = RENDER_SIZE,
    uv_space: bool | None = None,
) -> dict:
    """Leave-one-out over the folder's meshes; per object-view and per object (UV) rows.

    Raises
    ------
    InputError
        Before any synthesis: not a folder, fewer than two meshes, a mesh without UVs
        and texture, or an ``only`` name that is not one of the meshes.
    """
    from imagemap.io import InputError

    if not Path(folder).is_dir():
        raise InputError(f"{folder}: not a folder of textured meshes")
    files = mesh_files(folder)
    names = [p.stem for p in files]
    if len(files) < 2:
        raise InputError(f"{folder}: {len(files)} mesh(es); leave-one-out needs at least two")
    unknown = sorted(set(only or ()) - set(names))
    if unknown:
        raise InputError(f"--only: no mesh named {', '.join(unknown)} in {folder}")
    meshes = {p.stem: TexturedArrays.load(p) for p in files}
    shared = shares_uv_layout(folder, list(meshes.values()))
    rows, uv_rows, pictures = [], [], {}
    for name in names:
        if only and name not in only:
            continue
        truth = meshes[name]
        path, made, seconds = synthesize(name, folder, out, views, preset, uv_space=uv_space)
        ours = TexturedArrays.load(path)
        chosen = [r.example_names for r in made.results]
        first = chosen[0][0]
        # The paste of the before table: the front view's depth selection's first choice.
        depth_first = first_choice(name, folder)
        centre, radius = truth.bounding_sphere()
        others = [n for n in names if n != name]
        picture_rows = []
        for azimuth, elevation in eval_views:
            camera = look_at(azimuth, elevation, centre, radius, size)
            truth_image, mask = render(truth, camera)
            ours_image, ours_mask = render(ours, camera)
            both = mask & ours_mask
            pastes = {
                other: render(truth.with_texture(meshes[other].texture), camera)[0]
                for other in others
            }
            paste_errors = {o: image_errors(img, truth_image, both) for o, img in pastes.items()}
            best = min(paste_errors, key=lambda o: paste_errors[o]["rgb"])
            rows.append({
                "object": name,
                "view": f"{azimuth:g},{elevation:g}",
                "synthesis_view": f"{azimuth:g},{elevation:g}" in _view_labels(views),
                "mask_iou": float(both.sum() / max((mask | ours_mask).sum(), 1)),
                "ours": image_errors(ours_image, truth_image, both),
                "paste": paste_errors[first],
                "depth_paste": paste_errors[depth_first],
                "best_paste": paste_errors[best],
                "first_choice": first,
                "depth_first_choice": depth_first,
                "best_choice": best,
            })  # fmt: skip
            picture_rows.append([truth_image, ours_image, pastes[first]])
        pictures[name] = picture_rows
        uv_row = {"object": name, "seconds": seconds, "examples_per_view": chosen,
                  "path": made.path}  # fmt: skip
        if shared:
            uv_row["ours"] = uv_errors(ours.texture, truth.texture, truth.uv, truth.faces)
            uv_row["paste"] = uv_errors(meshes[first].texture, truth.texture, truth.uv,
                                        truth.faces)  # fmt: skip
            uv_row["ours_atlas"] = texture_at(ours.texture)
            uv_row["truth_atlas"] = texture_at(truth.texture)
        uv_rows.append(uv_row)
        print(f"{name}: {seconds:.1f} s, examples per view {chosen}", flush=True)
    return {"rows": rows, "uv_rows": uv_rows, "pictures": pictures, "shared_uv": shared}


def _view_labels(views: str) -> set[str]:
    from imagemap.scene.views import parse_views

    return {str(v) for v in parse_views(views)}


def summary(report: dict) -> dict[str, float]:
    """Means over object-views of each measure, and how often ours beats the paste."""
    rows = report["rows"]
    out = {}
    for who in ("ours", "paste", "depth_paste", "best_paste"):
        for key in ("rgb", "de00", "crisp"):
            out[f"{who}_{key}"] = float(np.mean([r[who][key] for r in rows]))
    wins = [r["ours"]["rgb"] < r["paste"]["rgb"] for r in rows]
    out["ours_beats_paste"] = int(sum(wins))
    out["object_views"] = len(rows)
    new = [r for r in rows if not r["synthesis_view"]]
    out["ours_beats_paste_new_angles"] = int(sum(r["ours"]["rgb"] < r["paste"]["rgb"] for r in new))
    out["new_angle_views"] = len(new)
    crisp = [r["ours"]["crisp"] >= r["paste"]["crisp"] for r in rows]
    out["ours_as_crisp_as_paste"] = int(sum(crisp))
    out["ours_beats_depth_paste"] = int(
        sum(r["ours"]["rgb"] < r["depth_paste"]["rgb"] for r in rows)
    )
    out["ours_as_crisp_as_depth_paste"] = int(
        sum(r["ours"]["crisp"] >= r["depth_paste"]["crisp"] for r in rows)
    )
    return out


def table(report: dict) -> str:
    """The per object-view table (Markdown) and the UV-space rows."""
    lines = [
        "| object | view | ours RGB | paste RGB | best RGB | ours dE00 | paste dE00 | "
        "ours crisp | paste crisp | first choice | best |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in report["rows"]:
        mark = "" if r["synthesis_view"] else " (new)"
        lines.append(
            f"| {r['object']} | {r['view']}{mark} | {r['ours']['rgb']:.2f} | "
            f"{r['paste']['rgb']:.2f} | {r['best_paste']['rgb']:.2f} | "
            f"{r['ours']['de00']:.2f} | {r['paste']['de00']:.2f} | {r['ours']['crisp']:.2f} | "
            f"{r['paste']['crisp']:.2f} | {r['first_choice']} | {r['best_choice']} |"
        )
    s = summary(report)
    lines.append(
        f"| **mean** | | {s['ours_rgb']:.2f} | {s['paste_rgb']:.2f} | {s['best_paste_rgb']:.2f} "
        f"| {s['ours_de00']:.2f} | {s['paste_de00']:.2f} | {s['ours_crisp']:.2f} | "
        f"{s['paste_crisp']:.2f} | | |"
    )
    lines.append("")
    lines.append(
        f"ours beats the first-choice paste in {s['ours_beats_paste']} of {s['object_views']} "
        f"object-views ({s['ours_beats_paste_new_angles']} of {s['new_angle_views']} at new "
        f"angles); at least as crisp as the paste in {s['ours_as_crisp_as_paste']}. Against "
        f"the front view's depth selection's first choice (the before table's paste, mean RGB "
        f"{s['depth_paste_rgb']:.2f}, crisp {s['depth_paste_crisp']:.2f}): better in "
        f"{s['ours_beats_depth_paste']}, as crisp in {s['ours_as_crisp_as_depth_paste']}."
    )
    if report["shared_uv"]:
        lines += [
            "",
            "| object | path | UV ours RGB | UV paste RGB | UV ours dE00 | UV paste dE00 | "
            "UV ours crisp | UV paste crisp | seconds |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for r in report["uv_rows"]:
            lines.append(
                f"| {r['object']} | {r['path']} | {r['ours']['rgb']:.2f} | "
                f"{r['paste']['rgb']:.2f} | "
                f"{r['ours']['de00']:.2f} | {r['paste']['de00']:.2f} | "
                f"{r['ours']['crisp']:.2f} | {r['paste']['crisp']:.2f} | {r['seconds']:.1f} |"
            )
    return "\n".join(lines)


def write_pictures(report: dict, out: Path) -> list[Path]:
    """Per object: rows of angles, columns truth | ours | first-choice paste; atlases too."""
    from skimage import io as skio

    written = []
    for name, picture_rows in report["pictures"].items():
        grid = np.concatenate([np.concatenate(row, axis=1) for row in picture_rows], axis=0)
        path = out / f"{name}_views.png"
        skio.imsave(path, (np.clip(grid, 0, 1) * 255).astype(np.uint8), check_contrast=False)
        written.append(path)
    for row in report["uv_rows"]:
        if "ours_atlas" in row:
            pair = np.concatenate([row["truth_atlas"], row["ours_atlas"]], axis=1)
            path = out / f"{row['object']}_atlas.png"
            skio.imsave(path, (np.clip(pair, 0, 1) * 255).astype(np.uint8), check_contrast=False)
            written.append(path)
    return written


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    prep = commands.add_parser("prepare", help="build the face class from a copy of FFHQ-UV")
    prep.add_argument("--source", type=Path, required=True)
    prep.add_argument("--out", type=Path, default=DEFAULT_DIR)
    run = commands.add_parser("run", help="leave-one-out over a folder of textured meshes")
    run.add_argument("folder", type=Path, nargs="?", default=DEFAULT_DIR)
    run.add_argument("--views", default=SYNTHESIS_VIEWS)
    run.add_argument("--preset", default="busts")
    run.add_argument("--out", type=Path, default=DEFAULT_OUT)
    run.add_argument("--only", default="", help="comma-separated object names")
    run.add_argument(
        "--path",
        choices=tuple(PATHS),
        default="auto",
        help="the mesh route's own choice (auto), or the uv-space or views path forced",
    )
    args = parser.parse_args(argv)
    if args.command == "prepare":
        for path in prepare(args.source, args.out):
            print(path)
        return 0
    from imagemap.io import InputError

    only = [n for n in args.only.split(",") if n] or None
    try:
        args.out.mkdir(parents=True, exist_ok=True)
        report = evaluate(
            args.folder, args.out, args.views, args.preset, only, uv_space=PATHS[args.path]
        )
    except InputError as exc:
        print(f"error: {exc}")
        return 2
    print(table(report))
    for path in write_pictures(report, args.out):
        print(path)
    keep = {
        "rows": report["rows"],
        "uv_rows": [{k: v for k, v in r.items() if not k.endswith("_atlas")}
                    for r in report["uv_rows"]],
        "summary": summary(report),
        "views": args.views,
        "preset": args.preset,
        "path": args.path,
        "eval_views": [list(v) for v in EVAL_VIEWS],
    }  # fmt: skip
    (args.out / "results.json").write_text(json.dumps(keep, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
