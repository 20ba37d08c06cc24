"""Textured meshes that import as intended (issue #34): material fields, normals, alpha, units."""

from __future__ import annotations

import json
import os
import shutil
import struct
import subprocess

import numpy as np
import pytest
import trimesh

from imagemap.io import InputError
from imagemap.scene import project_texture, render_mesh
from imagemap.scene.files import (
    DEFAULT_ROUGHNESS,
    SurfaceMaterial,
    corner_normals,
    export_textured,
    load_mesh,
    material_of,
    textured_mesh,
    unit_scale,
)
from imagemap.scene.surface import keep_surface


def glb_json(path) -> dict:
    """The JSON chunk of a GLB file (read by hand, not through trimesh)."""
    data = open(path, "rb").read()
    assert data[:4] == b"glTF"
    length, kind = struct.unpack("<II", data[12:20])
    assert kind == 0x4E4F534A  # "JSON"
    return json.loads(data[20 : 20 + length])


def glb_accessor(path, index: int) -> np.ndarray:
    """Accessor ``index`` of a GLB as an array (float32 VEC2/VEC3 or scalar indices)."""
    data = open(path, "rb").read()
    tree = glb_json(path)
    json_length = struct.unpack("<I", data[12:16])[0]
    binary = data[20 + json_length + 8 :]
    accessor = tree["accessors"][index]
    view = tree["bufferViews"][accessor["bufferView"]]
    dtype = {5126: np.float32, 5125: np.uint32, 5123: np.uint16}[accessor["componentType"]]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[accessor["type"]]
    start = view.get("byteOffset", 0) + accessor.get("byteOffset", 0)
    values = np.frombuffer(binary, dtype=dtype, count=accessor["count"] * width, offset=start)
    return values.reshape(accessor["count"], width)


def sphere_with_texture(alpha_mode=None, **material) -> trimesh.Trimesh:
    """An icosphere with planar UVs, an RGBA texture whose left half has alpha 0."""
    from PIL import Image
    from trimesh.visual.material import PBRMaterial

    sphere = trimesh.creation.icosphere(subdivisions=3)
    uv = (sphere.vertices[:, :2] + 1.0) / 2.0
    rgba = np.zeros((32, 32, 4), np.uint8)
    rgba[..., :3] = (200, 120, 90)
    rgba[:, 16:, 3] = 255  # u >= 0.5 opaque, u < 0.5 transparent
    texture = PBRMaterial(
        baseColorTexture=Image.fromarray(rgba, "RGBA"), alphaMode=alpha_mode, **material
    )
    sphere.visual = trimesh.visual.TextureVisuals(uv=uv, material=texture)
    return sphere


def test_material_states_a_dielectric_and_a_roughness_and_normals_are_written(tmp_path):
    """glTF's metallicFactor defaults to 1 (metal): ours must be written, 0, with a roughness."""
    box = trimesh.creation.box()
    mesh = textured_mesh(box.vertices, box.faces, box.vertices[:, :2] + 0.5, np.ones((8, 8, 3)))
    path = export_textured(mesh, tmp_path / "box.glb")[0]
    tree = glb_json(path)
    pbr = tree["materials"][0]["pbrMetallicRoughness"]
    assert pbr["metallicFactor"] == 0.0
    assert pbr["roughnessFactor"] == pytest.approx(DEFAULT_ROUGHNESS)
    attributes = tree["meshes"][0]["primitives"][0]["attributes"]
    assert "NORMAL" in attributes
    normals = glb_accessor(path, attributes["NORMAL"])
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-5)
    loaded = trimesh.load(path, force="mesh")
    assert loaded.visual.material.metallicFactor == 0.0


