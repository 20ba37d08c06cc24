"""Issue #46: the uv-space and registered paths carry the examples' PBR maps, each texel's
read where its colour came from (:func:`imagemap.mesh.maps.atlas_maps`)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import trimesh
from PIL import Image
from trimesh.visual.material import PBRMaterial

from imagemap.materials import decode_normals, encode_normals
from imagemap.mesh.maps import atlas_maps
from imagemap.mesh.register import closest_points
from imagemap.scene.bake import rasterize_uv

#: Atlas side of the known answers (texels).
SIZE = 32
#: 8-bit maps: a carried value is its example's within this (two rounding steps of 1/255).
BYTE = 2.5 / 255
#: A carried normal's components within this of the known answer (8-bit encoding, and
#: MikkTSpace's frames on a flat sheet: exact).
NORMAL_TOLERANCE = 0.02
#: The examples' normals lean 0.6 of the way (about 37 degrees) towards their own +u.
TILT = np.array([0.6, 0.0, 0.8])


def _sheet(uv_of) -> trimesh.Trimesh:
    """A flat square (z = 0, normal +z) of 2 x 8 x 8 faces, UVs ``uv_of(x, y)``."""
    lin = np.linspace(0.0, 1.0, 9)
    x, y = np.meshgrid(lin, lin)
    vertices = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]
    grid = np.arange(81).reshape(9, 9)
    a, b, c, d = grid[:-1, :-1], grid[:-1, 1:], grid[1:, :-1], grid[1:, 1:]
    faces = np.concatenate([np.stack([a, b, d], -1), np.stack([a, d, c], -1)]).reshape(-1, 3)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert np.allclose(mesh.face_normals, [0, 0, 1])
    mesh.visual = trimesh.visual.TextureVisuals(uv=uv_of(vertices[:, 0], vertices[:, 1]))
    return mesh


def _material(normal=None, roughness=None, size: int = 16) -> PBRMaterial:
    """A material with a constant normal (tangent space) and/or roughness map."""
    base = Image.fromarray(np.full((size, size, 3), 128, np.uint8))
    options = {"baseColorTexture": base}
    if normal is not None:
        rgb = np.broadcast_to(encode_normals(np.asarray(normal)), (size, size, 3))
        options["normalTexture"] = Image.fromarray(np.round(rgb * 255).astype(np.uint8))
    if roughness is not None:
        packed = np.zeros((size, size, 3), np.uint8)
        packed[..., 1] = round(roughness * 255)
        options["metallicRoughnessTexture"] = Image.fromarray(packed)
        options["roughnessFactor"] = 1.0
    return PBRMaterial(**options)


def _identity_source(size: int) -> np.ndarray:
    rows, cols = np.indices((size, size), dtype=np.int32)
    return np.stack([np.zeros_like(rows), rows, cols], axis=-1)


def _registered(example: trimesh.Trimesh, query: trimesh.Trimesh, matrix: np.ndarray):
    """A registered example as the registered path hands it over: the example's own face
    and barycentrics at every used texel of the query's atlas (``matrix``: example ->
    query world, a similarity)."""
    texel, face, bary = rasterize_uv(np.asarray(query.visual.uv), query.faces, SIZE)
    points = np.einsum("nk,nkc->nc", bary, query.vertices[query.faces[face]])
    inverse = np.linalg.inv(matrix)
    own = points @ inverse[:3, :3].T + inverse[:3, 3]
    found, weights, _ = closest_points(np.asarray(example.vertices), example.faces, own)
    example_mesh = example
    return SimpleNamespace(
        name="example",
        mesh=query,
        example_mesh=example_mesh,
        texture=np.zeros((SIZE, SIZE, 3), np.uint8),
        registration=SimpleNamespace(matrix=matrix),
        correspondence=(texel, found.astype(np.int32), weights.astype(np.float32)),
    ), texel


@pytest.mark.parametrize("mirrored", [False, True])
def test_registered_normals_turn_with_the_layout(mirrored):
    """The query's UVs are the example's turned by 90 degrees (u along +y, v along -x), so
    the example's lean towards its +u (world +x) is, in the query's tangent frame, a lean
    towards -v: (0, -0.6, 0.8). Mirrored (the example is the query reflected in x, u along
    its own +x, which the registration takes to the query's -x): towards +v. A copy of
    the tangent-space values would give (0.6, 0, 0.8) in both."""
    query = _sheet(lambda x, y: np.c_[y, 1.0 - x])
    if mirrored:
        example = _sheet(lambda x, y: np.c_[1.0 - x, y])  # u along its own +x once mirrored
        example.vertices[:, 0] *= -1.0
        example.faces = example.faces[:, ::-1]  # outwards (+z) again
        matrix = np.diag([-1.0, 1.0, 1.0, 1.0])
        expected = [0.0, 0.6, 0.8]
    else:
        example = _sheet(lambda x, y: np.c_[x, y])
        matrix = np.eye(4)
        expected = [0.0, -0.6, 0.8]
    example.visual.material = _material(normal=TILT, roughness=0.3)
    registered, texel = _registered(example, query, matrix)
    mask = np.zeros((SIZE, SIZE), bool)
    mask.flat[texel] = True
    result = SimpleNamespace(source=_identity_source(SIZE), mask=mask)
    maps = atlas_maps(result, [registered], query)
    assert sorted(maps) == ["normal", "roughness"]
    normals = decode_normals(maps["normal"].reshape(-1, 3)[texel])
    assert np.abs(normals - expected).max() < NORMAL_TOLERANCE
    assert np.abs(maps["roughness"].reshape(-1)[texel] - 0.3).max() < BYTE


def test_uv_space_maps_come_from_the_texels_the_colour_came_from():
    """Two examples in the query's layout: A (roughness 0.2, no normal map) and B
    (roughness 0.8, a constant leaning normal; a 64 px texture over 16 px maps). The left
    half of the atlas copies A, the right half B at other texels: the maps are A's and
    B's there, B's normal as it is (the same layout: the same tangent frames), A's flat."""
    query = _sheet(lambda x, y: np.c_[x, y])
    a = SimpleNamespace(name="a", mesh=_sheet(lambda x, y: np.c_[x, y]),
                        texture=np.zeros((SIZE, SIZE, 3), np.uint8))  # fmt: skip
    b = SimpleNamespace(name="b", mesh=_sheet(lambda x, y: np.c_[x, y]),
                        texture=np.zeros((64, 64, 3), np.uint8))  # fmt: skip
    a.mesh.visual.material = _material(roughness=0.2)
    b.mesh.visual.material = _material(normal=TILT, roughness=0.8)
    source = _identity_source(SIZE)
    right = np.zeros((SIZE, SIZE), bool)
    right[:, SIZE // 2 :] = True
    source[right, 0] = 1
    source[right, 1:] = source[right, 1:] * 2 + 1  # B's own texture is twice the size
    result = SimpleNamespace(source=source, mask=np.ones((SIZE, SIZE), bool))
    maps = atlas_maps(result, [a, b], query)
    rough = maps["roughness"]
    assert np.abs(rough[~right] - 0.2).max() < BYTE
    assert np.abs(rough[right] - 0.8).max() < BYTE
    normals = decode_normals(maps["normal"])
    assert np.abs(normals[right] - TILT).max() < NORMAL_TOLERANCE
    assert np.abs(normals[~right] - [0.0, 0.0, 1.0]).max() < NORMAL_TOLERANCE


def test_no_maps_when_no_example_has_one():
    """Examples with a colour only (the generated fish before their roughness): no map
    is made up."""
    query = _sheet(lambda x, y: np.c_[x, y])
    plain = SimpleNamespace(name="a", mesh=_sheet(lambda x, y: np.c_[x, y]),
                            texture=np.zeros((SIZE, SIZE, 3), np.uint8))  # fmt: skip
    plain.mesh.visual.material = _material()
    result = SimpleNamespace(source=_identity_source(SIZE), mask=np.ones((SIZE, SIZE), bool))
    assert atlas_maps(result, [plain], query) == {}
