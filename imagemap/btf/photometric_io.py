"""Files of a photometric-stereo set: the images (alpha kept), a mask, the lights.

:func:`read_image_stack` reads N images of one size into (N, H, W, C) in [0, 1], keeping an
alpha channel (:func:`imagemap.btf.photometric.split_alpha` turns it into a mask, never into
light); :func:`read_mask` reads a mask image; :func:`read_lights` the light directions.

Lights format (one light per line, in the order of the images; ``#`` starts a comment; numbers
separated by spaces or commas)::

    # psmImages' own lights.txt is read as it is: a first line holding only the count
    12
    0.403259 0.480808 0.778592      a vector towards the light (normalized here)
    ...

or, per line, two numbers: ``AZIMUTH ELEVATION`` in degrees (azimuth 0 = right, 90 = up
the image; elevation 90 = from the camera). All lines of a file use the same form. The
frame is the image's: x to the right, y up, z towards the camera (a light with z <= 0 or
elevation <= 0 cannot light a surface facing the camera and is refused: usually a sign
mistake).

Example
-------
>>> import tempfile
>>> path = Path(tempfile.mkdtemp()) / "lights.txt"
>>> _ = path.write_text("# az el\\n0 45\\n90 45\\n180, 45\\n")
>>> read_lights(path).round(3).tolist()[1]
[0.0, 0.707, 0.707]
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from imagemap.io import InputError, _load_raw, _to_unit_float

__all__ = ["LIGHTS_FORMAT", "read_image_stack", "read_lights", "read_mask"]

#: What ``--help`` says about the file (kept here with the reader).
LIGHTS_FORMAT = (
    "text file, one light per image in their order: 'X Y Z' (a vector towards the light; x "
    "right, y up, z towards the camera) or 'AZIMUTH ELEVATION' in degrees (0 = right, 90 = "
    "up; elevation 90 = from the camera); '#' comments; an optional first line holding only "
    "the count (psmImages' lights.txt). Example line: '0.40 0.48 0.78' or '50 51'"
)

#: Lines longer than this are not a lights file (a binary file given by mistake).
_MAX_LINE = 1000


def read_lights(path: str | os.PathLike) -> np.ndarray:
    """Unit vectors towards the lights, (N, 3) float64, from a lights file (see above).

    Raises
    ------
    InputError
        Naming the file and line: unreadable, mixed or wrong number of values, not
        finite, zero, at or behind the image plane, a count line that disagrees.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: lights file not found")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not a readable text lights file ({exc})") from None
    rows: list[tuple[int, list[float]]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        if len(line) > _MAX_LINE:
            raise InputError(f"{path}:{number}: line too long for a lights file")
        fields = [f for f in re.split(r"[\s,]+", line.split("#", 1)[0].strip()) if f]
        if not fields:
            continue
        try:
            rows.append((number, [float(f) for f in fields]))
        except ValueError:
            raise InputError(f"{path}:{number}: not numbers: {line.strip()!r}") from None
    count = None
    if rows and len(rows[0][1]) == 1:
        (number, (value,)) = rows.pop(0)
        if not (value.is_integer() and value >= 1):
            raise InputError(f"{path}:{number}: a count line must hold a whole number >= 1")
        count = int(value)
    if not rows:
        raise InputError(f"{path}: no lights")
    widths = {len(values) for _, values in rows}
    if len(widths) != 1 or widths.pop() not in (2, 3):
        number = next(n for n, v in rows if len(v) != len(rows[0][1]) or len(v) not in (2, 3))
        raise InputError(
            f"{path}:{number}: every line needs 3 numbers (X Y Z) or every line 2 "
            "(AZIMUTH ELEVATION)"
        )
    if count is not None and count != len(rows):
        raise InputError(f"{path}: the first line says {count} lights, the file has {len(rows)}")
    values = np.array([v for _, v in rows], dtype=np.float64)
    lines = [n for n, _ in rows]
    bad = ~np.isfinite(values).all(axis=1)
    if bad.any():
        raise InputError(f"{path}:{lines[int(np.argmax(bad))]}: not finite")
    if values.shape[1] == 2:
        azimuth, elevation = np.deg2rad(values[:, 0]), np.deg2rad(values[:, 1])
        low = (values[:, 1] <= 0) | (values[:, 1] > 90)
        if low.any():
            raise InputError(
                f"{path}:{lines[int(np.argmax(low))]}: elevation must be in (0, 90] degrees"
            )
        return np.stack(
            [
                np.cos(elevation) * np.cos(azimuth),
                np.cos(elevation) * np.sin(azimuth),
                np.sin(elevation),
            ],
            axis=1,
        )
    norms = np.linalg.norm(values, axis=1)
    behind = (norms == 0) | (values[:, 2] <= 0)
    if behind.any():
        raise InputError(
            f"{path}:{lines[int(np.argmax(behind))]}: the light vector must point towards the "
            "camera side (z > 0; x right, y up)"
        )
    return values / norms[:, None]


def _read_array(path: Path) -> np.ndarray:
    image = _to_unit_float(_load_raw(path), path)
    if image.ndim == 2:
        image = image[..., None]
    if image.ndim != 3 or image.shape[2] not in (1, 2, 3, 4):
        raise InputError(
            f"{path}: expected a grey, grey+alpha, RGB or RGBA image, got {image.shape}"
        )
    if not np.all(np.isfinite(image)):
        raise InputError(f"{path}: image has NaN or infinite values")
    return image


def read_image_stack(paths) -> np.ndarray:
    """N images of one size and channel count, (N, H, W, C) float32 in [0, 1], alpha kept.

    Raises
    ------
    InputError
        Naming the file: unreadable, NaN, or its size or channels differ from the first.

    Example
    -------
    >>> import tempfile
    >>> from imagemap.io import write_image
    >>> folder = Path(tempfile.mkdtemp())
    >>> paths = [write_image(folder / f"{i}.png", np.full((2, 3), 0.5)) for i in range(3)]
    >>> read_image_stack(paths).shape
    (3, 2, 3, 1)
    """
    paths = [Path(p) for p in paths]
    images: list[np.ndarray] = []
    for path in paths:
        image = _read_array(path)
        if images and image.shape != images[0].shape:
            raise InputError(
                f"{path}: {image.shape[1]}x{image.shape[0]} with {image.shape[2]} channels; "
                f"{paths[0]} is {images[0].shape[1]}x{images[0].shape[0]} with "
                f"{images[0].shape[2]}: every image must match"
            )
        images.append(image)
    return np.stack(images)


def read_mask(path: str | os.PathLike, shape: tuple[int, int]) -> np.ndarray:
    """A mask image as (H, W) bool: pixels at least half of full scale (alpha if the image
    has one) are inside. It must have ``shape`` and select at least one pixel.

    Example
    -------
    >>> import tempfile
    >>> from imagemap.io import write_image
    >>> path = write_image(Path(tempfile.mkdtemp()) / "m.png", np.eye(2))
    >>> read_mask(path, (2, 2)).tolist()
    [[True, False], [False, True]]
    """
    path = Path(path)
    image = _read_array(path)
    values = image[..., -1] if image.shape[2] in (2, 4) else image.max(axis=2)
    if values.shape != tuple(shape):
        raise InputError(
            f"{path}: mask is {values.shape[1]}x{values.shape[0]}, the images {shape[1]}x{shape[0]}"
        )
    mask = values >= 0.5
    if not mask.any():
        raise InputError(f"{path}: mask selects no pixel (none at half scale or more)")
    return mask
