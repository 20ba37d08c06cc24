"""Photometric stereo on a grey sphere under 12 known lights: the figures of docs/btf.md.

By default the sphere is the generated one (:func:`data_gen.photometric.grey_sphere`:
glossy, with attached and cast shadows, ambient light, noise and 8-bit levels), whose
normals and heights are known exactly. ``--psm DIR`` runs on psmImages' real "gray" set
(S. Seitz) instead, which the user fetches (no licence is stated for it, so it is not
redistributed here; docs/real_data.md): DIR holds ``gray/gray.0.tga`` ..
``gray/gray.11.tga``, ``gray/gray.mask.tga`` and ``lights.txt``, as psmImages.zip and
github.com/xiumingzhang/photometric-stereo's ``psmImages`` folder do. Its images are
reduced as the copy the tests once held was (4 x 4 pixel blocks averaged, the mean of R,
G, B, 8-bit again: 128 x 85) unless ``--full-size``; its normals and heights follow from
the mask's circle. Every variant is scored by the mean angular error of the normals on
the mask (degrees) and the RMS error of the heights (pixels, after removing the mean).
Prints markdown tables.

    python benchmarks/photometric_sphere.py [--seed S]
    python benchmarks/photometric_sphere.py --psm scratch/psmImages [--full-size]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from imagemap.btf.integration import frankot_chellappa, poisson_integration  # noqa: E402
from imagemap.btf.photometric import (  # noqa: E402
    SATURATION_LEVEL,
    SHADOW_LEVEL,
    flat_where_left_out,
    photometric_stereo,
    split_alpha,
)
from imagemap.btf.photometric_io import read_image_stack, read_lights  # noqa: E402

#: Fractions of the sphere's samples clipped by a simulated overexposure.
CLIPPED_FRACTIONS = (0.05, 0.15, 0.30)
#: psmImages' pictures are reduced by this factor along each axis (unless --full-size).
PSM_REDUCTION = 4


def load_generated(seed: int = 0):
    """Grey images (N, H, W, 1), lights (N, 3), mask (H, W), true normals and heights."""
    from data_gen.photometric import grey_sphere

    made = grey_sphere(seed)
    return made.images[..., None], made.lights, made.mask, made.normals, made.heights


def load_psm(folder: Path, reduction: int = PSM_REDUCTION):
    """psmImages' grey set: images (N, H, W, 1), lights, mask; normals and heights from
    the mask's circle. ``reduction`` > 1 averages blocks of that side (8-bit again)."""
    folder = Path(folder)
    colour = read_image_stack([folder / "gray" / f"gray.{i}.tga" for i in range(12)])
    # From the files' 8-bit levels in double precision, each channel's blocks averaged
    # before the channels (the order the reduced copy was made in: float32, or the other
    # order, moves a mean across a rounding boundary in 490-1,116 of its 130,560 samples).
    levels = np.round(colour[..., :3].astype(np.float64) * 255.0) / 255.0
    mask_image = read_image_stack([folder / "gray" / "gray.mask.tga"])[0, ..., :3].mean(-1)
    n, h, w = levels.shape[:3]
    h, w = h // reduction * reduction, w // reduction * reduction

    def blocks(a):  # (..., H, W, C) -> block means
        shape = (*a.shape[:-3], h // reduction, reduction, w // reduction, reduction, a.shape[-1])
        return a[..., :h, :w, :].reshape(shape).mean(axis=(-4, -2))

    grey = blocks(levels).mean(axis=-1)  # the sphere is grey: R, G, B differ by 0.005
    if reduction > 1:
        grey = np.round(grey * 255.0) / 255.0
    mask = blocks(mask_image[..., None])[..., 0] >= 0.5  # at least half inside the mask
    truth, depth = sphere(mask)
    return (
        grey[..., None].astype(np.float32),
        read_lights(folder / "lights.txt"),
        mask,
        truth,
        depth,
    )


def sphere(mask):
    """Normals (H, W, 3) and heights (H, W) of the sphere the mask outlines."""
    ys, xs = np.nonzero(mask)
    cy, cx, r = ys.mean(), xs.mean(), np.sqrt(mask.sum() / np.pi)
    yy, xx = np.mgrid[0 : mask.shape[0], 0 : mask.shape[1]]
    nx, ny = (xx - cx) / r, -(yy - cy) / r
    nz = np.sqrt(np.clip(1 - nx**2 - ny**2, 0, None))
    return np.stack([nx, ny, nz], -1), r * nz


def angular_error(normals, truth, where) -> float:
    cosine = np.clip((normals * truth).sum(-1), -1.0, 1.0)
    return float(np.degrees(np.arccos(cosine))[where].mean())


def height_error(height, truth, mask) -> float:
    difference = (height[mask] - height[mask].mean()) - (truth[mask] - truth[mask].mean())
    return float(np.sqrt((difference**2).mean()))


def overexpose(images, mask, fraction):
    """Images scaled so that ``fraction`` of the sphere's samples clip, 8-bit again."""
    gain = 1.0 / np.quantile(images[:, mask], 1.0 - fraction)
    return np.round(np.clip(images * gain, 0.0, 1.0) * 255.0) / 255.0


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=0, help="the generated sphere's seed")
    parser.add_argument("--psm", type=Path, help="a psmImages folder (gray/, lights.txt)")
    parser.add_argument("--full-size", action="store_true", help="psmImages unreduced")
    args = parser.parse_args(argv)
    if args.psm is not None:
        reduction = 1 if args.full_size else PSM_REDUCTION
        images, lights, mask, truth, depth = load_psm(args.psm, reduction)
        label = "real"
    else:
        images, lights, mask, truth, depth = load_generated(args.seed)
        label = "generated"
    print(f"{label} sphere: {mask.shape[1]} x {mask.shape[0]}, {int(mask.sum())} px on it\n")
    cut = {"min_intensity": SHADOW_LEVEL, "max_intensity": SATURATION_LEVEL}

    print("| input | normals' mean error (deg) |\n|---|---:|")
    grey = images[..., 0]
    rows = {
        "grey, whole frame solved, no cut-offs (black samples dropped)": photometric_stereo(
            grey, lights
        ),
        "grey, mask, shadow and saturation cut-offs (the command)": photometric_stereo(
            grey, lights, mask=mask, **cut
        ),
    }
    alpha = mask[None, ..., None].repeat(len(images), 0).astype(np.float32)
    rgba = np.concatenate([images.repeat(3, -1), alpha], -1)
    rows["RGBA, alpha averaged into the intensity (before #35)"] = photometric_stereo(
        rgba.mean(-1), lights
    )
    rows["grey + alpha, alpha averaged (before #35)"] = photometric_stereo(
        np.concatenate([images, alpha], -1).mean(-1), lights
    )
    colour, alpha_mask = split_alpha(rgba)
    rows["RGBA, alpha as the mask (now)"] = photometric_stereo(
        colour, lights, mask=alpha_mask, **cut
    )
    rows["grey, the lights read with y down (the wrong frame)"] = photometric_stereo(
        grey, lights * [1.0, -1.0, 1.0], mask=mask, **cut
    )
    for name, (normals, _) in rows.items():
        print(f"| {name} | {angular_error(normals, truth, mask):.2f} |")

    print("\n| shadow cut-off (full scale) | mean error (deg) |\n|---|---:|")
    for level in (0.0, 2 / 255, 5 / 255, 10 / 255, 20 / 255):
        normals, _ = photometric_stereo(grey, lights, mask=mask, min_intensity=level)
        print(f"| {level * 255:.0f}/255 | {angular_error(normals, truth, mask):.2f} |")

    print(
        "\n| samples clipped | pixels with a clipped sample | before clipping | clipped, kept "
        "| clipped, dropped (the command) | all pixels: kept / dropped |\n"
        "|---:|---:|---:|---:|---:|---:|"
    )
    # The same sphere rendered Lambertian (albedo 0.6, 8-bit) under the same lights: where
    # the model holds, what the cut-off can do.
    shading = np.clip(np.einsum("hwc,nc->nhw", truth, lights), 0.0, None) * mask
    lambertian = np.round(0.6 * shading * 255.0) / 255.0
    for name, source in ((label, grey), ("Lambertian", lambertian)):
        reference, _ = photometric_stereo(source, lights, mask=mask)
        for fraction in CLIPPED_FRACTIONS:
            clipped = overexpose(source, mask, fraction)
            affected = mask & (clipped >= 1.0).any(axis=0)
            kept, _ = photometric_stereo(clipped, lights, mask=mask)
            dropped, _ = photometric_stereo(clipped, lights, mask=mask, **cut)
            print(
                f"| {name} {fraction:.0%} | {affected.sum()} of {mask.sum()} | "
                f"{angular_error(reference, truth, affected):.2f} | "
                f"{angular_error(kept, truth, affected):.2f} | "
                f"{angular_error(dropped, truth, affected):.2f} | "
                f"{angular_error(kept, truth, mask):.2f} / "
                f"{angular_error(dropped, truth, mask):.2f} |"
            )

    print("\n| heights | relief (px) | RMS error (px) |\n|---|---:|---:|")
    whole, _ = photometric_stereo(grey, lights, **cut)
    masked, _ = photometric_stereo(grey, lights, mask=mask, **cut)
    print(f"| truth | {np.ptp(depth[mask]):.1f} | 0 |")
    for name, height in (
        ("Frankot-Chellappa over the whole frame", frankot_chellappa(flat_where_left_out(whole))),
        ("Frankot-Chellappa, background set flat", frankot_chellappa(masked, mask=mask)),
        (
            "least squares on the mask (Poisson; the command)",
            poisson_integration(masked, mask=mask),
        ),
        ("least squares on the mask, true normals", poisson_integration(truth, mask=mask)),
    ):
        print(f"| {name} | {np.ptp(height[mask]):.1f} | {height_error(height, depth, mask):.2f} |")

    print("\n| lights' angle from the view (deg) | condition number | mean error (deg) |")
    print("|---:|---:|---:|")
    for polar, condition, error in condition_rows():
        print(f"| {polar:g} | {condition:.1f} | {error:.2f} |")


