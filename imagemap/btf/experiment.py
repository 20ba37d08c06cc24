"""The cross-device paper's Table 2 on procedural ground-truth materials.

One module for one job: one experiment, from its material sources to its table and pictures.

For every material: render the full BTF (``size`` x ``size``, e.g. 33 lights x 9
views, RGB) through its *material source*, compress it (k = 100) as the reference
S'; cut
the ``sample_size`` x ``sample_size`` input region out of the *uncompressed*
matrix and compress it on its own (so nothing of the rest leaks into the
input); simulate four scans of the full sample (its own rows at the top view,
light theta 22 deg, azimuths 0/90/180/270, through the Table 1 device response
with a lamp colour and noise); then time each method and measure its relative
error against S' from the factors alone.

Methods: ``tiling`` (the sample repeated), the paper's four pixel-wise settings,
``texture_optimization`` (the engine, the paper's R = 8), two probes that are not in
the paper (:data:`TUNED_TEXTURE`, texture optimization with small windows, and
:data:`PIXELWISE_MEAN_SETTINGS`, the mean of the 16 nearest texels), and any method
plugged in through ``extra_methods`` (``moving_average`` by default: see
:func:`default_extra_methods`).

Material sources: a source is a callable ``(size, seed) -> (S, light_dirs,
view_dirs)`` giving the ground-truth BTF matrix (rows light x view x RGB, columns
the size x size texels). The procedural materials of :mod:`imagemap.btf.materials`
(cloth, leather, wallpaper, wood, velvet, lacquered_leather, cobbles) are known by
name; pass ``sources={name: source}`` for others, or :func:`register_material` them.

Example
-------
>>> sorted(MATERIAL_SOURCES)[:3]
['cloth', 'cobbles', 'lacquered_leather']
>>> rows = run_experiment("table2/", materials=["leather"])  # doctest: +SKIP
"""

from __future__ import annotations

import csv
import dataclasses
import logging
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from imagemap.btf.constraints import scanner_response
from imagemap.btf.core import BTF, compress, directions_to_vectors, relative_error
from imagemap.btf.extrapolate import (
    _OLD_SEARCH_NAMES,
    CONSTRAINT_AZIMUTHS,
    CONSTRAINT_THETA,
    PixelwiseParams,
    TextureOptimizationParams,
    constraint_images,
    pixelwise,
    prepare_scans,
    texture_optimization,
    tile,
)
from imagemap.btf.materials import MATERIALS
from imagemap.btf.rendering import ground_truth
from imagemap.io import InputError, atomic_path, write_image
from imagemap.outputs import check_output_directory

__all__ = [
    "PIXELWISE_MEAN_SETTINGS",
    "PIXELWISE_SETTINGS",
    "TUNED_TEXTURE",
    "MATERIAL_SOURCES",
    "ExperimentParams",
    "GroundTruth",
    "MaterialSource",
    "comparison_picture",
    "prepare_material",
    "register_material",
    "run_methods",
    "default_extra_methods",
    "run_material",
    "run_experiment",
    "format_table",
    "method_names",
]

log = logging.getLogger("imagemap")

#: The paper's four pixel-wise trials (Table 2), then R = 1 and 2 on colour only (not in
#: the paper: separates the neighbourhood's effect from the descriptors'):
#: name -> (R, ws, wc).
PIXELWISE_SETTINGS = {
    "pixelwise_R0_ws0_wc1": (0, 0.0, 1.0),
    "pixelwise_R0_ws1_wc0": (0, 1.0, 0.0),
    "pixelwise_R1_ws1_wc10": (1, 1.0, 10.0),
    "pixelwise_R2_ws1_wc10": (2, 1.0, 10.0),
    "pixelwise_R1_ws0_wc1": (1, 0.0, 1.0),
    "pixelwise_R2_ws0_wc1": (2, 0.0, 1.0),
}

#: Not in the paper: R = 1 pixel-wise with the mean of the 16 nearest texels' rows, a
#: probe of how much of a method's score comes from averaging candidates.
PIXELWISE_MEAN_SETTINGS = {"pixelwise_R1_ws1_wc10_mean16": (1, 1.0, 10.0, 16)}

