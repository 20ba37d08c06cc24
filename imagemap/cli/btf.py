"""``imagemap btf``: extrapolate a measured BTF sample, render it, reproduce Table 2."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from imagemap.io import InputError

log = logging.getLogger("imagemap")

METHODS = ("pixelwise", "texture_optimization")


def load_btf(path: str | Path):
    """A BTF from our ``.npz`` or a Bonn UBO2014 DFMF ``.btf`` file."""
    from imagemap.btf import BTF
    from imagemap.btf.ubo2014 import read_ubo2014

    path = Path(path)
    if path.suffix.lower() == ".btf":
        return read_ubo2014(path)
    if path.suffix.lower() == ".npz":
        return BTF.load(path)
    raise InputError(f"{path}: unsupported BTF format {path.suffix!r} (use .npz or .btf)")


def register(subparsers: argparse._SubParsersAction) -> None:
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
    p.add_argument("sample", help="sample BTF (.npz written by imagemap, or UBO2014 .btf)")
    p.add_argument(
        "--scans",
        nargs=4,
        required=True,
        metavar=("SCAN0", "SCAN90", "SCAN180", "SCAN270"),
        help="four scans of the large sample, light azimuths 0, 90, 180, 270",
    )
    p.add_argument("-o", "--output", required=True, help="output BTF (.npz)")
    p.add_argument("--method", choices=METHODS, default="pixelwise")
    p.add_argument("--radius", type=int, default=None, help="R (pixelwise 0, texture 8)")
    p.add_argument("--ws", type=float, default=None, help="surface weight (pixelwise 0)")
    p.add_argument("--wc", type=float, default=None, help="colour weight (pixelwise 1)")
    p.add_argument(
        "--search", choices=("approximate", "exact", "pynndescent"), default="approximate"
    )
    p.add_argument(
        "--linear-scans",
        action="store_true",
        help="scans are already linear (skip the Table 1 colour correction)",
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
    p.add_argument("-o", "--output", required=True, help="output PNG")
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
    p.add_argument("--sample-size", type=int, default=None, help="cut-out side (size / 4)")
    p.add_argument("--methods", nargs="+", default=None, help="subset of the methods")
    p.add_argument(
        "--search", choices=("approximate", "exact", "pynndescent"), default="approximate"
    )
    p.add_argument("--seed", type=int, default=0)
    add_common_options(p)
    p.set_defaults(func=_experiment)

    try:  # issue 6's moving-average subcommands hang off the same `btf` group
        from imagemap.cli import btf_ma
    except ImportError:
        btf_ma = None
    if btf_ma is not None:
        btf_ma.register(btf_subparsers)


def _extrapolate(args: argparse.Namespace) -> int:
    from imagemap.btf.extrapolate import ExtrapolationParams, TextureOptimizationParams, extrapolate
    from imagemap.io import read_image

    sample = load_btf(args.sample)
    scans = [read_image(path) for path in args.scans]
    if any(s.shape != scans[0].shape for s in scans):
        raise InputError(f"--scans: the four scans differ in size {[s.shape for s in scans]}")
    if args.method == "pixelwise":
        defaults = ExtrapolationParams()
        params = ExtrapolationParams(
            radius=defaults.radius if args.radius is None else args.radius,
            ws=defaults.ws if args.ws is None else args.ws,
            wc=defaults.wc if args.wc is None else args.wc,
            search=args.search,
            seed=args.seed,
        )
    else:
        defaults = TextureOptimizationParams()
        params = TextureOptimizationParams(
            radius=defaults.radius if args.radius is None else args.radius,
            ws=defaults.ws if args.ws is None else args.ws,
            wc=defaults.wc if args.wc is None else args.wc,
            seed=args.seed,
        )
    response = None if args.linear_scans else _table1()
    result = extrapolate(sample, scans, params, response=response, quiet=args.quiet)
    result.save(args.output)
    if not args.quiet:
        print(
            f"wrote {args.output}: {result.shape[0]}x{result.shape[1]} texels, "
            f"k = {result.n_components}",
            file=sys.stderr,
        )
    return 0


def _table1():
    from imagemap.btf.constraints import TABLE1_RESPONSE

    return TABLE1_RESPONSE


def _render(args: argparse.Namespace) -> int:
    import numpy as np

    from imagemap.io import write_image

    btf = load_btf(args.btf)
    light = btf.nearest_light(*args.light)
    view = btf.nearest_view(*args.view)
    image = np.clip(btf.image(light, view) * args.exposure, 0.0, 1.0)
    if not args.linear:
        image = image ** (1 / 2.2)
    write_image(args.output, image)
    return 0


def _experiment(args: argparse.Namespace) -> int:
    from imagemap.btf.experiment import ExperimentParams, format_table, run_experiment

    if args.size < 16:
        raise InputError(f"--size: at least 16 texels, got {args.size}")
    sample_size = args.sample_size or max(8, args.size // 4)
    params = ExperimentParams(
        size=args.size, sample_size=sample_size, search=args.search, seed=args.seed
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
