"""Speed and memory benchmarks of imagemap: prints a table and writes it as JSON.

Every case runs in this process, one after the other, after one tiny warm-up
synthesis whose time is reported on its own ("first call (JIT / cache load)").
Per case it records:

- ``seconds``: wall time of the call (``time.perf_counter``);
- ``rss_peak_mb``: the process's peak resident set during the case (the
  ``VmHWM`` high-water mark of ``/proc/self/status``, reset before each case
  through ``/proc/self/clear_refs``), i.e. the whole process, imports included;
  ``rss_delta_mb`` is that peak minus the resident set just before the case.
  Where the mark cannot be reset, ``resource.getrusage`` ``ru_maxrss`` is used and
  the delta is only the growth of the process's lifetime peak (a lower bound);
- ``traced_peak_mb``: the ``tracemalloc`` peak of the case (Python and NumPy
  allocations; numba's and BLAS's own buffers are not traced). Tracing is on only
  while memory is measured; see ``--no-tracemalloc``.

Data (generated examples, the BTF sample, scans and ground-truth rendering) is
made once and cached under ``benchmarks/.data/`` (``--data``); its time is not
part of any figure.

Usage
-----
    python benchmarks/run.py                      # everything (about 10-20 min on 2 cores)
    python benchmarks/run.py --quick              # tiny sizes: checks the plumbing
    python benchmarks/run.py --only colorize --backends patchmatch,exact
    python benchmarks/run.py --only quality       # leave-one-out CIEDE2000 of a fish class
    python benchmarks/run.py --only scaling       # time and memory against size, m, database
    imagemap bench --quick                        # the same, from the command line
"""

from __future__ import annotations

import argparse
import gc
import importlib.util
import json
import os
import platform
import re
import resource
import shutil
import subprocess
import sys
import time
import tracemalloc
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

BENCHMARKS = Path(__file__).resolve().parent
if str(BENCHMARKS.parent) not in sys.path:
    # Run as a script from a checkout: import this checkout's imagemap and data_gen.
    sys.path.insert(0, str(BENCHMARKS.parent))

from imagemap.io import InputError, atomic_path, write_image  # noqa: E402

GROUPS = ("jit", "colorize", "btf", "cli", "scaling", "quality")
BACKENDS = ("patchmatch", "exact", "pynndescent")
MB = 1024.0 * 1024.0

#: Targets of issue 14 for the scaling curves (seconds, MB), by map side.
SCALING_TARGETS = {1024: (None, 400.0), 2048: (180.0, 1536.0), 4096: (900.0, 6144.0)}

#: Targets of issue 7 (seconds), by case name.
TARGETS = {
    "colorize 200x150": 1.0,
    "colorize 512x512": 8.0,
    "colorize 1024x1024": 40.0,
    "btf pixelwise R=2 128->512": 10.0,
    "btf texture optimization 128->512": 60.0,
}
#: Peak memory targets (MB), by case name: issue 14 (issue 7 asked 4 GB at 1024x1024).
MEMORY_TARGETS = {"colorize 200x150": 150.0, "colorize 1024x1024": 400.0}


@dataclass(frozen=True)
class Settings:
    """Sizes of one benchmark run (full or quick)."""

    colorize_sizes: tuple[tuple[int, int], ...]  # (width, height)
    exact_max_pixels: int  # colorize with the exact backend only up to this many pixels
    pynndescent_max_pixels: int
    btf_sample: int
    btf_size: int
    btf_material: str = "leather"
    btf_k: int = 100
    jit_size: tuple[int, int] = (80, 60)
    quality_size: tuple[int, int] = (200, 150)
    quality_count: int = 8
    cli_size: tuple[int, int] = (200, 150)
    radii: tuple[int, ...] = (0, 1, 2)
    # Scaling curves (each point a fresh process: its whole peak RSS, warm numba cache).
    scaling_sizes: tuple[int, ...] = (256, 512, 1024, 2048)  # square maps; 4096 by hand
    scaling_m: tuple[int, ...] = (1, 2, 4, 8)
    scaling_m_size: int = 256
    scaling_database: tuple[int, ...] = (10, 30, 100, 300, 1000)
    extra: dict = field(default_factory=dict)


FULL = Settings(
    colorize_sizes=((200, 150), (512, 512), (1024, 1024)),
    exact_max_pixels=512 * 512,
    pynndescent_max_pixels=512 * 512,
    btf_sample=128,
    btf_size=512,
)
QUICK = Settings(
    colorize_sizes=((80, 60), (128, 96)),
    exact_max_pixels=128 * 96,
    pynndescent_max_pixels=128 * 96,
    btf_sample=32,
    btf_size=64,
    btf_k=16,
    jit_size=(40, 30),
    quality_size=(80, 60),
    quality_count=4,
    cli_size=(80, 60),
    radii=(0, 2),
    scaling_sizes=(64, 96),
    scaling_m=(1, 2),
    scaling_m_size=64,
    scaling_database=(10, 30),
)


