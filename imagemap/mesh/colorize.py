"""Colorizing a mesh: in its UV atlas, from examples in its layout or registered into it;
else by views.

Three paths (:attr:`MeshResult.path` says which ran, and the log at INFO):

- **uv-space** (:mod:`imagemap.mesh.uvspace`): when the query mesh and textured mesh
  examples of the database share one UV layout (a registered template, as scanned
  faces), the texture is synthesised in the atlas itself, with surface guides and the
  examples' own textures. No view: nothing hidden, nothing mirrored. The layout is
  detected (:func:`imagemap.mesh.uvspace.shares_layout`) or declared (``uv_space=True``,
  ``--uv-space``).
- **registered** (:mod:`imagemap.mesh.register`): when the database has textured mesh
  examples but not in the query's layout, each is registered to the query in 3-D
  (rigid, mirrored where the class allows it, then smooth non-rigid) and resampled into
  the query's atlas (an xatlas atlas for a query without UVs); the uv-space synthesis
  then runs on them as on examples in the layout.
- **views** (depth-map examples only, or forced): one synthesis per view, all from the
  same examples (chosen once for the object, :func:`shared_examples`), textured by
  projection (one view) or baked into a UV atlas, each texel from the view that sees it
  best (:func:`imagemap.scene.bake.bake_views`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from imagemap.database import Database
from imagemap.depth.config import resolve_config
from imagemap.depth.pipeline import colorize
from imagemap.depth.selection import selection_distances
from imagemap.io import InputError
from imagemap.mesh.fineviews import fine_factor, fine_views
from imagemap.mesh.library import ExampleSet
from imagemap.mesh.register import registered_examples
from imagemap.mesh.uvspace import (
    LAYOUT_TEST_SIZE,
    UVExample,
    colorize_uv,
    mesh_uv_arrays,
    shares_layout,
    surface_maps,
)
from imagemap.scene.bake import (
    MIN_TEXTURE_SIZE,
    bake_views,
    project_texture,
    uv_atlas,
    view_shares,
)
from imagemap.scene.files import check_finite, load_mesh, textured_mesh
from imagemap.scene.views import (
    DEFAULT_SIZE,
    FRONT,
    MeshRender,
    View,
    parse_view,
    parse_views,
    render_mesh,
    texture_image,
)
from imagemap.validate import check_int, check_mesh, check_size

__all__ = [
    "PATHS",
    "MeshResult",
    "colorize_mesh",
    "selection_distances",
    "shared_examples",
    "uv_layout_examples",
]

log = logging.getLogger("imagemap")

#: The mesh route's three ways of making a texture.
PATHS = ("uv-space", "registered", "views")
#: The engine's atlas size on the registered path (the uv-space path's is
#: :data:`imagemap.mesh.uvspace.WORKING_SIZE`): every example is already resampled into the
#: query's atlas, so the engine only chooses which example each part comes from, and the
#: texture is copied at the output size. fish_008 (512², 2 of 8 examples): the same
#: figures at 128 as at 256 (mean ΔE00 30.97 / 30.99, crispness 0.83 / 0.84, flank
#: difference 3.68 / 3.79) at 0.3 of the synthesis' CPU.
REGISTERED_WORKING_SIZE = 128


@dataclass
class MeshResult:
    """A textured mesh, and what made it.

    Attributes
    ----------
    mesh : trimesh.Trimesh
        With UVs and the texture.
    renders : list of MeshRender
        One per view (none on the uv-space path).
    results : list of ColorizeResult
        One per view; on the uv-space path one, whose image is the texture.
    path : str
        ``"uv-space"``, ``"registered"`` or ``"views"`` (:data:`PATHS`).
    examples : list of UVExample
        The two atlas paths: the examples the texture was copied from, in the order of
        ``results[0].example_names`` (their PBR maps are carried the same way,
        :func:`imagemap.mesh.maps.atlas_maps`); empty on the views path.
    fine : list of FineSource
        Views path: each view's copy at the texels' resolution
        (:func:`imagemap.mesh.fineviews.fine_source`), through which its PBR maps are
        copied too; empty when the views were baked as synthesized.
    """

    mesh: object  # trimesh.Trimesh with UVs and texture
    renders: list[MeshRender]
    results: list  # one ColorizeResult per view (uv-space: one, the atlas)
    path: str = "views"
    examples: list = field(default_factory=list)
    fine: list = field(default_factory=list)

    @property
    def image(self) -> np.ndarray:
        """The first view's synthesized map (H, W, 3); on the uv-space path, the texture."""
        return self.results[0].image

    @property
    def example_names(self) -> list[str]:
        """The examples used (the same for every view)."""
        return list(self.results[0].example_names)


