"""The cross-device paper's Table 2 on procedural ground-truth materials.

For every material: render the full BTF (``size`` x ``size``, 33 lights x 9 views,
RGB; :mod:`data_gen.materials`), compress it (k = 100) as the reference S'; cut
the ``sample_size`` x ``sample_size`` input region out of the *uncompressed*
matrix and compress it on its own (so nothing of the rest leaks into the
input); simulate four scans of the full sample (its own rows at the top view,
light theta 22 deg, azimuths 0/90/180/270, through the Table 1 device response
with a lamp colour and noise); then time each method and measure its relative
error against S' from the factors alone.

Methods: ``tiling`` (the sample repeated), the paper's four pixel-wise settings,
``texture_optimization`` (the engine), and any method plugged in through
``extra_methods`` (e.g. ``moving_average``: see :func:`default_extra_methods`).

Example
-------
>>> rows = run_experiment("table2/", materials=["leather"], size=128)  # doctest: +SKIP
"""

from __future__ import annotations

import csv
import importlib
import logging
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from imagemap.btf.constraints import scanner_response
from imagemap.btf.core import BTF, compress, relative_error
from imagemap.btf.extrapolate import (
    CONSTRAINT_AZIMUTHS,
    CONSTRAINT_THETA,
    ExtrapolationParams,
    TextureOptimizationParams,
    constraint_images,
    pixelwise,
    prepare_scans,
    texture_optimization,
    tile,
)
from imagemap.io import InputError, atomic_path, write_image

__all__ = [
    "PIXELWISE_SETTINGS",
    "ExperimentParams",
    "default_extra_methods",
    "run_material",
    "run_experiment",
    "format_table",
]

log = logging.getLogger("imagemap")

#: The paper's four pixel-wise trials (Table 2): name -> (R, ws, wc).
PIXELWISE_SETTINGS = {
    "pixelwise_R0_ws0_wc1": (0, 0.0, 1.0),
    "pixelwise_R0_ws1_wc0": (0, 1.0, 0.0),
    "pixelwise_R1_ws1_wc10": (1, 1.0, 10.0),
    "pixelwise_R2_ws1_wc10": (2, 1.0, 10.0),
}

#: A method hook: (sample BTF, output shape (H, W), seed) -> BTF sharing the sample's U.
ExtraMethod = Callable[[BTF, tuple[int, int], int], BTF]


@dataclass(frozen=True)
class ExperimentParams:
    """Sizes, compression and scanner simulation of the experiment.

    Parameters
    ----------
    size : int
        Side of the full sample (the paper: 512).
    sample_size : int
        Side of the measured cut-out (the paper: 128).
    sample_origin : (int, int) or None
        Top-left corner of the cut-out; None centres it.
    k : int
        Components kept (the paper: 100).
    scanner_gain : 3 floats
        Colour and brightness of the scanner lamp relative to the BTF dome.
    scanner_noise : float
        Standard deviation of the scanner noise in scan units.
    search : {"approximate", "exact", "pynndescent"}
        Nearest-neighbour search of the pixel-wise method.
    texture : TextureOptimizationParams
    comparison_light : (theta, phi)
        Light of the rendered comparison images (top view).
    seed : int
    """

    size: int = 512
    sample_size: int = 128
    sample_origin: tuple[int, int] | None = None
    k: int = 100
    scanner_gain: tuple[float, float, float] = (1.25, 1.1, 0.9)
    scanner_noise: float = 0.003
    search: str = "approximate"
    texture: TextureOptimizationParams = field(default_factory=TextureOptimizationParams)
    comparison_light: tuple[float, float] = (60.0, 45.0)
    seed: int = 0


def default_extra_methods() -> dict[str, ExtraMethod]:
    """Methods other modules offer: ``moving_average`` if
    ``imagemap.btf.moving_average.experiment_method(sample, shape, seed)`` exists."""
    methods: dict[str, ExtraMethod] = {}
    try:
        module = importlib.import_module("imagemap.btf.moving_average")
    except ImportError:
        return methods
    hook = getattr(module, "experiment_method", None)
    if callable(hook):
        methods["moving_average"] = hook
    return methods


