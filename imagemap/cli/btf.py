"""``imagemap btf``: extrapolate a measured BTF sample, render it, reproduce Table 2."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from imagemap.cli import PIXELWISE_BACKEND_NAMES
from imagemap.cli.paths import check_paths
from imagemap.errors import InputError

#: The parser loads no scientific module (``imagemap --help`` stays fast): each command
#: imports what it needs when it runs, and register() imports imagemap.cli's helpers late
#: because imagemap.cli imports this module.
DEFERRED_IMPORTS = "command functions import their modules when run; the parser loads none"


def _log():
    """The ``imagemap`` logger (logging is imported when a command logs, not for its parser)."""
    import logging

    return logging.getLogger("imagemap")


METHODS = ("pixelwise", "texture_optimization")
BTF_INPUT = "sample BTF (.npz written by imagemap, or UBO2014 .btf)"


def register(subparsers: argparse._SubParsersAction) -> dict[str, argparse._SubParsersAction]:
    """Add ``imagemap btf`` and its subcommands; returns the group for other modules."""
    from imagemap.cli import add_common_options

    parser = subparsers.add_parser(
        "btf",
        help="BTF extrapolation: sample BTF + four scans -> large BTF",
        description=(
            "Extrapolate a measured, TSVD-compressed BTF sample to a large material sample "
            "guided by four flatbed-scanner images (lit from azimuths 0, 90, 180, 270)."
        ),
    )
    btf_subparsers = parser.add_subparsers(dest="btf_command", metavar="BTF_COMMAND")
    parser.set_defaults(func=lambda args: (parser.print_help(), 2)[1])

    p = btf_subparsers.add_parser(
        "extrapolate",
        help="sample BTF + four scans -> large BTF (.npz)",
        description="Synthesize the eigentextures of the large sample; U is the sample's.",
    )
    p.add_argument("sample", help=BTF_INPUT)
    p.add_argument(
        "--scans",
        nargs=4,
        required=True,
        metavar=("SCAN0", "SCAN90", "SCAN180", "SCAN270"),
        help="four scans of the large sample, light azimuths 0, 90, 180, 270 (with "
        "--register: the 0 degree scan first, the others in any order)",
    )
    p.add_argument("-o", "--output", required=True, help="output BTF (.npz)")
    p.add_argument("--method", choices=METHODS, default="pixelwise")
    p.add_argument("--radius", type=int, default=None, help="R (pixelwise 0, texture 8)")
    p.add_argument("--ws", type=float, default=None, help="surface weight (pixelwise 0)")
    p.add_argument("--wc", type=float, default=None, help="colour weight (pixelwise 1)")
    p.add_argument(
        "--backend",
        choices=PIXELWISE_BACKEND_NAMES,
        default=None,
        help="pixel-wise nearest-neighbour search (default pca_kdtree; kdtree and exact are exact)",
    )
    p.add_argument(
        "--search",
        choices=("approximate", "exact", "pynndescent"),
        default=None,
        help=argparse.SUPPRESS,  # deprecated: --backend (approximate = pca_kdtree)
    )
    response = p.add_mutually_exclusive_group()
    response.add_argument(
        "--linear-scans",
        action="store_true",
        help="scans are already linear (skip the Table 1 colour correction)",
    )
    response.add_argument(
        "--chart",
        metavar="PNG",
        help="a scan of an X-Rite ColorChecker (cropped to the chart) from the same "
        "scanner: its fitted response replaces the paper's Table 1 constants",
    )
    p.add_argument(
        "--register",
        action="store_true",
        help="find the scans' quarter turns, small rotations and shifts and undo them "
        "(the result covers the square the four scans share)",
    )
    p.add_argument(
        "--find-order",
        action="store_true",
        help="with --register: let the sample BTF decide which scan was lit from which "
        "azimuth and turn the scans to its frame (for anisotropic materials; default: the "
        "first scan is lit from azimuth 0, the others follow from their turns)",
    )
    p.add_argument(
        "--max-rotation",
        type=float,
        default=5.0,
        help="with --register: largest rotation searched besides quarter turns (degrees)",
    )
    p.add_argument(
        "--allow-misfit",
        action="store_true",
        help="with --register: go on when a scan does not fit the reference scan (match "
        "confidence below 17: another material or piece, or a failed alignment); by default "
        "such a run is refused and nothing is written",
    )
    p.add_argument("--seed", type=int, default=0)
    add_common_options(p)
    p.set_defaults(func=_extrapolate)

    p = btf_subparsers.add_parser(
        "render",
        help="one relit image of a BTF (PNG)",
        description="Decompress the image nearest to a light and view direction.",
    )
    p.add_argument("btf", help="BTF (.npz or UBO2014 .btf)")
    p.add_argument("-o", "--output", required=True, help="output image (.png)")
    p.add_argument("--light", nargs=2, type=float, default=(45.0, 0.0), metavar=("THETA", "PHI"))
    p.add_argument("--view", nargs=2, type=float, default=(0.0, 0.0), metavar=("THETA", "PHI"))
    p.add_argument("--exposure", type=float, default=1.0, help="multiply radiance before gamma")
    p.add_argument("--linear", action="store_true", help="no display gamma (default 2.2)")
    p.set_defaults(func=_render)

    p = btf_subparsers.add_parser(
        "experiment",
        help="the paper's Table 2 on procedural materials",
        description="Writes DIR/table2.csv, DIR/table2.md and a comparison PNG per material.",
    )
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--materials", nargs="+", default=["cloth", "leather", "wallpaper", "wood"])
    p.add_argument("--size", type=int, default=512, help="full sample side (texels)")
    p.add_argument(
        "--sample-size",
        type=int,
        default=None,
        help="cut-out side for every material (default: size / 4, size / 2 for cloth, velvet)",
    )
    p.add_argument("--methods", nargs="+", default=None, help="subset of the methods")
    p.add_argument(
        "--search", choices=("approximate", "exact", "pynndescent"), default="approximate"
    )
    p.add_argument("--seed", type=int, default=0)
    add_common_options(p)
    p.set_defaults(func=_experiment)

    from imagemap.cli import btf_photometric

    btf_photometric.register(btf_subparsers)
    return {"btf": btf_subparsers}


def _extrapolate(args: argparse.Namespace) -> int:
    from imagemap.btf import load_btf
    from imagemap.btf.extrapolate import PixelwiseParams, TextureOptimizationParams, extrapolate
    from imagemap.io import read_image

    check_paths(
        {"-o": args.output},
        {"sample": args.sample, "--scans": args.scans, "--chart": args.chart},
        {"-o": (".npz",)},
    )
    if args.radius is not None and args.radius < 0:
        raise InputError(f"--radius: must be >= 0, got {args.radius}")
    if args.seed < 0:
        raise InputError(f"--seed: must be >= 0, got {args.seed}")
    if not 0 <= args.max_rotation <= 20:  # NaN fails too
        raise InputError(f"--max-rotation: between 0 and 20 degrees, got {args.max_rotation}")
    if args.find_order and not args.register:
        raise InputError("--find-order: works on registered scans; add --register")
    if args.allow_misfit and not args.register:
        raise InputError("--allow-misfit: applies to registered scans; add --register")
    from imagemap.outputs import resolve

    for i, path in enumerate(args.scans):
        for earlier in args.scans[:i]:
            if resolve(path) == resolve(earlier):
                raise InputError(
                    f"--scans: {path} is given twice (also as {earlier}); four scans under "
                    "four lamp directions are needed"
                )
    backend = args.backend
    if args.search is not None:
        _log().warning("--search is deprecated; use --backend (approximate = pca_kdtree)")
        if backend is None:
            backend = {"approximate": "pca_kdtree", "exact": "kdtree"}.get(args.search, args.search)
    kind = PixelwiseParams if args.method == "pixelwise" else TextureOptimizationParams
    defaults = kind()
    ws = defaults.ws if args.ws is None else _weight(args.ws, "--ws")
    wc = defaults.wc if args.wc is None else _weight(args.wc, "--wc")
    if ws == 0 and wc == 0:
        raise InputError(
            f"--ws {ws:g}, --wc {wc:g}: both 0 leave nothing to match ({args.method} defaults: "
            f"--ws {defaults.ws:g} --wc {defaults.wc:g}); give one > 0"
        )
    radius = defaults.radius if args.radius is None else args.radius
    params: PixelwiseParams | TextureOptimizationParams
    if kind is PixelwiseParams:
        backend = backend or defaults.backend
        params = PixelwiseParams(radius=radius, ws=ws, wc=wc, backend=backend, seed=args.seed)
    else:
        params = TextureOptimizationParams(radius=radius, ws=ws, wc=wc, seed=args.seed)

    sample = load_btf(args.sample, finite=True)
    from imagemap.btf.extrapolate import check_scans

    scans = check_scans(
        [read_image(path) for path in args.scans], [f"--scans {path}" for path in args.scans]
    )
    response = None if args.linear_scans else _response(args.chart)
    if args.register:
        from imagemap.btf.registration import register_scans

        registration = register_scans(
            scans,
            max_rotation=args.max_rotation,
            response=response,
            names=[f"--scans {path}" for path in args.scans],
        )
        if registration.suspect and not args.allow_misfit:
            from imagemap.btf.registration import MIN_CONFIDENCE

            shown = ", ".join(
                f"{args.scans[i]} (match confidence {registration.confidences[i]:.1f})"
                for i in registration.suspect
            )
            raise InputError(
                f"--scans: {shown} does not fit {args.scans[0]} (correct alignments measure "
                f"{MIN_CONFIDENCE:.0f} and more): a scan of another material or piece, or a "
                "failed alignment; nothing written (--allow-misfit goes on anyway)"
            )
        scans = registration.images
        if args.find_order:
            from imagemap.btf.extrapolate import constraint_images, prepare_scans
            from imagemap.btf.orientation import apply_orientation, orient_to_sample

            sample_images = constraint_images(sample)
            prepared = prepare_scans(scans, sample_images, response=response)
            _, hypothesis, _ = orient_to_sample(prepared, sample_images, seed=args.seed)
            scans = apply_orientation(scans, hypothesis)
        _log().info(
            "registered: azimuths %s, quarter turns %s, angles %s, shifts %s",
            registration.azimuths,
            registration.turns,
            [round(a, 2) for a in registration.angles],
            [tuple(round(v, 2) for v in s) for s in registration.shifts],
        )
    elif any(s.shape != scans[0].shape for s in scans):
        raise InputError(
            f"--scans: the four scans differ in size {[s.shape for s in scans]} "
            "(--register aligns turned and shifted scans)"
        )
    result = extrapolate(sample, scans, params, response=response, quiet=args.quiet)
    result.save(args.output)
    if not args.quiet:
        print(
            f"wrote {args.output}: {result.shape[0]}x{result.shape[1]} texels, "
            f"k = {result.n_components}",
            file=sys.stderr,
        )
    return 0


def _weight(value: float, name: str) -> float:
    if not value >= 0 or value == float("inf"):  # NaN fails the first test
        raise InputError(f"{name}: a finite weight >= 0, got {value}")
    return value


def _response(chart: str | None):
    """The scanner response: fitted from a chart scan, or the paper's Table 1."""
    from imagemap.btf.constraints import TABLE1_RESPONSE

    if chart is None:
        return TABLE1_RESPONSE
    from imagemap.btf.response import fit_chart_response
    from imagemap.io import read_image

    try:
        fit = fit_chart_response(read_image(chart))
    except InputError as exc:
        raise InputError(f"--chart {chart}: {exc}") from exc
    r = fit.response
    _log().info(
        "scanner response from %s: offsets %s, multipliers %s, gammas %s (RMS %s)",
        chart,
        [round(v, 4) for v in r.offsets],
        [round(v, 3) for v in r.multipliers],
        [round(v, 3) for v in r.gammas],
        [round(v, 4) for v in fit.rms_scan_error],
    )
    return r


