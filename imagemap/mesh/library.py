"""A database as the mesh route reads it: its examples seen from any view, and the meshes
of its mesh examples (:class:`ExampleSet`).

``imagemap synthesize`` reads a database from its folder (views rendered on first use and
cached, meshes loaded when the uv-space path asks); ``imagemap batch`` prepares the same
set once (every view it may need rendered, every mesh example loaded) and ships it to its
workers (:meth:`ExampleSet.prepared`), so a worker without the database's files makes the
same bytes as the single command.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from imagemap.database import Database, database_at_view, prepare_database
from imagemap.example import Example
from imagemap.io import InputError
from imagemap.materials import example_maps
from imagemap.scene.examples import MeshExample, maps_seen
from imagemap.scene.files import load_mesh
from imagemap.scene.views import (
    DEFAULT_MARGIN,
    DEFAULT_SIZE,
    FRONT,
    View,
    render_colours,
    render_mesh,
)

__all__ = ["KEPT_PICTURES", "ExampleSet", "view_key"]

#: Renders :meth:`ExampleSet.picture` keeps (a worker's next objects often choose the same
#: examples): 16 pictures at 951x714 are 130 MB.
KEPT_PICTURES = 16


@dataclass
class ExampleSet:
    """Examples for the mesh route: pictures and mesh examples, by view, and the meshes.

    Attributes
    ----------
    source : Database or None
        The database on disk (views rendered on demand, meshes loaded on demand); None for
        a set made only of prepared views.
    views : dict
        :func:`view_key` (view and size) -> Database of that view (prepared); a dict
        keyed by ``str(view)`` alone is read too.
    meshes : dict
        Name -> loaded ``trimesh.Trimesh`` of each mesh example (filled on first use, or
        by :meth:`prepared`).
    mesh_names : tuple of str
        The names of the examples that are meshes, in the database's order.
    names : list of str
        Every example's name, in the database's order.
    pictures : dict
        Mesh examples' colours rendered on demand at a view and size the set was not
        prepared for (:meth:`picture`), the latest :data:`KEPT_PICTURES`.
    picture_maps : dict
        Their PBR maps from the same renders (:meth:`maps`), by the same keys.
    """

    source: Database | None
    views: dict[str, Database] = field(default_factory=dict)
    meshes: dict[str, Any] = field(default_factory=dict)
    mesh_names: tuple[str, ...] = ()
    names: list[str] = field(default_factory=list)
    pictures: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    picture_maps: dict[str, dict] = field(default_factory=dict, repr=False)

    @classmethod
    def of(cls, database: Database | dict[str, Database] | ExampleSet) -> ExampleSet:
        """An ExampleSet of a Database, of prepared views (``str(view)`` -> Database), or itself."""
        if isinstance(database, ExampleSet):
            return database
        if isinstance(database, Database):
            meshes = tuple(e.name for e in database if isinstance(e, MeshExample))
            return cls(source=database, mesh_names=meshes, names=list(database.names))
        if isinstance(database, dict) and all(isinstance(d, Database) for d in database.values()):
            if not database:
                raise InputError("database: no prepared view")
            first = next(iter(database.values()))
            return cls(source=None, views=dict(database), names=list(first.names))
        raise InputError(
            f"database: expected a Database, prepared views or an ExampleSet, got {database!r}"
        )

    def at_view(self, view: View, size: tuple[int, int]) -> Database:
        """The database with its mesh examples seen from ``view`` at ``size``."""
        for key in (view_key(view, size), str(view)):
            if key in self.views:
                return self.views[key]
        if self.source is None:
            raise InputError(
                f"view {view}: not among the prepared views ({', '.join(self.views) or 'none'})"
            )
        return database_at_view(self.source, view, size)

    def _holds(self, view: View, size: tuple[int, int]) -> bool:
        """Whether :meth:`at_view` gives the examples seen from ``view`` at ``size`` (a
        database's renders, or a prepared view of that size; a set keyed by ``str(view)``
        alone holds another size, which :meth:`picture` renders instead)."""
        return self.source is not None or view_key(view, size) in self.views

    def picture(self, name: str, view: View, size: tuple[int, int]) -> np.ndarray:
        """Mesh example ``name``'s colours seen from ``view`` at ``size`` (H, W, 3): its
        render (cached on disk) when the set reads a database, else rendered from its
        loaded mesh as that render is made (a batch's prepared set, which ships the meshes
        but not every size) and kept for the next objects of the worker."""
        key = f"{name}|{view_key(view, size)}"
        if key in self.pictures:
            return self.pictures[key]
        if self._holds(view, size):
            return self.at_view(view, size)[name].image
        mesh = self.mesh(name)
        render = render_mesh(mesh, view, size, DEFAULT_MARGIN)
        picture = render_colours(mesh, render)
        while len(self.pictures) >= KEPT_PICTURES:
            dropped = next(iter(self.pictures))
            self.pictures.pop(dropped)
            self.picture_maps.pop(dropped, None)
        self.pictures[key] = picture
        # Its PBR maps from the same render, as the database's render caches them.
        self.picture_maps[key] = maps_seen(mesh, render)
        return picture

    def maps(self, name: str, view: View, size: tuple[int, int]) -> dict[str, np.ndarray]:
        """Mesh example ``name``'s PBR maps seen from ``view`` at ``size`` (by kind, the
        normals in the picture's frame), as :meth:`picture` sees its colours: the
        database's cached render, else rendered with the picture from the loaded mesh."""
        key = f"{name}|{view_key(view, size)}"
        if key not in self.pictures and self._holds(view, size):
            return example_maps(self.at_view(view, size)[name])
        self.picture(name, view, size)
        return self.picture_maps[key]

    def mesh(self, name: str):
        """The loaded mesh of the mesh example ``name`` (loaded once)."""
        if name not in self.meshes:
            if self.source is None or name not in self.mesh_names:
                raise InputError(f"{name}: not a mesh example of this database")
            example = self.source[name]
            self.meshes[name] = load_mesh(example.mesh_path)  # type: ignore[attr-defined]
        return self.meshes[name]

    def prepared(
        self,
        views: tuple[View, ...] | list[View],
        sizes: tuple[int, int] | list[tuple[int, int]],
        *,
        meshes: bool = True,
        pictures: bool = True,
    ) -> ExampleSet:
        """A copy that needs no file; what a batch ships.

        Every view of ``views`` at each of ``sizes`` (one (W, H) or a list) prepared
        (arrays loaded, mesh examples rendered; picture examples loaded once whatever
        the sizes); with ``meshes``, every mesh example's mesh loaded; with ``pictures``,
        the database as a depth-map query sees it too (mesh examples from the front at
        the default size, as ``imagemap synthesize DEPTH`` renders them).
        """
        if self.source is None:
            return self
        if len(sizes) == 2 and all(isinstance(v, int | np.integer) for v in sizes):
            sizes = [sizes]  # type: ignore[list-item]
        wanted = [(v, (int(s[0]), int(s[1]))) for s in sizes for v in views]  # type: ignore[index]
        if pictures:
            wanted.append((FRONT, DEFAULT_SIZE))
        ready: dict[str, Database] = {}
        loaded: dict[int, Example] = {}  # picture examples: the same at every view and size
        for view, at in wanted:
            key = view_key(view, at)
            if key not in ready:
                ready[key] = prepare_database(self.at_view(view, at), loaded)
        kept = {name: self.mesh(name) for name in self.mesh_names} if meshes else {}
        return ExampleSet(
            source=None,
            views=ready,
            meshes=kept,
            mesh_names=self.mesh_names if meshes else (),
            names=self.names,
        )


def view_key(view: View, size: tuple[int, int]) -> str:
    """The key of a view's database in :attr:`ExampleSet.views`: ``"az,el@WxH"``.

    Examples
    --------
    >>> view_key(FRONT, (200, 150))
    '0,0@200x150'
    """
    return f"{view}@{int(size[0])}x{int(size[1])}"