# ----------------------------------------------------------------------------- memory


class MemoryProbe:
    """Peak resident set and tracemalloc peak of one case.

    Example
    -------
    >>> with MemoryProbe(trace=True) as probe:  # doctest: +SKIP
    ...     work()
    >>> probe.rss_peak_mb, probe.traced_peak_mb  # doctest: +SKIP
    """

    def __init__(self, trace: bool = True) -> None:
        self.trace = trace
        self.resettable = _reset_peak_rss()
        self.rss_peak_mb = float("nan")
        self.rss_delta_mb = float("nan")
        self.traced_peak_mb = float("nan")

    def __enter__(self) -> MemoryProbe:
        gc.collect()
        self.resettable = _reset_peak_rss()
        self.rss_before_mb = _status_mb("VmRSS") if self.resettable else _maxrss_mb()
        if self.trace:
            tracemalloc.start()
        return self

    def __exit__(self, *exc) -> None:
        if self.trace:
            self.traced_peak_mb = tracemalloc.get_traced_memory()[1] / MB
            tracemalloc.stop()
        if self.resettable:
            self.rss_peak_mb = _status_mb("VmHWM")
        else:
            self.rss_peak_mb = _maxrss_mb()
        self.rss_delta_mb = max(0.0, self.rss_peak_mb - self.rss_before_mb)


def _reset_peak_rss() -> bool:
    """Reset the kernel's peak-RSS mark of this process (Linux >= 4.0)."""
    try:
        with open("/proc/self/clear_refs", "w") as handle:
            handle.write("5")
        return _status_mb("VmHWM") > 0
    except OSError:
        return False


def _status_mb(key: str) -> float:
    try:
        text = Path("/proc/self/status").read_text()
    except OSError:
        return float("nan")
    found = re.search(rf"^{key}:\s+(\d+) kB", text, re.MULTILINE)
    return int(found.group(1)) / 1024.0 if found else float("nan")


def _maxrss_mb() -> float:
    return _rusage_mb(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)


def _rusage_mb(maxrss: int) -> float:
    return maxrss / MB if sys.platform == "darwin" else maxrss / 1024.0  # bytes on macOS, else kB


def measure(function: Callable[[], object], trace: bool = True) -> tuple[object, dict]:
    """Run ``function()`` once: its value and seconds, peak RSS, tracemalloc peak.

    Time is measured with tracing on when ``trace``; see ``--no-tracemalloc``.
    """
    with MemoryProbe(trace=trace) as probe:
        start = time.perf_counter()
        value = function()
        seconds = time.perf_counter() - start
    return value, {
        "seconds": seconds,
        "rss_peak_mb": probe.rss_peak_mb,
        "rss_delta_mb": probe.rss_delta_mb,
        "traced_peak_mb": probe.traced_peak_mb,
        "rss_method": "VmHWM reset per case" if probe.resettable else "ru_maxrss growth",
    }


# ----------------------------------------------------------------------------- data


def fish_class(data_dir: Path, size: tuple[int, int], count: int = 3, holdout: int = 1) -> Path:
    """A generated fish class (``count`` objects, the last ``holdout`` held out), cached."""
    width, height = size
    out = data_dir / f"fish_{width}x{height}_n{count}_h{holdout}"
    ready = out.is_dir() and (not holdout or (out / "holdout").is_dir())
    if not ready:
        # data_gen writes into a fresh directory; a half-made one is replaced.
        tmp = out.with_name(out.name + ".tmp")
        if tmp.exists():
            shutil.rmtree(tmp)
        command = [
            sys.executable, "-m", "data_gen", "fish", "--count", str(count),
            "--size", f"{width}x{height}", "--seed", "0", "--out", str(tmp), "-q",
        ]  # fmt: skip
        if holdout:
            command += ["--holdout", str(holdout)]
        subprocess.run(command, check=True, cwd=BENCHMARKS.parent, env=_child_env())
        if out.exists():
            shutil.rmtree(out)
        tmp.rename(out)
    return out


def _child_env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(
        filter(None, [str(BENCHMARKS.parent), env.get("PYTHONPATH")])
    )
    return env


def _holdout_depth(class_dir: Path) -> Path:
    found = sorted((class_dir / "holdout").glob("*_depth.png"))
    if not found:
        raise InputError(f"{class_dir}/holdout: no query depth map")
    return found[0]


@dataclass
class BtfData:
    sample: object  # imagemap.btf.BTF
    scans: list[np.ndarray]
    truth: np.ndarray  # (H, W, 3) linear, top view, comparison light
    light: tuple[float, float]


