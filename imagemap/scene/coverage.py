"""Choosing views by how much of the surface they see (the mesh route's default, ``--views auto``).

Greedy: start from the first candidate (the front), then add the candidate that
sees the most surface area no chosen view sees yet, until a new view would add less
than :data:`MIN_GAIN` of the total area or :data:`ENOUGH` of it is seen. A face
counts as seen by a view when a pixel of that view's render hits it at an angle of
at most :data:`MAX_ANGLE_DEGREES` between its normal and the view direction (a
grazing view smears a texture).

Examples
--------
>>> import trimesh
>>> box = trimesh.creation.box(extents=(2.0, 1.0, 0.5))
>>> [str(v) for v in choose_views(box, size=(40, 30))]
['0,0', '180,0', '0,90', '0,-90', '90,0', '-90,0']
"""

from __future__ import annotations

import numpy as np

from imagemap.scene.views import DEFAULT_SIZE, NAMED_VIEWS, View, render_mesh

__all__ = ["CANDIDATES", "ENOUGH", "MAX_ANGLE_DEGREES", "MIN_GAIN", "choose_views", "seen_area"]

#: The views considered, front first: the six axis views, so the choice is among
#: views a user can name (front, back, left, right, top, bottom).
CANDIDATES = tuple(NAMED_VIEWS[n] for n in ("front", "back", "top", "bottom", "right", "left"))
#: A view that adds less than this share of the surface area is not worth a synthesis
#: (each view costs one synthesis, 2-4 s at 200x150).
MIN_GAIN = 0.02
#: Stop when this share of the area is seen.
ENOUGH = 0.99
#: A face hit at more than this angle to the view direction does not count as seen.
MAX_ANGLE_DEGREES = 75.0


def seen_area(mesh, view: View, size: tuple[int, int] = DEFAULT_SIZE) -> np.ndarray:
    """Boolean (F,): the faces ``view`` sees squarely enough (see the module notes)."""
    render = render_mesh(mesh, view, size)
    seen = np.zeros(len(mesh.faces), dtype=bool)
    seen[np.unique(render.face[render.mask])] = True
    facing = np.asarray(mesh.face_normals) @ view.direction
    return seen & (facing >= np.cos(np.radians(MAX_ANGLE_DEGREES)))


def choose_views(
    mesh, candidates: tuple[View, ...] | list[View] = CANDIDATES, size=DEFAULT_SIZE
) -> list[View]:
    """The candidates that together see the surface, most useful first (front first).

    Parameters
    ----------
    mesh : trimesh.Trimesh
    candidates : sequence of View
        The first is always taken.
    size : (int, int)
        Render size used to find what each view sees.

    Returns
    -------
    list of View
    """
    area = np.asarray(mesh.area_faces, dtype=np.float64)
    total = max(float(area.sum()), 1e-300)
    seen = {view: seen_area(mesh, view, size) for view in candidates}
    chosen = [candidates[0]]
    covered = seen[candidates[0]].copy()
    while len(chosen) < len(candidates) and area[covered].sum() / total < ENOUGH:
        gains = {
            view: float(area[seen[view] & ~covered].sum()) / total
            for view in candidates
            if view not in chosen
        }
        best = max(gains, key=lambda view: (gains[view], -candidates.index(view)))
        if gains[best] < MIN_GAIN:
            break
        chosen.append(best)
        covered |= seen[best]
    return chosen
