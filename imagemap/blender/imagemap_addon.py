"""imagemap for Blender: "Texture from Examples" on the selected meshes.

Select mesh objects, run Object > Texture from Examples (or F3, "Texture from
Examples"), pick a database folder (textured meshes, or NAME_depth.png beside
NAME_image.png and their PBR maps) and a preset. Each object is written to a
temporary GLB in its own coordinates, textured by ``imagemap synthesize`` in a
subprocess, read back, and its mesh replaced by the result (same object,
transform and modifiers; the new mesh carries the material with its colour,
normal and roughness/metallic maps). While it runs, the status bar names the
object and the step, the cursor shows the progress, and Esc cancels; the
interface is never blocked (a timer polls the subprocess). In the background
(``blender -b``) or with ``wait=True`` the operator runs to the end at once.

The add-on needs imagemap installed where Blender can start it: set the command
in the add-on's preferences (default ``imagemap``; e.g.
``/path/to/venv/bin/python -m imagemap``). It imports nothing of imagemap.
"""

from __future__ import annotations

import os
import queue
import shlex
import shutil
import subprocess
import tempfile
import threading

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty, StringProperty

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
    ("busts", "Busts", "heads and shoulders"),
    ("fish", "Fish", "fish and similar animals"),
    ("humans", "Humans", "whole figures"),
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
    """Write ``obj``'s mesh, in its own coordinates, as a GLB (one temporary object)."""
    query = bpy.data.objects.new("imagemap_query", obj.data)
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
        for other in selected:
            other.select_set(True)
        bpy.context.view_layer.objects.active = active


def _apply_result(obj, path: str) -> None:
    """Replace ``obj``'s mesh by the textured mesh in ``path`` (material included)."""
    before = set(bpy.data.objects)
    bpy.ops.import_scene.gltf(filepath=path)
    imported = [o for o in bpy.data.objects if o not in before]
    meshes = [o for o in imported if o.type == "MESH"]
    if not meshes:
        raise RuntimeError(f"{path}: no mesh in imagemap's output")
    old = obj.data
    obj.data = meshes[0].data
    obj.data.name = f"{obj.name}_imagemap"
    for other in imported:
        bpy.data.objects.remove(other)
    if old.users == 0:
        bpy.data.meshes.remove(old)


class _Job:
    """One object's synthesis: a subprocess and the lines it writes on stderr."""

    def __init__(self, obj, command: list[str], folder: str) -> None:
        self.name = obj.name
        self.query = os.path.join(folder, f"{len(os.listdir(folder))}_query.glb")
        self.output = os.path.join(folder, f"{len(os.listdir(folder))}_textured.glb")
        _export_query(obj, self.query)
        self.command = [*command, self.query, "-o", self.output]
        self.lines: queue.Queue[str] = queue.Queue()
        self.last = "starting"
        self.log: list[str] = []
        self.process = subprocess.Popen(
            self.command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
        )
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.process.stderr is not None  # Popen(stderr=PIPE) gives a pipe
        for line in self.process.stderr:
            self.lines.put(line.rstrip())

    def poll(self) -> int | None:
        while not self.lines.empty():
            line = self.lines.get()
            if line:
                self.last = line.removeprefix("imagemap: ").strip()
                self.log.append(line)
        return self.process.poll()

    def wait(self) -> int:
        code = self.process.wait()
        while self.poll() is None:
            pass
        return code

    def cancel(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()


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
    preset: EnumProperty(name="Preset", items=PRESETS, default="busts")  # type: ignore[valid-type]
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

    def _arguments(self, context) -> list[str]:
        command = shlex.split(self.command or _preference_command(context))
        database = bpy.path.abspath(self.database)
        arguments = [*command, "synthesize", "--db", database, "--preset", self.preset]
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
        self._folder = tempfile.mkdtemp(prefix="imagemap-blender-")
        self._base = self._arguments(context)
        self._todo = [o.name for o in objects]
        self._done = 0
        self._failed: list[str] = []
        if bpy.app.background or self.wait:
            for name in self._todo:
                job = _Job(bpy.data.objects[name], self._base, self._folder)
                self._finish(job, job.wait())
            return self._summary()
        self._job = _Job(bpy.data.objects[self._todo[0]], self._base, self._folder)
        wm = context.window_manager
        self._timer = wm.event_timer_add(POLL_SECONDS, window=context.window)
        wm.progress_begin(0, len(self._todo))
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def _finish(self, job: _Job, code: int) -> None:
        if code == 0 and os.path.isfile(job.output):
            _apply_result(bpy.data.objects[job.name], job.output)
        else:
            tail = " | ".join(job.log[-3:]) or f"exit code {code}"
            self._failed.append(job.name)
            self.report({"ERROR"}, f"imagemap: {job.name}: {tail}")
        self._done += 1

    def _summary(self) -> set[str]:
        shutil.rmtree(self._folder, ignore_errors=True)
        good = self._done - len(self._failed)
        self.report({"INFO"}, f"imagemap: {good} of {len(self._todo)} object(s) textured")
        return {"FINISHED"} if good else {"CANCELLED"}

    def modal(self, context, event):
        wm = context.window_manager
        if event.type == "ESC":
            self._job.cancel()
            self._stop(context)
            self.report({"WARNING"}, f"imagemap: cancelled at {self._job.name}")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        code = self._job.poll()
        position = f"{self._done + 1}/{len(self._todo)}"
        context.workspace.status_text_set(
            f"imagemap: {self._job.name} ({position}): {self._job.last}  (Esc cancels)"
        )
        if code is None:
            return {"RUNNING_MODAL"}
        self._finish(self._job, code)
        wm.progress_update(self._done)
        if self._done < len(self._todo):
            self._job = _Job(bpy.data.objects[self._todo[self._done]], self._base, self._folder)
            return {"RUNNING_MODAL"}
        self._stop(context)
        return self._summary()

    def _stop(self, context) -> None:
        context.window_manager.event_timer_remove(self._timer)
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