def shared_examples(
    renders: list[MeshRender],
    databases: list[Database],
    m: int,
    weights: np.ndarray | None = None,
) -> list[str]:
    """The ``m`` examples nearest the object over all its views: one choice for every view.

    Each view's selection distances (:func:`selection_distances`, the query's depth
    against the examples seen from the same view), per pixel of the object, are summed
    with ``weights``: by default each view's share of the surface it sees best
    (:func:`imagemap.scene.bake.view_shares` needs the mesh; without it, equal weights),
    so a view that gives the texture little (a fish seen head-on: 2-4 % of its surface,
    but ten times the flanks' distances) does not choose for it. Ties keep the
    database's order.
    """
    names = databases[0].names
    if weights is None:
        weights = np.full(len(renders), 1.0 / len(renders))
    total = np.zeros(len(names))
    for render, database, weight in zip(renders, databases, weights, strict=True):
        if database.names != names:
            raise InputError("the views' databases hold different examples")
        pixels = max(int(render.mask.sum()), 1)
        total += weight * selection_distances(render.depth, database) / pixels
    order = np.argsort(total, kind="stable")[: min(m, len(names))]
    return [names[i] for i in order]


def _by_use(results: list, names: list[str]) -> list[str]:
    """``names`` ordered by the share of the object the views made so far copied from each
    (ties keep the order): the next views prefer what the object already shows, so that
    one part is not one example's in one view and another's in the next."""
    used = np.zeros(len(names))
    for result in results:
        index = result.source[..., 0][result.mask]
        for k, name in enumerate(result.example_names):
            if name in names:
                used[names.index(name)] += np.count_nonzero(index == k)
    order = np.argsort(-used, kind="stable")
    return [names[i] for i in order]


def uv_layout_examples(
    mesh,
    database: Database | dict[str, Database] | ExampleSet,
    uv_space: bool | None = None,
    names: list[str] | None = None,
) -> list | None:
    """The database's mesh examples in the query's UV layout, or None: the views path.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The query.
    database : Database, prepared views or ExampleSet
        Prepared views without the meshes (a dict) have no mesh example: always None.
    uv_space : bool, optional
        As :func:`colorize_mesh`: True declares every textured mesh example to be in the
        query's layout, False never takes the uv-space path, None detects the layout
        (:func:`imagemap.mesh.uvspace.shares_layout`).
    names : list of str, optional
        The examples asked for: the uv-space path is taken only when all of them are in
        the layout.

    Returns
    -------
    list of UVExample, or None

    Raises
    ------
    InputError
        With ``uv_space=True``, when the path cannot run (no UVs, no textured mesh
        example, an example named that is not one).
    """

    if uv_space is False:
        return None
    examples = ExampleSet.of(database)
    if not examples.mesh_names:
        if uv_space:
            raise InputError("--uv-space: the database has no textured mesh examples")
        return None
    if getattr(mesh.visual, "uv", None) is None:
        if uv_space:
            raise InputError("--uv-space: the query mesh has no UV coordinates")
        return None
    meshes = [n for n in examples.mesh_names if not names or n in names]
    if not meshes:
        if uv_space:
            raise InputError("--uv-space: the database has no textured mesh examples")
        return None
    query_maps = surface_maps(*mesh_uv_arrays(mesh), LAYOUT_TEST_SIZE)
    shared, others = [], []
    for name in meshes:
        example_mesh = examples.mesh(name)
        has_uv = getattr(example_mesh.visual, "uv", None) is not None
        texture = texture_image(example_mesh) if has_uv else None
        if texture is None:
            if uv_space:
                raise InputError(f"--uv-space: mesh example {name} has no UVs and texture")
            others.append(name)
            continue
        if uv_space or shares_layout(mesh, example_mesh, query_maps):
            # Kept as bytes (as read): a quarter of float32's memory at 1024^2 and more.
            texture = np.round(texture * 255.0).astype(np.uint8)
            shared.append(UVExample(name, example_mesh, texture))
        else:
            others.append(name)
    if not shared:
        return None
    missing = sorted(set(names or ()) - {e.name for e in shared})
    if missing:
        if uv_space:
            raise InputError(f"--uv-space: {', '.join(missing)} not a textured mesh example")
        log.info("uv-space path not taken: %s not in the query's UV layout", ", ".join(missing))
        return None
    if others:
        log.info("not in the query's UV layout (left out): %s", ", ".join(others))
    return shared


