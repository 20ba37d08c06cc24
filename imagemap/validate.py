"""Argument checks at the door of the Python API and of the command line.

Every check raises :class:`~imagemap.io.InputError` naming the argument (API) or
the option (CLI, through argparse's own error: exit code 2 and the option's name).

Examples
--------
>>> check_int("m", 2, minimum=1)
2
>>> check_int("m", 1.5, minimum=1)
Traceback (most recent call last):
...
imagemap.errors.InputError: m: expected an integer, got 1.5
"""

from __future__ import annotations

import argparse
import math
import numbers
import os
import sys
from typing import Any, NamedTuple

# Nothing heavy at import: the command line builds its parser with these types
# before NumPy is loaded (imagemap --help stays fast).
from imagemap.errors import InputError

__all__ = [
    "Check",
    "check_examples",
    "check_float",
    "check_int",
    "check_mesh",
    "check_size",
    "check_seed",
    "finite_float",
    "non_negative_float",
    "non_negative_int",
    "parse_size",
    "positive_int",
    "check_settings",
    "setting",
]


def _is_bool(value) -> bool:
    """A Python or NumPy boolean (a NumPy one exists only once NumPy is imported)."""
    numpy = sys.modules.get("numpy")
    return isinstance(value, bool) or (numpy is not None and isinstance(value, numpy.bool_))


def check_int(name: str, value, minimum: int | None = None, maximum: int | None = None) -> int:
    """``value`` as an int, or :class:`InputError` naming ``name``.

    Booleans, floats (even 2.0) and strings are refused: ``m="2"`` is a mistake
    that would otherwise surface deep inside NumPy.
    """
    if _is_bool(value) or not isinstance(value, numbers.Integral):
        raise InputError(f"{name}: expected an integer, got {value!r}")
    value = int(value)
    if minimum is not None and value < minimum:
        raise InputError(f"{name}: must be at least {minimum}, got {value}")
    if maximum is not None and value > maximum:
        raise InputError(f"{name}: must be at most {maximum}, got {value}")
    return value


def check_seed(value, name: str = "seed") -> int:
    """A seed for :func:`numpy.random.default_rng`: an integer >= 0."""
    return check_int(name, value, minimum=0)


