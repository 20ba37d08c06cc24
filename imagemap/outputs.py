"""Output paths planned and checked before any work, then written all-or-nothing.

One module for one job: the output plan: every path checked before work, written together.

Rules (docs/errors.md):

- Every output path is resolved (symbolic links followed) and compared with every
  input and every other output before any work. An output that is an input (the
  query depth, a file of the database, the held-out truth beside a query), or that
  two outputs share, is an :class:`~imagemap.io.InputError` naming both paths.
- An output's suffix must match what is written (``.png`` for images, ``.json`` for
  reports, ``.npz`` for archives).
- An existing file that belongs to an example or a held-out truth of any database (read
  by this command or not) is no output either: ``NAME_image.*``, ``NAME_labels.png``,
  ``NAME.json`` and every PBR map ``NAME_KIND.*`` that has a ``NAME_depth.*`` or a
  ``NAME`` mesh beside it (:func:`example_file`), and any existing depth map
  ``NAME_depth.*``. ``--overwrite`` (``synthesize``) replaces the kinds it names,
  :data:`OVERWRITE_KINDS`, and nothing else.
- Every output's folder must exist and be writable, or be creatable under a
  writable folder; an output may not be a directory. All of this is checked before
  the work starts.
- The outputs of one result are written as a set: each to a temporary file beside
  its target, then all renamed; if any fails, the temporaries are removed and no
  target is touched.

Examples
--------
>>> import shutil, tempfile
>>> folder = Path(tempfile.mkdtemp())
>>> plan = OutputPlan()
>>> plan.add_input(folder / "q_depth.png", "query depth")
>>> _ = plan.add_output(folder / "map.png", "-o", suffixes=(".png",))
>>> plan.check()  # no clash, and the folder is writable
>>> _ = plan.add_output(folder / "q_depth.png", "--provenance", suffixes=(".png",))
>>> plan.check()  # doctest: +ELLIPSIS
Traceback (most recent call last):
imagemap.errors.InputError: ...q_depth.png (--provenance) would overwrite ...q_depth.png (query...

A set of outputs is written whole, or not at all:

>>> def fail(tmp):
...     raise OSError("disk full")
>>> write_all({folder / "a.txt": lambda tmp: tmp.write_text("a"), folder / "b.txt": fail})
Traceback (most recent call last):
OSError: disk full
>>> list(folder.iterdir())  # neither a.txt nor a temporary file
[]
>>> write_all({folder / "a.txt": lambda tmp: tmp.write_text("a")})[0].read_text()
'a'
>>> shutil.rmtree(folder)
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import tempfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import unquote

from imagemap.io import InputError, make_temporary

__all__ = [
    "EXAMPLE_KINDS",
    "MESH_SUFFIXES",
    "OVERWRITE_KINDS",
    "TEXTURED_SUFFIXES",
    "TRUTH_SUFFIXES",
    "OutputPlan",
    "check_output_directory",
    "check_writable",
    "example_file",
    "exported",
    "mesh_companions",
    "query_name",
    "resolve",
    "same_file",
    "truths_beside",
    "write_all",
    "written_companions",
]


def resolve(path: str | os.PathLike) -> Path:
    """The absolute path with symbolic links and ``..`` resolved (the file need not exist)."""
    return Path(os.path.realpath(os.path.expanduser(os.fspath(path))))


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """True when ``a`` and ``b`` name the same file (same resolved path, or hard links)."""
    ra, rb = resolve(a), resolve(b)
    if os.path.normcase(ra) == os.path.normcase(rb):
        return True
    try:
        return os.path.samefile(ra, rb)
    except OSError:  # one of them does not exist
        return False


def _nearest_existing(path: Path) -> Path:
    for parent in path.parents:
        if parent.exists():
            return parent
    return Path(path.anchor or ".")


def check_writable(path: str | os.PathLike, what: str = "output") -> None:
    """Raise :class:`InputError` unless a file can be written at ``path``.

    ``path`` must not be a directory; its folder must exist and be writable, or be
    creatable inside the nearest existing folder (probed by creating and removing a
    temporary file there, which also catches read-only file systems).
    """
    target = resolve(path)
    if target.is_dir():
        raise InputError(f"{path}: {what} is a directory; give a file name")
    folder = target.parent
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{path}: cannot write {what}: {folder} is not a directory")
    existing = folder if folder.exists() else _nearest_existing(target)
    if not existing.is_dir():
        raise InputError(f"{path}: cannot write {what}: {existing} is not a directory")
    try:
        fd, probe = tempfile.mkstemp(prefix=".imagemap-probe.", dir=existing)
    except OSError as exc:
        raise InputError(
            f"{path}: cannot write {what} into {existing} ({exc.strerror or exc})"
        ) from None
    os.close(fd)
    os.unlink(probe)


def check_output_directory(path: str | os.PathLike, what: str = "output directory") -> None:
    """Raise :class:`InputError` unless ``path`` is, or can be made, a writable directory."""
    target = resolve(path)
    if target.exists() and not target.is_dir():
        raise InputError(f"{path}: {what} is an existing file, not a directory")
    check_writable(target / "probe", what)


#: Files beside a query (depth map or mesh) that hold its truth, as ``data_gen --holdout``
#: writes them: NAME followed by one of these. No output replaces them (unless
#: ``imagemap synthesize --overwrite``).
TRUTH_SUFFIXES = (
    "_image.png",
    "_image.jpg",
    "_image.jpeg",
    "_image.tif",
    "_image.tiff",
    "_labels.png",
    ".json",
)

#: Suffixes read as meshes (anything trimesh loads that holds triangles); also
#: :data:`imagemap.scene.MESH_SUFFIXES`.
MESH_SUFFIXES = (".obj", ".ply", ".glb", ".gltf", ".stl", ".off")
#: Suffixes written as textured meshes; also :data:`imagemap.scene.TEXTURED_SUFFIXES`
#: (here, so that ``imagemap synthesize`` tells a mesh request without imagemap.scene).
TEXTURED_SUFFIXES = (".glb", ".obj")
#: Suffixes of a depth map ``NAME_depth.*`` (what a database and a batch read as one).
DEPTH_SUFFIXES = (".png", ".tif", ".tiff", ".npy")
#: The files of an example or a held-out truth beside its ``NAME_depth.*`` or ``NAME``
#: mesh, by kind: ``NAME_image.*``, ``NAME_labels.*``, ``NAME.json`` and the PBR maps
#: (:data:`imagemap.materials.MAP_KINDS`; data_gen writes them beside every instance).
EXAMPLE_KINDS = ("image", "labels", "json", "normal", "roughness", "metallic", "height", "ao")
#: The kinds ``imagemap synthesize --overwrite`` may replace (its help and docs/errors.md
#: name them): the colour, labels and sidecar of a truth. A PBR map, a depth map or a
#: mesh is never replaced, with or without it.
OVERWRITE_KINDS = ("image", "labels", "json")

_DEPTH_NAME = re.compile(r"^(?P<name>.+)_depth\.(?:png|tif|tiff|npy)$", re.IGNORECASE)
_EXAMPLE_NAME = re.compile(
    rf"^(?P<name>.+?)(?:_(?P<kind>{'|'.join(k for k in EXAMPLE_KINDS if k != 'json')})"
    r"\.(?:png|jpg|jpeg|tif|tiff)|(?P<json>\.json))$",
    re.IGNORECASE,
)
# MTL statements naming a file (a texture); options such as "-bm 1.0" may precede the name.
_MTL_FILE = re.compile(r"^\s*(?:map_\w+|bump|disp|decal|norm|refl)\s+(?P<rest>.+?)\s*$", re.I)
_OBJ_MTLLIB = re.compile(r"^\s*mtllib\s+(?P<rest>.+?)\s*$")


def query_name(path: str | os.PathLike) -> str:
    """The object name of a query: ``fish_008_depth.png`` -> ``fish_008``, ``a.glb`` -> ``a``.

    Examples
    --------
    >>> query_name("holdout/fish_008_depth.png"), query_name("meshes/fish_008.glb")
    ('fish_008', 'fish_008')
    """
    path = Path(path)
    match = _DEPTH_NAME.match(path.name)
    return match["name"] if match else path.stem


def truths_beside(path: str | os.PathLike) -> list[Path]:
    """The files beside a query that hold its truth (NAME + :data:`TRUTH_SUFFIXES`), if any."""
    path = Path(path)
    name = query_name(path)
    return [p for s in TRUTH_SUFFIXES if (p := path.parent / f"{name}{s}").is_file()]


def example_file(path: str | os.PathLike) -> tuple[str, Path] | None:
    """(kind, owner) when ``path`` is a file of an example or a held-out truth, else None.

    Such a file is named ``NAME`` + the suffix of one of :data:`EXAMPLE_KINDS`
    (``NAME_image.png``, ``NAME_labels.png``, ``NAME.json``, ``NAME_roughness.png`` ...)
    and has the object it describes beside it: ``NAME_depth.*`` (:data:`DEPTH_SUFFIXES`)
    or a ``NAME`` mesh (:data:`MESH_SUFFIXES`), the owner returned. A depth map
    ``NAME_depth.*`` is its own owner (kind ``"depth"``). Whether the file exists is
    not looked at.

    Examples
    --------
    >>> import tempfile
    >>> folder = Path(tempfile.mkdtemp())
    >>> _ = (folder / "fish_005_depth.png").write_bytes(b"depth")
    >>> kind, owner = example_file(folder / "fish_005_roughness.png")
    >>> kind, owner.name
    ('roughness', 'fish_005_depth.png')
    >>> example_file(folder / "fish_006_image.png") is None  # no fish_006 beside it
    True
    """
    path = Path(path)
    if _DEPTH_NAME.match(path.name):
        return "depth", path
    match = _EXAMPLE_NAME.match(path.name)
    if match is None:
        return None
    name, kind = match["name"], (match["kind"] or "json").lower()
    owners = [f"{name}_depth{suffix}" for suffix in DEPTH_SUFFIXES]
    owners += [f"{name}{suffix}" for suffix in MESH_SUFFIXES]
    for owner in owners:
        if (path.parent / owner).is_file():
            return kind, path.parent / owner
    return None


def _named_files(folder: Path, rest: str) -> list[Path]:
    # The file name is the whole rest, or its last token when options precede it.
    names = [rest, rest.split()[-1]] if rest.split() else [rest]
    return [folder / name for name in dict.fromkeys(names) if (folder / name).is_file()]


def mesh_companions(path: str | os.PathLike) -> list[Path]:
    """The files a mesh file reads besides itself: an OBJ's material libraries and their
    textures, a glTF's external buffers and images (those that exist).

    A mesh query's or example's companions are inputs: no output may replace them.

    Examples
    --------
    >>> import tempfile
    >>> folder = Path(tempfile.mkdtemp())
    >>> _ = (folder / "a.obj").write_text("mtllib a.mtl\\nv 0 0 0\\n")
    >>> _ = (folder / "a.mtl").write_text("newmtl m\\nmap_Kd -bm 1 photo.jpg\\n")
    >>> _ = (folder / "photo.jpg").write_bytes(b"jpeg")
    >>> [p.name for p in mesh_companions(folder / "a.obj")]
    ['a.mtl', 'photo.jpg']
    """
    path = Path(path)
    suffix = path.suffix.lower()
    found: list[Path] = []
    try:
        if suffix == ".obj":
            with open(path, errors="replace") as handle:
                for line in handle:
                    if match := _OBJ_MTLLIB.match(line):
                        found += _named_files(path.parent, match["rest"])
            for mtl in list(found):
                for line in mtl.read_text(errors="replace").splitlines():
                    if match := _MTL_FILE.match(line):
                        found += _named_files(mtl.parent, match["rest"])
        elif suffix == ".gltf":
            document = json.loads(path.read_text(errors="replace"))
            for item in [*document.get("buffers", []), *document.get("images", [])]:
                uri = item.get("uri", "") if isinstance(item, dict) else ""
                if uri and not uri.startswith("data:"):
                    found += _named_files(path.parent, unquote(uri))
    except (OSError, ValueError, AttributeError):
        pass  # an unreadable mesh is reported by its reader; nothing more to protect
    return list(dict.fromkeys(found))


def written_companions(path: str | os.PathLike, map_kinds: Sequence[str] = ()) -> list[Path]:
    """The files written beside a textured mesh or a map: an OBJ's ``STEM.mtl`` and its
    texture ``STEM.png``; ``STEM_KIND.png`` for each PBR map kind written with it.

    Examples
    --------
    >>> [p.name for p in written_companions("out/fish.obj", ["roughness"])]
    ['fish.mtl', 'fish.png', 'fish_roughness.png']
    >>> written_companions("out/fish.glb")
    []
    """
    path = Path(path)
    found = []
    if path.suffix.lower() == ".obj":
        found += [path.with_suffix(".mtl"), path.with_suffix(".png")]
    found += [path.with_name(f"{path.stem}_{kind}.png") for kind in map_kinds]
    return found


@dataclass(frozen=True)
class _Output:
    path: Path
    what: str
    main: Path | None = None  # a companion: written beside this output, as part of its set
    fresh: bool = False  # an existing file here is replaced only if claimed


class _Files:
    """Paths looked up by resolved name and by inode (hard links), built once."""

    def __init__(self) -> None:
        self.by_name: dict[str, tuple[Path, str]] = {}
        self.by_inode: dict[tuple[int, int], tuple[Path, str]] = {}

    def add(self, path: Path, what: str) -> None:
        self.by_name.setdefault(os.path.normcase(resolve(path)), (path, what))
        with contextlib.suppress(OSError):
            stat = os.stat(path)
            self.by_inode.setdefault((stat.st_dev, stat.st_ino), (path, what))

    def find(self, path: Path) -> tuple[Path, str] | None:
        found = self.by_name.get(os.path.normcase(resolve(path)))
        if found is None:
            with contextlib.suppress(OSError):
                stat = os.stat(path)
                found = self.by_inode.get((stat.st_dev, stat.st_ino))
        return found


@dataclass
class OutputPlan:
    """Inputs and outputs of one command, checked against each other before the work.

    What may not be replaced: the inputs (:meth:`add_input`; a query with its mesh
    companions and held-out truths, :meth:`add_query`), every file of a database and
    anything in its folder (:meth:`add_database`). Outputs (:meth:`add_output`) may not
    share a file, and their companions (an OBJ's ``.mtl`` and texture, PBR maps) are
    checked as outputs too: an existing file in a companion's place is replaced only
    when its main output exists as well (a previous run's set), never a user's file
    that merely has the name. An output added with ``fresh=True`` (a batch's) replaces
    an existing file only if :meth:`claim` was told it is a previous run's.

    An existing file of an example or a held-out truth (:func:`example_file`) is no
    output unless ``overwrite`` is True and its kind is one of :data:`OVERWRITE_KINDS`;
    ``overwrite`` None: the command has no ``--overwrite`` (the message offers none).
    """

    overwrite: bool | None = None
    inputs: list[tuple[Path, str]] = field(default_factory=list)
    protected_dirs: list[tuple[Path, str]] = field(default_factory=list)
    outputs: list[_Output] = field(default_factory=list)
    claimed: set[str] = field(default_factory=set)

    def add_input(self, path: str | os.PathLike, what: str) -> None:
        """A file the command reads (or must keep): no output may replace it."""
        self.inputs.append((Path(path), what))

    def add_query(
        self, path: str | os.PathLike, what: str, *, overwrite: bool = False, hint: str = ""
    ) -> None:
        """A query (depth map or mesh): itself, the files a mesh reads (MTL, textures), and
        unless ``overwrite`` the held-out truth beside it (:data:`TRUTH_SUFFIXES`; ``hint``
        says how to replace it anyway)."""
        path = Path(path)
        self.add_input(path, what)
        for companion in mesh_companions(path):
            self.add_input(companion, f"a file {path.name} reads")
        if not overwrite:
            for truth in truths_beside(path):
                self.add_input(truth, f"held-out truth beside {path.name}{hint}")

    def add_protected_dir(self, path: str | os.PathLike, what: str) -> None:
        """A directory (a database) no output may be written into."""
        self.protected_dirs.append((Path(path), what))

    def add_database(self, database=None, directory: str | os.PathLike | None = None) -> None:
        """A database: its folder (nothing is written into it) and every file of every
        example wherever it lies (depth, image, labels, JSON, PBR maps, a mesh and the
        files it reads)."""
        if directory is not None:
            self.add_protected_dir(directory, "the database")
        for example in database or ():
            paths = [
                getattr(example, attribute, None)
                for attribute in ("depth_path", "image_path", "labels_path", "json_path")
            ]
            image = getattr(example, "image_path", None)
            if image is not None:
                paths += [
                    Path(image).with_name(f"{example.name}_{kind}{suffix}")
                    for kind in ("normal", "roughness", "metallic", "height", "ao")
                    for suffix in (".png", ".tif", ".tiff", ".jpg")
                ]
            mesh = getattr(example, "mesh_path", None)
            if mesh is not None:
                paths += [mesh, *mesh_companions(mesh)]
            for path in paths:
                if path is not None:
                    self.add_input(path, f"database file of {example.name}")

    def add_output(
        self,
        path: str | os.PathLike,
        what: str,
        suffixes: tuple[str, ...] | None = None,
        *,
        companions: Sequence[str | os.PathLike] = (),
        fresh: bool = False,
    ) -> Path:
        """A file the command writes; ``suffixes`` are the accepted extensions.

        ``companions`` are the files written with it (:func:`written_companions`);
        ``fresh``: an existing file in its place (or a companion's) is a user's unless
        claimed (:meth:`claim`).
        """
        path = Path(path)
        if suffixes and path.suffix.lower() not in suffixes:
            raise InputError(
                f"{path}: {what} is written as {' or '.join(suffixes)}, "
                f"not {path.suffix or 'a file without suffix'!r}"
            )
        self.outputs.append(_Output(path, what, fresh=fresh))
        for companion in companions:
            companion = Path(companion)
            self.outputs.append(
                _Output(companion, f"written beside {path.name} ({what})", path, fresh)
            )
        return path

    def add_companion(
        self, path: str | os.PathLike, main: str | os.PathLike, what: str, *, fresh: bool = False
    ) -> Path:
        """A file written beside ``main`` as part of its set (a PBR map beside a map)."""
        path = Path(path)
        self.outputs.append(_Output(path, what, Path(main), fresh))
        return path

    def claim(self, paths: Iterable[str | os.PathLike]) -> None:
        """Existing files a ``fresh`` output may replace: a previous run's outputs."""
        self.claimed.update(os.path.normcase(resolve(p)) for p in paths)

    def check(self) -> None:
        """Raise :class:`InputError` on the first clash or unwritable output."""
        inputs = _Files()
        for source, source_what in self.inputs:
            inputs.add(source, source_what)
        folders = {resolve(folder): (folder, what) for folder, what in self.protected_dirs}
        seen: dict[str, _Output] = {}
        probed: set[Path] = set()
        written = {os.path.normcase(resolve(output.path)) for output in self.outputs}
        for output in self.outputs:
            path, what = output.path, output.what
            full = resolve(path)
            key = os.path.normcase(full)
            if key in seen:
                other = seen[key]
                raise InputError(
                    f"{path} ({what}) and {other.path} ({other.what}) are the same file: "
                    "give each output its own name"
                )
            seen[key] = output
            if (found := inputs.find(path)) is not None:
                source, source_what = found
                raise InputError(
                    f"{path} ({what}) would overwrite {source} ({source_what}): "
                    "give the output another name"
                )
            for folder in (full.parent, full):
                if folder in folders:
                    shown, folder_what = folders[folder]
                    raise InputError(
                        f"{path} ({what}) would be written into {shown} ({folder_what}): "
                        "write outputs outside the database"
                    )
            if full.is_file() or full.is_symlink():
                self._check_replace(output, key)
                self._check_example(output, written)
            if full.parent not in probed or full.is_dir():
                check_writable(path, what)
                probed.add(full.parent)

    def _check_example(self, output: _Output, written: set[str]) -> None:
        """An existing file of an example or a held-out truth: replaced only with
        ``overwrite``, and only a kind of :data:`OVERWRITE_KINDS`. A file whose owner is
        written by this command too (``-o x.glb --report x.json``, run again) is part of
        an earlier run's set, not an example."""
        found = example_file(output.path)
        if found is None:
            return
        kind, owner = found
        if kind != "depth" and os.path.normcase(resolve(owner)) in written:
            return
        path, what = output.path, output.what
        if kind == "depth":
            raise InputError(
                f"{path} ({what}) would replace a depth map (a query or an example's): "
                "give the output another name"
            )
        named = ", ".join(f"NAME{'.json' if k == 'json' else f'_{k}.png'}" for k in OVERWRITE_KINDS)
        if self.overwrite and kind in OVERWRITE_KINDS:
            return
        if self.overwrite:
            way = " (or --no-maps, which writes no PBR map)" if output.main is not None else ""
            raise InputError(
                f"{path} ({what}) would replace the {kind} map of {owner.name}'s example or "
                f"held-out truth; --overwrite replaces {named} only, never a {kind} map: "
                f"give the output another name{way}"
            )
        way = ""
        if self.overwrite is False and kind in OVERWRITE_KINDS:
            way = "; --overwrite replaces it"
        shown = "sidecar" if kind == "json" else kind
        raise InputError(
            f"{path} ({what}) would replace the {shown} of an example or held-out truth "
            f"(beside {owner.name}){way}: give the output another name"
        )

    def _check_replace(self, output: _Output, key: str) -> None:
        """An existing file at an output: replaced only when it is the output's own."""
        if output.fresh and key not in self.claimed:
            raise InputError(
                f"{output.path} ({output.what}) exists and no earlier run here wrote it: "
                "it would be replaced; move it away or choose another output folder"
            )
        if output.main is not None and not output.fresh and not output.main.is_file():
            raise InputError(
                f"{output.path} exists and is not part of an earlier {output.main.name}; "
                f"writing {output.main.name} would replace it ({output.what}): move it "
                "away or choose another output name"
            )


def exported(
    export: Callable[[Path], object], target: str | os.PathLike, planned: Iterable[Path] = ()
) -> tuple[dict[Path, Callable[[Path], None]], Callable[[], None]]:
    """Run a writer of several files (``export(path)``, such as a textured mesh's) into a
    staging folder beside ``target``, and return :func:`write_all` writers moving each file
    it made to its place, and a clean-up to call afterwards (it removes the staging
    folder).

    Every file made must be ``target`` or one of ``planned`` (the companions checked in
    the plan): anything else is a ``RuntimeError`` before any target is touched.

    Examples
    --------
    >>> import tempfile
    >>> folder = Path(tempfile.mkdtemp())
    >>> def export(path):
    ...     path.write_text("obj"); path.with_suffix(".mtl").write_text("mtl")
    >>> writers, cleanup = exported(export, folder / "m.obj", [folder / "m.mtl"])
    >>> sorted(p.name for p in write_all(writers)); cleanup()
    ['m.mtl', 'm.obj']
    >>> sorted(p.name for p in folder.iterdir())
    ['m.mtl', 'm.obj']
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=STAGING_PREFIX, dir=target.parent))

    def cleanup() -> None:
        shutil.rmtree(staging, ignore_errors=True)

    try:
        export(staging / target.name)
        allowed = {target.name, *(Path(p).name for p in planned)}
        made = sorted(p for p in staging.rglob("*") if p.is_file())
        stray = [
            p.relative_to(staging) for p in made if p.parent != staging or p.name not in allowed
        ]
        if stray or not (staging / target.name).is_file():
            raise RuntimeError(
                f"{target}: the writer made {', '.join(map(str, stray)) or 'no ' + target.name}, "
                "which the output plan did not check"
            )
    except BaseException:
        cleanup()
        raise

    def mover(source: Path) -> Callable[[Path], None]:
        return lambda tmp: os.replace(source, tmp)

    return {target.parent / p.name: mover(p) for p in made}, cleanup


#: The staging folders of :func:`exported` (a killed run's are removed by a resumed batch).
STAGING_PREFIX = ".imagemap-export."


@contextlib.contextmanager
def _staged(targets: list[Path]) -> Iterator[list[Path]]:
    temporaries: list[Path] = []
    try:
        for target in targets:
            target.parent.mkdir(parents=True, exist_ok=True)
            temporaries.append(make_temporary(target, "".join(target.suffixes) or ".tmp"))
        yield temporaries
    except BaseException:
        for tmp in temporaries:
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
        raise


def write_all(writers: dict[Path, Callable[[Path], None]]) -> list[Path]:
    """Write a set of outputs all-or-nothing.

    ``writers`` maps each target to a function that writes the content to the
    temporary path it is given. Every content is written to its temporary file
    first; only when all succeeded are they renamed onto their targets. On any
    failure (or Ctrl-C) the temporaries are removed and no target changes.
    """
    targets = [Path(t) for t in writers]
    umask = os.umask(0)
    os.umask(umask)
    with _staged(targets) as temporaries:
        for target, tmp in zip(targets, temporaries, strict=True):
            writers[target](tmp)
            os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; outputs get the usual mode
        for target, tmp in zip(targets, temporaries, strict=True):
            os.replace(tmp, target)
    return targets
