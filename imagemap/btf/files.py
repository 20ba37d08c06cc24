"""Reading a BTF whatever its file format: our ``.npz`` or a Bonn UBO2014 ``.btf``."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from imagemap.btf.core import BTF
from imagemap.btf.ubo2014 import read_ubo2014
from imagemap.io import InputError

__all__ = ["BTF_SUFFIXES", "check_finite", "load_btf"]

#: File suffixes :func:`load_btf` reads.
BTF_SUFFIXES = (".npz", ".btf")


def load_btf(path: str | os.PathLike, *, finite: bool = False) -> BTF:
    """A BTF from our ``.npz`` (:meth:`BTF.save`) or a Bonn UBO2014 DFMF ``.btf`` file.

    With ``finite`` a BTF holding NaN or infinite values is refused (see
    :func:`check_finite`).

    Example
    -------
    >>> btf = load_btf("sample.npz")  # doctest: +SKIP
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".btf":
        btf = read_ubo2014(path)
    elif suffix == ".npz":
        btf = BTF.load(path)
    else:
        raise InputError(f"{path}: unsupported BTF format {path.suffix!r} (use .npz or .btf)")
    if finite:
        check_finite(btf, str(path))
    return btf


def check_finite(btf: BTF, name: str = "btf") -> BTF:
    """``btf`` itself, or InputError naming ``name`` if a factor has NaN or Inf."""
    for label in ("eigen_abrdfs", "singular_values", "eigentextures"):
        values = getattr(btf, label)
        if not np.all(np.isfinite(values)):
            bad = int(np.count_nonzero(~np.isfinite(values)))
            raise InputError(f"{name}: {label} has {bad} NaN or infinite values")
    return btf
