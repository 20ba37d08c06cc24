"""The engine's digest (:func:`engine_digest`), part of the options' key each manifest records."""

from __future__ import annotations

from imagemap.cache import source_digest

__all__ = ["ENGINE_MODULES", "engine_digest"]


#: The modules whose code shapes a map or a texture. A batch resumed after one of them
#: changed (an upgrade) redoes its objects rather than mix two engines' outputs.
ENGINE_MODULES = (
    "align",
    "cache",  # the cached renders' and paddings' keys: a wrong one reuses a stale entry
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


def engine_digest() -> str:
    """A digest of the source of :data:`ENGINE_MODULES` (the version where it is unreadable,
    :func:`imagemap.cache.source_digest`)."""
    return source_digest(ENGINE_MODULES)[:16]
