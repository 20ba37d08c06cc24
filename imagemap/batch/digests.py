"""The engine's digest (:func:`engine_digest`), part of the options' key each manifest records."""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

import imagemap

__all__ = ["ENGINE_MODULES", "engine_digest"]


#: The modules whose code shapes a map or a texture. A batch resumed after one of them
#: changed (an upgrade) redoes its objects rather than mix two engines' outputs.
ENGINE_MODULES = (
    "align",
    "core",
    "database",
    "depth",
    "example",
    "io",
    "materials",
    "mesh",
    "outputs",
    "render",
    "scene",
    "tangents",
)


@functools.cache
def engine_digest() -> str:
    """A digest of the source of :data:`ENGINE_MODULES` (the version where it is unreadable).

    The package's files are read, not imported: no module's import cost or side effects
    for a digest."""
    digest = hashlib.sha256()
    package = Path(__file__).parents[1]  # imagemap/, this module being imagemap/batch/
    try:
        for name in ENGINE_MODULES:
            # A module, or every module of a subpackage in a fixed order.
            files = [package / f"{name}.py"] if (package / f"{name}.py").exists() else []
            files = files or sorted((package / name).rglob("*.py"))
            if not files:
                raise OSError(name)
            for path in files:
                digest.update(path.relative_to(package).as_posix().encode())
                digest.update(path.read_bytes())
    except OSError:  # no source files (a frozen install)
        return f"version {imagemap.__version__}"
    return digest.hexdigest()[:16]