def registrable_examples(
    database: Database | dict[str, Database] | ExampleSet,
    names: list[str] | None = None,
) -> dict | None:
    """The textured mesh examples (name -> mesh) for the registered path, or None.

    None when the database has no mesh example with UVs and a texture (depth-map
    examples only: the views path), or when an example asked for in ``names`` is not one.
    """
    examples = ExampleSet.of(database)
    wanted = [n for n in examples.mesh_names if not names or n in names]
    if not wanted or (names and set(names) - set(wanted)):
        return None
    found = {}
    for name in wanted:
        example_mesh = examples.mesh(name)
        if (
            getattr(example_mesh.visual, "uv", None) is not None
            and texture_image(example_mesh) is not None
        ):
            found[name] = example_mesh
    if not found or (names and set(names) - set(found)):
        return None
    return found


def with_atlas(mesh):
    """``mesh`` itself when it has per-vertex UVs, else a copy with an xatlas atlas
    (vertices split along the charts' seams; :func:`imagemap.scene.bake.uv_atlas`)."""
    uv = getattr(mesh.visual, "uv", None)
    if uv is not None and len(uv) == len(mesh.vertices):
        return mesh
    import trimesh  # deferred: start-up (only a mesh without UVs needs a new one)

    vertices, faces, uv, _ = uv_atlas(mesh)
    return trimesh.Trimesh(
        vertices, faces, visual=trimesh.visual.TextureVisuals(uv=uv), process=False
    )


