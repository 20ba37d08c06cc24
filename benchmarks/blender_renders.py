"""Textured GLBs rendered by Blender, side by side (#46, item 7): the truth beside ours.

Run with a Python that has Blender's module (``pip install bpy`` in its own environment:
bpy's wheel wants Python 3.11 and numpy < 2), headless::

    /path/to/bpy/python benchmarks/blender_renders.py --out grid.png \\
        --angles "0,0 40,25 -140,25" truth.glb ours.glb transfer.glb

Each GLB is imported by Blender's own glTF importer into an empty scene and rendered with
Cycles on the CPU (:data:`SAMPLES` samples, denoised when Blender has OpenImageDenoise),
"Standard" view transform (the texture's colours, not a film look), a grey sky, a sun over
the camera's shoulder and an orthographic camera. Angles are the library's
(:class:`imagemap.scene.View`: azimuth about +y from +z, elevation towards +y, in the
glTF's frame; the importer turns glTF's +y up into Blender's +z). Every GLB of a row is
framed by the FIRST GLB's extent seen from that angle, so that meshes of one geometry line
up. The grid: rows are the angles, columns the GLBs, in the order given, on white.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

#: Cycles samples per pixel: with the denoiser, enough for a matte textured object.
SAMPLES = 24
#: Picture size of each cell (width, height).
CELL = (320, 240)
#: The object's extent (as the first GLB has it) fills this share of the picture.
FILL = 0.92


def _clear() -> None:
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)


def _import(path: Path) -> list:
    import bpy

    bpy.ops.import_scene.gltf(filepath=str(path))
    return [o for o in bpy.context.scene.objects if o.type == "MESH"]


def _points(objects) -> np.ndarray:
    """Every vertex of the objects in Blender's world (N, 3)."""
    points = []
    for obj in objects:
        matrix = np.array(obj.matrix_world)
        co = np.empty(len(obj.data.vertices) * 3)
        obj.data.vertices.foreach_get("co", co)
        points.append(co.reshape(-1, 3) @ matrix[:3, :3].T + matrix[:3, 3])
    return np.concatenate(points)


def _direction(azimuth: float, elevation: float) -> np.ndarray:
    """Towards the camera, in Blender's frame (glTF (x, y, z) is Blender's (x, -z, y))."""
    az, el = math.radians(azimuth), math.radians(elevation)
    gltf = np.array([math.sin(az) * math.cos(el), math.sin(el), math.cos(az) * math.cos(el)])
    return np.array([gltf[0], -gltf[2], gltf[1]])


def _basis(towards: np.ndarray, elevation: float) -> tuple[np.ndarray, np.ndarray]:
    """(right, up) of a camera looking along ``-towards`` with the world's up (+z) up."""
    up = np.array([0.0, 0.0, 1.0]) if abs(elevation) < 89.0 else np.array([0.0, 1.0, 0.0])
    right = np.cross(-towards, up)
    right /= np.linalg.norm(right)
    return right, np.cross(right, -towards)


def _stage(points: np.ndarray, azimuth: float, elevation: float) -> None:
    """An orthographic camera framing ``points`` from one angle, a sun and a sky."""
    import bpy
    from mathutils import Matrix, Vector

    scene = bpy.context.scene
    for obj in [o for o in scene.objects if o.type in ("CAMERA", "LIGHT")]:
        bpy.data.objects.remove(obj, do_unlink=True)
    towards = _direction(azimuth, elevation)
    right, up = _basis(towards, elevation)
    centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
    radius = float(np.linalg.norm(points - centre, axis=1).max())
    across, along = (points - centre) @ right, (points - centre) @ up
    middle = (
        centre
        + right * 0.5 * (across.max() + across.min())
        + up * 0.5 * (along.max() + along.min())
    )
    width, height = np.ptp(across), np.ptp(along)
    aspect = CELL[0] / CELL[1]
    camera_data = bpy.data.cameras.new("camera")
    camera_data.type = "ORTHO"
    camera_data.sensor_fit = "HORIZONTAL"
    camera_data.ortho_scale = max(width, height * aspect) / FILL
    camera_data.clip_start, camera_data.clip_end = radius * 0.01, radius * 10.0
    camera = bpy.data.objects.new("camera", camera_data)
    scene.collection.objects.link(camera)
    camera.location = Vector(middle + towards * 4.0 * radius)
    camera.rotation_euler = Matrix((right, up, towards)).transposed().to_euler()
    scene.camera = camera
    # The sun over the camera's right shoulder, from a little above.
    sun_data = bpy.data.lights.new("sun", "SUN")
    sun_data.energy = 3.0
    sun = bpy.data.objects.new("sun", sun_data)
    scene.collection.objects.link(sun)
    light_from = towards + 0.5 * right + 0.6 * up
    sun.rotation_euler = Vector(-light_from).normalized().to_track_quat("-Z", "Y").to_euler()


