"""The add-on module needs Blender's ``bpy``: not collected with the package's doctests."""

collect_ignore = ["imagemap_addon.py"]