def _render(args: argparse.Namespace) -> int:
    import numpy as np

    from imagemap.btf import load_btf
    from imagemap.io import write_image
    from imagemap.render import display_gamma

    check_paths({"-o": args.output}, {"btf": args.btf}, {"-o": (".png",)})
    for name, (theta, phi) in (("--light", args.light), ("--view", args.view)):
        if not (np.isfinite(theta) and np.isfinite(phi) and 0 <= theta <= 90):
            raise InputError(f"{name}: THETA in 0..90 and a finite PHI, got {theta} {phi}")
    if not (np.isfinite(args.exposure) and args.exposure > 0):
        raise InputError(f"--exposure: a finite number > 0, got {args.exposure}")
    btf = load_btf(args.btf, finite=True)
    light = btf.nearest_light(*args.light)
    view = btf.nearest_view(*args.view)
    image = np.clip(btf.image(light, view) * args.exposure, 0.0, 1.0)
    if not args.linear:
        image = display_gamma(image)
    write_image(args.output, image)
    return 0


def _experiment(args: argparse.Namespace) -> int:
    from imagemap.btf.experiment import (
        MATERIAL_SOURCES,
        MIN_SAMPLE_SIZE,
        MIN_SIZE,
        ExperimentParams,
        format_table,
        run_experiment,
    )
    from imagemap.outputs import check_output_directory

    if args.size < MIN_SIZE:
        raise InputError(f"--size: at least {MIN_SIZE} texels, got {args.size}")
    if args.sample_size is not None:
        # One cut-out side for every material.
        if not MIN_SAMPLE_SIZE <= args.sample_size < args.size:
            raise InputError(
                f"--sample-size: from {MIN_SAMPLE_SIZE} to --size - 1 = {args.size - 1}, got "
                f"{args.sample_size} (a cut-out as large as the sample is the reference "
                "itself: every error would be 0)"
            )
        sample_size, sample_sizes = args.sample_size, {}
    else:
        # The paper's proportions: a quarter of the side, half for the cloths (256 of 512).
        sample_size = max(MIN_SAMPLE_SIZE, args.size // 4)
        sample_sizes = {m: max(MIN_SAMPLE_SIZE, args.size // 2) for m in ("cloth", "velvet")}
    unknown = [m for m in args.materials if m not in MATERIAL_SOURCES]
    if unknown:
        raise InputError(f"--materials: unknown {unknown}; choose from {sorted(MATERIAL_SOURCES)}")
    if args.seed < 0:
        raise InputError(f"--seed: must be >= 0, got {args.seed}")
    if args.methods:
        from imagemap.btf.experiment import method_names

        known = method_names()
        unknown = [m for m in args.methods if m not in known]
        if unknown:
            raise InputError(f"--methods: unknown {unknown}; choose from {known}")
    check_output_directory(args.out, "--out folder")
    params = ExperimentParams(
        size=args.size,
        sample_size=sample_size,
        sample_sizes=sample_sizes,
        search=args.search,
        seed=args.seed,
    )
    rows = run_experiment(
        args.out,
        materials=args.materials,
        params=params,
        methods=args.methods,
        quiet=args.quiet,
    )
    if not args.quiet:
        print(format_table(rows))
        print(f"wrote {Path(args.out) / 'table2.csv'}, table2.md and comparison PNGs")
    return 0