#: Not in the paper: texture optimization with the settings that did best in our
#: study (small windows, every window matched; README, BTF section).
TUNED_TEXTURE: dict[str, dict[str, Any]] = {
    "texture_optimization_R2_stride1": {"radius": 2, "stride": 1}
}

#: A method hook: (sample BTF, output shape (H, W), seed) -> BTF sharing the sample's U.
ExtraMethod = Callable[[BTF, tuple[int, int], int], BTF]

#: A ground truth: (size, seed) -> (S (n_rows, size * size) float32, light_dirs (n, 2),
#: view_dirs (m, 2)); rows in (light, view, RGB) C order, columns row-major texels.
MaterialSource = Callable[[int, int], tuple[np.ndarray, np.ndarray, np.ndarray]]

#: Materials known by name: the procedural ones of :mod:`imagemap.btf.materials`, and any
#: added by :func:`register_material`.
MATERIAL_SOURCES: dict[str, MaterialSource] = {
    name: partial(ground_truth, name) for name in MATERIALS
}


def register_material(name: str, source: MaterialSource) -> None:
    """Make ``source`` available to :func:`run_experiment` under ``name``."""
    if not callable(source):
        raise InputError(f"material {name!r}: the source must be callable (size, seed) -> S, ...")
    MATERIAL_SOURCES[str(name)] = source


def _source(name: str, sources: Mapping[str, MaterialSource] | None) -> MaterialSource:
    if sources and name in sources:
        return sources[name]
    if name in MATERIAL_SOURCES:
        return MATERIAL_SOURCES[name]
    known = sorted({*(sources or {}), *MATERIAL_SOURCES})
    raise InputError(
        f"material {name!r}: no source; known: {known or 'none'} (pass "
        f"sources={{name: source}} or register_material() for another)"
    )


#: Smallest full sample (texels): the cut-out needs room inside it and the scans' 16-texel
#: margins (registration) a side of more.
MIN_SIZE = 16

#: Smallest cut-out side (texels): the pixel-wise R = 2 neighbourhoods are 5 wide.
MIN_SAMPLE_SIZE = 8


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
    sample_sizes : mapping of material name to int
        Cut-out side for some materials (the paper used 256 for its cloth).
    texture : TextureOptimizationParams
    comparison_lights : sequence of (theta, phi)
        Lights of the rendered comparison images, one row each.
    comparison_view : (theta, phi)
        View of the comparison images (the top view by default; an oblique view
        shows what the scans cannot see: parallax, varnish, fibres).
    seed : int
    """

    size: int = 512
    sample_size: int = 128
    sample_origin: tuple[int, int] | None = None
    k: int = 100
    scanner_gain: tuple[float, float, float] = (1.25, 1.1, 0.9)
    scanner_noise: float = 0.003
    search: str = "approximate"
    sample_sizes: Mapping[str, int] = field(default_factory=lambda: {"cloth": 256, "velvet": 256})
    texture: TextureOptimizationParams = field(default_factory=TextureOptimizationParams)
    comparison_lights: tuple[tuple[float, float], ...] = ((60.0, 45.0), (22.0, 180.0))
    comparison_view: tuple[float, float] = (0.0, 0.0)
    seed: int = 0

    def __post_init__(self) -> None:
        if isinstance(self.size, bool) or not isinstance(self.size, int) or self.size < MIN_SIZE:
            raise InputError(f"size: an integer >= {MIN_SIZE} texels, got {self.size!r}")
        self._check_side("sample_size", self.sample_size)
        if not self.k >= 1:
            raise InputError(f"k: at least 1 component, got {self.k}")

    def _check_side(self, label: str, side) -> int:
        if (
            isinstance(side, bool)
            or not isinstance(side, int | np.integer)
            or not (MIN_SAMPLE_SIZE <= side < self.size)
        ):
            raise InputError(
                f"{label}: the cut-out side must be an integer from {MIN_SAMPLE_SIZE} to "
                f"size - 1 = {self.size - 1}, got {side!r} (a cut-out as large as the "
                "sample is the reference itself: every error would be 0)"
            )
        return int(side)

    def sample_side(self, name: str) -> int:
        """The cut-out side for material ``name``, or InputError if it does not fit."""
        if name in self.sample_sizes:
            return self._check_side(f"sample_sizes[{name!r}]", self.sample_sizes[name])
        return int(self.sample_size)


def default_extra_methods() -> dict[str, ExtraMethod]:
    """The methods beyond the paper's: ``moving_average`` (the parametric model)."""
    from imagemap.btf.moving_average import experiment_method  # deferred: MA model, its row

    return {"moving_average": experiment_method}


