"""Object classes, one instance end to end, and the colour helpers the classes share.

An :class:`ObjectClass` samples shape, appearance and view parameters from a
Generator, builds an :class:`~data_gen.geometry.Assembly`, and colours surface hits
(part labels and RGB from canonical surface coordinates). :func:`make_instance` runs
the chain: parameters -> mesh -> small view jitter -> orthographic ray cast -> depth,
image-map and part-label map.
"""

from __future__ import annotations

import colorsys
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import trimesh

from data_gen.geometry import Assembly
from data_gen.render import OrthographicView, cast_orthographic

__all__ = [
    "PART_ROUGHNESS",
    "Instance",
    "ObjectClass",
    "SurfaceHits",
    "hsv",
    "instance_maps",
    "instance_rng",
    "make_instance",
    "mix",
    "part_roughness",
]

#: Foreground depth is 0.1 at the class's far z and 1.0 at its near z (see
#: ObjectClass.depth_range); hits beyond the far z are clipped to this floor so that
#: no foreground pixel is 0 (background).
DEPTH_FLOOR = 0.02


@dataclass
class SurfaceHits:
    """What a class's colouring function sees of every ray hit (N hits).

    ``component`` (N,) indexes ``component_names``; ``canonical`` (N, 3) are the
    surface coordinates interpolated from the vertices; ``points`` (N, 3) are the hit
    points in the object's own frame (before the view jitter).
    """

    component: np.ndarray
    component_names: tuple[str, ...]
    canonical: np.ndarray
    points: np.ndarray

    def where(self, *names: str) -> np.ndarray:
        """Boolean (N,) mask of the hits on any of the named components."""
        ids = [i for i, n in enumerate(self.component_names) if n in names]
        return np.isin(self.component, ids)


