"""Mesh primitives with canonical coordinates, and their assembly into one trimesh.

Every primitive is a deformed icosphere, so it is a closed, consistently wound
triangle mesh. Beside its vertices it carries *canonical* coordinates: where each
vertex sat on the unit sphere before the deformation (for a limb: across-limb
position and the fraction along it). Appearance is a function of the canonical
coordinates interpolated at the ray hit, so stripes, spots and part boundaries are
attached to the surface and follow it when the shape or the pose changes.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import trimesh

__all__ = ["Assembly", "Component", "assemble", "ellipsoid", "limb", "sphere_component"]


@dataclass
class Component:
    """One closed sub-mesh: vertices (N, 3), faces (M, 3), canonical coordinates (N, 3)."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    canonical: np.ndarray


@dataclass
class Assembly:
    """All components of an object in one mesh, with per-face component ids."""

    mesh: trimesh.Trimesh
    component_names: tuple[str, ...]
    face_component: np.ndarray  # (F,) int: index into component_names
    vertex_canonical: np.ndarray  # (V, 3) float32


def _unit_sphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    return np.asarray(sphere.vertices, dtype=np.float64), np.asarray(sphere.faces)


def sphere_component(
    name: str,
    deform: Callable[[np.ndarray], np.ndarray],
    subdivisions: int = 3,
) -> Component:
    """A unit icosphere whose vertices are moved by ``deform`` (canonical -> object space).

    ``deform`` must keep the orientation (no mirroring), so the outward winding of the
    faces survives.
    """
    canonical, faces = _unit_sphere(subdivisions)
    vertices = np.asarray(deform(canonical), dtype=np.float64)
    return _outward(Component(name, vertices, faces, canonical))


def _outward(component: Component) -> Component:
    """Flip the winding if a deformation mirrored the sphere (negative signed volume)."""
    corners = component.vertices[component.faces]
    signed_volume = np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2]))
    if signed_volume.sum() < 0:
        component.faces = component.faces[:, ::-1].copy()
    return component


def _frame(direction: np.ndarray, up_hint: Sequence[float] = (0.0, 0.0, 1.0)) -> np.ndarray:
    """Rotation (3, 3) whose third column is ``direction`` (unit), columns right-handed."""
    axis = direction / np.linalg.norm(direction)
    hint = np.asarray(up_hint, dtype=np.float64)
    if abs(float(hint @ axis)) > 0.95:
        hint = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    first = np.cross(hint, axis)
    first /= np.linalg.norm(first)
    second = np.cross(axis, first)
    return np.stack([first, second, axis], axis=1)


def ellipsoid(
    name: str,
    center: Sequence[float],
    radii: Sequence[float],
    rotation: np.ndarray | None = None,
    subdivisions: int = 2,
) -> Component:
    """An ellipsoid with semi-axes ``radii``, rotated by ``rotation`` (3, 3), at ``center``."""
    rotation = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    center = np.asarray(center, dtype=np.float64)
    return sphere_component(name, lambda p: (p * radii) @ rotation.T + center, subdivisions)


def limb(
    name: str,
    start: Sequence[float],
    end: Sequence[float],
    radius_start: float,
    radius_end: float,
    flatten: float = 1.0,
    subdivisions: int = 2,
    up_hint: Sequence[float] = (0.0, 0.0, 1.0),
) -> Component:
    """A tapered capsule from ``start`` to ``end`` (round caps of the two radii).

    The unit sphere is cut at its equator and the halves are pulled apart along the
    axis, so the band of triangles across the equator becomes the (conical) side.
    Canonical coordinates: (x, y) across the limb on the unit circle, and the
    fraction along it in [0, 1] (caps slightly beyond).

    ``flatten`` < 1 squeezes the cross-section along the frame's first axis (the
    direction of ``up_hint`` x axis), e.g. for a foot or a hand.
    """
    start = np.asarray(start, dtype=np.float64)
    end = np.asarray(end, dtype=np.float64)
    length = float(np.linalg.norm(end - start))
    rotation = _frame(end - start, up_hint)
    unit, faces = _unit_sphere(subdivisions)
    far_half = unit[:, 2] >= 0
    radius = np.where(far_half, radius_end, radius_start)
    local = np.empty_like(unit)
    local[:, 0] = unit[:, 0] * radius * flatten
    local[:, 1] = unit[:, 1] * radius
    local[:, 2] = unit[:, 2] * radius + np.where(far_half, length, 0.0)
    vertices = local @ rotation.T + start
    canonical = np.stack([unit[:, 0], unit[:, 1], local[:, 2] / max(length, 1e-9)], axis=1)
    return _outward(Component(name, vertices, faces, canonical))


def assemble(components: Sequence[Component]) -> Assembly:
    """Concatenate components into one trimesh (unprocessed, so face order is kept).

    Each component is closed, so the whole is watertight edge-wise; components may
    interpenetrate, which ray casting with the first hit handles.
    """
    vertices, faces, canonical, face_component = [], [], [], []
    offset = 0
    for index, component in enumerate(components):
        vertices.append(component.vertices)
        faces.append(component.faces + offset)
        canonical.append(component.canonical)
        face_component.append(np.full(len(component.faces), index, dtype=np.int32))
        offset += len(component.vertices)
    mesh = trimesh.Trimesh(np.concatenate(vertices), np.concatenate(faces), process=False)
    return Assembly(
        mesh=mesh,
        component_names=tuple(c.name for c in components),
        face_component=np.concatenate(face_component),
        vertex_canonical=np.concatenate(canonical).astype(np.float32),
    )