def method_names(extra_methods: Mapping[str, ExtraMethod] | None = None) -> list[str]:
    """Every method's name in table order; ``extra_methods`` None: the default extras.

    Example
    -------
    >>> method_names({})[:2]
    ['tiling', 'pixelwise_R0_ws0_wc1']
    """
    if extra_methods is None:
        extra_methods = default_extra_methods()
    return [
        "tiling",
        *PIXELWISE_SETTINGS,
        "texture_optimization",
        *TUNED_TEXTURE,
        *PIXELWISE_MEAN_SETTINGS,
        *extra_methods,
    ]


def _scan_rows(
    matrix: np.ndarray, light_dirs: np.ndarray, view_dirs: np.ndarray, shape
) -> list[np.ndarray]:
    """The full sample's own images at the top view, light theta 22, four azimuths."""
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
    from imagemap.render import display_gamma  # deferred: render, pictures only

    return display_gamma(image)


@dataclass
class GroundTruth:
    """One material's inputs and reference, shared by every method.

    Attributes
    ----------
    name : str
    reference : BTF
        The full sample's own compression (k components), the error's S'.
    sample : BTF
        The cut-out, compressed on its own.
    scans : list of four (H, W, 3) arrays
        Simulated flatbed scans of the full sample (device response, lamp, noise).
    seconds : float
        Rendering and compression time.
    """

    name: str
    reference: BTF
    sample: BTF
    scans: list
    seconds: float = 0.0


def prepare_material(
    name: str,
    params: ExperimentParams = ExperimentParams(),
    *,
    sources: Mapping[str, MaterialSource] | None = None,
) -> GroundTruth:
    """Render, compress, cut out and scan one material (see the module's docstring)."""
    started = time.perf_counter()
    source = _source(name, sources)
    s = params.sample_side(name)
    matrix, lights, views = source(params.size, params.seed)
    matrix = np.asarray(matrix, dtype=np.float32)
    lights = np.asarray(lights, dtype=np.float32)
    views = np.asarray(views, dtype=np.float32)
    shape = (params.size, params.size)
    if matrix.shape != (len(lights) * len(views) * 3, params.size * params.size):
        raise InputError(
            f"material {name!r}: the source gave S of shape {matrix.shape} for "
            f"{len(lights)} lights, {len(views)} views, RGB and {params.size}^2 texels"
        )
    reference = compress(matrix, shape=shape, light_dirs=lights, view_dirs=views, k=params.k)
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
    seconds = time.perf_counter() - started
    log.info("%s: ground truth and compression %.1f s", name, seconds)
    return GroundTruth(name, reference, sample, scans, seconds)


def _renders(btf: BTF, params: ExperimentParams) -> list[np.ndarray]:
    view = btf.nearest_view(*params.comparison_view)
    return [btf.image(btf.nearest_light(*light), view) for light in params.comparison_lights]