def colorize_mesh(
    mesh,
    database: Database | dict[str, Database] | ExampleSet,
    views: list[View] | str | None = None,
    *,
    size: tuple[int, int] = DEFAULT_SIZE,
    texture_size: int | None = None,
    uv_space: bool | list | None = None,
    registered: bool | None = None,
    preset="busts",
    seed: int = 0,
    examples: list[str] | None = None,
    quiet: bool = True,
    step: Callable[[str], None] | None = None,
    fine: bool = True,
    **colorize_options,
) -> MeshResult:
    """Synthesize a texture for a mesh: in its UV atlas, or from views (see the module notes).

    Parameters
    ----------
    mesh : trimesh.Trimesh or path
    database : Database, dict or ExampleSet
        The examples; or, prepared for each view (:func:`prepare_database`), a dict
        from ``str(view)`` (``"az,el"``) to Database (views path only); or an
        :class:`~imagemap.mesh.library.ExampleSet` (a batch's prepared set: views and meshes).
    views : list of View or str, optional
        The front by default; e.g. ``"front,back,left,right"`` (views path).
    size : (int, int)
        (width, height) of each view's depth map.
    texture_size : int, optional
        The texture's width and height; default: the query's own texture's, else the
        examples' (uv-space) or one from the mesh's texel density (views).
    uv_space : bool or list, optional
        True: synthesize in the UV atlas, the database's mesh examples declared to be in
        the query's layout; False: never; None (default): when some mesh examples are
        found in the query's layout; or the examples :func:`uv_layout_examples` found.
    preset, seed, examples, quiet, **colorize_options
        As :func:`imagemap.colorize`. Without ``examples``, the examples are chosen once
        for the object and every view uses them.
    step : callable, optional
        Called with a line of text as each long step begins: the synthesis in the atlas
        (uv-space), or each view's synthesis and then the bake (views): one call per view
        plus one (the mesh command's progress lines, :func:`imagemap.progress.step_line`).
    fine : bool
        Views path, mesh examples among those used: each view's map is
        copied again at the texels' resolution before the bake
        (:mod:`imagemap.mesh.fineviews`; #46 item 2, no stair steps); False bakes the
        synthesized maps as they are.

    Returns
    -------
    MeshResult
    """

    if not hasattr(mesh, "faces"):
        mesh = load_mesh(check_mesh(mesh))  # a path; None, a Scene, a PointCloud: InputError
    check_mesh(mesh)
    check_finite(mesh, "mesh")  # NaN vertices or UVs: refused, never dropped
    size = check_size(size, minimum=8)  # render_mesh's own smallest picture
    config = resolve_config(preset, **colorize_options)
    names = list(examples) if examples else None
    if views is None:
        views = [FRONT]
    elif isinstance(views, str):
        views = parse_views(views)
    elif isinstance(views, View):
        views = [views]
    if not isinstance(views, list | tuple) or not all(isinstance(v, str | View) for v in views):
        raise InputError(
            f"views: expected a View, a list of View objects or 'AZ,EL' / names, got {views!r}"
        )
    views = [parse_view(v) for v in views]
    examples_set = ExampleSet.of(database)
    if examples_set.source is not None:
        for name in names or ():
            examples_set.source[name]  # an unknown name is an InputError listing the known ones
    if texture_size is not None:
        texture_size = check_int("texture_size", texture_size, minimum=8)
    if not (uv_space is None or isinstance(uv_space, bool | list)):
        raise InputError(
            f"uv_space: expected True, False, None or the examples found, got {uv_space!r}"
        )
    uv_examples: list | None
    if isinstance(uv_space, list):
        uv_examples = uv_space  # found already (uv_layout_examples)
    else:
        uv_examples = uv_layout_examples(mesh, examples_set, uv_space, names)
    if uv_examples is not None:
        if texture_size is None:
            texture_size = _atlas_size(mesh, [e.texture for e in uv_examples])
        log.info(
            "mesh route: uv-space path (%d examples in the query's UV layout: %s), %d^2 texture",
            len(uv_examples),
            ", ".join(e.name for e in uv_examples),
            texture_size,
        )
        return _synthesize_in_atlas(
            mesh, uv_examples, config, texture_size, names, seed, quiet, step, "uv-space"
        )
    to_register = (
        registrable_examples(examples_set, names)
        if registered or (registered is None and uv_space is not False)
        else None
    )
    if to_register is not None:
        return _colorize_registered(
            mesh, to_register, config, texture_size, names, seed, quiet, step
        )

    renders, databases = [], []
    for view in views:
        render = render_mesh(mesh, view, size)
        if not render.mask.any():
            raise InputError(f"nothing of the mesh is visible from view {view}")
        renders.append(render)
        databases.append(examples_set.at_view(view, size))
    if names is None and len(views) > 1:
        shares = view_shares(mesh, renders)
        names = shared_examples(renders, databases, config.selection.m, shares)
    log.info(
        "mesh route: views path (%s), examples %s",
        ", ".join(str(v) for v in views),
        ", ".join(names) if names else "chosen by the view",
    )
    results = []
    fine_sources: list = []
    for render, examples_at_view in zip(renders, databases, strict=True):
        if step is not None:
            step(f"synthesizing view {render.view}")
        result = colorize(
            render.depth, examples_at_view, preset=config, seed=seed, quiet=quiet, examples=names
        )
        results.append(result)
        if names is not None and len(views) > 1:
            names = _by_use(results, names)
    if step is not None:
        step("projecting the view" if len(views) == 1 else f"baking {len(views)} views")
    # Each view copied again at the texels' resolution (#46 item 2), when an example can
    # be seen that finely (a mesh example; a picture has its pixels), then baked (or,
    # one view, projected: the texture is the fine picture).
    meshes = any(n in examples_set.mesh_names for r in results for n in r.example_names)
    factor = fine_factor(mesh, views, size, texture_size) if fine and meshes else 1
    images = [r.image for r in results]
    if factor > 1:
        images, fine_sources = fine_views(examples_set, renders, results, databases, factor)
        log.info("views copied at %dx their size for the %s", factor,
                 "projection" if len(views) == 1 else "bake")  # fmt: skip
    if len(views) == 1:
        textured = project_texture(mesh, renders[0], images[0])
    else:
        textured = bake_views(mesh, renders, images, texture_size)
    return MeshResult(
        mesh=textured, renders=renders, results=results, path="views", fine=fine_sources
    )