def test_pbr_maps_become_normal_and_metallic_roughness_textures(tmp_path):
    box = trimesh.creation.box()
    roughness = np.linspace(0, 1, 64).reshape(8, 8)
    mesh = textured_mesh(
        box.vertices,
        box.faces,
        box.vertices[:, :2] + 0.5,
        np.ones((8, 8, 3)),
        maps={"roughness": roughness, "normal": np.full((8, 8, 3), [0.5, 0.5, 1.0])},
    )
    path = export_textured(mesh, tmp_path / "box.glb")[0]
    material = glb_json(path)["materials"][0]
    pbr = material["pbrMetallicRoughness"]
    assert "normalTexture" in material and "metallicRoughnessTexture" in pbr
    # The roughness is in the texture (factor 1); metallic stays 0 with no metallic map.
    assert pbr["roughnessFactor"] == 1.0 and pbr["metallicFactor"] == 0.0
    loaded = trimesh.load(path, force="mesh")
    packed = np.asarray(loaded.visual.material.metallicRoughnessTexture.convert("RGB"))
    np.testing.assert_allclose(packed[..., 1] / 255.0, roughness, atol=0.5 / 255 + 1e-6)


def test_corner_normals_keep_a_box_flat_and_a_sphere_round():
    box = trimesh.creation.box()
    normals = corner_normals(box.vertices, box.faces)
    np.testing.assert_allclose(normals, np.repeat(box.face_normals[:, None], 3, axis=1), atol=1e-9)
    sphere = trimesh.creation.icosphere(subdivisions=3)
    normals = corner_normals(sphere.vertices, sphere.faces)
    radial = (
        sphere.vertices[sphere.faces]
        / np.linalg.norm(sphere.vertices[sphere.faces], axis=2)[..., None]
    )
    assert np.einsum("fkc,fkc->fk", normals, radial).min() > 0.999


def test_smooth_normals_ignore_uv_seams():
    """A sphere cut along a UV seam (duplicated vertices) gets the same normal on both sides."""
    sphere = trimesh.creation.icosphere(subdivisions=2)
    faces = sphere.faces.copy()
    vertices = np.concatenate([sphere.vertices, sphere.vertices])
    right = sphere.vertices[faces].mean(axis=1)[:, 0] > 0
    faces[right] += len(sphere.vertices)  # the right half uses its own copies
    mesh = textured_mesh(vertices, faces, vertices[:, :2] * 0.5 + 0.5, np.ones((4, 4, 3)))
    used = np.unique(faces)
    radial = vertices[used] / np.linalg.norm(vertices[used], axis=1, keepdims=True)
    assert np.einsum("ij,ij->i", mesh.vertex_normals[used], radial).min() > 0.99


def test_the_inputs_own_normals_alpha_mode_and_sides_are_kept(tmp_path):
    source = sphere_with_texture(alpha_mode="MASK", alphaCutoff=0.3, doubleSided=True)
    # Normals of the file, deliberately not the smooth ones: all tilted towards +x.
    odd = source.vertex_normals + [0.8, 0.0, 0.0]
    source.vertex_normals = odd / np.linalg.norm(odd, axis=1, keepdims=True)
    source.export(tmp_path / "source.glb")
    source = load_mesh(tmp_path / "source.glb")
    assert source.metadata["file_normals"]
    assert material_of(source) == SurfaceMaterial(
        alpha_mode="MASK", alpha_cutoff=0.3, double_sided=True
    )
    render = render_mesh(source, "front", size=(64, 64))
    synthesized = project_texture(source, render, np.full((64, 64, 3), 0.5, np.float32))
    kept = keep_surface(synthesized, source)
    path = export_textured(kept, tmp_path / "kept.glb")[0]
    tree = glb_json(path)
    material = tree["materials"][0]
    assert material["alphaMode"] == "MASK"
    assert material["alphaCutoff"] == pytest.approx(0.3)
    assert material["doubleSided"] is True
    assert material["pbrMetallicRoughness"]["metallicFactor"] == 0.0
    loaded = load_mesh(path)
    assert loaded.metadata["file_normals"]
    # Face by face, every corner has the source's normal.
    corners_out = np.asarray(loaded.vertex_normals)[loaded.faces]
    corners_in = np.asarray(source.vertex_normals)[source.faces]
    np.testing.assert_allclose(corners_out, corners_in, atol=2e-3)
    # Alpha: the texture's alpha at each face centre's UV is the source's there.
    from imagemap.scene.views import sample_image

    centre = np.full((len(loaded.faces), 3), 1 / 3)
    uv_out = np.einsum("fk,fkc->fc", centre, loaded.visual.uv[loaded.faces])
    alpha_out = np.asarray(loaded.visual.material.baseColorTexture.getchannel("A"), np.float32)
    alpha_out = sample_image(alpha_out[..., None] / 255.0, uv_out)[:, 0]
    uv_in = np.einsum("fk,fkc->fc", centre, source.visual.uv[source.faces])
    clear = uv_in[:, 0] < 0.45
    solid = uv_in[:, 0] > 0.55
    assert clear.sum() > 100 and solid.sum() > 100
    assert alpha_out[clear].max() < 0.05
    assert alpha_out[solid].min() > 0.95