def run_methods(
    truth: GroundTruth,
    params: ExperimentParams = ExperimentParams(),
    *,
    methods: Sequence[str] | None = None,
    extra_methods: Mapping[str, ExtraMethod] | None = None,
    quiet: bool = True,
) -> tuple[list[dict], dict[str, list[np.ndarray]]]:
    """Time every method on one prepared material and measure its relative error.

    Returns
    -------
    rows : list of dict
        material, method, rel_error_pct, seconds.
    renders : dict
        method (and "reference") -> one (H, W, 3) linear image per comparison light.
    """
    extra_methods = dict(extra_methods or {})
    all_methods = method_names(extra_methods)
    methods = list(methods) if methods else all_methods
    unknown = [m for m in methods if m not in all_methods]
    if unknown:
        raise InputError(f"methods: unknown {unknown}; choose from {all_methods}")
    reference, sample, name = truth.reference, truth.sample, truth.name
    shape = reference.shape
    sample_images = constraint_images(sample)
    renders = {"reference": _renders(reference, params)}
    rows = []
    for method in methods:
        t0 = time.perf_counter()
        if method == "tiling":
            result = tile(sample, shape)
        elif method in PIXELWISE_SETTINGS:
            radius, ws, wc = PIXELWISE_SETTINGS[method]
            target_images = prepare_scans(truth.scans, sample_images)
            pw = PixelwiseParams(
                radius, ws, wc, backend=_OLD_SEARCH_NAMES[params.search], seed=params.seed
            )
            result, _ = pixelwise(sample, sample_images, target_images, pw)
        elif method in PIXELWISE_MEAN_SETTINGS:
            radius, ws, wc, k = PIXELWISE_MEAN_SETTINGS[method]
            target_images = prepare_scans(truth.scans, sample_images)
            search = params.search if params.search != "pynndescent" else "approximate"
            pw = PixelwiseParams(
                radius, ws, wc, backend=_OLD_SEARCH_NAMES[search], seed=params.seed, neighbours=k
            )
            result, _ = pixelwise(sample, sample_images, target_images, pw)
        elif method == "texture_optimization" or method in TUNED_TEXTURE:
            target_images = prepare_scans(truth.scans, sample_images)
            texture = params.texture
            if method in TUNED_TEXTURE:
                texture = dataclasses.replace(texture, **TUNED_TEXTURE[method])
            result, _ = texture_optimization(
                sample, sample_images, target_images, texture, quiet=quiet
            )
        else:
            result = extra_methods[method](sample, shape, params.seed)
        seconds = time.perf_counter() - t0
        error = relative_error(reference, result)
        rows.append(
            {"material": name, "method": method, "rel_error_pct": error, "seconds": seconds}
        )
        renders[method] = _renders(result, params)
        log.info("%s %-24s %6.2f %%  %7.2f s", name, method, error, seconds)
    return rows, renders


def run_material(
    name: str,
    params: ExperimentParams = ExperimentParams(),
    *,
    sources: Mapping[str, MaterialSource] | None = None,
    methods: Sequence[str] | None = None,
    extra_methods: Mapping[str, ExtraMethod] | None = None,
    quiet: bool = True,
) -> tuple[list[dict], dict[str, list[np.ndarray]]]:
    """:func:`prepare_material`, then :func:`run_methods`."""
    truth = prepare_material(name, params, sources=sources)
    return run_methods(truth, params, methods=methods, extra_methods=extra_methods, quiet=quiet)


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


def comparison_picture(
    renders: Mapping[str, Sequence[np.ndarray]],
    *,
    crop: tuple[int, int, int] | None = None,
    labels: bool = True,
) -> np.ndarray:
    """One column per method (reference first), one row per comparison light.

    Parameters
    ----------
    renders : method -> linear images, one per light (as :func:`run_methods` gives).
    crop : (top, left, side), optional
        Show only this square of each image (detail at full resolution).
    labels : bool
        Write the method's name on each panel of the first row (needs Pillow).

    Returns
    -------
    (rows * (side + gap), columns * (side + gap), 3) float32 display image (gamma 2.2).
    """
    columns = list(renders)
    n_rows = len(next(iter(renders.values())))
    panels = {}
    for method in columns:
        for row, image in enumerate(renders[method]):
            if crop is not None:
                top, left, side = crop
                image = image[top : top + side, left : left + side]
            panels[method, row] = _display(image)
    height, width = next(iter(panels.values())).shape[:2]
    gap = 4
    canvas = np.ones(
        (n_rows * (height + gap) - gap, len(columns) * (width + gap) - gap, 3), dtype=np.float32
    )
    for (method, row), panel in panels.items():
        y, x = row * (height + gap), columns.index(method) * (width + gap)
        canvas[y : y + height, x : x + width] = panel
    if labels:
        canvas = _label(canvas, [(c, i * (width + gap)) for i, c in enumerate(columns)])
    return canvas


