"""Photometric stereo on a real grey sphere (tests/data/psm_gray): the figures of docs/btf.md.

The sphere's normals and heights are known from its mask's circle, so every variant is
scored by the mean angular error of the normals on the mask (degrees) and the RMS error of
the heights (pixels, after removing the mean). Prints markdown tables.

    python benchmarks/photometric_sphere.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from imagemap.btf.integration import frankot_chellappa, poisson_integration  # noqa: E402
from imagemap.btf.photometric import (  # noqa: E402
    SATURATION_LEVEL,
    SHADOW_LEVEL,
    photometric_stereo,
    split_alpha,
)
from imagemap.btf.photometric_io import read_image_stack, read_lights, read_mask  # noqa: E402

DATA = ROOT / "tests" / "data" / "psm_gray"
#: Fractions of the sphere's samples clipped by a simulated overexposure.
CLIPPED_FRACTIONS = (0.05, 0.15, 0.30)


def load():
    """Grey images (N, H, W, 1), lights (N, 3), mask (H, W)."""
    images = read_image_stack([DATA / f"gray.{i}.png" for i in range(12)])
    return images, read_lights(DATA / "lights.txt"), read_mask(DATA / "mask.png", images.shape[1:3])


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


def main() -> None:
    images, lights, mask = load()
    truth, depth = sphere(mask)
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
    for label, source in (("real", grey), ("Lambertian", lambertian)):
        reference, _ = photometric_stereo(source, lights, mask=mask)
        for fraction in CLIPPED_FRACTIONS:
            clipped = overexpose(source, mask, fraction)
            affected = mask & (clipped >= 1.0).any(axis=0)
            kept, _ = photometric_stereo(clipped, lights, mask=mask)
            dropped, _ = photometric_stereo(clipped, lights, mask=mask, **cut)
            print(
                f"| {label} {fraction:.0%} | {affected.sum()} of {mask.sum()} | "
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
        ("Frankot-Chellappa over the whole frame", frankot_chellappa(whole)),
        ("Frankot-Chellappa, background set flat", frankot_chellappa(masked, mask=mask)),
        (
            "least squares on the mask (Poisson; the command)",
            poisson_integration(masked, mask=mask),
        ),
        ("least squares on the mask, true normals", poisson_integration(truth, mask=mask)),
    ):
        print(f"| {name} | {np.ptp(height[mask]):.1f} | {height_error(height, depth, mask):.2f} |")


if __name__ == "__main__":
    main()
