"""imagemap: example-based synthesis of image-maps and BTF extrapolation on one engine.

The Python API takes and returns NumPy arrays:

>>> import imagemap
>>> db = imagemap.Database.from_directory("examples/fish")        # doctest: +SKIP
>>> result = imagemap.colorize(depth, db, preset="fish", seed=0)  # doctest: +SKIP
>>> result.image, result.provenance, result.cost                  # doctest: +SKIP

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
    "export_textured": "imagemap.mesh",
    "render_mesh": "imagemap.mesh",
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
    from imagemap.mesh import colorize_mesh, export_textured, render_mesh

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
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("imagemap")
    except PackageNotFoundError:  # run from a checkout that was never installed
        return "0+unknown"
