"""Procedural example classes (fish, busts, humans, shells) rendered with trimesh ray casting.

Each instance is a triangle mesh built from randomized shape parameters, coloured by
procedural functions of its surface (:mod:`data_gen.procedural`), and rendered by an
orthographic ray cast into a depth map (nearer = larger, background 0), an unlit
image-map and a part-label map, in the database format :mod:`imagemap.database` reads.

Example
-------
>>> import data_gen
>>> fish = data_gen.make_instance("fish", 0, seed=0, size=(80, 60))
>>> fish.depth.shape
(60, 80)
"""

from __future__ import annotations

from data_gen.busts import BUSTS
from data_gen.core import Instance, ObjectClass
from data_gen.core import make_instance as _make_instance
from data_gen.dataset import contact_sheet, write_class
from data_gen.fish import FISH
from data_gen.humans import HUMANS
from data_gen.shells import SHELLS

__all__ = [
    "CLASSES",
    "Instance",
    "ObjectClass",
    "contact_sheet",
    "make_instance",
    "write_class",
]

CLASSES: dict[str, ObjectClass] = {
    "fish": FISH,
    "busts": BUSTS,
    "humans": HUMANS,
    "shells": SHELLS,
}


def make_instance(
    class_name: str,
    index: int,
    seed: int = 0,
    size: tuple[int, int] | None = None,
    keep_mesh: bool = False,
) -> Instance:
    """Instance ``index`` of the class ``class_name`` (see :func:`data_gen.core.make_instance`)."""
    from imagemap.io import InputError

    if class_name not in CLASSES:
        raise InputError(f"class: unknown class {class_name!r} (choose from {sorted(CLASSES)})")
    return _make_instance(CLASSES[class_name], index, seed=seed, size=size, keep_mesh=keep_mesh)
