"""Planning a batch: its options, one job per input, and every output checked before any work."""

from __future__ import annotations

import hashlib
import json
import os
import re
from collections.abc import Mapping
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from imagemap.batch.digests import engine_digest
from imagemap.database import Database
from imagemap.depth.config import DepthConfig, resolve_config
from imagemap.io import InputError
from imagemap.outputs import OutputPlan, check_output_directory, resolve, written_companions
from imagemap.scene import FRONT, MESH_SUFFIXES, View, file_digest, parse_views
from imagemap.validate import check_float, check_int, check_seed

__all__ = [
    "DONE_DIR",
    "MIN_VIEW_SIDE",
    "REPORT_NAME",
    "BatchOptions",
    "Job",
    "check_outputs",
    "plan_jobs",
    "with_map_companions",
]


_DEPTH_RE = re.compile(r"^(?P<name>.+)_depth\.(?:png|tif|tiff|npy)$", re.IGNORECASE)
DONE_DIR = ".imagemap-done"
#: The smallest side of a view's depth map (``--size``'s own minimum).
MIN_VIEW_SIDE = 16


@dataclass(frozen=True)
class BatchOptions:
    """What every object of a batch is synthesized with.

    ``options`` are :data:`imagemap.depth.config.OPTIONS` by name (a mapping; kept
    as sorted pairs), over ``preset``; ``views`` apply to meshes (a depth-map query
    sees mesh examples as ``imagemap synthesize`` shows them to it: from the front at
    the default size), and with ``auto_views`` they are the candidates each mesh
    chooses from by coverage (``--views auto``); ``texture_size`` None: each mesh's
    own atlas resolution; ``size`` None: each mesh's views as fine as its texels
    (:func:`imagemap.scene.bake.view_size_for`, the default of ``imagemap synthesize
    MESH``; :attr:`Job.size`); ``scale`` multiplies the written coordinates
    (``--units``/``--scale``); ``uv_space`` as ``--uv-space``/``--no-uv-space`` (None:
    detected); ``registered`` False as ``--no-register``; ``maps`` False writes the
    colour only (``--no-maps``); ``background`` None writes RGBA maps with a transparent
    background, else RGB on that colour.
    Every object is made as ``imagemap synthesize`` makes it with the same options
    (:meth:`mesh_request`). Checked when built: an unknown preset or option, or a
    value the configuration refuses, is an
    :class:`InputError`.
    """

    preset: str = "busts"
    options: Any = ()
    seed: int = 0
    views: tuple[View, ...] = (FRONT,)
    size: tuple[int, int] | None = None
    texture_size: int | None = None
    mesh_format: str = "glb"
    background: tuple[float, float, float] | None = None
    auto_views: bool = False
    scale: float = 1.0
    uv_space: bool | None = None
    registered: bool | None = None
    maps: bool = True

    def __post_init__(self) -> None:
        if not isinstance(self.options, Mapping | tuple | list):
            raise InputError(f"options: expected a mapping of option names, got {self.options!r}")
        try:
            pairs = self.options.items() if isinstance(self.options, Mapping) else self.options
            options = tuple(sorted((str(k), v) for k, v in dict(pairs).items() if v is not None))
        except (TypeError, ValueError):
            raise InputError(
                f"options: expected (name, value) pairs, got {self.options!r}"
            ) from None
        object.__setattr__(self, "options", options)
        self.config()  # refuses a bad preset, option or combination now
        check_seed(self.seed)
        if isinstance(self.views, str):
            object.__setattr__(self, "views", tuple(parse_views(self.views)))
        if isinstance(self.views, View) or not all(isinstance(v, View) for v in self.views):
            raise InputError(f"views: expected a sequence of View or a string, got {self.views!r}")
        object.__setattr__(self, "views", tuple(self.views))
        if not self.views:
            raise InputError("views: at least one view is needed")
        if len(set(self.views)) != len(self.views):
            raise InputError(f"views: a view is given twice in {[str(v) for v in self.views]}")
        if self.size is not None:
            if not (isinstance(self.size, tuple | list) and len(self.size) == 2):
                raise InputError(f"size: expected (width, height) or None, got {self.size!r}")
            size = tuple(check_int("size", v, minimum=MIN_VIEW_SIDE) for v in self.size)
            object.__setattr__(self, "size", size)
        if self.texture_size is not None:
            check_int("texture_size", self.texture_size, minimum=1)
        scale = check_float("scale", self.scale, 0.0, float("inf"))
        if not scale > 0:
            raise InputError(f"scale: must be a positive number, got {self.scale}")
        object.__setattr__(self, "scale", float(scale))
        if self.uv_space not in (None, True, False):
            raise InputError(f"uv_space: expected True, False or None, got {self.uv_space!r}")
        if self.registered not in (None, True, False):
            raise InputError(f"registered: expected True, False or None, got {self.registered!r}")
        for flag in ("auto_views", "maps"):
            if not isinstance(getattr(self, flag), bool):
                raise InputError(f"{flag}: expected True or False, got {getattr(self, flag)!r}")
        if self.mesh_format not in ("glb", "obj"):
            raise InputError(f"mesh format must be glb or obj, got {self.mesh_format!r}")
        if self.background is not None:
            colour = tuple(check_float("background", c, 0.0, 1.0) for c in self.background)
            if len(colour) != 3:
                raise InputError(f"background: expected (r, g, b) in [0, 1], got {colour}")
            object.__setattr__(self, "background", colour)

    def record(self) -> dict:
        """The options as a JSON-ready dict (what a manifest records beside :meth:`key`)."""
        record = asdict(self)
        record["views"] = [str(v) for v in self.views]
        return record

    def key(self) -> str:
        """A digest of everything that changes the outputs: the options and the engine's code."""
        record = self.record()
        record["engine"] = engine_digest()
        return hashlib.sha256(json.dumps(record, sort_keys=True).encode()).hexdigest()[:16]

    def colorize_options(self) -> dict:
        """The options as keywords of :func:`imagemap.colorize`."""
        return dict(self.options)

    def config(self) -> DepthConfig:
        """The :class:`~imagemap.depth.config.DepthConfig` every object is made with."""
        return resolve_config(self.preset, **self.colorize_options())

    def view_size(self, mesh) -> tuple[int, int]:
        """The views' size for ``mesh``: ``size``, else the one ``imagemap synthesize
        MESH`` chooses for it by default (:func:`imagemap.scene.bake.view_size_for`)."""
        if self.size is not None:
            return (int(self.size[0]), int(self.size[1]))
        from imagemap.scene.bake import view_size_for  # deferred: start-up (trimesh)

        return view_size_for(mesh, self.views, self.texture_size)

    def mesh_request(self, size: tuple[int, int] | None = None):
        """The :class:`~imagemap.mesh.route.MeshRequest` a mesh is made with: the one
        ``imagemap synthesize MESH`` builds from the same options; ``size`` is the
        mesh's views' (:meth:`view_size`; needed when ``self.size`` is None)."""
        from imagemap.mesh.route import MeshRequest  # deferred: start-up (workers only)

        size = size if size is not None else self.size
        if size is None:
            raise InputError("mesh_request: size None: give the mesh's (BatchOptions.view_size)")
        return MeshRequest(
            views=tuple(self.views),
            auto_views=self.auto_views,
            size=(int(size[0]), int(size[1])),
            texture_size=self.texture_size,
            config=self.config(),
            seed=self.seed,
            uv_space=self.uv_space,
            registered=self.registered,
            maps=self.maps,
        )


