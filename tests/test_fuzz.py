"""Random bytes and truncated files fed to every reader: each gives InputError, none hangs.

Every reader (depth, image, .npz, part labels, the database sidecar JSON, the BTF
archive and the Bonn UBO2014 file, the moving-average model) meets: random bytes
under each suffix it accepts, and a valid file of that format cut at several
lengths. Each call runs under a time limit (SIGALRM), so a decoder that loops on
damaged input fails the test instead of hanging it.
"""

from __future__ import annotations

import contextlib
import json
import signal
from pathlib import Path

import numpy as np
import pytest

from imagemap.database import Database
from imagemap.io import InputError, read_depth, read_image, read_npz, write_image, write_npz

SECONDS = 10  # per call: generous on a shared machine, far below a hang


@contextlib.contextmanager
def time_limit(seconds: int = SECONDS):
    def expire(signum, frame):
        raise TimeoutError(f"reader did not return within {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def _example_with(path: Path, name: str):
    """Example ``x`` read through the database: a valid depth and image, and the damaged
    file at ``path`` moved in as its ``name``."""
    folder = path.parent
    depth = np.zeros((16, 16), np.uint16)
    depth[4:12, 4:12] = 40000
    write_image(folder / "x_depth.png", depth)
    write_image(folder / "x_image.png", np.zeros((16, 16, 3)))
    path.replace(folder / name)
    return Database.from_directory(folder)["x"]


def _labels_reader(path: Path):
    """Part labels are read through the database, beside a valid depth and image."""
    return _example_with(path, "x_labels.png").labels


def _json_reader(path: Path):
    return _example_with(path, "x.json").info


def _btf_reader(path: Path):
    from imagemap.btf.core import BTF

    return BTF.load(path)


def _ubo_reader(path: Path):
    from imagemap.btf.ubo2014 import read_ubo2014

    return read_ubo2014(path)


def _ma_reader(path: Path):
    from imagemap.btf.moving_average import MovingAverageModel

    return MovingAverageModel.load(path)


#: reader name -> (function, suffixes it accepts)
READERS = {
    "read_depth": (read_depth, (".png", ".tif", ".npy")),
    "read_image": (read_image, (".png", ".jpg", ".tif")),
    "read_npz": (read_npz, (".npz",)),
    "labels": (_labels_reader, (".png",)),
    "json sidecar": (_json_reader, (".json",)),
    "BTF.load": (_btf_reader, (".npz",)),
    "read_ubo2014": (_ubo_reader, (".btf",)),
    "MovingAverageModel.load": (_ma_reader, (".npz",)),
}


def valid_file(folder: Path, suffix: str) -> Path:
    """A small valid file of the format of ``suffix``."""
    rng = np.random.default_rng(0)
    depth = np.zeros((24, 32), np.float32)
    depth[6:18, 8:24] = rng.uniform(0.3, 0.9, (12, 16)).astype(np.float32)
    path = folder / f"valid{suffix}"
    if suffix == ".png":
        write_image(path, np.round(depth * 65535).astype(np.uint16))
    elif suffix == ".jpg":
        import imageio.v3 as iio

        iio.imwrite(path, (rng.random((24, 32, 3)) * 255).astype(np.uint8), extension=".jpg")
    elif suffix == ".tif":
        import tifffile

        tifffile.imwrite(path, depth)
    elif suffix == ".npy":
        np.save(path, depth)
    elif suffix == ".npz":
        write_npz(path, depth=depth, image=rng.random((24, 32, 3)))
    elif suffix == ".json":
        path.write_text(json.dumps({"name": "x", "parts": [1, 2, 3]}))
    elif suffix == ".btf":
        path.write_bytes(b"!DFMF08FCR" + rng.integers(0, 256, 400, dtype=np.uint8).tobytes())
    return path


CASES = [
    (reader, suffix, kind)
    for reader, (_, suffixes) in READERS.items()
    for suffix in suffixes
    for kind in ("random", "empty", "truncated")
]


@pytest.mark.parametrize("reader, suffix, kind", CASES)
def test_damaged_files_give_input_error(tmp_path, reader, suffix, kind):
    function, _ = READERS[reader]
    rng = np.random.default_rng(abs(hash((reader, suffix, kind))) % 2**32)
    if kind == "random":
        blobs = [rng.integers(0, 256, n, dtype=np.uint8).tobytes() for n in (1, 17, 700, 5000)]
    elif kind == "empty":
        blobs = [b""]
    else:
        full = valid_file(tmp_path, suffix).read_bytes()
        # A PNG cut inside its closing IEND chunk (or the last IDAT checksum) still holds
        # every pixel, and decoders read it: cut PNGs inside their pixel data only.
        last = 2 * len(full) // 3 if suffix == ".png" else len(full) - 1
        cuts = sorted({1, 8, len(full) // 3, len(full) // 2, last} - {0})
        blobs = [full[:n] for n in cuts if n < len(full)]
    for i, blob in enumerate(blobs):
        folder = tmp_path / f"{kind}{i}"
        folder.mkdir()
        path = folder / f"damaged{suffix}"
        path.write_bytes(blob)
        with time_limit(), pytest.raises(InputError) as info:
            function(path)
        message = str(info.value)
        assert "damaged" in message or "x_labels" in message or "x.json" in message, message
        assert "pip install" not in message


def test_random_bytes_under_an_image_suffix_never_crash_the_cli(tmp_path, capsys):
    from imagemap.cli import main

    rng = np.random.default_rng(1)
    db = tmp_path / "db"
    db.mkdir()
    (db / "a_depth.png").write_bytes(rng.integers(0, 256, 300, dtype=np.uint8).tobytes())
    (db / "a_image.png").write_bytes(b"")
    assert main(["db", "check", str(db)]) == 1
    out = capsys.readouterr().out
    assert "a_depth.png" in out and "not a readable image" in out
