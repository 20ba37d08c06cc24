"""Procedural ground-truth BTF materials: :mod:`imagemap.btf.materials` and
:mod:`imagemap.btf.rendering`, re-exported.

``imagemap btf experiment`` renders them at run time, so they live in ``imagemap`` (which
never imports ``data_gen``); this module keeps the data generator's name for them.

Example
-------
>>> from data_gen.materials import default_sampling, make_material, render_btf_matrix
>>> lights, views = default_sampling()
>>> render_btf_matrix(make_material("leather", size=16), lights[:2], views[:1]).shape
(6, 256)
"""

from __future__ import annotations

from imagemap.btf.materials import (
    EASY_MATERIALS,
    HARD_MATERIALS,
    MATERIALS,
    Material,
    make_material,
    scan_configuration,
)
from imagemap.btf.rendering import (
    default_sampling,
    ground_truth,
    render_btf_matrix,
    shadow_mask,
    view_hits,
)

__all__ = [
    "EASY_MATERIALS",
    "HARD_MATERIALS",
    "MATERIALS",
    "Material",
    "default_sampling",
    "ground_truth",
    "make_material",
    "render_btf_matrix",
    "scan_configuration",
    "shadow_mask",
    "view_hits",
]