@dataclass(frozen=True)
class Job:
    """One object of a batch: its source file, kind and outputs."""

    source: Path
    name: str
    kind: str  # "depth" or "mesh"
    output: Path
    manifest: Path
    companions: tuple[Path, ...] = ()  # written with the output (an OBJ's .mtl and texture)
    # BatchOptions.key() as the batch's process computed it: a worker started later would
    # digest the engine's files as they are then (an upgrade mid-batch), not as they were.
    options_key: str = ""
    # A mesh's views' size (BatchOptions.view_size), chosen where the database is
    # prepared for it; None: BatchOptions.size.
    size: tuple[int, int] | None = None


def plan_jobs(
    input_dir: str | os.PathLike, out_dir: str | os.PathLike, options: BatchOptions
) -> list[Job]:
    """One :class:`Job` per depth map (``NAME_depth.*``) or mesh in ``input_dir``, by name.

    Every path is absolute (a Dask worker resolves a relative one against its own working
    directory). Two inputs whose outputs meet (``a_depth.png`` and ``a.npy``, or a depth
    ``a_depth.png`` and an OBJ mesh ``a_image.obj``, whose texture is ``a_image.png``) are
    an :class:`InputError` naming both.
    """
    shown_input = input_dir
    input_dir, out_dir = resolve(input_dir), resolve(out_dir)
    if not input_dir.exists():
        raise InputError(f"{shown_input}: input directory not found")
    if not input_dir.is_dir():
        raise InputError(f"{shown_input}: not a directory")
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"{out_dir}: output exists and is not a directory")
    jobs = []
    outputs: dict[Path, Path] = {}
    try:
        entries = sorted(input_dir.iterdir())
    except OSError as exc:
        raise InputError(f"{shown_input}: cannot be listed ({exc.strerror or exc})") from None
    for entry in entries:
        if not entry.is_file():
            continue
        if match := _DEPTH_RE.match(entry.name):
            name, kind = match["name"], "depth"
            output = out_dir / f"{name}_image.png"
        elif entry.suffix.lower() in MESH_SUFFIXES:
            name, kind = entry.stem, "mesh"
            output = out_dir / f"{name}.{options.mesh_format}"
        else:
            continue
        companions = tuple(written_companions(output))
        for path in (output, *companions):
            if path in outputs:
                raise InputError(
                    f"{entry} and {outputs[path]} would both write {path.name} in {out_dir}: "
                    "rename one of them"
                )
            outputs[path] = entry
        manifest = out_dir / DONE_DIR / f"{entry.name}.json"
        jobs.append(Job(entry, name, kind, output, manifest, companions))
    if not jobs:
        raise InputError(
            f"{input_dir}: no depth maps (NAME_depth.png|tif|npy) or meshes "
            f"({', '.join(MESH_SUFFIXES)}) found"
        )
    return jobs


