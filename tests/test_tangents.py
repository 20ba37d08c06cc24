"""glTF TANGENT in the MikkTSpace convention (issue #46 item 4): known answers, the
vertices a file needs, and the normal map baked in the frames the file states.
(Blender's own tangents on our files: tests/test_blender.py.)"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from imagemap.mesh.maps import _to_tangent_space
from imagemap.scene import project_texture, render_mesh
from imagemap.scene.files import export_textured, textured_mesh
from imagemap.scene.surface import frame_mesh, keep_surface
from imagemap.tangents import corner_tangents, mikk_tangents, tangent_frames, tangent_split
from tests.test_glb import glb_accessor, glb_json

#: Float32 in the file against float64 in the bake: the frames agree far better than this.
FRAME_DEGREES = 0.05


def cylinder(rings: int = 6, segments: int = 24, mirrored: bool = False):
    """An open cylinder (radius 1, height 1) with u around it, v along it, outward faces."""
    u, v = np.meshgrid(np.linspace(0, 1, segments + 1), np.linspace(0, 1, rings + 1))
    angle = 2 * np.pi * u.ravel()
    points = np.column_stack([np.cos(angle), np.sin(angle), v.ravel()])
    uv = np.column_stack([1 - u.ravel() if mirrored else u.ravel(), v.ravel()])
    at = np.arange(points.shape[0]).reshape(rings + 1, segments + 1)
    a, b, c, d = at[:-1, :-1], at[:-1, 1:], at[1:, 1:], at[1:, :-1]
    faces = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    normals = points * [1, 1, 0]
    return points, faces, normals, uv


def angle_degrees(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    cosine = np.einsum("ij,ij->i", a, b)
    cosine /= np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1)
    return np.degrees(np.arccos(np.clip(cosine, -1, 1)))


@pytest.mark.parametrize("mirrored", [False, True])
def test_a_cylinders_tangents_run_around_it_and_w_says_which_way(mirrored):
    points, faces, normals, uv = cylinder(mirrored=mirrored)
    tangents = mikk_tangents(points, faces, normals, uv)
    around = np.column_stack([-points[:, 1], points[:, 0], np.zeros(len(points))])
    expected = -around if mirrored else around  # along increasing u
    np.testing.assert_allclose(tangents[:, :3], expected, atol=1e-9)
    # w: the bitangent w n x t runs along increasing v (+z) either way.
    assert set(tangents[:, 3]) == {-1.0 if mirrored else 1.0}
    bitangent = np.cross(normals, tangents[:, :3]) * tangents[:, 3:]
    np.testing.assert_allclose(bitangent, np.tile([0, 0, 1.0], (len(points), 1)), atol=1e-9)


def test_tangents_are_unit_and_perpendicular_to_the_normals():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    uv = sphere.vertices[:, [0, 2]] * [0.3, 0.5] + 0.5  # oblique planar UVs
    tangents = mikk_tangents(sphere.vertices, sphere.faces, sphere.vertex_normals, uv)
    np.testing.assert_allclose(np.linalg.norm(tangents[:, :3], axis=1), 1.0, atol=1e-12)
    dots = np.einsum("ij,ij->i", tangents[:, :3], sphere.vertex_normals)
    assert np.abs(dots).max() < 1e-12
    assert set(np.unique(tangents[:, 3])) <= {-1.0, 1.0}


def test_projection_uvs_split_the_silhouette_and_nothing_else():
    """Projection UVs turn over at the silhouette: there a vertex has a tangent with w
    +1 and one with -1, so the file needs two vertices; elsewhere none is added."""
    sphere = trimesh.creation.icosphere(subdivisions=3)
    uv = sphere.vertices[:, :2] / 2 + 0.5  # seen from +z: the back is mirrored
    faces, origin = tangent_split(sphere.faces, uv)
    area_sign = np.sign(sphere.face_normals[:, 2])
    front = np.bincount(sphere.faces[area_sign > 0].ravel(), minlength=len(uv)) > 0
    back = np.bincount(sphere.faces[area_sign < 0].ravel(), minlength=len(uv)) > 0
    assert len(origin) - len(uv) == int((front & back).sum()) > 0
    np.testing.assert_array_equal(origin[faces], sphere.faces)  # the same corners
    # After the split every vertex has one tangent: its corners agree.
    corners = corner_tangents(
        sphere.vertices[origin], faces, sphere.vertex_normals[origin], uv[origin]
    )
    per_vertex = mikk_tangents(
        sphere.vertices[origin], faces, sphere.vertex_normals[origin], uv[origin]
    )
    np.testing.assert_allclose(per_vertex[faces], corners, atol=1e-12)
    # An atlas without folds (the cylinder) is not split.
    points, cylinder_faces, _, cylinder_uv = cylinder()
    assert len(tangent_split(cylinder_faces, cylinder_uv)[1]) == len(points)


def test_the_glb_states_the_tangents_the_normal_map_was_baked_in(tmp_path):
    """The route bakes normals in frame_mesh's MikkTSpace frames; the GLB written from
    keep_surface states TANGENTs whose frames (as a renderer builds them) are the same."""
    source = trimesh.creation.icosphere(subdivisions=3)
    source.apply_scale([1.0, 0.7, 0.5])
    render = render_mesh(source, "30,20", size=(64, 48))
    textured = project_texture(source, render, np.full((48, 64, 3), 0.5))
    pixels = np.flatnonzero(render.mask)
    face = render.face.flat[pixels]
    bary = render.barycentric.reshape(-1, 3)[pixels].astype(np.float64)
    frames = frame_mesh(textured, source)
    normal = tangent_frames(
        corner_tangents(frames.vertices, frames.faces, frames.vertex_normals, frames.visual.uv),
        frames.vertex_normals,
        frames.faces,
        face,
        bary,
    )[2]
    tilt = np.cross(normal, [0.0, 0.0, 1.0]) + np.cross(normal, [1.0, 0.0, 0.0])
    world = normal + 0.4 * tilt  # a bumpy surface's normals, leaning every which way
    world /= np.linalg.norm(world, axis=1, keepdims=True)
    local = _to_tangent_space(world, frames, face, bary)

    flat = np.full((48, 64, 3), [0.5, 0.5, 1.0])
    with_map = textured_mesh(
        textured.vertices, textured.faces, textured.visual.uv, flat[..., :3], maps={"normal": flat}
    )
    path = export_textured(keep_surface(with_map, source), tmp_path / "n.glb")[0]
    attributes = glb_json(path)["meshes"][0]["primitives"][0]["attributes"]
    assert "TANGENT" in attributes and not any(k.startswith("_") for k in attributes)
    tangents = glb_accessor(path, attributes["TANGENT"]).astype(np.float64)
    normals = glb_accessor(path, attributes["NORMAL"]).astype(np.float64)
    file_faces = glb_accessor(path, glb_json(path)["meshes"][0]["primitives"][0]["indices"])
    file_faces = file_faces.reshape(-1, 3).astype(np.int64)
    assert len(tangents) > len(source.vertices)  # split at the silhouette
    np.testing.assert_allclose(np.abs(tangents[:, 3]), 1.0)
    t, b, n = tangent_frames(tangents[file_faces], normals, file_faces, face, bary)
    shaded = local[:, :1] * t + local[:, 1:2] * b + local[:, 2:] * n
    assert angle_degrees(shaded, world).max() < FRAME_DEGREES

    # No normal map, no TANGENT.
    plain = textured_mesh(textured.vertices, textured.faces, textured.visual.uv, flat)
    written = export_textured(plain, tmp_path / "plain.glb")[0]
    assert "TANGENT" not in glb_json(written)["meshes"][0]["primitives"][0]["attributes"]