def _detail_crop(params: ExperimentParams) -> tuple[int, int, int]:
    """A square near the top-left corner, clear of the centred cut-out (full resolution)."""
    side = max(8, min(160, params.size * 5 // 16))
    return params.size // 16, params.size // 16, side


def _label(canvas: np.ndarray, names: Sequence[tuple[str, int]]) -> np.ndarray:
    try:
        from PIL import Image, ImageDraw  # deferred: Pillow, optional (labels)
    except ImportError:  # labels are a nicety
        return canvas
    image = Image.fromarray((np.clip(canvas, 0, 1) * 255).astype(np.uint8))
    draw = ImageDraw.Draw(image)
    for text, x in names:
        short = text.replace("pixelwise_", "pw ").replace("texture_optimization", "tex. opt.")
        draw.rectangle([x, 0, x + 7 * len(short) + 4, 12], fill=(0, 0, 0))
        draw.text((x + 2, 0), short, fill=(255, 255, 255))
    return np.asarray(image, dtype=np.float32) / 255.0


def run_experiment(
    out: str | os.PathLike,
    *,
    materials: Sequence[str] = ("cloth", "leather", "wallpaper", "wood"),
    params: ExperimentParams = ExperimentParams(),
    sources: Mapping[str, MaterialSource] | None = None,
    methods: Sequence[str] | None = None,
    extra_methods: Mapping[str, ExtraMethod] | None = None,
    quiet: bool = True,
) -> list[dict]:
    """Run :func:`run_material` for each material; write table2.csv, table2.md, PNGs.

    Writes ``out/table2.csv`` (material, method, rel_error_pct, seconds),
    ``out/table2.md``, ``out/<material>_comparison.png`` (reference, then each
    method, one row per comparison light, top view) and ``out/<material>_detail.png``
    (the same for a square away from the cut-out, at full resolution). Materials are looked up in
    ``sources``, then in :data:`MATERIAL_SOURCES`.

    Returns
    -------
    rows : list of dict
    """
    out = Path(out)
    for name in materials:
        _source(name, sources)  # fail before any work
        params.sample_side(name)
    if extra_methods is None:
        extra_methods = default_extra_methods()
    known = method_names(extra_methods)
    unknown = [m for m in methods or () if m not in known]
    if unknown:
        raise InputError(f"methods: unknown {unknown}; choose from {known}")
    check_output_directory(out, "output folder")
    out.mkdir(parents=True, exist_ok=True)
    if params.search == "pynndescent":
        _warm_up_pynndescent(params.seed)
    rows: list[dict] = []
    total = time.perf_counter()
    for name in materials:
        material_rows, renders = run_material(
            name,
            params,
            sources=sources,
            methods=methods,
            extra_methods=extra_methods,
            quiet=quiet,
        )
        rows += material_rows
        write_image(out / f"{name}_comparison.png", comparison_picture(renders))
        write_image(
            out / f"{name}_detail.png", comparison_picture(renders, crop=_detail_crop(params))
        )
        _write_csv(out / "table2.csv", rows)
    seconds = time.perf_counter() - total
    order = " | ".join(["reference", *[r["method"] for r in rows if r["material"] == materials[0]]])
    lights = "; ".join(f"theta {t:g}, phi {p:g}" for t, p in params.comparison_lights)
    cut = ", ".join(f"{m} {params.sample_side(m)}" for m in materials)
    text = (
        f"# Table 2 on procedural materials\n\n"
        f"{params.size}x{params.size} full sample, cut-out side per material: {cut}; "
        f"k = {params.k}; relative error (%) against the full sample's own compression, "
        f"and seconds per method. Whole run: {seconds:.0f} s.\n\n"
        f"{format_table(rows)}\n\n"
        f"Comparison images (`<material>_comparison.png`), columns left to right: "
        f"{order}; rows: light {lights}; view theta {params.comparison_view[0]:g}, phi "
        f"{params.comparison_view[1]:g}. `<material>_detail.png`: the "
        f"square {_detail_crop(params)} (top, left, side), away from the cut-out.\n"
    )
    with atomic_path(out / "table2.md") as tmp:
        tmp.write_text(text)
    return rows


def _warm_up_pynndescent(seed: int) -> None:
    """Compile pynndescent's numba code once, so that no method's time includes it."""
    from imagemap.core.search import PynndescentIndex  # deferred: numba

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
