"""imagemap for Blender: "Texture from Examples" on the selected meshes.

Select mesh objects, run Object > Texture from Examples (or F3, "Texture from
Examples"), pick a database folder (textured meshes, or NAME_depth.png beside
NAME_image.png and their PBR maps) and a preset ("auto": the one named like the
database's class). Each object is written to a temporary GLB in world
coordinates (its transform applied: a squashed sphere is textured as the
ellipsoid it looks like), textured by ``imagemap synthesize`` in a subprocess,
read back, brought into the object's own coordinates and its mesh replaced by
the result (same object, transform and modifiers; the new mesh carries the
material with its colour, normal and roughness/metallic maps). While it runs,
the status bar names the object and the command's step (its progress lines,
``imagemap: [STEP/TOTAL] ...``), the cursor shows the progress within and across
objects, and Esc cancels (the subprocess is ended and the temporary folder
removed); the interface is never blocked (a timer polls the subprocess). In the
background (``blender -b``) or with ``wait=True`` the operator runs to the end at once.

The add-on needs imagemap installed where Blender can start it: set the command
in the add-on's preferences (default ``imagemap``; e.g.
``/path/to/venv/bin/python -m imagemap``). It imports nothing of imagemap; its
parts that need no Blender are in ``addon_tools.py`` beside it.
"""

from __future__ import annotations

import os
import shlex
import shutil
import tempfile

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, IntProperty, StringProperty
from mathutils import Matrix

from .addon_tools import (
    PRESET_NAMES,
    CommandRun,
    database_class,
    database_preset,
    is_mirrored,
    local_from_world,
    remove_folder,
)

bl_info = {
    "name": "imagemap: Texture from Examples",
    "author": "imagemap",
    "version": (0, 2, 0),
    "blender": (4, 2, 0),
    "location": "View3D > Object > Texture from Examples",
    "description": "Texture selected meshes from a database of examples (imagemap synthesize)",
    "category": "Material",
}

PRESETS = [
    ("auto", "Auto", "the preset named like the database's class (its records, else its names)"),
    *[(name, name.capitalize(), f"imagemap's {name} preset") for name in PRESET_NAMES],
]
#: Seconds between two looks at the running subprocess (the interface's refresh).
POLL_SECONDS = 0.25


class ImagemapPreferences(bpy.types.AddonPreferences):
    bl_idname = __package__ or __name__

    # Blender declares properties as annotations that are calls (bpy's idiom, read at
    # registration); mypy takes a call for an invalid type, hence [valid-type] ignores.
    command: StringProperty(  # type: ignore[valid-type]
        name="imagemap command",
        default="imagemap",
        description="How to start imagemap, e.g. 'imagemap' or '/path/venv/bin/python -m imagemap'",
    )

    def draw(self, context):
        self.layout.prop(self, "command")


def _preference_command(context) -> str:
    addon = context.preferences.addons.get(__package__ or __name__)
    return addon.preferences.command if addon is not None else "imagemap"


def _export_query(obj, path: str) -> None:
    """Write ``obj``'s mesh, in world coordinates (its transform applied), as a GLB.

    imagemap renders views of what it is sent: sent in the object's own coordinates,
    a sphere scaled 1.5 x 0.5 x 0.6 was textured as a ball and squashed afterwards
    (issue #46). A copy of the mesh is moved, so the object's own is untouched.
    """
    data = obj.data.copy()
    data.transform(obj.matrix_world)  # custom normals follow (Blender's own transform)
    if is_mirrored(np.array(obj.matrix_world)):
        data.flip_normals()  # a mirroring transform turns the faces inside out
    query = bpy.data.objects.new("imagemap_query", data)
    bpy.context.scene.collection.objects.link(query)
    selected = list(bpy.context.selected_objects)
    active = bpy.context.view_layer.objects.active
    try:
        for other in selected:
            other.select_set(False)
        query.select_set(True)
        bpy.context.view_layer.objects.active = query
        bpy.ops.export_scene.gltf(
            filepath=path, export_format="GLB", use_selection=True, export_apply=False
        )
    finally:
        bpy.data.objects.remove(query)
        bpy.data.meshes.remove(data)
        for other in selected:
            other.select_set(True)
        bpy.context.view_layer.objects.active = active