def check_float(
    name: str, value, minimum: float | None = None, maximum: float | None = None
) -> float:
    """``value`` as a finite float in [minimum, maximum], or :class:`InputError`."""
    if _is_bool(value) or not isinstance(value, numbers.Real):
        raise InputError(f"{name}: expected a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise InputError(f"{name}: must be a finite number, got {value}")
    if minimum is not None and value < minimum:
        raise InputError(f"{name}: must be at least {minimum:g}, got {value:g}")
    if maximum is not None and value > maximum:
        raise InputError(f"{name}: must be at most {maximum:g}, got {value:g}")
    return value


#: The smallest side of a rendered view (``--size``): the pyramid's coarsest level still
#: holds a window (the same bound as the command line's).
MIN_VIEW_SIDE = 16


def check_size(value, name: str = "size", minimum: int = MIN_VIEW_SIDE) -> tuple[int, int]:
    """A (width, height) pair of integers >= ``minimum``, or :class:`InputError`.

    Examples
    --------
    >>> check_size((200, 150))
    (200, 150)
    >>> check_size("200x150")
    Traceback (most recent call last):
    ...
    imagemap.errors.InputError: size: expected (width, height), got '200x150'
    """
    if isinstance(value, str | bytes) or not hasattr(value, "__len__") or len(value) != 2:
        raise InputError(f"{name}: expected (width, height), got {value!r}")
    width, height = (check_int(name, v, minimum=minimum) for v in value)
    return width, height


def check_mesh(value, name: str = "mesh", paths: bool = True):
    """A triangle mesh (``trimesh.Trimesh``: vertices and faces), or with ``paths`` a path
    to read one from; anything else (None, a Scene, a PointCloud) is an
    :class:`InputError` naming ``name``.

    Examples
    --------
    >>> check_mesh("head.glb")
    'head.glb'
    >>> check_mesh(None)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    imagemap.errors.InputError: mesh: expected a triangle mesh (trimesh.Trimesh) ... NoneType
    """
    if paths and isinstance(value, str | os.PathLike):
        return value
    faces = getattr(value, "faces", None)
    if faces is None or getattr(value, "vertices", None) is None:
        hint = (
            " (a Scene: trimesh.load(path, force='mesh') joins its geometries)"
            if type(value).__name__ == "Scene"
            else ""
        )
        raise InputError(
            f"{name}: expected a triangle mesh (trimesh.Trimesh)"
            f"{' or its path' if paths else ''}, got {type(value).__name__}{hint}"
        )
    if len(faces) == 0:
        raise InputError(f"{name}: the mesh has no triangles")
    return value


def check_examples(examples) -> list[str] | None:
    """Example names: None, one name as a string, or a sequence of names."""
    if examples is None:
        return None
    if isinstance(examples, str):
        return [examples]
    if isinstance(examples, (bytes, dict)) or not hasattr(examples, "__iter__"):
        raise InputError(f"examples: expected a list of example names, got {examples!r}")
    names = list(examples)
    for name in names:
        if not isinstance(name, str):
            raise InputError(f"examples: expected example names (strings), got {name!r}")
    if len(set(names)) != len(names):
        raise InputError(f"examples: a name is given twice in {names}")
    return names


# -- argparse types: a bad value is argparse's error naming the option (exit 2) ----------


def _argparse_type(check, description: str):
    def parse(text: str):
        try:
            value = float(text) if "float" in description else int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {description}, got {text!r}") from None
        try:
            return check(value)
        except InputError as exc:
            message = str(exc).split(": ", 1)[-1]
            raise argparse.ArgumentTypeError(f"{message} ({description})") from None

    parse.__name__ = description
    return parse


#: argparse ``type=`` for options that take an integer >= 1 (``--m``, ``--workers``).
positive_int = _argparse_type(lambda v: check_int("value", v, minimum=1), "an integer >= 1")
#: argparse ``type=`` for integers >= 0 (``--seed``, ``--holdout``).
non_negative_int = _argparse_type(lambda v: check_int("value", v, minimum=0), "an integer >= 0")
#: argparse ``type=`` for a finite float >= 0 (``--example-preference``).
non_negative_float = _argparse_type(
    lambda v: check_float("value", v, minimum=0.0), "a finite float >= 0"
)
#: argparse ``type=`` for a fraction in [0, 1] (``--edge-support``).
fraction = _argparse_type(
    lambda v: check_float("value", v, minimum=0.0, maximum=1.0), "a float from 0 to 1"
)
#: argparse ``type=`` for any finite float.
finite_float = _argparse_type(lambda v: check_float("value", v), "a finite float")


def parse_size(text: str) -> tuple[int, int]:
    """argparse ``type=`` for ``--size WIDTHxHEIGHT``: ``"200x150"`` -> (200, 150)."""
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, got {text!r}") from None
    if width < 16 or height < 16:
        raise argparse.ArgumentTypeError(f"size {text!r} is too small (at least 16x16)")
    return width, height


class Check(NamedTuple):
    """What a setting's value must be (:func:`setting`): its kind and bounds.

    ``kind`` is ``"float"`` (finite, in [minimum, maximum], below ``below``),
    ``"floats"`` (a tuple of such), ``"int"``, ``"bool"``, ``"choice"`` (one of
    ``choices``), ``"odd_width"`` (an odd positive integer: a window's width) or
    ``"odd_widths"`` (a non-empty tuple of them). ``optional``: None passes too.

    A named tuple, not a dataclass: the command line's parser imports this module, and
    making a dataclass (and importing :mod:`dataclasses`) costs a few ms of every start.
    """

    kind: str = "float"
    minimum: float | None = None
    maximum: float | None = None
    below: float | None = None
    choices: tuple[str, ...] = ()
    optional: bool = False

    def __call__(self, name: str, value: Any) -> None:
        if value is None and self.optional:
            return
        if self.kind == "floats":
            if not isinstance(value, tuple):
                raise InputError(f"{name}: expected a tuple of numbers, got {value!r}")
            for item in value:
                self._replace(kind="float")(name, item)
        elif self.kind == "float":
            value = check_float(name, value, minimum=self.minimum, maximum=self.maximum)
            if self.below is not None and value >= self.below:
                raise InputError(f"{name}: must be below {self.below:g}, got {value:g}")
        elif self.kind == "int":
            check_int(name, value, minimum=self.minimum, maximum=self.maximum)  # type: ignore[arg-type]
        elif self.kind == "bool":
            if not _is_bool(value):
                raise InputError(f"{name}: expected True or False, got {value!r}")
        elif self.kind == "choice":
            if value not in self.choices:
                raise InputError(f"unknown {name} {value!r}; use one of {self.choices}")
        elif self.kind == "odd_width":
            if _is_bool(value) or not isinstance(value, int) or value < 1 or value % 2 == 0:
                raise InputError(f"{name}: must be odd and positive, got {value!r}")
        elif self.kind == "odd_widths":
            if (
                not isinstance(value, tuple)
                or not value
                or any(_is_bool(k) or not isinstance(k, int) or k < 1 or k % 2 == 0 for k in value)
            ):
                raise InputError(f"{name}: odd positive widths, got {value!r}")
        else:
            raise ValueError(f"unknown check kind {self.kind!r}")


def setting(default: Any, **check: Any) -> Any:
    """A dataclass field with its default and the :class:`Check` its value must pass
    (:func:`check_settings` runs them all): the bounds stand beside the field they bound.

    Examples
    --------
    >>> from dataclasses import dataclass
    >>> @dataclass(frozen=True)
    ... class Example:
    ...     m: int = setting(2, kind="int", minimum=1)
    ...     def __post_init__(self):
    ...         check_settings(self)
    >>> Example(m=0)
    Traceback (most recent call last):
    ...
    imagemap.errors.InputError: m: must be at least 1, got 0
    """
    if isinstance(default, (list, dict, set)):
        raise TypeError("setting: use an immutable default (a tuple)")
    from dataclasses import field  # deferred: start-up (the parser imports this module)

    return field(default=default, metadata={"check": Check(**check)})


def check_settings(instance: Any) -> None:
    """Run the :class:`Check` of every field of a dataclass made with :func:`setting`."""
    from dataclasses import fields  # deferred: start-up (the parser imports this module)

    for f in fields(instance):
        check = f.metadata.get("check")
        if check is not None:
            check(f.name, getattr(instance, f.name))
