"""Procedural solid textures for the example classes: :mod:`imagemap.btf.procedural`.

They moved to ``imagemap`` because the BTF experiment's materials are made of them and
``imagemap`` never imports ``data_gen``; the fish, busts, humans and shells keep importing them from
here.

Example
-------
>>> import numpy as np
>>> from data_gen.procedural import fbm
>>> fbm(np.zeros((2, 2, 2)), seed=1).shape
(2, 2)
"""

from __future__ import annotations

from imagemap.btf.procedural import (
    Seed,
    color_ramp,
    fbm,
    marble,
    perlin,
    spots,
    stripes,
    turbulence,
    wood,
    worley,
)

__all__ = [
    "Seed",
    "color_ramp",
    "fbm",
    "marble",
    "perlin",
    "spots",
    "stripes",
    "turbulence",
    "wood",
    "worley",
]
