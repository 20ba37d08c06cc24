"""Databases of examples on disk: pairs of depth map and image-map.

A database is a directory of ``NAME_depth.png`` (8- or 16-bit), ``NAME_depth.tif``
(float) or ``NAME_depth.npy`` beside ``NAME_image.png``. Other files
(``NAME_labels.png``, ``NAME.json``, PBR maps ``NAME_normal.png``, ``NAME_roughness.png``
... of :mod:`imagemap.materials`, contact sheets) may sit beside them and are read when
present. Arrays are loaded on first use and cached, so opening a large
database costs nothing until its examples are needed. A database opened with
``keep_arrays=False`` (``imagemap synthesize`` with one query) has them dropped once
the synthesis has posed its examples (:meth:`Database.release_arrays`): the selection
reads every example's depth, and a single synthesis needs none of them after it.
"""

from __future__ import annotations

import numbers
import os
import re
from pathlib import Path
from typing import TYPE_CHECKING

from imagemap.example import Example
from imagemap.io import InputError
from imagemap.materials import MAP_KINDS, example_maps
from imagemap.outputs import MESH_SUFFIXES

if TYPE_CHECKING:
    from imagemap.scene.views import View

__all__ = ["Database", "Example", "check_database", "database_at_view", "prepare_database"]

#: The smallest object an example may have: one window of the finest level (7x7 in every
#: preset, the paper's Table 1). A smaller example cannot give a single whole window.
MIN_EXAMPLE_PIXELS = 49


def _meshes(path, view, size, taken) -> tuple[list, list[str]]:
    """:func:`imagemap.scene.examples.mesh_examples`; that module (and the rest of
    :mod:`imagemap.scene`: 30-45 ms of a fresh process's CPU) only imported when the folder
    holds a mesh file or a view is given: a folder of pictures has no mesh examples."""
    root = Path(path)
    if view is None and not (
        root.is_dir()
        and any(
            entry.suffix.lower() in MESH_SUFFIXES and entry.is_file() for entry in root.iterdir()
        )
    ):
        return [], []
    from imagemap.scene.examples import mesh_examples  # deferred: start-up (above)

    return mesh_examples(path, view, size, taken)


#: The arrays an :class:`Example` reads from its files and caches (``NAME_path`` beside
#: each): what :meth:`Database.release_arrays` drops.
_FILE_ARRAYS = ("depth", "image", "labels")

_DEPTH_RE = re.compile(r"^(?P<name>.+)_depth\.(?:png|tif|tiff|npy)$", re.IGNORECASE)
_IMAGE_RE = re.compile(r"^(?P<name>.+)_image\.(?:png|jpg|jpeg|tif|tiff)$", re.IGNORECASE)


