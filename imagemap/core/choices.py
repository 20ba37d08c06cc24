"""The engine's named choices, for the command line's parser and the configurations.

Apart from :mod:`imagemap.core.params` (which re-exports them) so that a parser can
offer them without making the parameters' dataclasses.
"""

from __future__ import annotations

__all__ = ["APPEARANCE_PYRAMIDS", "BACKENDS", "VOTES"]

#: Nearest-neighbour searches of the E-step (:mod:`imagemap.core.search`).
BACKENDS = ("patchmatch", "exact", "pynndescent")
#: How matched windows make the map (:attr:`EngineParams.vote`), the values users type
#: (``--vote``): the mean M-step and a copy source made from the final matches; the mean
#: alone; the mode (a copy) inside the iterations too.
VOTES = ("copy", "mean", "mode")
#: What the appearance bands of a level are: its Gaussian level or its Laplacian band.
APPEARANCE_PYRAMIDS = ("gaussian", "laplacian")
