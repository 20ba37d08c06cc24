"""Issue #46: ``imagemap batch`` (local and Dask) writes the bytes ``imagemap synthesize``
writes with the same options: PBR maps, alpha mode, cut-off and sides, units, the
height map beside the mesh, the input's material name and roughness."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from data_gen import CLASSES
from data_gen.core import make_instance
from data_gen.dataset import write_instance
from imagemap.batch import BatchOptions, plan_jobs, run_batch
from imagemap.cli import main
from imagemap.io import write_image
from imagemap.scene import export_textured, load_mesh

SIZE = (40, 30)
#: The same options on both command lines (``--units cm``: issue #46 saw it ignored).
SHARED = ["--preset", "fish", "--size", "40x30", "--texture-size", "64", "--views", "front,back"]
SHARED += ["--units", "cm", "-q"]
#: The PBR maps of the database's examples (data_gen's instances carry all four).
KINDS = ("normal", "roughness", "height", "ao")


def fin_mesh(name: str = "FinSkin"):
    """An ellipsoid of 480 faces (a fish's body, in centimetres) with UVs, its 64 px
    texture's left third cut away by alpha: an artist's alpha-masked, double-sided
    material (cut-off 0.4, roughness 0.35, named ``name``)."""
    import trimesh
    from PIL import Image
    from trimesh.visual.material import PBRMaterial

    lon, lat = np.meshgrid(np.linspace(0, 2 * np.pi, 25), np.linspace(-1.3, 1.3, 11))
    vertices = np.stack(
        [30 * np.cos(lat) * np.cos(lon), 12 * np.sin(lat), 8 * np.cos(lat) * np.sin(lon)], -1
    ).reshape(-1, 3)
    uv = np.stack([lon / (2 * np.pi), (lat + 1.3) / 2.6], -1).reshape(-1, 2)
    grid = np.arange(11 * 25).reshape(11, 25)
    a, b, c, d = grid[:-1, :-1], grid[:-1, 1:], grid[1:, :-1], grid[1:, 1:]
    faces = np.concatenate([np.stack([a, c, b], -1), np.stack([b, c, d], -1)]).reshape(-1, 3)
    rows = np.linspace(0, 1, 64)[:, None, None]
    rgba = np.concatenate([np.broadcast_to(rows * [0.9, 0.5, 0.2], (64, 64, 3)),
                           np.ones((64, 64, 1))], axis=2)  # fmt: skip
    rgba[:, : 64 // 3, 3] = 0.0  # the cut-away third (u < 1/3)
    material = PBRMaterial(
        baseColorTexture=Image.fromarray(np.round(rgba * 255).astype(np.uint8), "RGBA"),
        alphaMode="MASK",
        alphaCutoff=0.4,
        doubleSided=True,
        roughnessFactor=0.35,
        name=name,
    )
    visual = trimesh.visual.TextureVisuals(uv=uv, material=material)
    mesh = trimesh.Trimesh(vertices, faces, visual=visual, process=False)
    outward = np.einsum("ij,ij->i", mesh.face_normals, mesh.triangles_center) > 0
    assert outward.all()  # the winding the renderer culls by
    return mesh


@pytest.fixture(scope="module")
def routes(tmp_path_factory):
    """A database of 3 fish pictures with normal, roughness, height and ao maps; queries:
    one depth map and one alpha-masked mesh; the outputs of ``imagemap synthesize`` (one
    call per query) and of ``imagemap batch`` (one local worker) with the same options."""
    root = tmp_path_factory.mktemp("routes")
    previous = os.environ.get("IMAGEMAP_CACHE")
    os.environ["IMAGEMAP_CACHE"] = str(root / "cache")
    db, queries, single, batch = (root / n for n in ("db", "queries", "single", "batch"))
    for index in range(3):
        write_instance(make_instance(CLASSES["fish"], index, seed=0, size=SIZE), db)
    depth = make_instance(CLASSES["fish"], 3, seed=0, size=SIZE).depth
    write_image(queries / "fish_003_depth.png", depth, bits=16)
    export_textured(fin_mesh(), queries / "fin.glb")
    single.mkdir()
    for query, output, options in (
        ("fish_003_depth.png", "fish_003_image.png", ["--preset", "fish", "-q"]),  # no mesh's
        ("fin.glb", "fin.glb", SHARED),
    ):
        command = ["synthesize", str(queries / query), "--db", str(db), "-o", str(single / output)]
        assert main([*command, *options]) == 0
    assert main(["batch", str(queries), "--db", str(db), "-o", str(batch), *SHARED]) == 0
    yield root
    if previous is None:
        os.environ.pop("IMAGEMAP_CACHE", None)
    else:
        os.environ["IMAGEMAP_CACHE"] = previous


def outputs(folder: Path) -> dict[str, bytes]:
    """Every file an output folder holds (batch bookkeeping aside), by the name ``imagemap
    batch`` gives it: a single depth map's ``NAME_image_KIND.png`` is the batch's
    ``NAME_KIND.png`` (as ``imagemap synthesize A B -o DIR`` names them)."""
    found = {}
    for path in sorted(folder.iterdir()):
        if path.is_file() and path.name != "batch_report.json":
            found[path.name.replace("_image_", "_")] = path.read_bytes()
    return found


def test_batch_writes_the_bytes_of_synthesize(routes):
    """Issue #46: the batch wrote depth maps without PBR maps, meshes with a base colour
    only (roughness 0.6), alpha-masked meshes OPAQUE and single-sided, and ignored
    --units. Every file of both routes is compared, byte for byte."""
    single, batch = outputs(routes / "single"), outputs(routes / "batch")
    maps = [f"fish_003_{kind}.png" for kind in KINDS]
    assert sorted(batch) == sorted(["fin.glb", "fin_height.png", "fish_003_image.png", *maps])
    assert sorted(single) == sorted(batch)
    differ = [name for name in batch if single[name] != batch[name]]
    assert differ == []


def test_the_masked_mesh_keeps_what_its_artist_set(routes):
    """The alpha-masked mesh through the batch: MASK at 0.4, double-sided, its material's
    name, an RGBA texture with the cut-away third transparent, the examples' normal,
    roughness and ao maps, in metres from centimetres, and its height map beside it
    (16-bit grey, not a constant)."""
    from PIL import Image

    from imagemap.scene.files import material_of

    made = load_mesh(routes / "batch" / "fin.glb")
    settings = material_of(made)
    assert (settings.alpha_mode, settings.alpha_cutoff, settings.double_sided) == (
        "MASK",
        pytest.approx(0.4),
        True,
    )
    assert settings.name == "FinSkin"
    material = made.visual.material
    assert material.baseColorTexture.mode == "RGBA"
    assert material.normalTexture is not None and material.occlusionTexture is not None
    assert material.metallicRoughnessTexture is not None and material.roughnessFactor == 1.0
    # The cut-away third of the surface is transparent in the new texture too: each
    # face's centre, found in both textures (the same faces in the same order).
    source = load_mesh(routes / "queries" / "fin.glb")
    assert len(made.faces) == len(source.faces)
    alpha = np.asarray(material.baseColorTexture.getchannel("A"), np.float32) / 255
    centre = np.asarray(made.visual.uv)[made.faces].mean(axis=1)
    size = alpha.shape[0]
    cols = np.clip((centre[:, 0] * size).astype(int), 0, size - 1)
    rows = np.clip(((1 - centre[:, 1]) * size).astype(int), 0, size - 1)
    first = np.asarray(source.visual.uv)[source.faces].mean(axis=1)[:, 0]
    cut, kept = first < 0.25, first > 0.45  # well inside the cut third, and the rest
    assert cut.sum() > 50 and kept.sum() > 200
    assert alpha[rows[cut], cols[cut]].max() < 0.4 < alpha[rows[kept], cols[kept]].min()
    extent = np.ptp(np.asarray(made.vertices), axis=0)
    assert extent == pytest.approx(np.ptp(np.asarray(source.vertices), axis=0) * 0.01)
    height = Image.open(routes / "batch" / "fin_height.png")
    assert height.mode.startswith("I") and height.size == (64, 64)
    values = np.asarray(height)
    assert values.max() > 256 and len(np.unique(values)) > 256  # 16 bits used


def test_dask_writes_the_bytes_of_the_local_batch(routes, tmp_path):
    """A Dask LocalCluster (threads) writes the same bytes as the local batch."""
    distributed = pytest.importorskip("distributed", reason="dask[distributed] not installed")
    from imagemap.scene.views import parse_view

    options = BatchOptions(
        preset="fish",
        size=SIZE,
        texture_size=64,
        views=(parse_view("front"), parse_view("back")),
        scale=0.01,
    )
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        address = cluster.scheduler_address
        summary = run_batch(routes / "queries", routes / "db", tmp_path, options, scheduler=address)
    assert (summary.done, summary.failed) == (2, 0)
    dask, local = outputs(tmp_path), outputs(routes / "batch")
    assert sorted(dask) == sorted(local)
    assert [name for name in local if dask[name] != local[name]] == []


def test_a_bad_unit_stops_the_batch_before_any_work(routes, tmp_path, capsys):
    out = tmp_path / "out"
    command = ["batch", str(routes / "queries"), "--db", str(routes / "db"), "-o", str(out)]
    assert main([*command, "--units", "furlong", "-q"]) != 0
    assert "--units" in capsys.readouterr().err
    assert not out.exists() or not any(out.iterdir())


def test_the_input_roughness_map_is_kept_where_the_examples_have_none():
    """An input whose roughness is a texture keeps it (sampled onto the new atlas) when no
    example gives one; its factor alone would flatten it to one value."""
    from PIL import Image

    from imagemap.scene.files import textured_mesh
    from imagemap.scene.surface import keep_surface

    source = fin_mesh()
    ramp = np.broadcast_to(np.linspace(0, 1, 64)[None, :, None], (64, 64, 3))
    packed = np.round(ramp * 255).astype(np.uint8)
    source.visual.material.metallicRoughnessTexture = Image.fromarray(packed, "RGB")
    source.visual.material.roughnessFactor = 0.5
    plain = textured_mesh(
        source.vertices, source.faces, source.visual.uv, np.full((32, 32, 3), 0.5)
    )
    kept = keep_surface(plain, source)
    material = kept.visual.material
    assert material.roughnessFactor == 1.0 and material.name == "FinSkin"
    rough = np.asarray(material.metallicRoughnessTexture, np.float32)[..., 1] / 255
    # The same UVs: the new 32 px texture's columns hold half the ramp (factor 0.5).
    assert rough.shape == (32, 32)
    middle = rough[16, 4:28]
    expected = 0.5 * (np.arange(4, 28) + 0.5) / 32
    assert middle == pytest.approx(expected, abs=0.03)


def _with_maps(source: Path, target: Path) -> None:
    """``source``'s textured mesh written to ``target`` with a normal map (leaning
    along +u in its top half) and a roughness ramp in its material."""
    from PIL import Image

    mesh = load_mesh(source)
    size = 64
    normal = np.zeros((size, size, 3), np.uint8)
    normal[...] = (128, 128, 255)
    normal[: size // 2] = (204, 128, 230)
    packed = np.zeros((size, size, 3), np.uint8)
    packed[..., 1] = np.linspace(40, 220, size).astype(np.uint8)[None, :]
    mesh.visual.material.normalTexture = Image.fromarray(normal, "RGB")
    mesh.visual.material.metallicRoughnessTexture = Image.fromarray(packed, "RGB")
    mesh.visual.material.roughnessFactor = 1.0
    export_textured(mesh, target)


@pytest.mark.parametrize(
    "path",
    [
        "views auto",
        "uv-space",
        pytest.param("registered", marks=pytest.mark.slow),  # 7 s per command
        pytest.param("views of mesh examples", marks=pytest.mark.slow),
        pytest.param("default size", marks=pytest.mark.slow),
    ],
)
def test_the_other_mesh_paths_give_the_same_bytes(path, routes, shared_heads, tmp_path):
    """``--views auto`` (each mesh chooses among the six candidates the batch prepared),
    the uv-space path (the batch ships its mesh examples' meshes), the registered path
    (a head with normal and roughness maps registered onto the fin: the maps carried, a
    TANGENT written), the views path from a mesh example (copied again at the texels'
    resolution: the batch renders the example at that size) and no ``--size`` (views as
    fine as the texels, each mesh its own, issue #46 item 2: the fin at 256² asks for
    317x238): the batch's GLB is the single command's, byte for byte, and the path is the
    one asked for."""
    import shutil

    queries, db = tmp_path / "queries", tmp_path / "db"
    queries.mkdir()
    db.mkdir()
    if path == "uv-space":  # two heads in one UV layout: one the example, one the query
        shutil.copy(shared_heads / "head_00.glb", db)
        shutil.copy(shared_heads / "head_01.glb", queries / "query.glb")
        options = ["--preset", "busts", "--texture-size", "64", "--uv-space", "-q"]
    elif path == "registered":  # a head in its own layout, the fin in another
        _with_maps(shared_heads / "head_00.glb", db / "head_00.glb")
        shutil.copy(routes / "queries" / "fin.glb", queries / "query.glb")
        options = ["--preset", "busts", "--texture-size", "64", "-q"]
    elif path == "views of mesh examples":  # copied again at 2x (#46 item 2): the batch
        # renders the example, and its normal and roughness maps, at the fine size from
        # the mesh it ships
        _with_maps(shared_heads / "head_00.glb", db / "head_00.glb")
        shutil.copy(routes / "queries" / "fin.glb", queries / "query.glb")
        options = ["--preset", "busts", "--size", "40x30", "--texture-size", "64", "-q"]
        options += ["--views", "front,back", "--no-register"]
    elif path == "default size":
        shutil.copytree(routes / "db", db, dirs_exist_ok=True)
        shutil.copy(routes / "queries" / "fin.glb", queries / "query.glb")
        options = ["--preset", "fish", "--texture-size", "256", "--views", "front,back", "-q"]
    else:
        shutil.copytree(routes / "db", db, dirs_exist_ok=True)
        shutil.copy(routes / "queries" / "fin.glb", queries / "query.glb")
        options = ["--preset", "fish", "--size", "40x30", "--texture-size", "64", "-q"]
        options += ["--views", "auto"]
    single = tmp_path / "single" / "query.glb"
    command = ["synthesize", str(queries / "query.glb"), "--db", str(db), "-o", str(single)]
    assert main([*command, *options, "--report", str(tmp_path / "report.json")]) == 0
    batch = tmp_path / "batch"
    assert main(["batch", str(queries), "--db", str(db), "-o", str(batch), *options]) == 0
    made = outputs(batch)
    assert "query.glb" in made
    assert outputs(single.parent) == made  # every file, byte for byte
    report = json.loads((tmp_path / "report.json").read_text())
    if path == "uv-space":
        assert report["path"] == "uv-space" and report["views"] == []
    elif path == "views of mesh examples":
        from tests.test_glb import glb_json

        material = glb_json(batch / "query.glb")["materials"][0]
        assert "normalTexture" in material
    elif path == "registered":
        from tests.test_glb import glb_json

        assert report["path"] == "registered" and report["views"] == []
        gltf = glb_json(batch / "query.glb")
        material = gltf["materials"][0]
        assert "normalTexture" in material
        assert "metallicRoughnessTexture" in material["pbrMetallicRoughness"]
        assert "TANGENT" in gltf["meshes"][0]["primitives"][0]["attributes"]
    elif path == "views of mesh examples":
        from imagemap.mesh.fineviews import fine_factor

        assert report["path"] == "views" and len(report["views"]) == 2
        assert fine_factor(load_mesh(queries / "query.glb"), ["front"], (40, 30), 64) > 1
    elif path == "default size":
        assert report["path"] == "views" and len(report["views"]) == 2
        assert tuple(report["size"]) == (317, 238)
    else:  # the fin is seen by some of the six, not all
        assert report["path"] == "views" and 1 < len(report["views"]) < 6


def test_batch_chooses_each_meshs_views_as_synthesize_does(tmp_path):
    """Issue #46 item 2: without ``--size`` both commands make a mesh's views as fine as
    its texels (the fin at 256²: 317x238, the cap); the batch kept 200x150, so its
    bytes differed from the single command's."""
    from imagemap.batch.run import _view_size
    from imagemap.cli import build_parser
    from imagemap.scene.bake import view_size_for
    from imagemap.scene.views import parse_view

    parser = build_parser()
    for command in (["batch", "IN"], ["synthesize", "q.glb"]):
        args = parser.parse_args([*command, "--db", "DB", "-o", "OUT"])
        assert args.size is None  # each mesh's own
    (tmp_path / "in").mkdir()
    export_textured(fin_mesh(), tmp_path / "in" / "fin.glb")
    views = (parse_view("front"), parse_view("back"))
    options = BatchOptions(preset="fish", texture_size=256, views=views)
    (job,) = plan_jobs(tmp_path / "in", tmp_path / "out", options)
    single = view_size_for(load_mesh(tmp_path / "in" / "fin.glb"), list(views), 256)
    assert _view_size(job, options) == single == (317, 238)
    fixed = BatchOptions(preset="fish", size=SIZE, texture_size=256, views=views)
    assert _view_size(job, fixed) == SIZE
