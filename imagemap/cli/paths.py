"""Output-path safety shared by the subcommands: checked before any work is done.

Every output path is resolved and compared with every input and every other output;
a clash is an error naming both paths. An output's suffix must be one the command
writes, and its folder must exist and be writable.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

from imagemap.errors import InputError

__all__ = ["check_paths"]


def check_paths(
    outputs: Mapping[str, str | os.PathLike | None],
    inputs: Mapping[str, str | os.PathLike | Sequence[str | os.PathLike] | None],
    suffixes: Mapping[str, Sequence[str]] | None = None,
) -> dict[str, Path]:
    """Check output paths against inputs, each other, their suffixes and their folders.

    Parameters
    ----------
    outputs : option name -> path (None: not asked for)
    inputs : option name -> path or list of paths (None: not given)
    suffixes : option name -> the suffixes that output may have (lower case, with dot)

    Returns
    -------
    dict
        Option name -> resolved output path, for the outputs given.

    Raises
    ------
    InputError
        Naming the option(s) and path(s) at fault.

    Example
    -------
    >>> check_paths({"-o": "a.npz"}, {"sample": "a.npz"})  # doctest: +IGNORE_EXCEPTION_DETAIL
    Traceback (most recent call last):
    imagemap.io.InputError: -o a.npz is the same file as sample a.npz ...
    """
    suffixes = suffixes or {}
    seen: dict[Path, tuple[str, str]] = {}
    for name, value in inputs.items():
        values = [] if value is None else [value] if isinstance(value, str | os.PathLike) else value
        for path in values:
            seen.setdefault(Path(path).resolve(), (name, str(path)))
    resolved: dict[str, Path] = {}
    for name, value in outputs.items():
        if value is None:
            continue
        path = Path(value)
        if path.is_dir():
            raise InputError(f"{name} {path}: is a directory; give a file name")
        full = path.resolve()
        if full in seen:
            other, shown = seen[full]
            raise InputError(
                f"{name} {path} is the same file as {other} {shown}; writing it would "
                "replace that file: choose another output name"
            )
        allowed = suffixes.get(name)
        if allowed and path.suffix.lower() not in allowed:
            raise InputError(
                f"{name} {path}: this output is written as {' or '.join(allowed)}; "
                f"the name must end so (got {path.suffix or 'no suffix'!r})"
            )
        folder = full.parent
        if not folder.is_dir():
            raise InputError(f"{name} {path}: folder {folder} does not exist")
        if not os.access(folder, os.W_OK):
            raise InputError(f"{name} {path}: folder {folder} is not writable")
        seen[full] = (name, str(path))
        resolved[name] = full
    return resolved
