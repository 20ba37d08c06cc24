"""imagemap: example-based synthesis of image-maps and BTF extrapolation on one engine.

The Python API takes and returns NumPy arrays:

>>> import imagemap
>>> db = imagemap.Database.from_directory("examples/fish")        # doctest: +SKIP
>>> result = imagemap.colorize(depth, db, preset="fish", seed=0)  # doctest: +SKIP
>>> result.image, result.provenance, result.cost                  # doctest: +SKIP
"""

from imagemap.colorization import PRESETS, ColorizeParams, ColorizeResult, colorize, select_examples
from imagemap.database import Database, Example
from imagemap.engine import EngineParams, EngineResult, Mapping, synthesize
from imagemap.io import InputError, read_depth, read_image, write_image

__all__ = [
    "PRESETS",
    "ColorizeParams",
    "ColorizeResult",
    "Database",
    "EngineParams",
    "EngineResult",
    "Example",
    "InputError",
    "Mapping",
    "colorize",
    "read_depth",
    "read_image",
    "select_examples",
    "synthesize",
    "write_image",
]

__version__ = "0.1.0"
