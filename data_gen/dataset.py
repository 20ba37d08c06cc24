"""Writing a class of instances to disk in the database format, with a contact sheet."""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

import numpy as np

from data_gen.core import (
    Instance,
    ObjectClass,
    colour_surface,
    make_instance,
    posed_instance,
)
from data_gen.render import ray_backend
from imagemap.io import InputError, atomic_path, write_image
from imagemap.progress import progress

__all__ = [
    "INSTANCE_MAPS",
    "compare_run",
    "contact_sheet",
    "instance_mesh",
    "planned_files",
    "write_class",
    "write_instance",
]

log = logging.getLogger(__name__)


#: The PBR maps :func:`write_instance` writes beside every instance
#: (:func:`data_gen.core.instance_maps`).
INSTANCE_MAPS = ("normal", "roughness", "height", "ao")


def planned_files(
    class_name: str, count: int, holdout: int = 0, meshes: bool = False
) -> list[Path]:
    """The files :func:`write_class` writes, relative to its ``out`` folder.

    Examples
    --------
    >>> [str(p) for p in planned_files("fish", 2, holdout=1)][:3]
    ['contact_sheet.png', 'fish_000.json', 'fish_000_ao.png']
    >>> len(planned_files("fish", 2, holdout=1, meshes=True))
    19
    """
    files = [Path("contact_sheet.png")]
    for index in range(count):
        name = f"{class_name}_{index:03d}"
        folder = Path("holdout") if index >= count - holdout else Path()
        kinds = ["depth", "image", "labels", *INSTANCE_MAPS]
        files += [folder / f"{name}_{kind}.png" for kind in kinds] + [folder / f"{name}.json"]
        if meshes:
            files.append(folder / "meshes" / f"{name}.glb")
    return sorted(files)


def compare_run(
    out: str | os.PathLike,
    existing: list[Path],
    class_name: str,
    *,
    count: int,
    seed: int,
    size: tuple[int, int],
    holdout: int = 0,
    meshes: bool = False,
) -> tuple[list[Path], list[Path], str]:
    """How a run compares with the earlier one whose files (``existing``, relative to
    ``out``) are in its folder: (the files it would replace, the files it would leave
    behind, why the settings differ; "" when they do not).

    The settings differ when an instance's JSON records another seed or size (or
    cannot be read), or when files of the earlier run are not among this run's
    (more instances, another holdout split, meshes): those would be left beside the
    new ones, a mixed database. Replacing an earlier run of the same settings rewrites
    the same bytes.
    """
    out = Path(out)
    planned = set(planned_files(class_name, count, holdout, meshes))
    replaced = sorted(p for p in existing if p in planned)
    left = sorted(p for p in existing if p not in planned)
    reasons = []
    for sidecar in (p for p in existing if p.suffix == ".json"):
        try:
            record = json.loads((out / sidecar).read_text())
            earlier = (int(record["seed"]), tuple(int(v) for v in record["size"]))
        except (OSError, ValueError, KeyError, TypeError):
            reasons.append(f"{sidecar} does not say its settings")
            break
        if earlier != (int(seed), tuple(int(v) for v in size)):
            reasons.append(
                f"{sidecar} was made at --seed {earlier[0]} --size {earlier[1][0]}x"
                f"{earlier[1][1]}, this run is --seed {seed} --size {size[0]}x{size[1]}"
            )
            break
    if left:
        reasons.append(
            f"{len(left)} of its files are not among this run's ({', '.join(map(str, left[:3]))}"
            f"{' ...' if len(left) > 3 else ''}: another --count, --holdout or --meshes)"
        )
    return replaced, left, "; ".join(reasons)


def write_instance(instance: Instance, directory: str | os.PathLike) -> list[Path]:
    """Write ``NAME_depth.png`` (16-bit), ``NAME_image.png``, ``NAME_labels.png``, ``NAME.json``
    and the PBR maps ``NAME_normal.png``, ``NAME_roughness.png``, ``NAME_height.png``
    (16-bit), ``NAME_ao.png`` (see :func:`data_gen.core.instance_maps`).

    Every file is written atomically. Returns the paths written.
    """
    directory = Path(directory)
    name = instance.name
    paths = [
        write_image(directory / f"{name}_depth.png", instance.depth, bits=16),
        write_image(directory / f"{name}_image.png", instance.image, bits=8),
        write_image(directory / f"{name}_labels.png", instance.labels),
    ]
    for kind, array in sorted(instance.maps.items()):
        bits = 16 if kind == "height" else 8
        paths.append(write_image(directory / f"{name}_{kind}.png", array, bits=bits))
    sidecar = directory / f"{name}.json"
    with atomic_path(sidecar) as tmp:
        tmp.write_text(json.dumps(instance.params, indent=1, sort_keys=True) + "\n")
    return [*paths, sidecar]