def _apply_result(obj, path: str, world) -> None:
    """Replace ``obj``'s mesh by the textured mesh in ``path`` (material included),
    brought from world coordinates into the object's own (``world``: its world matrix
    when it was sent), so the object sits where it was."""
    before = set(bpy.data.objects)
    bpy.ops.import_scene.gltf(filepath=path)
    imported = [o for o in bpy.data.objects if o not in before]
    meshes = [o for o in imported if o.type == "MESH"]
    if not meshes:
        raise RuntimeError(f"{path}: no mesh in imagemap's output")
    old = obj.data
    new = meshes[0].data
    # The importer's node transform (if any) first, then the object's inverse.
    local = Matrix(local_from_world(world).tolist()) @ meshes[0].matrix_world
    new.transform(local)
    if is_mirrored(world):
        new.flip_normals()
    obj.data = new
    obj.data.name = f"{obj.name}_imagemap"
    for other in imported:
        bpy.data.objects.remove(other)
    if old.users == 0:
        bpy.data.meshes.remove(old)


class _Job:
    """One object's synthesis: its mesh sent, the command running (:class:`CommandRun`)."""

    def __init__(self, obj, command: list[str], folder: str) -> None:
        self.name = obj.name
        self.world = np.array(obj.matrix_world)  # as sent: the result is brought back by it
        count = len(os.listdir(folder))
        self.query = os.path.join(folder, f"{count}_query.glb")
        self.output = os.path.join(folder, f"{count}_textured.glb")
        _export_query(obj, self.query)
        self.run = CommandRun([*command, self.query, "-o", self.output])


