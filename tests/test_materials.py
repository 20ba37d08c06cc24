"""The hard procedural BTF materials: parallax, hidden layers, ambiguous scans, seeds."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from imagemap.btf.experiment import MATERIAL_SOURCES
from imagemap.btf.materials import EASY_MATERIALS, HARD_MATERIALS, Material, make_material
from imagemap.btf.rendering import default_sampling, render_btf_matrix, view_hits

LIGHTS, VIEWS = default_sampling()


def _scan_images(matrix: np.ndarray, size: int) -> list[np.ndarray]:
    """The four flatbed-scan images (top view, light theta 22, phi 0/90/180/270)."""
    images = []
    for phi in (0.0, 90.0, 180.0, 270.0):
        gap = np.abs(LIGHTS[:, 0] - 22.0) + np.abs((LIGHTS[:, 1] - phi + 180.0) % 360.0 - 180.0)
        row = int(np.argmin(gap)) * len(VIEWS) * 3  # view 0 is the top view
        images.append(np.moveaxis(matrix[row : row + 3].reshape(3, size, size), 0, 2))
    return images


def _scan_rows(n_views: int = len(VIEWS)) -> np.ndarray:
    rows = []
    for phi in (0.0, 90.0, 180.0, 270.0):
        gap = np.abs(LIGHTS[:, 0] - 22.0) + np.abs((LIGHTS[:, 1] - phi + 180.0) % 360.0 - 180.0)
        rows += [int(np.argmin(gap)) * n_views * 3 + c for c in range(3)]
    return np.array(rows)


def test_view_rays_shift_a_raised_mark_by_height_times_tan_theta():
    # A plateau 6 texels above the reference plane carrying a bright mark: a view
    # from theta 60 at phi 0 sees it 6 tan(60) = 10.4 texels towards -x.
    size, margin = 48, 16
    full = size + 2 * margin
    height = np.zeros((full, full), np.float32)
    height[20:60, 20:60] = 6.0
    albedo = np.full((full, full, 3), 0.2, np.float32)
    albedo[38:42, 42:46] = 1.0  # mark centred at x = 43.5 - margin = 27.5
    flat = np.zeros((full, full), np.float32)
    material = Material(height, albedo, flat, flat + 1, "plateau", margin=margin, parallax=True)
    views = np.array([[0.0, 0.0], [60.0, 0.0], [30.0, 90.0]], np.float32)
    image = render_btf_matrix(material, np.array([[0.0, 0.0]], np.float32), views)
    image = image.reshape(3, 3, size, size)[:, 0]  # views x (size, size), red channel
    xs = np.arange(size)
    centres = [float((img > 0.5).sum(axis=0) @ xs / (img > 0.5).sum()) for img in image]
    rows = [float((img > 0.5).sum(axis=1) @ xs / (img > 0.5).sum()) for img in image]
    assert centres[0] == pytest.approx(27.5, abs=0.1)
    assert centres[1] - centres[0] == pytest.approx(-6.0 * np.tan(np.deg2rad(60.0)), abs=0.5)
    assert rows[2] - rows[0] == pytest.approx(-6.0 * np.tan(np.deg2rad(30.0)), abs=0.5)
    # Self-occlusion: seen from +x at 60 deg, the plateau (left wall at x = 20)
    # hides the floor for 6 tan(60) = 10.4 texels before it. Along a row through the
    # plateau, no texel shows floor in (9.6, 20); the reference texel x = 18 shows
    # the plateau's top at 18 + 10.4.
    _, x = view_hits(height, 60.0, 0.0, 0)  # the whole grid, margin included
    row = x[46]  # crosses the plateau
    floor = row[row < 20.0 - 1e-3]
    assert floor.size > 5 and not np.any((floor > 9.6 + 0.5) & (floor < 19.5))
    assert float(row[18]) == pytest.approx(18 + 6.0 * np.tan(np.deg2rad(60.0)), abs=0.05)


@pytest.mark.parametrize("name", ["velvet", "lacquered_leather"])
def test_hidden_layer_changes_the_btf_but_not_the_scans(name):
    size = 32
    material = make_material(name, size=size, seed=2)
    bare = make_material(name, size=size, seed=2)
    if name == "velvet":
        bare.fibres = np.zeros_like(bare.fibres)
    else:
        bare.varnish = np.zeros_like(bare.varnish)
    with_layer = render_btf_matrix(material, LIGHTS, VIEWS)
    without = render_btf_matrix(bare, LIGHTS, VIEWS)
    scans = _scan_rows()
    # The flatbed scans cannot tell them apart (below the simulated scanner noise) ..
    assert np.abs(with_layer[scans] - without[scans]).max() < 3e-3
    # .. the BTF can.
    change = np.linalg.norm(with_layer - without) / np.linalg.norm(with_layer)
    assert change > 0.1, change


def _close_pair_btf_differences(name: str, size: int = 40) -> np.ndarray:
    """For texels whose nearest scan-colour neighbour is within 2 %, the BTF difference."""
    matrix = render_btf_matrix(make_material(name, size=size, seed=1), LIGHTS, VIEWS)
    scans = np.concatenate(_scan_images(matrix, size), axis=2).reshape(-1, 12)
    distance, index = cKDTree(scans).query(scans, k=2)
    close = distance[:, 1] / np.linalg.norm(scans, axis=1) < 0.02
    texels = matrix.T
    diff = np.linalg.norm(texels - texels[index[:, 1]], axis=1) / np.linalg.norm(texels, axis=1)
    return diff[close]


def test_hard_materials_scan_alike_where_their_btfs_differ():
    easy = _close_pair_btf_differences("leather")
    for name in ("lacquered_leather", "velvet"):
        hard = _close_pair_btf_differences(name)
        assert len(hard) > 50
        # Near-equal scan constraints, BTFs a quarter apart: ambiguous by construction.
        assert hard.max() > 0.25, (name, hard.max())
        assert np.median(hard) > 2.5 * np.median(easy), (name, np.median(hard), np.median(easy))


def test_same_seed_same_bytes_and_every_material_registered():
    assert set(MATERIAL_SOURCES) >= set(EASY_MATERIALS) | set(HARD_MATERIALS)
    lights, views = LIGHTS[::8], VIEWS[::4]
    a = render_btf_matrix(make_material("cobbles", size=24, seed=5), lights, views)
    b = render_btf_matrix(make_material("cobbles", size=24, seed=5), lights, views)
    c = render_btf_matrix(make_material("cobbles", size=24, seed=6), lights, views)
    assert a.tobytes() == b.tobytes()
    assert not np.array_equal(a, c)
    matrix, source_lights, source_views = MATERIAL_SOURCES["velvet"](16, 0)
    assert matrix.shape == (len(source_lights) * len(source_views) * 3, 16 * 16)


def test_imagemap_never_imports_data_gen():
    """data_gen uses imagemap, never the reverse: ``btf experiment`` finds its materials in
    imagemap.btf.materials (it imported data_gen.materials to register them)."""
    import ast
    from pathlib import Path

    import imagemap

    offenders = []
    for path in Path(imagemap.__file__).parent.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module or ""]
            else:
                continue
            offenders += [f"{path.name}: {n}" for n in names if n.split(".")[0] == "data_gen"]
    assert not offenders, offenders
    assert set(MATERIAL_SOURCES) >= set(EASY_MATERIALS) | set(HARD_MATERIALS)