def test_an_opaque_input_stays_opaque_and_single_sided(tmp_path):
    source = trimesh.creation.icosphere(subdivisions=2)
    render = render_mesh(source, "front", size=(32, 32))
    kept = keep_surface(project_texture(source, render, np.full((32, 32, 3), 0.5)), source)
    material = glb_json(export_textured(kept, tmp_path / "k.glb")[0])["materials"][0]
    assert material["alphaMode"] == "OPAQUE" and material["doubleSided"] is False
    assert "alphaCutoff" not in material
    assert kept.visual.material.baseColorTexture.mode == "RGB"


def test_units_scale_the_coordinates_and_are_stated(tmp_path):
    box = trimesh.creation.box(extents=(200.0, 100.0, 50.0))  # modelled in millimetres
    mesh = textured_mesh(box.vertices, box.faces, np.zeros((8, 2)), np.ones((4, 4, 3)))
    path = export_textured(mesh, tmp_path / "mm.glb", scale=unit_scale("mm"))[0]
    tree = glb_json(path)
    position = glb_accessor(path, tree["meshes"][0]["primitives"][0]["attributes"]["POSITION"])
    np.testing.assert_allclose(np.ptp(position, axis=0), [0.2, 0.1, 0.05], rtol=1e-6)
    assert tree["asset"]["extras"]["imagemap"]["scale_to_metres"] == 0.001
    with pytest.raises(InputError, match="--units and --scale"):
        unit_scale("mm", 0.001)
    with pytest.raises(InputError, match="--units: 'furlong'"):
        unit_scale("furlong")
    with pytest.raises(InputError, match="--scale: must be a positive"):
        unit_scale(scale=-1.0)


def _validator() -> list[str] | None:
    """A command running the Khronos glTF validator (npm gltf-validator), or None."""
    node = shutil.which("node")
    folder = os.environ.get("IMAGEMAP_GLTF_VALIDATOR")  # a folder with node_modules/
    if node is None or not folder:
        return None
    script = (
        "const v=require('gltf-validator'),fs=require('fs');"
        "v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[1])))"
        ".then(r=>console.log(JSON.stringify(r.issues)))"
    )
    return [node, "-e", script], folder


def test_khronos_validator_finds_no_error(tmp_path):
    found = _validator()
    if found is None:
        pytest.skip(
            "set IMAGEMAP_GLTF_VALIDATOR to a folder where 'npm install gltf-validator' ran"
        )
    command, folder = found
    source = sphere_with_texture(alpha_mode="MASK", alphaCutoff=0.5)
    render = render_mesh(source, "front", size=(32, 32))
    kept = keep_surface(project_texture(source, render, np.full((32, 32, 3), 0.5)), source)
    path = export_textured(kept, tmp_path / "v.glb")[0]
    out = subprocess.run(
        [*command, str(path)], cwd=folder, capture_output=True, text=True, check=True
    )
    issues = json.loads(out.stdout)
    assert issues["numErrors"] == 0, issues["messages"][:5]
    # With a normal map (issue #46 item 4): TANGENT written, so no warning that the
    # viewer must make its own tangent space (MESH_PRIMITIVE_GENERATED_TANGENT_SPACE).
    flat = np.full((32, 32, 3), [0.5, 0.5, 1.0])
    mapped = textured_mesh(kept.vertices, kept.faces, kept.visual.uv, flat, maps={"normal": flat})
    path = export_textured(keep_surface(mapped, source), tmp_path / "n.glb")[0]
    out = subprocess.run(
        [*command, str(path)], cwd=folder, capture_output=True, text=True, check=True
    )
    issues = json.loads(out.stdout)
    assert issues["numErrors"] == issues["numWarnings"] == 0, issues["messages"][:5]