class Database:
    """An ordered collection of examples (sorted by name).

    Examples
    --------
    >>> import shutil, tempfile
    >>> import numpy as np
    >>> from imagemap.io import write_image
    >>> depth = np.zeros((8, 8), np.float32); depth[2:6, 2:6] = 0.5
    >>> folder = Path(tempfile.mkdtemp())
    >>> for name in ("fish_001", "fish_000"):
    ...     np.save(folder / f"{name}_depth.npy", depth)
    ...     _ = write_image(folder / f"{name}_image.png", np.ones((8, 8, 3)))
    >>> db = Database.from_directory(folder)
    >>> db.names, db["fish_001"].image.shape
    (['fish_000', 'fish_001'], (8, 8, 3))
    >>> in_memory = Database([Example.from_arrays("a", depth, np.zeros((8, 8, 3)))])
    >>> len(in_memory), in_memory[0].name
    (1, 'a')
    >>> shutil.rmtree(folder)
    """

    def __init__(
        self, examples: list[Example], source: str = "", *, keep_arrays: bool = True
    ) -> None:
        if isinstance(examples, (str, Example)) or not hasattr(examples, "__iter__"):
            raise InputError(f"Database: expected a list of Example, got {examples!r}")
        examples = list(examples)
        for example in examples:
            if not isinstance(example, Example):
                raise InputError(
                    f"Database: expected Example objects (Example.from_arrays(...)), "
                    f"got {type(example).__name__}"
                )
        names = [e.name for e in examples]
        if len(set(names)) != len(names):
            raise InputError(f"{source or 'database'}: duplicate example names")
        self.examples = sorted(examples, key=lambda e: e.name)
        self.source = source
        #: False: the arrays its examples read from files are dropped once a synthesis
        #: has posed its examples (:meth:`release_arrays`); True (a batch, the library):
        #: kept for the next query's selection.
        self.keep_arrays = keep_arrays

    def release_arrays(self) -> int:
        """Drop the arrays its examples read from files and cached (depth, image,
        labels; read again from the files when next asked for). Examples built from
        arrays and mesh examples (their renders) keep theirs.

        Returns
        -------
        int
            Bytes of arrays no longer held by the examples.

        Examples
        --------
        >>> import shutil, tempfile
        >>> import numpy as np
        >>> from imagemap.io import write_image
        >>> depth = np.zeros((8, 8), np.float32); depth[2:6, 2:6] = 0.5
        >>> folder = Path(tempfile.mkdtemp())
        >>> np.save(folder / "a_depth.npy", depth)
        >>> _ = write_image(folder / "a_image.png", np.ones((8, 8, 3)))
        >>> db = Database.from_directory(folder, keep_arrays=False)
        >>> first = db["a"].depth
        >>> db.release_arrays(), db["a"].depth is first, np.array_equal(db["a"].depth, first)
        (256, False, True)
        >>> shutil.rmtree(folder)
        """
        released = 0
        for example, name in self._releasable():
            cache = example.__dict__  # functools.cached_property keeps its values here
            if "depth" in cache:
                _ = example.shape  # kept: reading the image again checks it without the depth
            released += getattr(cache.pop(name, None), "nbytes", 0)
        return released

    def releasable_bytes(self) -> int:
        """Bytes of the arrays :meth:`release_arrays` would drop now."""
        return sum(
            getattr(example.__dict__.get(name), "nbytes", 0) for example, name in self._releasable()
        )

    def _releasable(self):
        """(example, array name) of every array read from a file that may be cached."""
        for example in self.examples:
            if type(example) is not Example:  # a mesh example's renders: costly to remake
                continue
            for name in _FILE_ARRAYS:
                if name not in example._arrays and getattr(example, f"{name}_path") is not None:
                    yield example, name

    @classmethod
    def from_directory(
        cls,
        path: str | os.PathLike,
        strict: bool = True,
        view=None,
        size=None,
        *,
        keep_arrays: bool = True,
    ) -> Database:
        """Open a database directory; with ``strict``, unpaired files are an error.

        Textured meshes in it (``NAME.glb``, ``.obj``, ``.ply``...) are examples too,
        rendered from ``view`` at ``size`` (W, H) on first use (see :mod:`imagemap.scene`).
        ``keep_arrays``: see :attr:`keep_arrays`.
        """
        if not isinstance(path, str | os.PathLike) or not str(path):
            raise InputError(f"Database.from_directory: expected a folder, got {path!r}")
        examples, problems = _scan(Path(path))
        meshes, mesh_problems = _meshes(path, view, size, {e.name for e in examples})
        examples, problems = [*examples, *meshes], problems + mesh_problems
        if strict and problems:
            raise InputError("; ".join(problems))
        if not examples:
            raise InputError(
                f"{path}: no examples found (expected NAME_depth.png beside NAME_image.png, "
                "or textured meshes)"
            )
        return cls(examples, source=str(path), keep_arrays=keep_arrays)

    def __len__(self) -> int:
        return len(self.examples)

    def __iter__(self):
        return iter(self.examples)

    def __getitem__(self, key: int | str) -> Example:
        if isinstance(key, str):
            for example in self.examples:
                if example.name == key:
                    return example
            raise InputError(
                f"{self.source or 'database'}: no example named {key!r} "
                f"(have: {', '.join(self.names[:10])}{'...' if len(self) > 10 else ''})"
            )
        if isinstance(key, bool) or not isinstance(key, numbers.Integral):
            raise InputError(
                f"{self.source or 'database'}: examples are found by name or position, got {key!r}"
            )
        if not -len(self) <= key < len(self):
            raise InputError(
                f"{self.source or 'database'}: no example at position {key} (it has {len(self)})"
            )
        return self.examples[key]

    @property
    def names(self) -> list[str]:
        return [e.name for e in self.examples]

    def without(self, *names: str | list[str]) -> Database:
        """The database less the named examples (for leave-one-out).

        Accepts names as arguments, a list of names, or one name as a string;
        an unknown name is an :class:`InputError`.

        Examples
        --------
        >>> import numpy as np
        >>> depth, image = np.ones((8, 8), np.float32), np.zeros((8, 8, 3))
        >>> db = Database([Example.from_arrays(n, depth, image) for n in ("a", "b", "c")])
        >>> db.without("b").names, db.without(["a", "c"]).names
        (['a', 'c'], ['b'])
        >>> db.without("d")
        Traceback (most recent call last):
        imagemap.errors.InputError: database: no example named 'd' (have: a, b, c)
        """
        flat: list[str] = []
        for item in names:
            if isinstance(item, str):
                flat.append(item)
            elif isinstance(item, (list, tuple, set, frozenset)):
                flat.extend(item)
            else:
                raise InputError(f"without: expected example names, got {item!r}")
        for name in flat:
            if not isinstance(name, str):
                raise InputError(f"without: expected example names, got {name!r}")
        unknown = sorted(set(flat) - set(self.names))
        if unknown:
            raise InputError(
                f"{self.source or 'database'}: no example named "
                f"{', '.join(repr(n) for n in unknown)} "
                f"(have: {', '.join(self.names[:10])}{'...' if len(self) > 10 else ''})"
            )
        drop = set(flat)
        return Database(
            [e for e in self.examples if e.name not in drop],
            source=self.source,
            keep_arrays=self.keep_arrays,
        )