def _atlas_size(mesh, example_textures: list) -> int:
    """The texture size of a UV path's output: the query's own texture's, else the
    examples' largest. A texture under MIN_TEXTURE_SIZE is a placeholder (a grey 2x2 that
    exporters give an untextured material) and does not count: it would make a 2x2 map."""
    own = texture_image(mesh)
    if own is not None and max(own.shape[:2]) >= MIN_TEXTURE_SIZE:
        return int(max(own.shape[:2]))
    return int(max(max(t.shape[:2]) for t in example_textures if t is not None))


def _colorize_registered(
    mesh, meshes: dict, config, texture_size, names, seed, quiet, step
) -> MeshResult:
    """The registered path: the mesh examples registered to the query, resampled into its
    atlas (:func:`imagemap.mesh.register.registered_examples`), then the uv-space
    synthesis on them."""
    query = with_atlas(mesh)
    if texture_size is None:
        texture_size = _atlas_size(mesh, [texture_image(m) for m in meshes.values()])
    if step is not None:
        step(f"registering {len(meshes)} mesh examples to the query")
    examples, _ = registered_examples(
        query,
        meshes,
        m=config.selection.m,
        texture_size=int(texture_size),
        mirror=bool(config.selection.mirror),
        names=names,
        seed=seed,
        guide_size=min(REGISTERED_WORKING_SIZE, int(texture_size)),  # the engine's (colorize_uv)
    )
    log.info(
        "mesh route: registered path (%d mesh examples in other layouts, kept %s), %d^2 texture",
        len(meshes),
        ", ".join(e.name for e in examples),
        texture_size,
    )
    return _synthesize_in_atlas(
        query,
        list[UVExample](examples),
        config,
        texture_size,
        [e.name for e in examples],
        seed,
        quiet,
        step,
        "registered",
        working_size=REGISTERED_WORKING_SIZE,
        same_texel=True,
    )


def _synthesize_in_atlas(
    mesh, examples, config, texture_size, names, seed, quiet, step, path: str, **options
) -> MeshResult:
    """The two UV paths' synthesis in ``mesh``'s atlas (:func:`colorize_uv`, with
    ``options``) and the textured mesh it makes."""
    if step is not None:
        step(f"synthesizing in the UV atlas ({texture_size}^2)")
    result = colorize_uv(
        mesh, examples, config, size=int(texture_size), names=names, seed=seed, quiet=quiet,
        **options,
    )  # fmt: skip
    vertices, faces, uv = mesh_uv_arrays(mesh)
    textured = textured_mesh(vertices, faces, uv, result.image)
    by_name = {e.name: e for e in examples}
    used = [by_name[name] for name in result.example_names]
    return MeshResult(mesh=textured, renders=[], results=[result], path=path, examples=used)
