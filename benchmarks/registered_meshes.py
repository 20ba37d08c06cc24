"""Meshes in their own UV layouts (#46, item 1): the registered path against the views path
and against a closest-point transfer, judged by renders from many angles.

``fish``: generated fish meshes (``data_gen fish --meshes``; each its own xatlas atlas),
the held-out one textured by the views path (``--views auto``, what the command ran
before), by the registered path, and by the closest-point transfer of the rigidly
registered first-choice example (the baseline: no synthesis). Rendered by the library's
orthographic ray caster (:func:`imagemap.scene.render_textured`, the same geometry for
all, so pixels compare) from 8 angles: both flanks, back, belly, head-on, tail-on and two
three-quarter views. Per angle: mean CIEDE2000 against the truth and crispness (fine-band
energy over the truth's, :func:`imagemap.metrics.fine_energy`); per object: the flank
difference, the mean CIEDE2000 between the front flank and the mirrored back flank (one
palette on both sides: small, as the truth's).

``heads``: the FFHQ-UV heads (``benchmarks/real_meshes.py prepare``), each held out and
given its own xatlas layout, textured from the others (in the HiFi3D++ layout) by the
registered path and by the closest-point transfer; rendered by
:mod:`benchmarks.real_meshes`' own perspective rasterizer from its four angles (none is a
synthesis view: this path has none).

    python benchmarks/registered_meshes.py fish [--data DIR] [--out OUT]
    python benchmarks/registered_meshes.py heads [--data DIR] [--out OUT]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

#: The 8 angles of the fish: flanks (front, back), back (top), belly (bottom), head-on
#: and tail-on (right, left), two three-quarter views.
FISH_ANGLES = ("0,0", "180,0", "0,90", "0,-90", "90,0", "-90,0", "40,25", "-140,25")
#: Render size of the fish pictures (width, height).
FISH_RENDER = (240, 180)
DEFAULT_FISH = ROOT / "scratch" / "registered" / "fish"
DEFAULT_OUT = ROOT / "scratch" / "registered" / "out"


def flank_difference(front: np.ndarray, back: np.ndarray, mask_f, mask_b) -> float:
    """Mean CIEDE2000 between the front flank and the back flank mirrored left-right."""
    from imagemap.metrics import ciede2000

    mirrored, mask_m = back[:, ::-1], mask_b[:, ::-1]
    both = mask_f & mask_m
    return float(ciede2000(front, mirrored, both))


def transfer(query, example_mesh, size: int, mirror: bool, seed: int = 0):
    """The closest-point transfer of the rigidly registered example's texture into the
    query's atlas (the baseline): (texture, residual)."""
    from imagemap.mesh.register import register_rigid, resample

    fit = register_rigid(example_mesh, query, mirror, seed)
    return resample(example_mesh, fit, query, size, seed).colour, fit.residual


def _render(mesh, angle: str):
    from imagemap.scene.views import render_mesh, render_textured

    render = render_mesh(mesh, angle, FISH_RENDER)
    return render_textured(mesh, angle, FISH_RENDER), render.mask


def run_fish(data: Path, out: Path, seed: int = 0) -> dict:
    from imagemap.database import Database
    from imagemap.mesh import colorize_mesh
    from imagemap.mesh.register import registered_examples
    from imagemap.metrics import ciede2000, fine_energy
    from imagemap.scene import load_mesh, render_textured, textured_mesh
    from imagemap.scene.coverage import choose_views
    from imagemap.scene.views import texture_image

    if not (data / "holdout" / "meshes").is_dir():
        from data_gen.dataset import write_class

        write_class("fish", data, count=9, seed=0, holdout=1, meshes=True, quiet=True)
    out.mkdir(parents=True, exist_ok=True)
    truth = load_mesh(data / "holdout" / "meshes" / "fish_008.glb")
    database = Database.from_directory(data / "meshes")
    made, seconds = {}, {}
    start = time.perf_counter()
    views = choose_views(truth)
    made["views"] = colorize_mesh(truth, database, views, preset="fish", seed=seed,
                                  registered=False).mesh  # fmt: skip
    seconds["views"] = time.perf_counter() - start
    start = time.perf_counter()
    result = colorize_mesh(truth, database, preset="fish", seed=seed)
    seconds["registered"] = time.perf_counter() - start
    made["registered"] = result.mesh
    meshes = {n: load_mesh(data / "meshes" / f"{n}.glb") for n in database.names}
    size = texture_image(truth).shape[0]
    _, residuals = registered_examples(truth, meshes, m=1, texture_size=64, seed=seed)
    first = min(residuals, key=lambda n: residuals[n])
    colour, _ = transfer(truth, meshes[first], size, mirror=True, seed=seed)
    made["transfer"] = textured_mesh(truth.vertices, truth.faces, truth.visual.uv, colour)
    report: dict = {"seconds": seconds, "first_choice": first,
                    "examples": result.example_names, "angles": {}}  # fmt: skip
    renders = {"truth": {a: _render(truth, a) for a in FISH_ANGLES}}
    for name, mesh in made.items():
        renders[name] = {a: _render(mesh, a) for a in FISH_ANGLES}
    for angle in FISH_ANGLES:
        truth_image, mask = renders["truth"][angle]
        row = {}
        for name in made:
            image = renders[name][angle][0]
            reference = fine_energy(truth_image, mask)
            row[name] = {"de00": ciede2000(image, truth_image, mask),
                         "crisp": fine_energy(image, mask) / reference}  # fmt: skip
        report["angles"][angle] = row
    report["flank_difference"] = {
        name: flank_difference(r["0,0"][0], r["180,0"][0], r["0,0"][1], r["180,0"][1])
        for name, r in renders.items()
    }
    report["mean"] = {
        name: {k: float(np.mean([report["angles"][a][name][k] for a in FISH_ANGLES]))
               for k in ("de00", "crisp")}
        for name in made
    }  # fmt: skip
    columns = ["truth", "views", "registered", "transfer"]
    rows = [
        np.concatenate(
            [render_textured(truth if c == "truth" else made[c], a, FISH_RENDER, shaded=True)
             for c in columns], axis=1)
        for a in FISH_ANGLES
    ]  # fmt: skip
    import imagemap

    imagemap.write_image(out / "fish_8_angles.png", np.concatenate(rows, axis=0))
    (out / "fish.json").write_text(json.dumps(report, indent=1))
    return report


