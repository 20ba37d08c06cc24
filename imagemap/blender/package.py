"""``python -m imagemap.blender.package [-o imagemap_texture.zip]``: the installable add-on.

The zip holds ``imagemap_texture/__init__.py`` (the add-on, with ``bl_info`` for
Blender's Install from Disk), ``imagemap_texture/addon_tools.py`` (its parts that need
no Blender) and ``imagemap_texture/blender_manifest.toml`` (for Blender 4.2+'s
extensions). Install it in Blender: Edit > Preferences > Add-ons > Install from Disk,
then set the add-on's "imagemap command".
"""

from __future__ import annotations

import argparse
import sys
import zipfile
from pathlib import Path

from imagemap.blender import ADDON_SOURCE, ADDON_TOOLS

__all__ = ["MODULE_NAME", "build_zip"]

#: The add-on's module name inside Blender.
MODULE_NAME = "imagemap_texture"

_MANIFEST = """\
schema_version = "1.0.0"
id = "imagemap_texture"
version = "0.2.0"
name = "imagemap: Texture from Examples"
tagline = "Texture meshes from a database of examples"
maintainer = "imagemap"
type = "add-on"
blender_version_min = "4.2.0"
license = ["SPDX:MIT"]

[permissions]
files = "Reads the example database, writes temporary meshes, runs imagemap"
"""


def build_zip(path: str | Path) -> Path:
    """Write the add-on zip at ``path`` (same bytes for the same source).

    Examples
    --------
    >>> import tempfile, zipfile
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     names = zipfile.ZipFile(build_zip(Path(folder) / "a.zip")).namelist()
    >>> [name.split("/")[1] for name in names]
    ['__init__.py', 'addon_tools.py', 'blender_manifest.toml']
    """
    from imagemap.io import atomic_path  # deferred: standalone script

    path = Path(path)
    with atomic_path(path) as tmp:
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as archive:
            for name, text in (
                (f"{MODULE_NAME}/__init__.py", ADDON_SOURCE.read_text()),
                (f"{MODULE_NAME}/addon_tools.py", ADDON_TOOLS.read_text()),
                (f"{MODULE_NAME}/blender_manifest.toml", _MANIFEST),
            ):
                info = zipfile.ZipInfo(name, date_time=(2026, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_DEFLATED
                archive.writestr(info, text)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m imagemap.blender.package", description=__doc__.splitlines()[0]
    )
    parser.add_argument("-o", "--output", default="imagemap_texture.zip", help="zip to write")
    args = parser.parse_args(argv)
    path = build_zip(args.output)
    print(
        f"wrote {path}: install it in Blender (Preferences > Add-ons > Install from Disk)",
        file=sys.stderr,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
