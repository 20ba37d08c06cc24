"""``imagemap btf ma-fit`` and ``ma-synthesize``: the moving-average BTF model."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

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


def register(btf_subparsers: argparse._SubParsersAction) -> None:
    """Add ``ma-fit`` and ``ma-synthesize`` to the ``imagemap btf`` command group."""
    from imagemap.cli import add_common_options

    p = btf_subparsers.add_parser(
        "ma-fit",
        help="fit the moving-average BTF model to a sample BTF (.npz model)",
        description=(
            "Range map by photometric stereo on the top view, K-means subspaces in CIELAB, "
            "K-L decorrelation, Gaussian-Laplacian pyramid and one random-decrement "
            "moving-average kernel per mono-spectral band-limited factor."
        ),
    )
    p.add_argument("sample", help="sample BTF (.npz written by imagemap, or UBO2014 .btf)")
    p.add_argument("-o", "--output", required=True, help="model file (.npz)")
    p.add_argument("--subspaces", type=int, default=8, help="K-means subspaces (1 = one model)")
    p.add_argument("--levels", type=int, default=4, help="pyramid levels")
    p.add_argument("--support", type=int, default=13, help="odd MA kernel width")
    p.add_argument("--kernel", choices=("signature", "spectral_root"), default="signature")
    p.add_argument("--no-deshade", action="store_true", help="model images as measured")
    p.add_argument("--bump-scale", type=float, default=1.0, help="range-map height multiplier")
    p.add_argument("--range-map", metavar="PNG", help="also write the recovered range map")
    p.add_argument("--seed", type=int, default=0)
    add_common_options(p)
    p.set_defaults(func=_fit)

    p = btf_subparsers.add_parser(
        "ma-synthesize",
        help="enlarged material from a moving-average model: BTF (.npz) or one image (.png)",
        description=(
            "Any output size; the result tiles seamlessly when the size is a multiple of "
            "2**(levels - 1) and of the range-map tile. A .npz output is a BTF on the "
            "sample's eigen-ABRDFs (give --sample); a .png output is the material under "
            "--light and --view, bump mapped with the enlarged range map."
        ),
    )
    p.add_argument("model", help="model file from 'imagemap btf ma-fit'")
    p.add_argument("-o", "--output", required=True, help="output BTF (.npz) or image (.png)")
    p.add_argument("--size", nargs=2, type=int, default=(512, 512), metavar=("H", "W"))
    p.add_argument("--sample", help="sample BTF whose U the output shares (.npz output)")
    p.add_argument("--light", nargs=2, type=float, default=(45.0, 0.0), metavar=("THETA", "PHI"))
    p.add_argument("--view", nargs=2, type=float, default=(0.0, 0.0), metavar=("THETA", "PHI"))
    p.add_argument("--exposure", type=float, default=1.0, help="multiply radiance before gamma")
    p.add_argument("--linear", action="store_true", help="no display gamma (default 2.2)")
    p.add_argument("--seed", type=int, default=0)
    add_common_options(p)
    p.set_defaults(func=_synthesize)


def _fit(args: argparse.Namespace) -> int:
    import numpy as np

    from imagemap.btf import load_btf
    from imagemap.btf.moving_average import (
        MIN_COARSE_SIDE,
        MAParams,
        compression_ratios,
        fit_moving_average_btf,
        max_levels,
        parameter_count,
    )
    from imagemap.io import write_image

    check_paths(
        {"-o": args.output, "--range-map": args.range_map},
        {"sample": args.sample},
        {"-o": (".npz",), "--range-map": (".png",)},
    )
    if args.levels < 1:
        raise InputError(f"--levels: at least 1, got {args.levels}")
    if args.support < 1 or args.support % 2 == 0:
        raise InputError(f"--support: a positive odd width, got {args.support}")
    if args.subspaces < 1:
        raise InputError(f"--subspaces: at least 1, got {args.subspaces}")
    if not (np.isfinite(args.bump_scale) and args.bump_scale >= 0):
        raise InputError(f"--bump-scale: a finite multiplier >= 0, got {args.bump_scale}")
    if args.seed < 0:
        raise InputError(f"--seed: must be >= 0, got {args.seed}")
    params = MAParams(
        levels=args.levels,
        support=args.support,
        kernel=args.kernel,
        n_subspaces=args.subspaces,
        deshade=not args.no_deshade,
        bump_scale=args.bump_scale,
    )
    sample = load_btf(args.sample, finite=True)
    most = max_levels(sample.shape)
    if args.levels > most:
        raise InputError(
            f"--levels {args.levels}: the sample {args.sample} is {sample.shape[0]}x"
            f"{sample.shape[1]} texels; its pyramid has room for at most {most} levels "
            f"(the coarsest at least {MIN_COARSE_SIDE} texels)"
        )
    model = fit_moving_average_btf(sample, params=params, seed=args.seed)
    model.save(args.output)
    if args.range_map:
        height = model.range_map
        write_image(args.range_map, (height - height.min()) / max(float(np.ptp(height)), 1e-12))
    if not args.quiet:
        counts = parameter_count(model)
        ratios = compression_ratios(model, sample.shape, tsvd_rank=sample.n_components)
        print(
            f"wrote {args.output}: {model.n_subspaces} subspaces, {counts['total']} numbers "
            f"({counts['kernels']} kernel taps, {counts['range_map']} range-map texels); "
            f"at the sample's {sample.shape[0]}x{sample.shape[1]}: {ratios['vs_raw']:.0f}x "
            f"smaller than raw, {ratios['vs_tsvd']:.0f}x smaller than TSVD k="
            f"{sample.n_components}",
            file=sys.stderr,
        )
    return 0


def _synthesize(args: argparse.Namespace) -> int:
    import numpy as np

    from imagemap.btf import load_btf
    from imagemap.btf.moving_average import (
        MovingAverageModel,
        sample_fingerprint,
        synthesis_bytes,
        synthesize_appearance,
        synthesize_btf,
    )
    from imagemap.btf.photometric import btf_direction_vectors
    from imagemap.io import write_image
    from imagemap.memory import check_memory
    from imagemap.render import display_gamma

    height, width = args.size
    if height < 1 or width < 1:
        raise InputError(f"--size: must be positive, got {height} {width}")
    check_paths(
        {"-o": args.output},
        {"model": args.model, "--sample": args.sample},
        {"-o": (".npz", ".png")},
    )
    for name, (theta, phi) in (("--light", args.light), ("--view", args.view)):
        if not (np.isfinite(theta) and np.isfinite(phi) and 0 <= theta <= 90):
            raise InputError(f"{name}: THETA in 0..90 and a finite PHI, got {theta} {phi}")
    if not (np.isfinite(args.exposure) and args.exposure > 0):
        raise InputError(f"--exposure: a finite number > 0, got {args.exposure}")
    if args.seed < 0:
        raise InputError(f"--seed: must be >= 0, got {args.seed}")
    model = MovingAverageModel.load(args.model)
    suffix = Path(args.output).suffix.lower()
    sample = None
    if suffix == ".npz":
        if not args.sample:
            raise InputError("--sample: required for a BTF (.npz) output (its U is shared)")
        sample = load_btf(args.sample, finite=True)
        if model.subspace_of.shape != (sample.n_lights, sample.n_views) or (
            model.sample_digest and model.sample_digest != sample_fingerprint(sample)
        ):
            raise InputError(
                f"--sample {args.sample}: not the BTF the model {args.model} was fitted on "
                "(give the sample of 'imagemap btf ma-fit'; another material's eigen-ABRDFs "
                "would turn the synthesized textures into nonsense)"
            )
        if not model.sample_digest:
            _log().warning("%s: an older model without its sample's fingerprint", args.model)
    check_memory(
        synthesis_bytes(
            model, (height, width), n_components=None if sample is None else sample.n_components
        ),
        f"--size {height} {width}",
        advice="use a smaller --size (the result tiles seamlessly when repeated)",
    )
    if sample is not None:
        result = synthesize_btf(model, sample, (height, width), seed=args.seed)
        result.save(args.output)
    elif suffix == ".png":
        light = btf_direction_vectors(np.array([args.light]))[0]
        view = btf_direction_vectors(np.array([args.view]))[0]
        image = synthesize_appearance(model, light, view, (height, width), seed=args.seed)
        image = np.clip(image * args.exposure, 0.0, 1.0)
        write_image(args.output, image if args.linear else display_gamma(image))
    else:
        raise InputError(f"{args.output}: unsupported output {suffix!r} (use .npz or .png)")
    if not args.quiet:
        print(f"wrote {args.output}: {height}x{width}", file=sys.stderr)
    return 0