def run_heads(data: Path, out: Path, seed: int = 0) -> dict:
    import trimesh
    from real_meshes import EVAL_VIEWS, RENDER_SIZE, TexturedArrays, image_errors, look_at, render

    from imagemap.database import Database
    from imagemap.mesh import colorize_mesh
    from imagemap.mesh.register import registered_examples
    from imagemap.scene import load_mesh
    from imagemap.scene.bake import uv_atlas
    from imagemap.scene.files import export_textured, textured_mesh

    out.mkdir(parents=True, exist_ok=True)
    files = sorted(data.glob("*.glb"))
    names = [p.stem for p in files]
    report: dict = {"objects": {}}
    pictures = []
    for name in names:
        truth_path = data / f"{name}.glb"
        truth = TexturedArrays.load(truth_path)
        mesh = load_mesh(truth_path)
        bare = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
        bare.merge_vertices()  # its own layout: xatlas on the welded surface
        vertices, faces, uv, _ = uv_atlas(bare)
        query = trimesh.Trimesh(vertices, faces, visual=trimesh.visual.TextureVisuals(uv=uv),
                                process=False)  # fmt: skip
        database = Database.from_directory(data).without(name)
        start = time.perf_counter()
        made = colorize_mesh(query, database, preset="busts", seed=seed)
        seconds = time.perf_counter() - start
        size = made.image.shape[0]
        meshes = {n: load_mesh(data / f"{n}.glb") for n in names if n != name}
        _, residuals = registered_examples(query, meshes, m=1, texture_size=64, seed=seed)
        first = min(residuals, key=lambda n: residuals[n])
        colour, _ = transfer(query, meshes[first], size, mirror=False, seed=seed)
        paths = {}
        for label, texture in (("registered", made.image), ("transfer", colour)):
            paths[label] = out / f"{name}_{label}.glb"
            export_textured(textured_mesh(vertices, faces, uv, texture), paths[label])
        arrays = {label: TexturedArrays.load(p) for label, p in paths.items()}
        centre, radius = truth.bounding_sphere()
        rows = []
        for azimuth, elevation in EVAL_VIEWS:
            camera = look_at(azimuth, elevation, centre, radius, RENDER_SIZE)
            truth_image, mask = render(truth, camera)
            row = {"view": f"{azimuth:g},{elevation:g}"}
            cells = [truth_image]
            for label, arr in arrays.items():
                image, own = render(arr, camera)
                row[label] = image_errors(image, truth_image, mask & own)
                cells.append(image)
            rows.append(row)
            pictures.append(np.concatenate(cells, axis=1))
        report["objects"][name] = {"seconds": seconds, "examples": made.example_names,
                                   "first_choice": first, "residuals": residuals,
                                   "views": rows}  # fmt: skip
        print(name, json.dumps(report["objects"][name], default=float), flush=True)
    import imagemap

    imagemap.write_image(out / "heads.png", np.concatenate(pictures, axis=0))
    (out / "heads.json").write_text(json.dumps(report, indent=1, default=float))
    return report


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("what", choices=("fish", "heads"))
    parser.add_argument("--data", type=Path)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    if args.what == "fish":
        report = run_fish(args.data or DEFAULT_FISH, args.out)
    else:
        report = run_heads(args.data or ROOT / "scratch" / "realdata" / "faces", args.out)
    print(json.dumps({k: v for k, v in report.items() if k != "objects"}, indent=1,
                     default=float))  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