@dataclass(frozen=True)
class ObjectClass:
    """A procedural class of objects.

    Parameters
    ----------
    name : str
    parts : tuple of str
        Part names; part ``i`` has label ``i + 1`` (0 is background).
    default_size : (int, int)
        (width, height) in pixels.
    frame : (float, float, float, float)
        World window (x_min, x_max, y_min, y_max) that must be visible; the pixel size
        is chosen so that it fits the picture, centred.
    depth_range : (float, float)
        World z mapped to depth 0.1 (far) and 1.0 (near): one fixed scale per class.
    sample_params : callable (Generator) -> dict
        Shape and appearance parameters (JSON-able).
    build : callable (dict) -> Assembly
    colorize : callable (dict, SurfaceHits) -> (labels (N,) uint8, rgb (N, 3) float32)
    max_jitter : dict, optional
        Largest view jitter: yaw, pitch, roll (degrees) and shift (pixels).
    uv_layout : callable (dict, Assembly) -> (source (V',), faces (F, 3), uv (V', 2)), optional
        The texture atlas of the class's mesh for ``--meshes`` (``source`` indexes the
        mesh's vertices, split along the charts' seams; ``faces`` index ``source``):
        for a mesh xatlas takes long to chart. None: xatlas
        (:func:`imagemap.scene.uv_atlas`).
    """

    name: str
    parts: tuple[str, ...]
    default_size: tuple[int, int]
    frame: tuple[float, float, float, float]
    depth_range: tuple[float, float]
    sample_params: Callable[[np.random.Generator], dict]
    build: Callable[[dict], Assembly]
    colorize: Callable[[dict, SurfaceHits], tuple[np.ndarray, np.ndarray]]
    max_jitter: dict = field(
        default_factory=lambda: {"yaw": 4.0, "pitch": 3.0, "roll": 3.0, "shift_px": 3.0}
    )
    uv_layout: Callable[[dict, Assembly], tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None


@dataclass
class Instance:
    """One rendered example: arrays (H, W) / (H, W, 3) and its parameters."""

    name: str
    depth: np.ndarray  # float32, nearer = larger, background 0, foreground in ~[0.1, 1]
    image: np.ndarray  # float32 RGB in [0, 1], background black
    labels: np.ndarray  # uint8 part ids, 0 = background
    params: dict  # JSON-able: class, seed, index, parts, palette, shape, view
    mesh: trimesh.Trimesh | None = None
    maps: dict = field(default_factory=dict)  # PBR maps by kind (see instance_maps)


#: Roughness of each part (by part name, across the classes): typical values of PBR
#: material charts (wet scales and lips glossy, hair and cloth rough, eyes near mirror).
PART_ROUGHNESS = {
    "back": 0.45,
    "belly": 0.4,
    "fins": 0.55,
    "tail": 0.55,
    "eye": 0.08,
    "gill": 0.5,
    "skin": 0.55,
    "hair": 0.8,
    "eyebrows": 0.8,
    "eyes": 0.08,
    "lips": 0.4,
    "clothing": 0.85,
    "shirt": 0.85,
    "trousers": 0.9,
    "shoes": 0.35,
    "plate": 0.5,
    "groove": 0.75,
    "rim": 0.5,
}
#: Roughness of a part missing from :data:`PART_ROUGHNESS`.
OTHER_ROUGHNESS = 0.6
#: How much a part's roughness follows its pattern: darker marks are rougher by up to
#: this much, so a roughness map has structure inside a part (and a test can see
#: that it follows the colour's source map, not just the parts).
ROUGHNESS_FROM_PATTERN = 0.15
#: Width (pixels) of the blur whose difference from the luminance is the relief.
RELIEF_SIGMA = 2.0
#: Slope of the normals per unit of relief (height in [0, 1] per pixel).
RELIEF_STRENGTH = 4.0
#: Occlusion: width (pixels) of the local mean depth, and darkening per unit of depth
#: below it (a crease 0.1 deep in depth units is 40 % occluded).
AO_SIGMA = 3.0
AO_STRENGTH = 4.0


def part_roughness(parts: Sequence[str], labels: np.ndarray, luma: np.ndarray) -> np.ndarray:
    """Roughness per pixel or texel: its part's value, rougher where the pattern is darker.

    ``labels`` are part ids (0: none, ``i + 1``: ``parts[i]``); ``luma`` the
    colour's luminance in [0, 1], same shape.

    Examples
    --------
    >>> part_roughness(("eye", "hair"), np.array([1, 2, 2]), np.array([1.0, 1.0, 0.0]))
    array([0.08, 0.8 , 0.95], dtype=float32)
    """
    table = np.array(
        [OTHER_ROUGHNESS] + [PART_ROUGHNESS.get(p, OTHER_ROUGHNESS) for p in parts], np.float32
    )
    base = table[np.clip(np.asarray(labels, dtype=np.int64), 0, len(parts))]
    return np.clip(base + ROUGHNESS_FROM_PATTERN * (1.0 - luma), 0.0, 1.0).astype(np.float32)


def instance_maps(
    parts: Sequence[str], image: np.ndarray, depth: np.ndarray, labels: np.ndarray
) -> dict[str, np.ndarray]:
    """PBR maps of a rendered instance: roughness per part, relief, its normals, occlusion.

    - ``roughness``: :func:`part_roughness` of each pixel's part and luminance;
    - ``height``: the relief, 0.5 plus the luminance's difference from its blur
      (:data:`RELIEF_SIGMA`) on the object, as if light marks were raised;
    - ``normal``: tangent-space normals of that relief (OpenGL: x right, y up),
      encoded ``(n + 1) / 2``; flat on the background;
    - ``ao``: 1 less how far the depth lies below its local mean (creases darker).

    Examples
    --------
    >>> from data_gen import CLASSES
    >>> fish = make_instance(CLASSES["fish"], 0, size=(80, 60))
    >>> sorted(fish.maps), fish.maps["normal"].shape
    (['ao', 'height', 'normal', 'roughness'], (60, 80, 3))
    """
    from scipy import ndimage

    mask = depth > 0
    luma = image @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
    roughness = np.where(mask, part_roughness(parts, labels, luma), OTHER_ROUGHNESS)
    # Blur within the object only (normalised convolution), so the silhouette is no relief.
    weight = ndimage.gaussian_filter(mask.astype(np.float32), RELIEF_SIGMA)
    smooth = ndimage.gaussian_filter(luma * mask, RELIEF_SIGMA) / np.maximum(weight, 1e-6)
    height = np.where(mask, np.clip(0.5 + (luma - smooth), 0.0, 1.0), 0.5).astype(np.float32)
    d_row, d_col = np.gradient(height)
    # Rows grow downwards, tangent y upwards: the y slope is -d_row.
    normals = np.stack(
        [-RELIEF_STRENGTH * d_col, RELIEF_STRENGTH * d_row, np.ones_like(height)], axis=-1
    )
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    normals[~mask] = (0.0, 0.0, 1.0)
    local = ndimage.gaussian_filter(depth, AO_SIGMA) / np.maximum(
        ndimage.gaussian_filter(mask.astype(np.float32), AO_SIGMA), 1e-6
    )
    below = np.maximum(local - depth, 0.0)
    ao = np.where(mask, np.clip(1.0 - AO_STRENGTH * below, 0.0, 1.0), 1.0)
    return {
        "normal": ((normals + 1.0) / 2.0).astype(np.float32),
        "roughness": roughness.astype(np.float32),
        "height": height,
        "ao": ao.astype(np.float32),
    }


def instance_rng(class_name: str, index: int, seed: int) -> np.random.Generator:
    """The Generator of instance ``index``: depends on (seed, class, index) only.

    So instance i of seed S is the same whatever the count of a run.
    """
    class_key = zlib.crc32(class_name.encode())
    return np.random.default_rng(np.random.SeedSequence([int(seed), class_key, int(index)]))


def smoothstep(edge0: float, edge1: float, x: np.ndarray) -> np.ndarray:
    """Hermite step from 0 at ``edge0`` to 1 at ``edge1`` (either order)."""
    t = np.clip((x - edge0) / (edge1 - edge0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def hsv(hue: float, saturation: float, value: float) -> list[float]:
    """An RGB triple (list of float in [0, 1]) from HSV; hue wraps around 1."""
    return [float(c) for c in colorsys.hsv_to_rgb(hue % 1.0, saturation, value)]


def mix(
    colors: Sequence[Sequence[float]], weight: np.ndarray, shade: np.ndarray | None = None
) -> np.ndarray:
    """Linear blend of two colours by ``weight`` (N,) in [0, 1], times ``shade`` (N,).

    Returns (N, 3) float32 in [0, 1].
    """
    first = np.asarray(colors[0], dtype=np.float32)
    second = np.asarray(colors[1], dtype=np.float32)
    weight = np.clip(np.asarray(weight, dtype=np.float32), 0.0, 1.0)[:, None]
    rgb = first + (second - first) * weight
    if shade is not None:
        rgb = rgb * np.asarray(shade, dtype=np.float32)[:, None]
    return np.clip(rgb, 0.0, 1.0).astype(np.float32)


def _view_rotation(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """4x4 rotation: roll about z, then pitch about x, then yaw about y (degrees)."""
    rz = trimesh.transformations.rotation_matrix(np.radians(roll), [0, 0, 1])
    rx = trimesh.transformations.rotation_matrix(np.radians(pitch), [1, 0, 0])
    ry = trimesh.transformations.rotation_matrix(np.radians(yaw), [0, 1, 0])
    return ry @ rx @ rz


def _sample_view(rng: np.random.Generator, max_jitter: dict) -> dict:
    return {key: float(rng.uniform(-limit, limit)) for key, limit in max_jitter.items()} | {
        "shift_y_px": float(rng.uniform(-1, 1) * max_jitter.get("shift_px", 0.0))
    }


def _view_window(object_class: ObjectClass, size: tuple[int, int], view: dict) -> OrthographicView:
    x_min, x_max, y_min, y_max = object_class.frame
    width, height = size
    pixel_size = max((x_max - x_min) / width, (y_max - y_min) / height)
    center = (
        0.5 * (x_min + x_max) - view["shift_px"] * pixel_size,
        0.5 * (y_min + y_max) + view["shift_y_px"] * pixel_size,
    )
    return OrthographicView(center=center, pixel_size=pixel_size, size=(width, height))


def _interpolate_canonical(
    mesh: trimesh.Trimesh, vertex_values: np.ndarray, faces: np.ndarray, points: np.ndarray
) -> np.ndarray:
    barycentric = trimesh.triangles.points_to_barycentric(mesh.triangles[faces], points)
    corners = vertex_values[mesh.faces[faces]]  # (N, 3 corners, 3 values)
    return np.einsum("nk,nkc->nc", barycentric, corners).astype(np.float32)


def posed_instance(object_class: ObjectClass, index: int, seed: int = 0) -> tuple:
    """Instance ``index``'s parameters, view, assembly, pose and posed mesh.

    One random sequence per instance (parameters first, then the view), so the
    rendered instance and its textured mesh are the same object.
    """
    rng = instance_rng(object_class.name, index, seed)
    params = object_class.sample_params(rng)
    view = _sample_view(rng, object_class.max_jitter)
    assembly = object_class.build(params)
    pose = _view_rotation(view["yaw"], view["pitch"], view["roll"])
    mesh = assembly.mesh.copy()
    mesh.apply_transform(pose)
    return params, view, assembly, pose, mesh


def colour_surface(
    object_class: ObjectClass, params, assembly, pose, mesh, faces, points
) -> tuple[np.ndarray, np.ndarray]:
    """Part labels and unlit colours of surface points (posed) on the given faces."""
    canonical = _interpolate_canonical(mesh, assembly.vertex_canonical, faces, points)
    surface = SurfaceHits(
        component=assembly.face_component[faces],
        component_names=assembly.component_names,
        canonical=canonical,
        points=trimesh.transform_points(points, np.linalg.inv(pose)).astype(np.float32),
    )
    return object_class.colorize(params, surface)


def make_instance(
    object_class: ObjectClass,
    index: int,
    seed: int = 0,
    size: tuple[int, int] | None = None,
    keep_mesh: bool = False,
) -> Instance:
    """Sample, build and render instance ``index`` of a class.

    Parameters
    ----------
    object_class : ObjectClass
        E.g. ``data_gen.CLASSES["fish"]``.
    index : int
        Instance number (its name is ``f"{class}_{index:03d}"``).
    seed : int, optional
        Run seed; with ``index`` and the class name it fixes the instance exactly.
    size : (int, int), optional
        (width, height); the class default if None.
    keep_mesh : bool, optional
        Keep the posed trimesh in the result (for inspection and tests).

    Returns
    -------
    Instance

    Example
    -------
    >>> from data_gen import CLASSES
    >>> fish = make_instance(CLASSES["fish"], 0, seed=1, size=(80, 60))
    >>> fish.depth.shape, fish.image.shape, int(fish.labels.max()) <= len(CLASSES["fish"].parts)
    ((60, 80), (60, 80, 3), True)
    """
    size = tuple(size) if size is not None else object_class.default_size
    params, view, assembly, pose, mesh = posed_instance(object_class, index, seed)
    window = _view_window(object_class, size, view)
    hits = cast_orthographic(mesh, window)
    hit_labels, hit_rgb = colour_surface(
        object_class, params, assembly, pose, mesh, hits.faces, hits.points
    )

    width, height = size
    z_far, z_near = object_class.depth_range
    depth = np.zeros((height, width), dtype=np.float32)
    scaled = 0.1 + 0.9 * (hits.z.flat[hits.pixels] - z_far) / (z_near - z_far)
    depth.flat[hits.pixels] = np.clip(scaled, DEPTH_FLOOR, 1.0)
    image = np.zeros((height, width, 3), dtype=np.float32)
    image.reshape(-1, 3)[hits.pixels] = hit_rgb
    labels = np.zeros((height, width), dtype=np.uint8)
    labels.flat[hits.pixels] = hit_labels

    name = f"{object_class.name}_{index:03d}"
    record = {
        "name": name,
        "class": object_class.name,
        "seed": int(seed),
        "index": int(index),
        "size": [int(width), int(height)],
        "parts": {str(i + 1): part for i, part in enumerate(object_class.parts)},
        "depth_units": {
            "world_z_far_at_0.1": z_far,
            "world_z_near_at_1.0": z_near,
            "pixel_size": window.pixel_size,
        },
        "view": view,
        "faces": int(len(mesh.faces)),
        **params,
    }
    maps = instance_maps(object_class.parts, image, depth, labels)
    return Instance(
        name, depth, image, labels, _jsonable(record), mesh if keep_mesh else None, maps
    )


def _jsonable(value):
    """Numpy scalars and arrays inside dicts/lists to plain Python for json."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return round(float(value), 6)
    if isinstance(value, float):
        return round(value, 6)
    return value