#: The cone's angles of :func:`condition_rows` (degrees from the view axis).
CONE_ANGLES = (40.0, 20.0, 10.0, 5.0, 3.0, 2.0, 1.5, 1.0, 0.5)


def condition_rows(noise: float = 0.005, seed: int = 0) -> list[tuple[float, float, float]]:
    """What the light matrix' condition number costs (the figures of
    :data:`imagemap.btf.photometric.MAX_LIGHT_CONDITION`): a Lambertian sphere (96 x 96,
    albedo 0.7) under 12 lights on a cone around the view, Gaussian noise of ``noise``
    and 8-bit levels; per cone angle (condition number, mean error on the sphere)."""
    rng = np.random.default_rng(seed)
    side = 96
    yy, xx = np.mgrid[0:side, 0:side]
    x, y = (xx - side / 2 + 0.5) / (side / 2 - 2), -(yy - side / 2 + 0.5) / (side / 2 - 2)
    mask = x**2 + y**2 < 0.8
    truth = np.stack([x, y, np.sqrt(np.clip(1 - x**2 - y**2, 0, None))], -1)
    azimuth = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    rows = []
    for polar in CONE_ANGLES:
        t = np.deg2rad(polar)
        lights = np.stack(
            [np.sin(t) * np.cos(azimuth), np.sin(t) * np.sin(azimuth), np.full(12, np.cos(t))], 1
        )
        shade = 0.7 * np.clip(np.einsum("hwc,nc->nhw", truth, lights), 0, None)
        noisy = np.round(np.clip(shade + rng.normal(0, noise, shade.shape), 0, 1) * 255) / 255
        found, _ = photometric_stereo(
            noisy, lights, mask=mask, min_intensity=SHADOW_LEVEL, max_intensity=SATURATION_LEVEL
        )
        rows.append((polar, float(np.linalg.cond(lights)), angular_error(found, truth, mask)))
    return rows


if __name__ == "__main__":
    main()