def with_map_companions(jobs: list[Job], kinds: list[str] | tuple[str, ...]) -> list[Job]:
    """Each job with the PBR maps it may write beside its output, for every kind the
    database has (:func:`imagemap.materials.database_map_kinds`), named as ``imagemap
    synthesize`` names them: a depth map's ``NAME_KIND.png`` beside its image-map (as
    ``imagemap synthesize A_depth.png B_depth.png -o DIR`` writes them), a mesh's
    ``STEM_height.png`` beside it (the map glTF has no slot for:
    :data:`imagemap.materials.SIDE_MAPS`)."""
    from imagemap.materials import SIDE_MAPS  # deferred: start-up

    out = []
    for job in jobs:
        if job.kind == "depth":
            maps = [job.output.with_name(f"{job.name}_{kind}.png") for kind in kinds]
        else:
            maps = [
                job.output.with_name(f"{job.output.stem}_{k}.png") for k in SIDE_MAPS if k in kinds
            ]
        if maps:
            job = replace(job, companions=(*job.companions, *maps))
        out.append(job)
    return out


def _outputs_of(job: Job) -> list[Path]:
    return [*job.companions, job.output]


def _names(job: Job) -> list[str]:
    return [p.name for p in _outputs_of(job)]


def _started(job: Job) -> Path:
    """Where a job records, before writing, the outputs it is about to write."""
    return job.manifest.with_name(job.manifest.name + ".started")


#: The batch's summary, written into the output folder.
REPORT_NAME = "batch_report.json"


def _claimed(out_dir: Path) -> list[Path]:
    """The files an earlier batch wrote into ``out_dir``: every output its manifests name
    (finished or started), its report, and the outputs its report records with the very
    content they have now (a manifest deleted since: the output is still the batch's)."""
    claimed = []
    done = out_dir / DONE_DIR
    manifests = [*done.glob("*.json"), *done.glob("*.json.started")] if done.is_dir() else []
    for manifest in sorted(manifests):
        try:
            record = json.loads(manifest.read_text())
        except (OSError, ValueError):
            continue
        if isinstance(record, dict):
            names = [*(record.get("outputs") or {}), *(record.get("planned") or [])]
            claimed += [out_dir / str(name) for name in names if Path(str(name)).name == name]
    report = out_dir / REPORT_NAME
    try:
        content = json.loads(report.read_text())
        if not {"done", "objects"} <= set(content):
            return claimed
    except (OSError, ValueError, TypeError):
        return claimed
    claimed.append(report)
    for record in content["objects"] if isinstance(content["objects"], list) else []:
        outputs = record.get("outputs") if isinstance(record, dict) else None
        for name, digest in (outputs or {}).items() if isinstance(outputs, dict) else ():
            path = out_dir / str(name)
            if Path(str(name)).name != name or path in claimed or not path.is_file():
                continue
            if file_digest(path) == digest:
                claimed.append(path)
    return claimed


def check_outputs(
    jobs: list[Job], database: Database, out_dir: str | os.PathLike, database_dir=None
) -> None:
    """Every output of a batch checked before any work (see the module docstring).

    Raises
    ------
    InputError
        Naming the output and what it would replace, or the folder that cannot be written.
    """
    out_dir = resolve(out_dir)
    check_output_directory(out_dir, "-o directory")
    plan = OutputPlan()
    for job in jobs:
        plan.add_query(job.source, f"input {job.kind}")
    if database_dir is None and database.source and Path(database.source).is_dir():
        database_dir = database.source
    plan.add_database(database, database_dir)
    for job in jobs:
        plan.add_output(job.output, "-o", companions=job.companions, fresh=True)
    plan.add_output(out_dir / REPORT_NAME, "the batch report", fresh=True)
    plan.claim(_claimed(out_dir))
    plan.check()
