"""Output paths planned and checked before any work, then written all-or-nothing.

Rules (the README's "Errors and overwrite rules"):

- Every output path is resolved (symbolic links followed) and compared with every
  input and every other output before any work. An output that is an input (the
  query depth, a file of the database, the held-out truth beside a query), or that
  two outputs share, is an :class:`~imagemap.io.InputError` naming both paths.
- An output's suffix must match what is written (``.png`` for images, ``.json`` for
  reports, ``.npz`` for archives).
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
import os
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from imagemap.io import InputError

__all__ = ["OutputPlan", "check_writable", "resolve", "same_file", "write_all"]


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


@dataclass
class OutputPlan:
    """Inputs and outputs of one command, checked against each other before the work."""

    inputs: list[tuple[Path, str]] = field(default_factory=list)
    protected_dirs: list[tuple[Path, str]] = field(default_factory=list)
    outputs: list[tuple[Path, str]] = field(default_factory=list)

    def add_input(self, path: str | os.PathLike, what: str) -> None:
        """A file the command reads (or must keep): no output may replace it."""
        self.inputs.append((Path(path), what))

    def add_protected_dir(self, path: str | os.PathLike, what: str) -> None:
        """A directory (a database) no output may be written into."""
        self.protected_dirs.append((Path(path), what))

    def add_output(
        self, path: str | os.PathLike, what: str, suffixes: tuple[str, ...] | None = None
    ) -> Path:
        """A file the command writes; ``suffixes`` are the accepted extensions."""
        path = Path(path)
        if suffixes and path.suffix.lower() not in suffixes:
            raise InputError(
                f"{path}: {what} is written as {' or '.join(suffixes)}, "
                f"not {path.suffix or 'a file without suffix'!r}"
            )
        self.outputs.append((path, what))
        return path

    def check(self) -> None:
        """Raise :class:`InputError` on the first clash or unwritable output."""
        seen: dict[str, tuple[Path, str]] = {}
        for path, what in self.outputs:
            key = os.path.normcase(resolve(path))
            if key in seen:
                other, other_what = seen[key]
                raise InputError(
                    f"{path} ({what}) and {other} ({other_what}) are the same file: "
                    "give each output its own name"
                )
            seen[key] = (path, what)
            for source, source_what in self.inputs:
                if same_file(path, source):
                    raise InputError(
                        f"{path} ({what}) would overwrite {source} ({source_what}): "
                        "give the output another name"
                    )
            for folder, folder_what in self.protected_dirs:
                if resolve(path).parent == resolve(folder):
                    raise InputError(
                        f"{path} ({what}) would be written into {folder} ({folder_what}): "
                        "write outputs outside the database"
                    )
            check_writable(path, what)


@contextlib.contextmanager
def _staged(targets: list[Path]) -> Iterator[list[Path]]:
    temporaries: list[Path] = []
    try:
        for target in targets:
            target.parent.mkdir(parents=True, exist_ok=True)
            suffix = "".join(target.suffixes) or ".tmp"
            fd, name = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=suffix, dir=target.parent)
            os.close(fd)
            temporaries.append(Path(name))
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