def _scan_rows(
    matrix: np.ndarray, light_dirs: np.ndarray, view_dirs: np.ndarray, shape
) -> list[np.ndarray]:
    """The full sample's own images at the top view, light theta 22, four azimuths."""
    from imagemap.btf.core import directions_to_vectors

    lights = directions_to_vectors(light_dirs)
    view = int(np.argmax(directions_to_vectors(view_dirs)[:, 2]))
    images = []
    for phi in CONSTRAINT_AZIMUTHS:
        target = directions_to_vectors(np.array([[CONSTRAINT_THETA, phi]]))[0]
        light = int(np.argmax(lights @ target))
        start = (light * len(view_dirs) + view) * 3
        images.append(np.moveaxis(matrix[start : start + 3].reshape(3, *shape), 0, 2).copy())
    return images


def _display(image: np.ndarray) -> np.ndarray:
    """Linear radiance to a viewable image (gamma 2.2)."""
    return np.clip(image, 0.0, 1.0) ** (1 / 2.2)


def run_material(
    name: str,
    params: ExperimentParams = ExperimentParams(),
    *,
    methods: Sequence[str] | None = None,
    extra_methods: Mapping[str, ExtraMethod] | None = None,
    quiet: bool = True,
) -> tuple[list[dict], dict[str, np.ndarray]]:
    """Run every method on one procedural material.

    Returns
    -------
    rows : list of dict
        material, method, rel_error_pct, seconds.
    renders : dict
        method -> (H, W, 3) linear image at ``comparison_light`` (plus "reference").
    """
    from data_gen.materials import default_sampling, make_material, render_btf_matrix

    if params.sample_size > params.size:
        raise InputError(f"sample_size {params.sample_size} exceeds size {params.size}")
    extra_methods = dict(extra_methods or {})
    all_methods = ["tiling", *PIXELWISE_SETTINGS, "texture_optimization", *extra_methods]
    methods = list(methods) if methods else all_methods
    unknown = [m for m in methods if m not in all_methods]
    if unknown:
        raise InputError(f"methods: unknown {unknown}; choose from {all_methods}")

    started = time.perf_counter()
    lights, views = default_sampling()
    shape = (params.size, params.size)
    material = make_material(name, size=params.size, seed=params.seed)
    matrix = render_btf_matrix(material, lights, views)
    reference = compress(matrix, shape=shape, light_dirs=lights, view_dirs=views, k=params.k)
    s = params.sample_size
    top, left = params.sample_origin or ((params.size - s) // 2, (params.size - s) // 2)
    columns = (np.arange(top, top + s)[:, None] * params.size + np.arange(left, left + s)).ravel()
    sample = compress(
        matrix[:, columns], shape=(s, s), light_dirs=lights, view_dirs=views, k=params.k
    )
    truth = _scan_rows(matrix, lights, views, shape)
    del matrix
    scans = [
        scanner_response(
            image, gain=params.scanner_gain, noise=params.scanner_noise, seed=params.seed + i
        )
        for i, image in enumerate(truth)
    ]
    log.info("%s: ground truth and compression %.1f s", name, time.perf_counter() - started)

    sample_images = constraint_images(sample)
    light = reference.nearest_light(*params.comparison_light)
    view = reference.nearest_view(0.0, 0.0)
    renders = {"reference": reference.image(light, view)}
    rows = []
    for method in methods:
        t0 = time.perf_counter()
        if method == "tiling":
            result = tile(sample, shape)
        elif method in PIXELWISE_SETTINGS:
            radius, ws, wc = PIXELWISE_SETTINGS[method]
            target_images = prepare_scans(scans, sample_images)
            pw = ExtrapolationParams(radius, ws, wc, search=params.search, seed=params.seed)
            result, _ = pixelwise(sample, sample_images, target_images, pw)
        elif method == "texture_optimization":
            target_images = prepare_scans(scans, sample_images)
            result, _ = texture_optimization(
                sample, sample_images, target_images, params.texture, quiet=quiet
            )
        else:
            result = extra_methods[method](sample, shape, params.seed)
        seconds = time.perf_counter() - t0
        error = relative_error(reference, result)
        rows.append(
            {"material": name, "method": method, "rel_error_pct": error, "seconds": seconds}
        )
        renders[method] = result.image(light, view)
        log.info("%s %-24s %6.2f %%  %7.2f s", name, method, error, seconds)
    return rows, renders


def format_table(rows: Sequence[dict]) -> str:
    """Markdown table: one row per method, a (error %, seconds) column pair per material."""
    materials = list(dict.fromkeys(r["material"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    cell = {(r["material"], r["method"]): r for r in rows}
    header = "| method | " + " | ".join(f"{m} error % | {m} s" for m in materials) + " |"
    rule = "|---|" + "---:|---:|" * len(materials)
    lines = [header, rule]
    for method in methods:
        parts = []
        for material in materials:
            r = cell.get((material, method))
            parts += [f"{r['rel_error_pct']:.2f}", f"{r['seconds']:.2f}"] if r else ["", ""]
        lines.append(f"| {method} | " + " | ".join(parts) + " |")
    return "\n".join(lines)


def _comparison(renders: dict[str, np.ndarray]) -> np.ndarray:
    """Panels left to right, top to bottom in the order of ``renders`` (4 per row)."""
    panels = [_display(img) for img in renders.values()]
    height, width = panels[0].shape[:2]
    gap = 4
    per_row = 4
    n_rows = -(-len(panels) // per_row)
    canvas = np.ones(
        (n_rows * (height + gap) - gap, per_row * (width + gap) - gap, 3), dtype=np.float32
    )
    for i, panel in enumerate(panels):
        y, x = (i // per_row) * (height + gap), (i % per_row) * (width + gap)
        canvas[y : y + height, x : x + width] = panel
    return canvas


def run_experiment(
    out: str | os.PathLike,
    *,
    materials: Sequence[str] = ("cloth", "leather", "wallpaper", "wood"),
    params: ExperimentParams = ExperimentParams(),
    methods: Sequence[str] | None = None,
    extra_methods: Mapping[str, ExtraMethod] | None = None,
    quiet: bool = True,
) -> list[dict]:
    """Run :func:`run_material` for each material; write table2.csv, table2.md, PNGs.

    Writes ``out/table2.csv`` (material, method, rel_error_pct, seconds),
    ``out/table2.md`` and ``out/<material>_comparison.png`` (reference, then each
    method, rendered at ``params.comparison_light`` from the top view).

    Returns
    -------
    rows : list of dict
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if extra_methods is None:
        extra_methods = default_extra_methods()
    if params.search == "pynndescent":
        _warm_up_pynndescent(params.seed)
    rows: list[dict] = []
    total = time.perf_counter()
    for name in materials:
        material_rows, renders = run_material(
            name, params, methods=methods, extra_methods=extra_methods, quiet=quiet
        )
        rows += material_rows
        write_image(out / f"{name}_comparison.png", _comparison(renders))
        _write_csv(out / "table2.csv", rows)
    seconds = time.perf_counter() - total
    order = " | ".join(["reference", *[r["method"] for r in rows if r["material"] == materials[0]]])
    text = (
        f"# Table 2 on procedural materials\n\n"
        f"{params.size}x{params.size} full sample, {params.sample_size}x{params.sample_size} "
        f"cut-out, k = {params.k}, 33 lights x 9 views x RGB; relative error (%) against the "
        f"full sample's own compression, and seconds per method. Whole run: {seconds:.0f} s.\n\n"
        f"{format_table(rows)}\n\n"
        f"Comparison images (`<material>_comparison.png`), left to right, top to bottom: "
        f"{order}; light theta {params.comparison_light[0]:g}, phi "
        f"{params.comparison_light[1]:g}, top view.\n"
    )
    with atomic_path(out / "table2.md") as tmp:
        tmp.write_text(text)
    return rows


def _warm_up_pynndescent(seed: int) -> None:
    """Compile pynndescent's numba code once, so that no method's time includes it."""
    from imagemap.search import PynndescentIndex

    rng = np.random.default_rng(seed)
    for dims in (14, 126):
        data = rng.random((500, dims), dtype=np.float32)
        PynndescentIndex(data, seed=seed).query(data[:50])


def _write_csv(path: Path, rows: Sequence[dict]) -> None:
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as handle:
        writer = csv.DictWriter(
            handle, fieldnames=["material", "method", "rel_error_pct", "seconds"]
        )
        writer.writeheader()
        for r in rows:
            writer.writerow(
                {
                    **r,
                    "rel_error_pct": f"{r['rel_error_pct']:.4f}",
                    "seconds": f"{r['seconds']:.3f}",
                }
            )
