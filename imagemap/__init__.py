"""imagemap: example-based synthesis of image-maps and BTF extrapolation on one engine.

The Python API takes and returns NumPy arrays. A database is usually a folder
(``imagemap.Database.from_directory("fish_db/")``); here, three painted ellipses
of different heights, and a query nearest the tallest:

>>> import numpy as np
>>> import imagemap
>>> yy, xx = np.mgrid[:30, :40]
>>> def ellipse(height):  # depth: larger is nearer, 0 is background
...     inside = (yy - 15) ** 2 / (height / 2) ** 2 + (xx - 20) ** 2 / 256 < 1
...     return np.where(inside, 0.7, 0).astype(np.float32)
>>> def paint(depth):  # red above row 15, cream below, black background
...     inside = (depth > 0)[..., None]
...     return np.where(inside, np.where(yy[..., None] < 15, [0.8, 0.2, 0.1], [0.9, 0.9, 0.6]), 0)
>>> db = imagemap.Database([imagemap.Example.from_arrays(f"height_{h}", ellipse(h),
...                         paint(ellipse(h))) for h in (12, 20, 24)])
>>> result = imagemap.colorize(ellipse(23), db, preset="fish", seed=0)
>>> result.example_names  # the examples nearest in depth, nearest first
['height_24', 'height_20']
>>> result.image[[10, 20], 20].round(2)  # copied colours: red above, cream below
array([[0.8, 0.2, 0.1],
       [0.9, 0.9, 0.6]], dtype=float32)
>>> result.image.shape, result.rgba.shape, result.provenance.shape
((30, 40, 3), (30, 40, 4), (30, 40, 3))

Imports are lazy (PEP 562): ``import imagemap`` loads nothing heavy, and a name
such as ``imagemap.colorize`` or a submodule such as ``imagemap.depth.budget`` is
imported on first use. So ``imagemap --help`` does not pay for scikit-image,
SciPy or numba, and ``from imagemap import colorize`` works as always.

>>> imagemap.InputError.__module__
'imagemap.errors'
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

#: Public name -> the module that defines it (imported on first access).
_LAZY = {
    "PRESETS": "imagemap.depth.config",
    "DepthConfig": "imagemap.depth.config",
    "ColorizeResult": "imagemap.depth.pipeline",
    "colorize": "imagemap.depth.pipeline",
    "select_examples": "imagemap.depth.selection",
    "Database": "imagemap.database",
    "Example": "imagemap.database",
    "EngineParams": "imagemap.core.engine",
    "EngineResult": "imagemap.core.engine",
    "Mapping": "imagemap.core.engine",
    "synthesize": "imagemap.core.engine",
    "InputError": "imagemap.errors",
    "read_depth": "imagemap.io",
    "read_image": "imagemap.io",
    "write_image": "imagemap.io",
    "colorize_mesh": "imagemap.mesh",
    "export_textured": "imagemap.scene",
    "render_mesh": "imagemap.scene",
}

__all__ = [
    "PRESETS",
    "DepthConfig",
    "ColorizeResult",
    "Database",
    "EngineParams",
    "EngineResult",
    "Example",
    "InputError",
    "Mapping",
    "colorize",
    "colorize_mesh",
    "export_textured",
    "read_depth",
    "read_image",
    "render_mesh",
    "select_examples",
    "synthesize",
    "write_image",
]

if TYPE_CHECKING:  # what type checkers and editors see
    from imagemap.core.engine import EngineParams, EngineResult, Mapping, synthesize
    from imagemap.database import Database, Example
    from imagemap.depth.config import PRESETS, DepthConfig
    from imagemap.depth.pipeline import ColorizeResult, colorize
    from imagemap.depth.selection import select_examples
    from imagemap.errors import InputError
    from imagemap.io import read_depth, read_image, write_image
    from imagemap.mesh import colorize_mesh
    from imagemap.scene import export_textured, render_mesh

    __version__: str


def __getattr__(name: str):
    """Import a public name, a submodule (``imagemap.batch``) or ``__version__`` on first use."""
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
    elif name == "__version__":
        value = _version()
    elif not name.startswith("_"):
        try:
            value = importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise  # the submodule exists but one of its own imports is missing
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value  # later accesses are plain attribute lookups
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__) | {"__version__"})


def _version() -> str:
    """The installed distribution's version: ``version`` in pyproject.toml is the one source."""
    from importlib.metadata import PackageNotFoundError, version  # deferred: start-up (0.07-0.1 s)

    try:
        return version("imagemap")
    except PackageNotFoundError:  # run from a checkout that was never installed
        return "0+unknown"