def btf_data(data_dir: Path, settings: Settings, seed: int = 0) -> BtfData:
    """Sample BTF (cut-out), four simulated scans and a truth image, cached on disk.

    Only what the methods read is rendered: the cut-out's full BTF (with a margin,
    so cast shadows at its border are those of the large sample) and, for the
    large sample, the four scan images and one comparison image.
    """
    from data_gen.materials import Material, default_sampling, make_material, render_btf_matrix
    from imagemap.btf import BTF, compress
    from imagemap.btf.constraints import scanner_response
    from imagemap.btf.extrapolate import CONSTRAINT_AZIMUTHS, CONSTRAINT_THETA
    from imagemap.io import read_npz, write_npz

    size, s = settings.btf_size, settings.btf_sample
    name = f"btf_{settings.btf_material}_{s}to{size}_k{settings.btf_k}_seed{seed}"
    sample_path, rest_path = data_dir / f"{name}_sample.npz", data_dir / f"{name}_scans.npz"
    light = (60.0, 45.0)
    if sample_path.exists() and rest_path.exists():
        rest = read_npz(rest_path)
        scans = [rest[f"scan{i}"] for i in range(4)]
        return BtfData(BTF.load(sample_path), scans, rest["truth"], light)

    lights, views = default_sampling()
    material = make_material(settings.btf_material, size=size, seed=seed)
    margin = min(16, (size - s) // 2)
    top = (size - s) // 2 - margin
    window = (slice(top, top + s + 2 * margin),) * 2
    crop = Material(
        material.height[window], material.albedo[window], material.gloss[window],
        material.shininess[window], material.name,
    )  # fmt: skip
    side = s + 2 * margin
    matrix = render_btf_matrix(crop, lights, views).reshape(-1, side, side)
    matrix = np.ascontiguousarray(matrix[:, margin : margin + s, margin : margin + s])
    sample = compress(
        matrix.reshape(len(matrix), -1), shape=(s, s), light_dirs=lights, view_dirs=views,
        k=settings.btf_k,
    )  # fmt: skip
    del matrix
    top_view = np.array([[0.0, 0.0]], np.float32)
    scan_lights = np.array([[CONSTRAINT_THETA, phi] for phi in CONSTRAINT_AZIMUTHS], np.float32)
    rows = render_btf_matrix(material, scan_lights, top_view).reshape(4, 3, size, size)
    scans = [
        scanner_response(
            np.moveaxis(rows[i], 0, 2), gain=(1.25, 1.1, 0.9), noise=0.003, seed=seed + i
        )
        for i in range(4)
    ]
    truth = render_btf_matrix(material, np.array([light], np.float32), top_view)
    truth = np.moveaxis(truth.reshape(3, size, size), 0, 2)
    data_dir.mkdir(parents=True, exist_ok=True)
    sample.save(sample_path)
    write_npz(rest_path, truth=truth, **{f"scan{i}": scan for i, scan in enumerate(scans)})
    return BtfData(sample, scans, truth, light)


# ----------------------------------------------------------------------------- cases


def _row(group: str, case: str, backend: str, figures: dict, **extra) -> dict:
    row = {"group": group, "case": case, "backend": backend, **figures, **extra}
    target = TARGETS.get(case)
    if target is not None and group != "jit":
        row["target_seconds"] = target
    if case in MEMORY_TARGETS:
        row["target_rss_mb"] = MEMORY_TARGETS[case]
    return row


def _colorize_call(class_dir: Path, backend: str):
    from imagemap import Database, colorize, read_depth

    database = Database.from_directory(class_dir)
    depth = read_depth(_holdout_depth(class_dir))

    def call():
        return colorize(depth, database, preset="fish", m=2, backend=backend, seed=0)

    return call


def _colorize_row(case: str, size: tuple[int, int], backend: str, result, figures: dict) -> dict:
    return _row(
        "colorize", case, backend, figures,
        size=f"{size[0]}x{size[1]}",
        objective=float(result.objective[0][-1]),
        iterations=[len(level) for level in result.objective],
        stages={k: float(v) for k, v in result.timings.items()},
        object_pixels=int(result.mask.sum()),
        examples=list(result.example_names),
    )  # fmt: skip


def run_jit(data_dir: Path, settings: Settings, backends: list[str], trace: bool) -> list[dict]:
    """The first synthesis of the process (numba compilation or cache load), then a second."""
    class_dir = fish_class(data_dir, settings.jit_size)
    rows = []
    for backend in [b for b in backends if b != "exact"] or ["patchmatch"]:
        call = _colorize_call(class_dir, backend)
        for attempt in ("first call (JIT / cache load)", "second call"):
            result, figures = measure(call, trace=trace)
            size = settings.jit_size
            rows.append(
                _colorize_row(f"{attempt} {size[0]}x{size[1]}", size, backend, result, figures)
                | {"group": "jit"}
            )
    return rows


def run_colorize(
    data_dir: Path, settings: Settings, backends: list[str], trace: bool, images: Path | None = None
) -> list[dict]:
    rows = []
    for size in settings.colorize_sizes:
        class_dir = fish_class(data_dir, size)
        pixels = size[0] * size[1]
        for backend in backends:
            case = f"colorize {size[0]}x{size[1]}"
            cap = {
                "exact": settings.exact_max_pixels,
                "pynndescent": settings.pynndescent_max_pixels,
            }
            if pixels > cap.get(backend, pixels):
                rows.append(
                    _row("colorize", case, backend, {}, size=f"{size[0]}x{size[1]}",
                         skipped=f"{backend} is run up to {cap[backend]} pixels only (too slow)")
                )  # fmt: skip
                continue
            result, figures = measure(_colorize_call(class_dir, backend), trace=trace)
            rows.append(_colorize_row(case, size, backend, result, figures))
            if images is not None:
                name = f"colorize_{size[0]}x{size[1]}_{backend}.png"
                write_image(images / name, result.on_background((1.0, 1.0, 1.0)))
            _progress(rows[-1])
    return rows


def _rendering(result_btf, data: BtfData) -> np.ndarray:
    """The result rendered at the comparison light, top view (linear RGB)."""
    light = result_btf.nearest_light(*data.light)
    return result_btf.image(light, result_btf.nearest_view(0.0, 0.0))


def _image_error(image: np.ndarray, data: BtfData) -> float:
    """Relative error (%) of a rendering against the truth at the same light and view."""
    return float(100.0 * np.linalg.norm(image - data.truth) / np.linalg.norm(data.truth))


def _display(image: np.ndarray) -> np.ndarray:
    """Linear radiance to a viewable image (gamma 2.2)."""
    return np.clip(image, 0.0, 1.0) ** (1 / 2.2)


def run_btf(
    data_dir: Path, settings: Settings, backends: list[str], trace: bool, images: Path | None = None
) -> list[dict]:
    from imagemap.btf.experiment import PIXELWISE_SETTINGS
    from imagemap.btf.extrapolate import (
        PixelwiseParams,
        TextureOptimizationParams,
        constraint_images,
        pixelwise,
        prepare_scans,
        texture_optimization,
    )

    data = btf_data(data_dir, settings)
    sample = data.sample
    sample_images = constraint_images(sample)
    by_radius = {r: (ws, wc) for r, ws, wc in PIXELWISE_SETTINGS.values()}
    shape = f"{settings.btf_sample}->{settings.btf_size}"
    tag = f"{settings.btf_material}_{settings.btf_sample}to{settings.btf_size}"
    if images is not None:
        write_image(images / f"btf_{tag}_truth.png", _display(data.truth))
    rows = []
    # The pixel-wise method's searches: PCA + k-d tree ("approximate", the default),
    # pynndescent, or exact.
    pixel_searches = [("pca+kdtree", "pca_kdtree")] if "patchmatch" in backends else []
    pixel_searches += [("pynndescent", "pynndescent")] if "pynndescent" in backends else []
    pixel_searches += [("exact", "kdtree")] if "exact" in backends else []
    for radius in settings.radii:
        ws, wc = by_radius[radius]
        for backend, search in pixel_searches:
            params = PixelwiseParams(radius=radius, ws=ws, wc=wc, backend=search, seed=0)

            def call(params=params):
                targets = prepare_scans(data.scans, sample_images)
                return pixelwise(sample, sample_images, targets, params)

            (result, _), figures = measure(call, trace=trace)
            image = _rendering(result, data)
            if images is not None:
                write_image(
                    images / f"btf_{tag}_pixelwise_R{radius}_{backend}.png", _display(image)
                )
            rows.append(
                _row("btf", f"btf pixelwise R={radius} {shape}", backend, figures, size=shape,
                     ws=ws, wc=wc, image_error_pct=_image_error(image, data))
            )  # fmt: skip
            _progress(rows[-1])
    for backend in backends:
        params = TextureOptimizationParams(backend=backend)

        def call(params=params):
            targets = prepare_scans(data.scans, sample_images)
            return texture_optimization(sample, sample_images, targets, params)

        (result, engine_result), figures = measure(call, trace=trace)
        image = _rendering(result, data)
        if images is not None:
            write_image(images / f"btf_{tag}_texture_optimization_{backend}.png", _display(image))
        rows.append(
            _row("btf", f"btf texture optimization {shape}", backend, figures, size=shape,
                 image_error_pct=_image_error(image, data),
                 objective=float(engine_result.objective[0][-1]),
                 iterations=[len(level) for level in engine_result.objective],
                 stages={k: float(v) for k, v in engine_result.timings.items()})
        )  # fmt: skip
        _progress(rows[-1])
    return rows


#: Runs ``python -m imagemap ARGS`` and, at exit, prints the process's own peak RSS:
#: ``ru_maxrss`` of a fork-exec'd child starts from its parent's peak, so it cannot be used.
_CLI_WRAPPER = (
    "import atexit, re, runpy, sys\n"
    "def report():\n"
    "    text = open('/proc/self/status').read()\n"
    "    found = re.search(r'^VmHWM:\\s+(\\d+) kB', text, re.M)\n"
    "    sys.stderr.write(f'\\nBENCH_VMHWM_KB={found.group(1) if found else -1}\\n')\n"
    "atexit.register(report)\n"
    "sys.argv = ['imagemap', *sys.argv[1:]]\n"
    "runpy.run_module('imagemap', run_name='__main__')\n"
)


def _startup_script():
    """``benchmarks/startup.py``, loaded by path (this script may be loaded so too)."""
    spec = importlib.util.spec_from_file_location(
        "imagemap_benchmarks_startup", BENCHMARKS / "startup.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return module


#: The floor's plans, recorded once per driver process: data folder and size -> plan file.
_FLOOR_PLAN: dict[str, Path] = {}


def run_floor(data_dir: Path | None = None, size: tuple[int, int] = (200, 150)) -> dict:
    """The floor of a fresh synthesis process: one process that imports every module an
    ``imagemap synthesize`` of the generated fish at ``size`` imports and loads every numba
    kernel it loads from numba's cache, and does no work (``benchmarks/startup.py``'s
    floor; its plan comes from one untimed synthesis, recorded once per driver process).
    Like ``imagemap``, it freezes the heap before exit: no closing collections in its
    wall time."""
    startup = _startup_script()
    data_dir = Path(data_dir or BENCHMARKS / ".data")
    key = f"{data_dir}:{size}"
    if key not in _FLOOR_PLAN:
        folder = data_dir / "floor"
        folder.mkdir(parents=True, exist_ok=True)
        class_dir = fish_class(data_dir, size)
        _FLOOR_PLAN[key] = startup.record(BENCHMARKS.parent, class_dir, folder)["plan"]
    found = startup.floor(BENCHMARKS.parent, _FLOOR_PLAN[key])
    figures = {
        "seconds": found["seconds"],
        "rss_peak_mb": found["rss_peak_mb"],
        "rss_method": "VmHWM of the child process at exit",
        "import_seconds": found["imports"],
        "kernel_load_seconds": found["kernel_load"],
    }
    return _row("cli", "floor: imports + numba cache load (fresh process)", "-", figures)


def run_cli(data_dir: Path, settings: Settings, out_dir: Path) -> list[dict]:
    """Two fresh ``imagemap synthesize`` processes: what a command-line user waits; and
    the floor of such a process (imports and numba's cache load, no synthesis)."""
    class_dir = fish_class(data_dir, settings.cli_size)
    out_dir.mkdir(parents=True, exist_ok=True)
    command = [
        sys.executable, "-c", _CLI_WRAPPER, "synthesize", str(_holdout_depth(class_dir)),
        "--db", str(class_dir), "-o", str(out_dir / "cli_map.png"), "--preset", "fish",
        "--m", "2", "--quiet",
    ]  # fmt: skip
    rows = []
    size = f"{settings.cli_size[0]}x{settings.cli_size[1]}"
    for attempt in ("first", "second"):
        start = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True, env=_child_env())
        seconds = time.perf_counter() - start
        if done.returncode != 0:
            raise RuntimeError(f"imagemap synthesize failed: {done.stderr.strip()}")
        found = re.search(r"BENCH_VMHWM_KB=(\d+)", done.stderr)
        figures = {
            "seconds": seconds,
            "rss_peak_mb": int(found.group(1)) / 1024.0 if found else float("nan"),
            "rss_method": "VmHWM of the child process at exit",
        }
        rows.append(
            _row("cli", f"imagemap synthesize {size} ({attempt} process)", "patchmatch", figures,
                 size=size)
        )  # fmt: skip
        _progress(rows[-1])
    rows.append(run_floor(data_dir, settings.cli_size))
    _progress(rows[-1])
    return rows


#: One colorize in a fresh process; prints its seconds and the process's peak RSS.
_SCALING_CHILD = (
    "import glob, json, re, sys, time\n"
    "from imagemap import Database, colorize, read_depth\n"
    "class_dir, m = sys.argv[1], int(sys.argv[2])\n"
    "database = Database.from_directory(class_dir)\n"
    "depth = read_depth(sorted(glob.glob(class_dir + '/holdout/*_depth.png'))[0])\n"
    "start = time.perf_counter()\n"
    "result = colorize(depth, database, preset='fish', m=m, seed=0)\n"
    "seconds = time.perf_counter() - start\n"
    "text = open('/proc/self/status').read()\n"
    "hwm = int(re.search(r'^VmHWM:\\s+(\\d+) kB', text, re.M).group(1)) / 1024.0\n"
    "print(json.dumps({'seconds': seconds, 'rss_peak_mb': hwm, 'stages': result.timings,\n"
    "                  'object_pixels': int(result.mask.sum())}))\n"
)


def _scaling_point(class_dir: Path, m: int) -> dict:
    done = subprocess.run(
        [sys.executable, "-c", _SCALING_CHILD, str(class_dir), str(m)],
        capture_output=True, text=True, env=_child_env(),
    )  # fmt: skip
    if done.returncode != 0:
        raise RuntimeError(f"scaling point {class_dir} m={m} failed: {done.stderr.strip()}")
    figures = json.loads(done.stdout.strip().splitlines()[-1])
    figures["rss_method"] = "VmHWM of a fresh process (imports and numba cache load included)"
    return figures


def synthetic_database(data_dir: Path, size: int, n: int, seed: int = 0):
    """``n`` examples made from a generated fish class by random shifts and flips (the
    selection's cost does not depend on what the depth maps show)."""
    from imagemap import Database, Example, read_depth

    class_dir = fish_class(data_dir, (size, size * 3 // 4), count=6, holdout=1)
    bases = [read_depth(p) for p in sorted(class_dir.glob("*_depth.png"))]
    rng = np.random.default_rng(seed)
    examples = []
    for i in range(n):
        depth = bases[i % len(bases)]
        depth = np.roll(depth, tuple(rng.integers(-8, 9, 2)), axis=(0, 1))
        if rng.random() < 0.5:
            depth = depth[:, ::-1]
        image = np.zeros(depth.shape + (3,), np.float32)
        examples.append(Example.from_arrays(f"x{i:04d}", np.ascontiguousarray(depth), image))
    query = read_depth(_holdout_depth(class_dir))
    return Database(examples), query


def run_scaling(data_dir: Path, settings: Settings, trace: bool) -> list[dict]:
    """Time and peak memory against map size and m (fresh processes), and the example
    selection's time per query against database size (in this process)."""
    from imagemap import select_examples

    rows = []
    for side in settings.scaling_sizes:
        class_dir = fish_class(data_dir, (side, side))
        figures = _scaling_point(class_dir, 2)
        target_s, target_mb = SCALING_TARGETS.get(side, (None, None))
        rows.append(
            _row("scaling", f"pixels {side}x{side} (m = 2, fresh process)", "patchmatch",
                 figures, size=f"{side}x{side}", pixels=side * side, m=2,
                 **({"target_seconds": target_s} if target_s else {}),
                 **({"target_rss_mb": target_mb} if target_mb else {}))
        )  # fmt: skip
        _progress(rows[-1])
    side = settings.scaling_m_size
    class_dir = fish_class(data_dir, (side, side), count=max(settings.scaling_m) + 1)
    for m in settings.scaling_m:
        figures = _scaling_point(class_dir, m)
        rows.append(
            _row("scaling", f"examples m = {m} ({side}x{side}, fresh process)", "patchmatch",
                 figures, size=f"{side}x{side}", m=m)
        )  # fmt: skip
        _progress(rows[-1])
    for n in settings.scaling_database:
        database, query = synthetic_database(data_dir, 200, n)
        for example in database:  # arrays in memory: the figure is the selection alone
            _ = example.depth
        _, first = measure(lambda d=database, q=query: select_examples(q, d, 2), trace)
        queries = 5
        start = time.perf_counter()
        for _ in range(queries):
            select_examples(query, database, 2)
        per_query = (time.perf_counter() - start) / queries
        rows.append(
            _row("scaling", f"selection, database of {n} (200x150)", "-",
                 {**first, "seconds": per_query}, database_size=n,
                 first_query_seconds=first["seconds"], per_query_seconds=per_query)
        )  # fmt: skip
        _progress(rows[-1])
    return rows


def run_quality(data_dir: Path, settings: Settings, backend: str) -> dict:
    """Leave-one-out mean CIEDE2000 of the full method on a small fish class."""
    from imagemap import Database
    from imagemap.depth.config import PRESETS
    from imagemap.evaluation import leave_one_out
    from imagemap.report import summarize

    class_dir = fish_class(data_dir, settings.quality_size, count=settings.quality_count, holdout=0)
    database = Database.from_directory(class_dir)
    params = PRESETS["fish"].replace_fields(backend=backend)
    start = time.perf_counter()
    evaluation = leave_one_out(database, preset=params, methods=("full",), workers=1)
    seconds = time.perf_counter() - start
    summary = summarize(evaluation)
    class_name, methods = next(iter(summary.items()))
    full = methods["full"]
    return {
        "class": class_name,
        "objects": int(full["objects"]),
        "size": f"{settings.quality_size[0]}x{settings.quality_size[1]}",
        "backend": backend,
        "ciede2000": float(full["ciede2000"]),
        "ssim": float(full["ssim"]),
        "part_transfer": float(full["part_transfer"]),
        "faulty": float(full["faulty"]),
        "seconds_per_object": float(full["seconds"]),
        "seconds": seconds,
    }


# ----------------------------------------------------------------------------- report


def machine() -> dict:
    """The machine the figures were measured on."""
    import numba

    cpu = platform.processor() or ""
    try:
        found = re.search(r"^model name\s*:\s*(.+)$", Path("/proc/cpuinfo").read_text(), re.M)
        cpu = found.group(1).strip() if found else cpu
    except OSError:
        pass
    try:
        total = re.search(r"^MemTotal:\s+(\d+) kB", Path("/proc/meminfo").read_text(), re.M)
        memory_gb = int(total.group(1)) / 1024.0 / 1024.0 if total else float("nan")
    except OSError:
        memory_gb = float("nan")
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "cores_usable": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "memory_gb": round(memory_gb, 1),
        "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
        "numba_threads": numba.config.NUMBA_NUM_THREADS,
        "platform": platform.platform(),
    }


def _fmt(value, digits: int = 2) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "–"
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    return str(value)


def format_table(rows: list[dict]) -> str:
    """Markdown table of the rows: time, memory, quality, target."""
    lines = [
        "| case | backend | s | target s | peak RSS MB | RSS Δ MB | traced MB | quality |",
        "|---|---|---:|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        if "skipped" in r:
            lines.append(f"| {r['case']} | {r['backend']} | skipped: {r['skipped']} ||||||")
            continue
        quality = ""
        if "objective" in r:
            quality = f"objective {r['objective']:.4g}"
        if "image_error_pct" in r:
            quality = (
                quality + "; " if quality else ""
            ) + f"image err {r['image_error_pct']:.2f} %"
        target = r.get("target_seconds")
        mark = ""
        if target is not None:
            mark = f"{target:g} {'✓' if r['seconds'] <= target else '✗'}"
        lines.append(
            f"| {r['case']} | {r['backend']} | {_fmt(r.get('seconds'))} | {mark} | "
            f"{_fmt(r.get('rss_peak_mb'), 0)} | {_fmt(r.get('rss_delta_mb'), 0)} | "
            f"{_fmt(r.get('traced_peak_mb'), 0)} | {quality} |"
        )
    return "\n".join(lines)


def format_stages(row: dict) -> str:
    """Markdown table of one case's per-stage seconds (``result.timings``, in stage order)."""
    stages = row.get("stages") or {}
    names = list(stages)
    total = sum(stages.values()) or float("nan")
    lines = ["| stage | s | share |", "|---|---:|---:|"]
    for name in names:
        lines.append(f"| {name} | {stages[name]:.3f} | {100 * stages[name] / total:.0f} % |")
    lines.append(f"| sum of stages | {total:.3f} | |")
    lines.append(f"| wall time | {row['seconds']:.3f} | |")
    return "\n".join(lines)


def breakdown_row(rows: list[dict]) -> dict | None:
    """The case whose stages the report breaks down: the 512x512 colorize (or the largest)."""
    candidates = [r for r in rows if r["group"] == "colorize" and r.get("stages")]
    preferred = [r for r in candidates if r["size"] == "512x512" and r["backend"] == "patchmatch"]
    if preferred:
        return preferred[0]
    candidates = [r for r in candidates if r["backend"] == "patchmatch"] or candidates
    return max(candidates, key=lambda r: r["object_pixels"], default=None)


def format_report(report: dict) -> str:
    m = report["machine"]
    parts = [
        f"Machine: {m['cpu']}, {m['cores']} cores, {m['memory_gb']} GB, load average "
        f"{', '.join(f'{x:.2f}' for x in m['load_average'] or [])} at start; Python "
        f"{m['python']}, NumPy {m['numpy']}, numba {m['numba']}.",
        "",
        format_table(report["rows"]),
    ]
    row = breakdown_row(report["rows"])
    if row is not None:
        parts += ["", f"Stages of {row['case']} ({row['backend']}):", "", format_stages(row)]
    if report.get("quality"):
        q = report["quality"]
        parts += [
            "",
            f"Quality: leave-one-out {q['class']} ({q['objects']} objects, {q['size']}, "
            f"{q['backend']}): mean CIEDE2000 {q['ciede2000']:.2f}, SSIM {q['ssim']:.3f}, "
            f"part transfer {q['part_transfer']:.3f}, faulty {100 * q['faulty']:.0f} %, "
            f"{q['seconds_per_object']:.2f} s/object.",
        ]
    parts += [
        "",
        "s = wall time; peak RSS = the process's resident-set high-water mark during the case "
        "(reset per case); RSS Δ = that peak minus the resident set before the case; traced = "
        "tracemalloc peak (Python/NumPy allocations only).",
    ]
    return "\n".join(parts)


def _progress(row: dict) -> None:
    if "skipped" in row:
        return
    print(
        f"  {row['case']:<44} {row['backend']:<12} {row['seconds']:8.2f} s  "
        f"{_fmt(row.get('rss_peak_mb'), 0):>6} MB",
        file=sys.stderr,
        flush=True,
    )


# ----------------------------------------------------------------------------- main


def build_parser(parser: argparse.ArgumentParser | None = None) -> argparse.ArgumentParser:
    """Options of ``benchmarks/run.py`` (shared with ``imagemap bench``)."""
    parser = parser or argparse.ArgumentParser(
        prog="benchmarks/run.py", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("--quick", action="store_true", help="tiny sizes (checks the plumbing)")
    parser.add_argument(
        "--only",
        default=None,
        help=f"comma-separated groups among {', '.join(GROUPS)} (default: all but quality "
        "with --quick, all otherwise)",
    )
    parser.add_argument(
        "--backends",
        default=None,
        help=f"comma-separated among {', '.join(BACKENDS)} (default: all; with --quick "
        "patchmatch,exact, as pynndescent compiles for about 40 s in a fresh environment)",
    )
    parser.add_argument("--quality", action="store_true", help="also run the quality group")
    parser.add_argument(
        "--json", default=str(BENCHMARKS / "results.json"), help="output JSON (default %(default)s)"
    )
    parser.add_argument(
        "--data",
        default=str(BENCHMARKS / ".data"),
        help="cache of generated data (default %(default)s)",
    )
    parser.add_argument(
        "--no-tracemalloc",
        action="store_true",
        help="do not trace allocations (times without tracing overhead; no traced peak)",
    )
    return parser


def _choices(
    text: str | None, allowed: tuple[str, ...], default: list[str], name: str
) -> list[str]:
    if text is None:
        return default
    chosen = [t.strip() for t in text.split(",") if t.strip()]
    unknown = [c for c in chosen if c not in allowed]
    if unknown or not chosen:
        raise InputError(f"{name}: {unknown or text!r} not among {', '.join(allowed)}")
    return chosen


def run(args: argparse.Namespace) -> dict:
    """Run the benchmark groups of ``args``; returns the report (also written as JSON)."""
    settings = QUICK if args.quick else FULL
    # The scaling curves start fresh processes and generate larger classes: never by default
    # with --quick (ask for them with --only scaling).
    quick_groups = [g for g in GROUPS if g not in ("quality", "scaling")]
    default_groups = quick_groups if args.quick else list(GROUPS)
    groups = _choices(args.only, GROUPS, default_groups, "--only")
    if args.quality and "quality" not in groups:
        groups.append("quality")
    default_backends = ["patchmatch", "exact"] if args.quick else list(BACKENDS)
    backends = _choices(args.backends, BACKENDS, default_backends, "--backends")
    data_dir = Path(args.data)
    data_dir.mkdir(parents=True, exist_ok=True)
    trace = not args.no_tracemalloc
    images = data_dir / "images"  # every result as a PNG: look at them
    report = {
        "machine": machine(),
        "settings": {"quick": bool(args.quick), "groups": groups, "backends": backends,
                     "tracemalloc": trace},
        "rows": [],
        "quality": None,
    }  # fmt: skip
    started = time.perf_counter()
    # The warm-up runs first whatever --only says: no other figure may include compilation.
    print("first call (JIT / cache load):", file=sys.stderr, flush=True)
    jit_rows = run_jit(data_dir, settings, backends, trace)
    for row in jit_rows:
        _progress(row)
    if "jit" in groups:
        report["rows"] += jit_rows
    if "colorize" in groups:
        report["rows"] += run_colorize(data_dir, settings, backends, trace, images)
    if "btf" in groups:
        if "pynndescent" in backends:
            from imagemap.btf.experiment import _warm_up_pynndescent

            _warm_up_pynndescent(0)
        report["rows"] += run_btf(data_dir, settings, backends, trace, images)
    if "cli" in groups:
        report["rows"] += run_cli(data_dir, settings, data_dir / "cli")
    if "scaling" in groups:
        report["rows"] += run_scaling(data_dir, settings, trace)
    if "quality" in groups:
        report["quality"] = run_quality(data_dir, settings, backends[0])
    report["seconds"] = time.perf_counter() - started
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as tmp:
        tmp.write_text(json.dumps(report, indent=1, default=float) + "\n")
    return report


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        report = run(args)
    except InputError as exc:
        print(f"benchmarks: error: {exc}", file=sys.stderr)
        return 2
    print(format_report(report))
    print(f"\n(written to {args.json}; {report['seconds']:.0f} s in all)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
