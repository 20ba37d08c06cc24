"""A Blender add-on: "Texture from examples" on the selected meshes.

The add-on itself is :mod:`imagemap.blender.imagemap_addon`: it runs inside Blender
(its own Python, with ``bpy``) and imports nothing of imagemap; it runs
``imagemap synthesize`` in a subprocess for each selected mesh, so Blender's
interface stays responsive, and assigns the textured result's material.
Its parts that need no Blender (progress lines, the transform, the preset, the
subprocess) are :mod:`imagemap.blender.addon_tools`, tested without Blender.
Build the installable zip with ``python -m imagemap.blender.package``.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["ADDON_SOURCE", "ADDON_TOOLS"]

#: The add-on's source file (copied into the zip as ``imagemap_texture/__init__.py``).
ADDON_SOURCE = Path(__file__).with_name("imagemap_addon.py")
#: Its parts that need no Blender (copied as ``imagemap_texture/addon_tools.py``).
ADDON_TOOLS = Path(__file__).with_name("addon_tools.py")