def _scan(root: Path) -> tuple[list[Example], list[str]]:
    if not root.exists():
        raise InputError(f"{root}: database directory not found")
    if not root.is_dir():
        raise InputError(f"{root}: not a directory")
    depths: dict[str, Path] = {}
    images: dict[str, Path] = {}
    problems = []
    try:
        entries = sorted(root.iterdir())
    except OSError as exc:
        raise InputError(f"{root}: cannot list the database ({exc.strerror or exc})") from None
    for entry in entries:
        if not entry.is_file():
            continue
        if match := _DEPTH_RE.match(entry.name):
            name = match["name"]
            if name in depths:
                problems.append(f"{entry}: second depth file for {name!r} ({depths[name].name})")
            depths[name] = entry
        elif match := _IMAGE_RE.match(entry.name):
            name = match["name"]
            if name in images:
                problems.append(
                    f"{entry}: second image-map file for {name!r} ({images[name].name})"
                )
            images[name] = entry
    for name in sorted(set(depths) - set(images)):
        problems.append(f"{depths[name]}: no image-map {name}_image.png beside it")
    for name in sorted(set(images) - set(depths)):
        problems.append(f"{images[name]}: no depth map {name}_depth.png beside it")
    examples = []
    for name in sorted(set(depths) & set(images)):
        labels = root / f"{name}_labels.png"
        sidecar = root / f"{name}.json"
        examples.append(
            Example(
                name=name,
                depth_path=depths[name],
                image_path=images[name],
                labels_path=labels if labels.exists() else None,
                json_path=sidecar if sidecar.exists() else None,
            )
        )
    return examples, problems


