"""Reading and writing images, depth maps and arrays, with checks at the door.

Every reader names the file and the problem when the input is bad (raising
:class:`InputError`), and every writer is atomic: the data go to a temporary
file in the destination folder, which is renamed over the target only once it
is complete, so an interrupted run never leaves a half-written file.
"""

from __future__ import annotations

import contextlib
import os
import re
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from imagemap.errors import InputError

__all__ = [
    "InputError",
    "atomic_path",
    "read_depth",
    "read_image",
    "read_npz",
    "write_image",
    "write_npz",
]

DEPTH_SUFFIXES = (".png", ".tif", ".tiff", ".npy")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    On any exception the temporary file is removed and ``path`` is untouched.

    Examples
    --------
    >>> import shutil, tempfile
    >>> target = Path(tempfile.mkdtemp()) / "out.npy"
    >>> with atomic_path(target) as tmp:
    ...     np.save(tmp, np.arange(3))
    ...     target.exists()  # written beside it, renamed at the end
    False
    >>> np.load(target)
    array([0, 1, 2])
    >>> with atomic_path(target) as tmp:
    ...     np.save(tmp, np.zeros(3))
    ...     raise RuntimeError("interrupted")
    Traceback (most recent call last):
    RuntimeError: interrupted
    >>> np.load(target), [p.name for p in target.parent.iterdir()]  # untouched, no temporary
    (array([0, 1, 2]), ['out.npy'])
    >>> shutil.rmtree(target.parent)
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    suffix = suffix if suffix is not None else "".join(path.suffixes)
    tmp_path = make_temporary(path, suffix)
    try:
        yield tmp_path
        # mkstemp creates 0600; a finished output gets the usual mode (0666 less umask).
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_path, 0o666 & ~umask)
        os.replace(tmp_path, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        raise


#: Marks the temporary files of atomic writes (``.STEM.XXXXXXXX.imagemap-tmp.SUFFIX``): a
#: resumed batch removes what a killed run left of its own writes by this mark, never a
#: user's ``.STEM.*.png``.
TEMPORARY_TAG = ".imagemap-tmp"
_TEMPORARY_RE = re.compile(
    r"^\.(?P<stem>.*)\.[a-z0-9_]{8}" + re.escape(TEMPORARY_TAG) + r"(?P<suffix>.*)$"
)


def make_temporary(path: str | os.PathLike, suffix: str | None = None) -> Path:
    """Create an empty temporary file beside ``path`` (its folder must exist), named so
    that :func:`is_temporary_of` knows it.

    Examples
    --------
    >>> import tempfile
    >>> folder = Path(tempfile.mkdtemp())
    >>> tmp = make_temporary(folder / "map.png")
    >>> is_temporary_of(tmp, folder / "map.png"), is_temporary_of(folder / ".map.x.png", "map.png")
    (True, False)
    """
    path = Path(path)
    suffix = suffix if suffix is not None else "".join(path.suffixes)
    fd, tmp = tempfile.mkstemp(
        prefix=f".{path.stem}.", suffix=TEMPORARY_TAG + suffix, dir=path.parent
    )
    os.close(fd)
    return Path(tmp)


def is_temporary(candidate: str | os.PathLike) -> bool:
    """Whether ``candidate`` is named as :func:`make_temporary` names its files."""
    return bool(_TEMPORARY_RE.match(Path(candidate).name))


def is_temporary_of(candidate: str | os.PathLike, target: str | os.PathLike) -> bool:
    """Whether ``candidate`` is a temporary file :func:`make_temporary` made for ``target``."""
    match = _TEMPORARY_RE.match(Path(candidate).name)
    target = Path(target)
    return bool(
        match
        and match["stem"] == target.stem
        and match["suffix"] == "".join(target.suffixes)
        and Path(candidate).parent == target.parent
    )


def _to_unit_float(array: np.ndarray, path: Path | str) -> np.ndarray:
    """Integer images to float32 in [0, 1] by their dtype's range; floats as they are.

    ``path`` names the source in messages (a file, or an in-memory example's name)."""
    if array.dtype == np.uint8:
        return array.astype(np.float32) / 255.0
    if array.dtype == np.uint16:
        return array.astype(np.float32) / 65535.0
    if np.issubdtype(array.dtype, np.integer):
        raise InputError(f"{path}: unsupported integer pixel type {array.dtype} (use 8 or 16 bit)")
    if np.issubdtype(array.dtype, np.floating):
        return array.astype(np.float32)
    raise InputError(f"{path}: unsupported pixel type {array.dtype}")


def _load_raw(path: Path) -> np.ndarray:
    try:
        if not path.exists():
            raise InputError(f"{path}: file not found")
        if not path.is_file():
            raise InputError(f"{path}: not a file")
    except OSError as exc:  # e.g. a folder on the way that cannot be searched
        raise InputError(f"{path}: cannot be opened ({exc.strerror or exc})") from None
    suffix = path.suffix.lower()
    try:
        if suffix == ".npy":
            array = np.load(path, allow_pickle=False)
        elif suffix in (".tif", ".tiff"):
            import tifffile  # deferred: start-up (0.05-0.09 s; only .tif depths need it)

            array = tifffile.imread(path)
        else:
            array = _read_png(path) if suffix == ".png" else None
            if array is None:  # not a plain PNG: imageio, with every plugin it has
                import imageio.v3 as iio  # deferred: start-up (0.1 s; PNGs and .npy need none)

                array = iio.imread(path)
    except InputError:
        raise
    except PermissionError as exc:
        raise InputError(f"{path}: cannot be read ({exc.strerror})") from None
    except MemoryError:
        raise InputError(f"{path}: too large to read into memory") from None
    except Exception as exc:  # any decoder failure is the file's fault here
        raise InputError(f"{path}: not a readable image ({_reason(exc, suffix)})") from exc
    array = np.asarray(array)
    if array.dtype == object or array.dtype.kind not in "biuf":
        raise InputError(f"{path}: not a readable image (pixel type {array.dtype})")
    return array


def _read_png(path: Path) -> np.ndarray | None:
    """A PNG's pixels read by Pillow alone, as imageio's Pillow plugin returns them
    (palette images in their palette's mode, 16-bit grey as uint16, a writeable array);
    None for a file that is not a plain PNG (an animated one, another format, or one
    Pillow cannot identify), which the caller gives to imageio as before.

    For speed only: importing imageio and letting it load all of Pillow's plugins costs
    about 0.07 s of CPU in every process that reads a picture (the maps are the same).
    """
    from PIL import Image, UnidentifiedImageError  # deferred: start-up (Pillow, 0.01 s)

    try:
        opened = Image.open(path)
    except UnidentifiedImageError:
        return None
    with opened:
        if opened.format != "PNG" or getattr(opened, "custom_mimetype", None) == "image/apng":
            return None
        pixels: Image.Image = opened
        if opened.mode == "P":
            if opened.palette is None:
                return None
            pixels = opened.convert(opened.palette.mode)
        elif opened.mode == "I":  # as imageio: 16-bit grey as uint16 (Pillow >= 10.1)
            pixels = opened.convert("I;16" if sys.byteorder == "little" else "I;16B")
        return np.array(pixels)


def _write_png(tmp: Path, array: np.ndarray) -> None:
    """``array`` (H, W) or (H, W, 3|4) as a PNG by Pillow alone: the bytes imageio's
    Pillow plugin writes (``Image.fromarray(array).save(file, format="PNG")``), without
    importing imageio and every Pillow plugin (about 0.07 s of CPU in a fresh process)."""
    from PIL import Image  # deferred: start-up (Pillow, 0.01 s)

    Image.fromarray(array).save(tmp, format="PNG")


def _writes_as_png(array: np.ndarray, extension: str) -> bool:
    """Whether :func:`_write_png` writes ``array`` as imageio would (a ``.png`` of one
    grey channel or 3-4 colours; imageio refuses (H, W, 1), and says so)."""
    return extension.lower() == ".png" and (array.ndim == 2 or array.shape[-1] in (3, 4))


def _reason(exc: Exception, suffix: str) -> str:
    """A short reason for a decoder's failure, without advice to install plugins."""
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    if "backend" in text or "plugin" in text or "pip install" in text:
        return f"not a valid {suffix.lstrip('.').upper() or 'image'} file, or damaged"
    return text[:200]


def read_depth(path: str | os.PathLike) -> np.ndarray:
    """Read a depth map as float32 (H, W); background is NaN-free 0.

    Accepts 8- or 16-bit PNG (scaled to [0, 1] by the bit depth), float TIFF and
    ``.npy``. Larger values are nearer; 0 or NaN is background (NaN becomes 0).

    Parameters
    ----------
    path : str or path-like
        The depth file.

    Returns
    -------
    depth : ndarray of float32, shape (H, W)

    Raises
    ------
    InputError
        Missing or unreadable file, more than one channel, no foreground,
        infinite or negative values.
    """
    path = Path(path)
    if path.suffix.lower() not in DEPTH_SUFFIXES:
        raise InputError(
            f"{path}: unsupported depth format {path.suffix!r} (use .png, .tif or .npy)"
        )
    raw = _load_raw(path)
    if raw.ndim == 3 and raw.shape[2] == 1:
        raw = raw[..., 0]
    if raw.ndim == 3 and raw.shape[2] in (2, 4):  # grey (+ alpha): alpha 0 is background
        alpha = raw[..., -1]
        colour = raw[..., :-1]
        if colour.shape[2] == 3 and not _grey(colour):
            raise InputError(
                f"{path}: a depth map must be grey, but its R, G and B channels differ "
                "(save the depth as a one-channel 8/16-bit PNG, a float TIFF or .npy)"
            )
        raw = np.where(alpha > 0, colour[..., 0], 0)
    if raw.ndim == 3 and raw.shape[2] == 3:
        if not _grey(raw):
            raise InputError(
                f"{path}: a depth map must be grey, but its R, G and B channels differ "
                "(save the depth as a one-channel 8/16-bit PNG, a float TIFF or .npy)"
            )
        raw = raw[..., 0]
    if raw.ndim != 2:
        raise InputError(f"{path}: a depth map must have one channel, got shape {raw.shape}")
    depth = _to_unit_float(raw, path)
    return validate_depth(depth, name=str(path))


def _grey(rgb: np.ndarray) -> bool:
    return bool(
        np.array_equal(rgb[..., 0], rgb[..., 1]) and np.array_equal(rgb[..., 0], rgb[..., 2])
    )


def validate_depth(depth: np.ndarray, name: str = "depth", *, copy: bool = True) -> np.ndarray:
    """Check a depth array and return it as float32 with background 0.

    NaN becomes background (0). Raises :class:`InputError` naming ``name`` on a
    wrong shape, infinite or negative values, or an empty foreground. With ``copy``
    False a float32 depth without NaN is not copied: a read-only view of it is
    returned (a caller that only reads it holds no second copy of the query).
    """
    depth = np.asarray(depth)
    if depth.ndim != 2:
        raise InputError(f"{name}: a depth map must be 2-D (H, W), got shape {depth.shape}")
    if depth.shape[0] < 8 or depth.shape[1] < 8:
        raise InputError(f"{name}: depth map of {depth.shape} is too small (at least 8x8)")
    if copy or depth.dtype != np.float32 or np.isnan(depth).any():
        depth = np.nan_to_num(depth.astype(np.float32), nan=0.0, posinf=np.inf, neginf=-np.inf)
    else:
        depth = depth.view()
        depth.flags.writeable = False
    if not np.all(np.isfinite(depth)):
        raise InputError(f"{name}: depth has infinite values")
    if np.any(depth < 0):
        raise InputError(f"{name}: depth has negative values (background must be 0 or NaN)")
    if not np.any(depth > 0):
        raise InputError(f"{name}: depth has no foreground (every pixel is 0 or NaN)")
    return depth


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read a colour image as float32 (H, W, 3) in [0, 1] (alpha dropped, grey expanded).

    Raises
    ------
    InputError
        Missing or unreadable file, NaN values, unsupported layout.
    """
    path = Path(path)
    raw = _load_raw(path)
    image = _to_unit_float(raw, path)
    if image.ndim == 2:
        image = np.repeat(image[..., None], 3, axis=2)
    if image.ndim != 3 or image.shape[2] not in (3, 4):
        raise InputError(f"{path}: expected an RGB(A) or grey image, got shape {image.shape}")
    if image.shape[2] == 4 and not np.any(image[..., 3] > 0):
        raise InputError(
            f"{path}: the image is fully transparent (alpha 0 everywhere): its colours are "
            "hidden; save it without alpha, or with the object opaque"
        )
    image = image[..., :3]
    if not np.all(np.isfinite(image)):
        raise InputError(f"{path}: image has NaN or infinite values")
    return np.clip(image, 0.0, 1.0)


def write_image(path: str | os.PathLike, image: np.ndarray, bits: int = 8) -> Path:
    """Write an image in [0, 1] (H, W), (H, W, 3) or (H, W, 4) as PNG, atomically.

    Parameters
    ----------
    path : str or path-like
        Destination (``.png``).
    image : ndarray
        Float values in [0, 1] (clipped), or uint8/uint16 written as they are. NaN is
        refused (:class:`InputError`): it is no colour, and was written as black.
    bits : {8, 16}
        Bit depth for float input.
    """
    path = Path(path)
    array = _image_array(path, image, bits)
    extension = path.suffix.lower() or ".png"
    with atomic_path(path) as tmp:
        if _writes_as_png(array, extension):
            _write_png(tmp, array)
        else:
            import imageio.v3 as iio  # deferred: start-up (0.1 s; PNGs and .npy need none)

            iio.imwrite(tmp, array, extension=extension)
    return path


def image_writer(image: np.ndarray, bits: int = 8, extension: str = ".png"):
    """A function writing ``image`` (as :func:`write_image` does) to the path it is given.

    For :func:`imagemap.outputs.write_all`, which writes a set of outputs
    all-or-nothing: the array is checked and converted here, before any file is made.
    """
    array = _image_array(Path(f"image{extension}"), image, bits)
    if _writes_as_png(array, extension):
        return lambda tmp: _write_png(tmp, array)
    import imageio.v3 as iio  # deferred: start-up (0.1 s; PNGs and .npy need none)

    def write(tmp: Path) -> None:
        iio.imwrite(tmp, array, extension=extension)

    return write


#: Rows of a float image converted to integers at a time when it is written.
_WRITE_ROWS = 256


def _image_array(path: Path, image: np.ndarray, bits: int) -> np.ndarray:
    array = np.asarray(image)
    if not (array.ndim == 2 or (array.ndim == 3 and array.shape[2] in (1, 3, 4))):
        raise ValueError(f"{path}: cannot write an image of shape {array.shape}")
    colour16 = array.ndim == 3 and array.shape[2] > 1 and (bits == 16 or array.dtype == np.uint16)
    if colour16:  # Pillow, imageio's PNG writer, stores 16-bit only for grey
        raise ValueError(f"{path}: 16-bit colour PNG is not supported; write 8-bit or a .tif")
    if np.issubdtype(array.dtype, np.floating):
        if bits not in (8, 16):
            raise ValueError("bits must be 8 or 16")
        missing = int(np.count_nonzero(np.isnan(array)))
        if missing:
            raise InputError(
                f"{path}: the image has {missing} NaN value(s) of {array.size}: NaN is no "
                "colour (it would be written as black); fill or mask them first"
            )
        scale = 255 if bits == 8 else 65535
        dtype = np.uint8 if bits == 8 else np.uint16
        # round(clip(x, 0, 1) * scale) a block of rows at a time, in place on the block's
        # copy: the same values as of the whole image, without its four float copies.
        out = np.empty(array.shape, dtype)
        for y0 in range(0, array.shape[0], _WRITE_ROWS):
            block = np.nan_to_num(array[y0 : y0 + _WRITE_ROWS])
            np.clip(block, 0.0, 1.0, out=block)
            np.multiply(block, scale, out=block)
            np.round(block, out=block)
            out[y0 : y0 + _WRITE_ROWS] = block
        array = out
    return array


def read_npz(path: str | os.PathLike, what: str = ".npz") -> dict[str, np.ndarray]:
    """All arrays of an ``.npz`` (no pickles), or :class:`InputError` naming the file.

    ``what`` names the expected content in the message (e.g. "BTF").
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: file not found")
    try:
        with np.load(path, allow_pickle=False) as data:
            return {name: data[name] for name in data.files}
    except Exception as exc:
        raise InputError(f"{path}: not a readable {what} ({exc})") from exc


def write_npz(path: str | os.PathLike, **arrays: np.ndarray) -> Path:
    """Save arrays to one ``.npz`` atomically."""
    path = Path(path)
    with atomic_path(path, suffix=".npz") as tmp:
        # allow_pickle spelled out (NumPy's default) so that a type checker matches
        # **arrays to savez_compressed's **kwds rather than to that bool keyword.
        np.savez_compressed(tmp, allow_pickle=True, **arrays)
    return path