class IMAGEMAP_OT_texture_from_examples(bpy.types.Operator):
    """Texture the selected meshes from a database of examples (imagemap synthesize)"""

    bl_idname = "imagemap.texture_from_examples"
    bl_label = "Texture from Examples"
    bl_options = {"REGISTER", "UNDO"}

    # Blender declares properties as annotations that are calls (bpy's idiom, read at
    # registration); mypy takes a call for an invalid type, hence [valid-type] ignores.
    database: StringProperty(  # type: ignore[valid-type]
        name="Database", subtype="DIR_PATH", description="folder of examples (imagemap database)"
    )
    preset: EnumProperty(name="Preset", items=PRESETS, default="auto")  # type: ignore[valid-type]
    views: StringProperty(  # type: ignore[valid-type]
        name="Views", default="auto", description="'auto' (by coverage) or e.g. 'front,back'"
    )
    seed: IntProperty(name="Seed", default=0, min=0)  # type: ignore[valid-type]
    options: StringProperty(  # type: ignore[valid-type]
        name="Options",
        default="",
        description="more imagemap synthesize options, e.g. '--texture-size 2048 --size 400x300'",
    )
    command: StringProperty(  # type: ignore[valid-type]
        name="Command", default="", description="imagemap command (empty: the preferences')"
    )
    wait: BoolProperty(  # type: ignore[valid-type]
        name="Wait", default=False, description="run to the end before returning (scripts)"
    )

    @classmethod
    def poll(cls, context):
        return any(o.type == "MESH" for o in context.selected_objects)

    def invoke(self, context, event):
        return context.window_manager.invoke_props_dialog(self)

    def _preset(self, database: str) -> str | None:
        """The preset asked for, or with "auto" the one named like the database's class."""
        if self.preset != "auto":
            return self.preset
        chosen = database_preset(database)
        if chosen is None:
            found = database_class(database)
            self.report(
                {"ERROR"},
                f"imagemap: the database's class ({found or 'no examples found'}) names no "
                f"preset ({', '.join(PRESET_NAMES)}): choose one",
            )
        else:
            self.report({"INFO"}, f"imagemap: preset {chosen} (the database's class)")
        return chosen

    def _arguments(self, context, preset: str) -> list[str]:
        command = shlex.split(self.command or _preference_command(context))
        database = bpy.path.abspath(self.database)
        arguments = [*command, "synthesize", "--db", database, "--preset", preset]
        arguments += ["--seed", str(self.seed)]
        arguments += ["--views", self.views or "auto", *shlex.split(self.options)]
        return arguments

    def execute(self, context) -> set[str]:
        database = bpy.path.abspath(self.database)
        if not database or not os.path.isdir(database):
            self.report({"ERROR"}, f"imagemap: database folder not found: {database!r}")
            return {"CANCELLED"}
        objects = [o for o in context.selected_objects if o.type == "MESH"]
        if not objects:
            self.report({"ERROR"}, "imagemap: select one or more mesh objects")
            return {"CANCELLED"}
        command = shlex.split(self.command or _preference_command(context))
        if not command or shutil.which(command[0]) is None:
            self.report({"ERROR"}, f"imagemap: command not found: {command[:1]} (see preferences)")
            return {"CANCELLED"}
        flat = [o.name for o in objects if np.linalg.det(np.array(o.matrix_world)[:3, :3]) == 0]
        if flat:
            self.report({"ERROR"}, f"imagemap: scale 0 on some axis: {', '.join(flat)}")
            return {"CANCELLED"}
        preset = self._preset(database)
        if preset is None:
            return {"CANCELLED"}
        self._folder = tempfile.mkdtemp(prefix="imagemap-blender-")
        self._base = self._arguments(context, preset)
        self._todo = [o.name for o in objects]
        self._done = 0
        self._failed: list[str] = []
        if bpy.app.background or self.wait:
            try:
                for name in self._todo:
                    job = _Job(bpy.data.objects[name], self._base, self._folder)
                    self._finish(job, job.run.wait())
            finally:
                remove_folder(self._folder)
            return self._summary()
        try:
            self._job = _Job(bpy.data.objects[self._todo[0]], self._base, self._folder)
        except BaseException:
            remove_folder(self._folder)
            raise
        wm = context.window_manager
        self._timer = wm.event_timer_add(POLL_SECONDS, window=context.window)
        wm.progress_begin(0, len(self._todo))
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def _finish(self, job: _Job, code: int) -> None:
        if code == 0 and os.path.isfile(job.output):
            _apply_result(bpy.data.objects[job.name], job.output, job.world)
        else:
            tail = " | ".join(job.run.log[-3:]) or f"exit code {code}"
            self._failed.append(job.name)
            self.report({"ERROR"}, f"imagemap: {job.name}: {tail}")
        self._done += 1

    def _summary(self) -> set[str]:
        remove_folder(self._folder)
        good = self._done - len(self._failed)
        self.report({"INFO"}, f"imagemap: {good} of {len(self._todo)} object(s) textured")
        return {"FINISHED"} if good else {"CANCELLED"}

    def modal(self, context, event):
        try:
            return self._modal(context, event)
        except BaseException:
            # Whatever failed (an export, an import), nothing is left running or on disk.
            self._cancel(context)
            raise

    def _modal(self, context, event):
        wm = context.window_manager
        if event.type == "ESC":
            self._cancel(context)
            self.report({"WARNING"}, f"imagemap: cancelled at {self._job.name}")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        code = self._job.run.poll()
        position = f"{self._done + 1}/{len(self._todo)}"
        context.workspace.status_text_set(
            f"imagemap: {self._job.name} ({position}): {self._job.run.last}  (Esc cancels)"
        )
        # Within the object too: its share done, from the command's own progress lines.
        wm.progress_update(self._done + self._job.run.fraction)
        if code is None:
            return {"RUNNING_MODAL"}
        self._finish(self._job, code)
        wm.progress_update(self._done)
        if self._done < len(self._todo):
            self._job = _Job(bpy.data.objects[self._todo[self._done]], self._base, self._folder)
            return {"RUNNING_MODAL"}
        self._stop(context)
        return self._summary()

    def _cancel(self, context) -> None:
        """End the subprocess (its files are no longer written), then remove them all."""
        job = getattr(self, "_job", None)
        if job is not None:
            job.run.cancel()
        self._stop(context)
        remove_folder(self._folder)

    def _stop(self, context) -> None:
        if getattr(self, "_timer", None) is not None:
            context.window_manager.event_timer_remove(self._timer)
            self._timer = None
            context.window_manager.progress_end()
        context.workspace.status_text_set(None)


def _menu(self, context):
    self.layout.operator(IMAGEMAP_OT_texture_from_examples.bl_idname)


CLASSES = (ImagemapPreferences, IMAGEMAP_OT_texture_from_examples)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.VIEW3D_MT_object.append(_menu)


def unregister():
    bpy.types.VIEW3D_MT_object.remove(_menu)
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
