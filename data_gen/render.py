"""Orthographic ray casting: moved to :mod:`imagemap.scene.raycast` (one renderer for both).

Kept so that ``from data_gen.render import cast_orthographic`` still works.
"""

from imagemap.scene.raycast import (
    OrthographicView,
    RayHits,
    cast_orthographic,
    first_hits,
    ray_backend,
)

__all__ = ["OrthographicView", "RayHits", "cast_orthographic", "first_hits", "ray_backend"]