def check_database(
    path: str | os.PathLike, view=None, size: tuple[int, int] | None = None
) -> tuple[list[dict], list[str]]:
    """Read every example of a database and report what was found.

    The examples are those :meth:`Database.from_directory` opens: image pairs and
    textured meshes, rendered from ``view`` at ``size`` (W, H) as a synthesis would.

    Parameters
    ----------
    path : str or path-like
        The database directory.
    view, size : optional
        How meshes are rendered (defaults: :data:`imagemap.scene.FRONT`, 200x150).

    Returns
    -------
    rows : list of dict
        One per readable example: name, source (``"images"`` or the mesh file's
        name), size, depth range, foreground fraction, whether labels and JSON are
        present, and the PBR maps it carries (``maps``: normal, roughness, ...).
    problems : list of str
        One message per problem (unpaired, unreadable, mismatched files, a mesh
        with nothing visible or no colours).

    Examples
    --------
    >>> import shutil, tempfile
    >>> import numpy as np
    >>> from imagemap.io import write_image
    >>> folder = Path(tempfile.mkdtemp())
    >>> depth = np.zeros((16, 24), np.float32); depth[4:12, 6:18] = 0.5
    >>> np.save(folder / "fish_000_depth.npy", depth)
    >>> _ = write_image(folder / "fish_000_image.png", np.ones((16, 24, 3)))
    >>> _ = write_image(folder / "fish_001_image.png", np.ones((16, 24, 3)))
    >>> rows, problems = check_database(folder)
    >>> rows[0]["name"], rows[0]["source"], rows[0]["size"], rows[0]["foreground"]
    ('fish_000', 'images', '24x16', 0.25)
    >>> [problem.replace(str(folder), "DB") for problem in problems]
    ['DB/fish_001_image.png: no depth map fish_001_depth.png beside it']
    >>> shutil.rmtree(folder)
    """
    examples, problems = _scan(Path(path))
    meshes, mesh_problems = _meshes(path, view, size, {e.name for e in examples})
    examples, problems = [*examples, *meshes], problems + mesh_problems
    rows = []
    for example in examples:
        try:
            depth, image = example.depth, example.image
            labels = example.labels
            _ = example.info  # a corrupt sidecar is a problem too
            maps = sorted(example_maps(example))  # a bad PBR map is a problem too
        except InputError as exc:
            problems.append(str(exc))
            continue
        foreground = depth[depth > 0]
        if foreground.size < MIN_EXAMPLE_PIXELS:
            problems.append(
                f"{example.depth_path or example.name}: its object has {foreground.size} "
                f"pixel(s); an example needs at least {MIN_EXAMPLE_PIXELS} (one window)"
            )
        rows.append(
            {
                "name": example.name,
                "source": example.mesh_path.name if hasattr(example, "mesh_path") else "images",
                "size": f"{depth.shape[1]}x{depth.shape[0]}",
                "depth_min": float(foreground.min()),
                "depth_max": float(foreground.max()),
                "foreground": float((depth > 0).mean()),
                "mean_colour": [round(float(c), 3) for c in image[depth > 0].mean(axis=0)],
                "labels": labels is not None,
                "json": example.json_path is not None,
                "maps": [k for k in MAP_KINDS if k in maps],
            }
        )
    if not examples and not problems:
        problems.append(f"{path}: no examples found")
    return rows, problems


def database_at_view(
    database: Database, view: View, size: tuple[int, int] | None = None
) -> Database:
    """The database with its mesh examples rendered from ``view`` (pictures unchanged)."""
    from imagemap.scene.examples import MeshExample  # deferred: start-up (imagemap.scene)

    examples = [
        e.at_view(view, size) if isinstance(e, MeshExample) else e for e in database.examples
    ]
    return Database(examples, source=database.source, keep_arrays=database.keep_arrays)


def prepare_database(database: Database, loaded: dict[int, Example] | None = None) -> Database:
    """Load every example's arrays now, so the database pickles with its data.

    Returns a database of in-memory examples (the same names and arrays): shipped
    to workers once, it is never read from disk or rendered again. ``loaded`` (by
    ``id`` of the example) shares the prepared copy of an example that several
    databases hold (a picture example at every view and size).
    """
    from imagemap.scene.examples import MeshExample  # deferred: start-up (imagemap.scene)

    loaded = {} if loaded is None else loaded
    examples = []
    for example in database:
        if id(example) in loaded:
            examples.append(loaded[id(example)])
            continue
        prepared = Example.from_arrays(example.name, example.depth, example.image, example.labels)
        prepared.__dict__["info"] = dict(example.info)
        maps = example_maps(example)  # PBR maps travel with the colour
        if maps:
            prepared._arrays["maps"] = dict(maps)
        if not isinstance(example, MeshExample):
            loaded[id(example)] = prepared
        examples.append(prepared)
    return Database(examples, source=database.source)
