"""``imagemap btf photometric``: normals, albedo and heights from images under known lights."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from imagemap.errors import InputError

#: The parser loads no scientific module (``imagemap --help`` stays fast): each command
#: imports what it needs when it runs, and register() imports imagemap.cli's helpers late
#: because imagemap.cli imports this module.
DEFERRED_IMPORTS = "command functions import their modules when run; the parser loads none"


def _log():
    """The ``imagemap`` logger (logging is imported when a command logs, not for its parser)."""
    import logging

    return logging.getLogger("imagemap")


#: --integration choices, as the API names them.
INTEGRATION_NAMES = {"poisson": "poisson", "frankot-chellappa": "frankot_chellappa"}

EXAMPLE = """\
example:
  imagemap btf photometric gray.{0..11}.png --lights lights.txt --mask mask.png \\
      -o normals.png --height height.npy --albedo albedo.png
  (the images in the lights' order: the shell's gray.*.png puts gray.10 before gray.2)

lights file (one line per image, in the order given):
  12                              optional: the count alone (psmImages' lights.txt)
  0.403259 0.480808 0.778592      X Y Z towards the light: x right, y up, z to the camera
or
  50.0 51.1                       AZIMUTH ELEVATION in degrees (0 = right, 90 = up)
"""


def register(btf_subparsers: argparse._SubParsersAction) -> None:
    """Add ``photometric`` to the ``imagemap btf`` command group."""
    from imagemap.cli import add_common_options

    p = btf_subparsers.add_parser(
        "photometric",
        help="normal map, albedo and heights from photographs under known lights",
        description=(
            "Least-squares photometric stereo (Woodham) on linear images of one view under "
            "N >= 3 known distant lights, then the heights by integrating the normals on the "
            "mask. Samples darker than --shadow-level or with a channel at --saturation-level "
            "or above are left out of their pixel's fit (a pixel keeps its clipped samples "
            "when fewer than half its lights would remain). An alpha channel is the mask, "
            "never light. Outputs are checked against the inputs before any work and written "
            "together or not at all."
        ),
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("images", nargs="+", help="N >= 3 images (PNG, TIFF), one per light")
    p.add_argument("--lights", required=True, metavar="FILE", help="light directions (below)")
    p.add_argument("--mask", metavar="PNG", help="the object (white); default: every pixel")
    p.add_argument("-o", "--output", required=True, help="normal map (.png, RGB = (n + 1) / 2)")
    p.add_argument(
        "--height",
        metavar="FILE",
        help="heights: .npy (float32 pixels, NaN off the mask) or .png (16-bit, scaled to "
        "the mask's range; the scale is printed)",
    )
    p.add_argument("--albedo", metavar="PNG", help="albedo (grey or RGB, 8-bit)")
    p.add_argument(
        "--integration",
        choices=tuple(INTEGRATION_NAMES),
        default="poisson",
        help="poisson: least squares on the mask only (default); frankot-chellappa: Fourier "
        "over the frame, the background set flat",
    )
    p.add_argument(
        "--gamma",
        type=float,
        default=1.0,
        help="the images' encoding gamma: values are raised to it (2.2 for sRGB files; "
        "default 1: linear, as raw or linear TIFF)",
    )
    p.add_argument(
        "--shadow-level",
        type=float,
        default=None,
        help="drop samples at or below this fraction of full scale (default 2/255)",
    )
    p.add_argument(
        "--saturation-level",
        type=float,
        default=None,
        help="drop samples with a channel at or above this fraction of full scale "
        "(default 0.99; 1 keeps every unclipped value, above 1 keeps all)",
    )
    add_common_options(p)
    p.set_defaults(func=_photometric)


def _warn_name_order(paths: list[str]) -> None:
    """Warn when the images are numbered and given in name order, not number order (the
    shell sorts img10 before img2; the lights file lists them by number)."""
    import re

    numbers = []
    for path in paths:
        found = re.findall(r"\d+", Path(path).name)
        if not found:
            return
        numbers.append(int(found[-1]))
    if len(set(numbers)) == len(numbers) and numbers != sorted(numbers):
        _log().warning(
            "images are not in the order of their numbers (%s, %s, ..); each is paired with "
            "the lights file's line of its position",
            paths[0],
            paths[1],
        )


def _fraction(value: float | None, default: float, name: str, upper: float) -> float:
    if value is None:
        return default
    if not 0.0 <= value <= upper:  # NaN fails too
        raise InputError(f"{name}: a fraction of full scale in 0..{upper:g}, got {value}")
    return float(value)


def _photometric(args: argparse.Namespace) -> int:
    import numpy as np

    from imagemap.btf.integration import integrate_normals
    from imagemap.btf.photometric import (
        SATURATION_LEVEL,
        SHADOW_LEVEL,
        check_light_matrix,
        flat_where_left_out,
        photometric_stereo,
        split_alpha,
        usable_samples,
    )
    from imagemap.btf.photometric_io import read_image_stack, read_lights, read_mask
    from imagemap.io import image_writer
    from imagemap.outputs import OutputPlan, resolve, write_all
    from imagemap.render import encode_normal_map

    # Options and paths first: nothing is read before they are known to be sound.
    if not (np.isfinite(args.gamma) and 0.1 <= args.gamma <= 10.0):
        raise InputError(f"--gamma: between 0.1 and 10, got {args.gamma}")
    shadow = _fraction(args.shadow_level, SHADOW_LEVEL, "--shadow-level", 1.0)
    saturation = _fraction(args.saturation_level, SATURATION_LEVEL, "--saturation-level", 2.0)
    if saturation <= shadow:
        raise InputError(
            f"--saturation-level {saturation:g} must be above --shadow-level {shadow:g}"
        )
    if len(args.images) < 3:
        raise InputError(f"images: photometric stereo needs 3 or more, got {len(args.images)}")
    _warn_name_order(args.images)
    seen: dict[Path, str] = {}
    for path in args.images:
        key = resolve(path)
        if key in seen:
            raise InputError(
                f"images: {path} is given twice (also as {seen[key]}); one image per light"
            )
        seen[key] = path
    plan = OutputPlan()
    for path in args.images:
        plan.add_input(path, "an input image")
    plan.add_input(args.lights, "--lights")
    if args.mask:
        plan.add_input(args.mask, "--mask")
    plan.add_output(args.output, "-o", suffixes=(".png",))
    if args.height:
        plan.add_output(args.height, "--height", suffixes=(".npy", ".png"))
    if args.albedo:
        plan.add_output(args.albedo, "--albedo", suffixes=(".png",))
    plan.check()

    lights = read_lights(args.lights)
    if len(lights) != len(args.images):
        raise InputError(
            f"--lights {args.lights}: {len(lights)} lights for {len(args.images)} images"
        )
    # Rank < 3 (identical lights, lights in one plane) decides no normal: refused before
    # the images are read. An ill-conditioned set is warned about by the solver.
    check_light_matrix(lights, f"--lights {args.lights}", warn=False)
    stack = read_image_stack(args.images)
    colour, alpha = split_alpha(stack)
    mask = alpha
    if alpha is not None and not alpha.any():
        raise InputError(f"images: the alpha channel of {args.images[0]}.. covers no pixel")
    if args.mask:
        given = read_mask(args.mask, colour.shape[1:3])
        mask = given if mask is None else mask & given
        if not mask.any():
            raise InputError(f"--mask {args.mask}: no pixel left inside the images' alpha")
    region = np.ones(colour.shape[1:3], bool) if mask is None else mask
    for path, image in zip(args.images, colour, strict=True):
        if image[region].max() <= shadow:
            raise InputError(
                f"{path}: black (no value above --shadow-level {shadow:g} on the mask): "
                "no light reached it"
            )
    linear = colour**args.gamma if args.gamma != 1.0 else colour
    levels = {"min_intensity": shadow**args.gamma, "max_intensity": saturation**args.gamma}
    used = usable_samples(linear, lights, mask=region, **levels)
    normals, albedo = photometric_stereo(
        linear, lights, mask=mask, lights_name=f"--lights {args.lights}", **levels
    )
    # Pixels whose samples decide no normal are left out (the solver warned, with their
    # share): no normal, albedo or height there; the maps get an alpha channel saying so.
    solved = region & np.all(np.isfinite(normals), axis=2)
    left_out = bool((region & ~solved).any())
    method = INTEGRATION_NAMES[args.integration]
    height = None
    if args.height:
        flat = flat_where_left_out(normals)
        height = integrate_normals(flat, mask=solved if left_out else mask, method=method)

    writers = {
        Path(args.output): image_writer(
            _with_alpha(encode_normal_map(flat_where_left_out(normals)), solved, left_out)
        )
    }
    if args.albedo:
        shown = np.nan_to_num(albedo[..., 0] if albedo.shape[2] == 1 else albedo)
        writers[Path(args.albedo)] = image_writer(
            _with_alpha(np.clip(shown, 0.0, 1.0), solved, left_out)
        )
    note = ""
    if height is not None:
        writers[Path(args.height)], note = _height_writer(Path(args.height), height, solved)
    write_all(writers)
    if not args.quiet:
        if note:
            print(note, file=sys.stderr)
        total = int(region.sum()) * len(lights)
        unsolved = int((region & ~solved).sum())
        print(
            f"wrote {args.output}: {int(solved.sum())} pixels solved from {len(lights)} "
            f"images{f', {unsolved} left out (transparent)' if left_out else ''}; "
            f"{total - int(used.sum())} of {total} samples left out (shadow, clipped, light "
            "behind)",
            file=sys.stderr,
        )
    return 0


def _with_alpha(picture, solved, left_out: bool):
    """``picture`` (H, W) or (H, W, 3) as it is, or, when pixels were left out, RGBA with
    alpha 0 where no normal was found (a grey picture repeated into RGB)."""
    import numpy as np

    if not left_out:
        return picture
    colour = picture if picture.ndim == 3 else np.repeat(picture[..., None], 3, axis=2)
    return np.concatenate([colour, solved[..., None].astype(colour.dtype)], axis=2)


def _height_writer(path: Path, height, region):
    """A writer of the heights and a note for the user: .npy float32 pixels (NaN off the
    mask), or a 16-bit PNG scaled to the mask's range (0 off the mask)."""
    import numpy as np

    from imagemap.io import image_writer

    if path.suffix.lower() == ".npy":
        values = np.where(region, height, np.nan).astype(np.float32)

        def write(tmp: Path) -> None:
            with open(tmp, "wb") as handle:
                np.save(handle, values, allow_pickle=False)

        return write, ""
    inside = height[region]
    low, span = float(inside.min()), float(np.ptp(inside))
    scaled = np.where(region, (height - low) / max(span, 1e-12), 0.0)
    note = f"wrote {path}: 16-bit heights, 0..65535 = {low:.3f}..{low + span:.3f} pixels"
    return image_writer(scaled, bits=16), note
