"""The error type of bad input, in a module that imports nothing heavy.

The command line imports it while building its parser, before NumPy or any other
scientific module is loaded (``imagemap --help`` stays fast). It is also
``imagemap.InputError`` and ``imagemap.io.InputError``.
"""

from __future__ import annotations

__all__ = ["InputError"]


class InputError(ValueError):
    """Bad input: the message names the file (where there is one) and the problem."""
