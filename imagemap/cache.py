"""The library's disk cache: its folder, and digests of the code its entries depend on.

Three kinds of entry are kept by the code that made them, each keyed by that code's own
source, so an edit makes them anew with no version number to remember: mesh examples'
renders (:mod:`imagemap.scene.examples`), the uv-space examples' padded textures
(:mod:`imagemap.mesh.uvspace`) and a batch's manifests (:mod:`imagemap.batch.digests`).
"""

from __future__ import annotations

import functools
import hashlib
import os
from pathlib import Path

import imagemap

__all__ = ["PACKAGE", "cache_dir", "source_digest"]

#: The package folder whose source files the digests read.
PACKAGE = Path(__file__).resolve().parent


def cache_dir() -> Path:
    """The library's cache folder: ``$IMAGEMAP_CACHE`` (``~`` expanded, as ``imagemap
    synthesize`` checks it), default ``~/.cache/imagemap``.

    Examples
    --------
    >>> import os
    >>> os.environ["IMAGEMAP_CACHE"] = "/tmp/imagemap-cache"
    >>> str(cache_dir())
    '/tmp/imagemap-cache'
    >>> del os.environ["IMAGEMAP_CACHE"]
    """
    root = os.environ.get("IMAGEMAP_CACHE")
    return Path(root).expanduser() if root else Path.home() / ".cache" / "imagemap"


@functools.cache
def source_digest(names: tuple[str, ...], package: Path = PACKAGE) -> str:
    """A SHA-256 (hex) of the source of ``names`` under ``package``, each a file
    (``"scene/views.py"``), a module (``"io"``: ``io.py``) or a subpackage (``"core"``: its
    modules in a fixed order), each file's path and bytes; ``"version X"`` where a file
    cannot be read (a frozen install). Files are read, not imported: no module's import
    cost or side effects for a digest. Computed once per process.

    Examples
    --------
    >>> source_digest(("io",)) == source_digest(("io.py",)) != source_digest(("core",))
    True
    """
    digest = hashlib.sha256()
    try:
        for name in names:
            if name.endswith(".py"):
                files = [package / name]
            elif (package / f"{name}.py").exists():
                files = [package / f"{name}.py"]
            else:
                files = sorted((package / name).rglob("*.py"))
            if not files:
                raise OSError(name)
            for path in files:
                digest.update(path.relative_to(package).as_posix().encode())
                digest.update(path.read_bytes())
    except OSError:  # no source files (a frozen install)
        return f"version {imagemap.__version__}"
    return digest.hexdigest()