def _settings() -> None:
    import bpy

    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = SAMPLES
    import _cycles  # Blender's own module: what this build of Cycles has

    scene.cycles.use_denoising = bool(getattr(_cycles, "with_openimagedenoise", False))
    scene.render.resolution_x, scene.render.resolution_y = CELL
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = True
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGBA"
    scene.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("sky")
    world.use_nodes = True
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (0.55, 0.55, 0.55, 1.0)
    background.inputs["Strength"].default_value = 1.0
    scene.world = world


def _read(path: Path) -> np.ndarray:
    """An RGBA PNG as float (H, W, 4), top row first."""
    import bpy

    image = bpy.data.images.load(str(path))
    pixels = np.array(image.pixels[:], dtype=np.float32).reshape(image.size[1], image.size[0], 4)
    bpy.data.images.remove(image)
    return pixels[::-1]


def render_grid(glbs: list[Path], angles: list[tuple[float, float]], out: Path) -> np.ndarray:
    """Render every GLB from every angle; write the grid (rows: angles) to ``out``."""
    import bpy

    cells = out.with_suffix("")
    cells.mkdir(parents=True, exist_ok=True)
    frame = None
    rows: list[list[np.ndarray]] = [[] for _ in angles]
    for k, glb in enumerate(glbs):
        _clear()
        _settings()
        objects = _import(glb)
        if not objects:
            raise SystemExit(f"{glb}: no mesh imported")
        if frame is None:
            frame = _points(objects)
        for i, (azimuth, elevation) in enumerate(angles):
            _stage(frame, azimuth, elevation)
            path = cells / f"{k}_{glb.stem}_{azimuth:g}_{elevation:g}.png"
            bpy.context.scene.render.filepath = str(path)
            bpy.ops.render.render(write_still=True)
            rgba = _read(path)
            # On white: the sRGB values over a white background by their alpha.
            rows[i].append(rgba[..., :3] * rgba[..., 3:] + (1.0 - rgba[..., 3:]))
    grid = np.concatenate([np.concatenate(r, axis=1) for r in rows], axis=0)
    _write(grid, out)
    return grid


def _write(grid: np.ndarray, out: Path) -> None:
    """The grid as an 8-bit PNG, through Blender's image writer."""
    import bpy

    height, width = grid.shape[:2]
    image = bpy.data.images.new("grid", width, height, alpha=True)
    rgba = np.concatenate([grid, np.ones((height, width, 1), np.float32)], axis=2)
    image.pixels[:] = np.clip(rgba[::-1], 0.0, 1.0).ravel()
    image.filepath_raw = str(out)
    image.file_format = "PNG"
    image.save()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("glbs", nargs="+", type=Path, help="truth first (it sets the framing)")
    parser.add_argument("--angles", required=True, help='"AZ,EL AZ,EL ..." (degrees)')
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    angles = [(float(a.split(",")[0]), float(a.split(",")[1])) for a in args.angles.split()]
    for glb in args.glbs:
        if not glb.is_file():
            raise SystemExit(f"{glb}: no such file")
    render_grid(args.glbs, angles, args.out)
    print(f"wrote {args.out} ({len(angles)} angles x {len(args.glbs)} meshes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