def instance_mesh(object_class: ObjectClass, index: int, seed: int = 0, texture_size: int = 512):
    """Instance ``index`` as a textured trimesh, posed as it is rendered (view jitter included).

    The class's colouring is evaluated at every texel of a UV atlas (the class's
    :attr:`~data_gen.core.ObjectClass.uv_layout`, else ``xatlas``), so
    the mesh rendered from the front shows the instance's image-map; its roughness
    per part (:func:`data_gen.core.part_roughness`) is the material's roughness
    texture. Same seed, same mesh and textures.
    """

    from data_gen.core import part_roughness
    from imagemap.core.blend import fill_background
    from imagemap.scene import rasterize_uv, textured_mesh, uv_atlas

    params, _, assembly, pose, mesh = posed_instance(object_class, index, seed)
    if object_class.uv_layout is not None:
        source, faces, uv = object_class.uv_layout(params, assembly)
        vertices = np.asarray(mesh.vertices, dtype=np.float64)[source]
    else:
        vertices, faces, uv, source = uv_atlas(mesh)
    texel, face, bary = rasterize_uv(uv, faces, texture_size)
    points = np.einsum("nk,nkc->nc", bary, vertices[faces[face]])
    labels, rgb = colour_surface(object_class, params, assembly, pose, mesh, face, points)
    texture = np.zeros((texture_size, texture_size, 4), dtype=np.float32)
    texture.reshape(-1, 4)[texel, :3] = rgb
    luma = rgb @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
    texture.reshape(-1, 4)[texel, 3] = part_roughness(object_class.parts, labels, luma)
    covered = np.zeros((texture_size, texture_size), dtype=bool)
    covered.flat[texel] = True
    texture = fill_background(texture, covered)
    return textured_mesh(vertices, faces, uv, texture[..., :3], maps={"roughness": texture[..., 3]})


def contact_sheet(
    instances: list[Instance], columns: int | None = None, gap: int = 4
) -> np.ndarray:
    """One picture of a class: for each instance its depth (grey) beside its image-map.

    Parameters
    ----------
    instances : list of Instance
        All of the same size.
    columns : int, optional
        Instances per row (about square overall by default).
    gap : int, optional
        Pixels of grey between tiles.

    Returns
    -------
    sheet : ndarray of float32, (H', W', 3) in [0, 1]
    """
    if not instances:
        raise InputError("contact sheet: no instances")
    height, width = instances[0].depth.shape
    columns = columns or max(1, int(np.ceil(np.sqrt(len(instances) / 2.0))))
    rows = int(np.ceil(len(instances) / columns))
    tile_w = 2 * width + gap
    sheet = np.full(
        (rows * (height + gap) + gap, columns * (tile_w + gap) + gap, 3), 0.25, dtype=np.float32
    )
    for k, instance in enumerate(instances):
        top = gap + (k // columns) * (height + gap)
        left = gap + (k % columns) * (tile_w + gap)
        sheet[top : top + height, left : left + width] = instance.depth[..., None]
        sheet[top : top + height, left + width + gap : left + tile_w] = instance.image
    return sheet


def write_class(
    object_class: ObjectClass | str,
    out: str | os.PathLike,
    count: int = 20,
    seed: int = 0,
    size: tuple[int, int] | None = None,
    holdout: int = 0,
    quiet: bool = False,
    meshes: bool = False,
) -> list[Instance]:
    """Make and write instances 0..count-1 of a class into ``out``.

    Parameters
    ----------
    object_class : ObjectClass or str
        The class or its name (``"fish"``, ``"busts"``, ``"humans"``).
    out : path-like
        Output directory (created). ``out/contact_sheet.png`` shows all instances.
    count : int, optional
    seed : int, optional
        Instance i of a seed is the same whatever ``count`` is.
    size : (int, int), optional
        (width, height); the class default if None.
    holdout : int, optional
        The last ``holdout`` instances go to ``out/holdout/`` instead, so they can be
        queries that are not in the database.
    quiet : bool, optional
        No progress bar.
    meshes : bool, optional
        Also write each instance as a textured mesh ``meshes/NAME.glb`` (beside the
        database, or in ``holdout/meshes/``), posed as rendered.

    Returns
    -------
    list of Instance (without meshes)

    Example
    -------
    >>> write_class("fish", "examples/fish", count=9, holdout=1)  # doctest: +SKIP
    """
    if isinstance(object_class, str):
        from data_gen import CLASSES

        if object_class not in CLASSES:
            raise InputError(
                f"class: unknown class {object_class!r} (choose from {sorted(CLASSES)})"
            )
        object_class = CLASSES[object_class]
    if count < 1:
        raise InputError(f"--count: must be at least 1, got {count}")
    if not 0 <= holdout < count:
        raise InputError(f"--holdout: must be in [0, count), got {holdout} for count {count}")
    out = Path(out)
    log.info("%s, ray backend %s", object_class.name, ray_backend())
    instances = []
    for index in progress(range(count), total=count, desc=object_class.name, quiet=quiet):
        instance = make_instance(object_class, index, seed=seed, size=size)
        target = out / "holdout" if index >= count - holdout else out
        write_instance(instance, target)
        if meshes:
            from imagemap.scene import export_textured

            textured = instance_mesh(object_class, index, seed=seed)
            export_textured(textured, target / "meshes" / f"{instance.name}.glb")
        instances.append(instance)
    write_image(out / "contact_sheet.png", contact_sheet(instances))
    return instances
