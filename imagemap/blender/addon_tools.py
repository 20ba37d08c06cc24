"""The Blender add-on's parts that need no Blender: testable outside it.

Shipped beside the add-on in its zip (``imagemap_texture/addon_tools.py``) and imported
by it relatively, so, like the add-on, this module imports nothing of imagemap (Blender
starts imagemap as a command, in its own environment): the standard library and NumPy
(which Blender carries) only.

- :func:`parse_progress` reads the mesh command's progress lines
  (``imagemap: [STEP/TOTAL] TEXT``, written by :func:`imagemap.mesh.route.texture_mesh`).
- :func:`local_from_world` and :func:`is_mirrored`: the object's world matrix is applied
  to the mesh sent, its inverse to the result.
- :func:`database_preset`: the preset named like the database's class.
- :class:`CommandRun`: the subprocess, its stderr read on a thread, cancelled and its
  folder removed by :meth:`CommandRun.cancel` and :func:`remove_folder`.
"""

from __future__ import annotations

import json
import os
import queue
import re
import shutil
import subprocess
import threading
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = [
    "PRESET_NAMES",
    "CommandRun",
    "Progress",
    "database_class",
    "database_preset",
    "is_mirrored",
    "local_from_world",
    "parse_progress",
    "remove_folder",
]

#: imagemap's class presets (``imagemap synthesize --preset``); tests/test_blender.py
#: checks them against imagemap's own list.
PRESET_NAMES = ("busts", "fish", "humans", "shells")

_PROGRESS = re.compile(r"^imagemap: \[(\d+)/(\d+)\] (.*)$")
#: Seconds a cancelled subprocess gets to end on SIGTERM before it is killed.
TERMINATE_SECONDS = 3.0


@dataclass(frozen=True)
class Progress:
    """One progress line of the mesh command: step ``step`` of ``total`` begins."""

    step: int
    total: int
    text: str

    @property
    def fraction(self) -> float:
        """The share of the object done when this step begins (0 at step 1)."""
        return (self.step - 1) / self.total


def parse_progress(line: str) -> Progress | None:
    """The progress in one stderr line of ``imagemap synthesize MESH``, or None.

    Examples
    --------
    >>> parse_progress("imagemap: [2/5] synthesizing view 90,0")
    Progress(step=2, total=5, text='synthesizing view 90,0')
    >>> parse_progress("imagemap: views chosen by coverage: 0,0; 180,0") is None
    True
    >>> parse_progress("imagemap: [6/5] nonsense") is None  # not a step of the total
    True
    """
    found = _PROGRESS.match(line.strip())
    if found is None:
        return None
    step, total = int(found[1]), int(found[2])
    if not 1 <= step <= total:
        return None
    return Progress(step, total, found[3])


def local_from_world(matrix) -> np.ndarray:
    """The inverse of an object's 4x4 affine world ``matrix``: what brings the textured
    result, made in world coordinates, back into the object's own.

    Examples
    --------
    >>> world = np.diag([1.5, 0.5, 0.6, 1.0])
    >>> world[:3, 3] = (2.0, 0.0, -1.0)
    >>> (local_from_world(world) @ world).round(12).tolist() == np.eye(4).tolist()
    True
    """
    matrix = np.asarray(matrix, dtype=np.float64)
    if matrix.shape != (4, 4) or not np.isfinite(matrix).all():
        raise ValueError(f"matrix: expected a finite 4x4 matrix, got shape {matrix.shape}")
    if not np.allclose(matrix[3], (0.0, 0.0, 0.0, 1.0)):
        raise ValueError(f"matrix: expected an affine matrix (last row 0 0 0 1), got {matrix[3]}")
    is_mirrored(matrix)  # a flat transform has no inverse: its clear error
    return np.linalg.inv(matrix)


def is_mirrored(matrix) -> bool:
    """Whether ``matrix`` turns space inside out (negative determinant): the faces sent
    must then be flipped, or their normals point inward.

    Examples
    --------
    >>> is_mirrored(np.diag([-1.0, 1.0, 1.0, 1.0])), is_mirrored(np.diag([2.0, 1.0, 1.0, 1.0]))
    (True, False)
    """
    matrix = np.asarray(matrix, dtype=np.float64)
    determinant = float(np.linalg.det(matrix[:3, :3]))
    if determinant == 0.0:
        raise ValueError("matrix: the object's transform is flat (scale 0 on some axis)")
    return determinant < 0.0


_MESH_SUFFIXES = (".glb", ".gltf", ".obj", ".ply")


def database_class(folder: str) -> str | None:
    """The class most examples of a database folder belong to, or None (none found).

    An example's class is its JSON record's ``class`` field (``NAME.json``, as
    ``python -m data_gen`` writes), else its name less a numeric suffix (``fish_003``:
    fish), as imagemap's evaluation reads it; examples are ``NAME_depth.*`` maps and
    meshes (``.glb``, ``.gltf``, ``.obj``, ``.ply``).
    """
    if not os.path.isdir(folder):
        raise ValueError(f"database folder not found: {folder!r}")
    files = sorted(os.listdir(folder))
    names = {f.rsplit("_depth.", 1)[0] for f in files if "_depth." in f}
    names |= {os.path.splitext(f)[0] for f in files if f.lower().endswith(_MESH_SUFFIXES)}
    classes: Counter[str] = Counter()
    for name in names:
        found = None
        record = os.path.join(folder, f"{name}.json")
        if os.path.isfile(record):
            try:
                with open(record, encoding="utf-8") as handle:
                    value = json.load(handle)
                found = value.get("class") if isinstance(value, dict) else None
            except (OSError, ValueError):
                found = None  # not a record of ours: the name tells
        if not isinstance(found, str) or not found:
            found = re.sub(r"[_-]?\d+$", "", name) or name
        classes[found] += 1
    if not classes:
        return None
    # Most examples; a tie goes to the first name in order, so the choice is repeatable.
    return max(sorted(classes), key=lambda c: classes[c])


def database_preset(folder: str, presets: Sequence[str] = PRESET_NAMES) -> str | None:
    """The preset named like the database's class (:func:`database_class`), or None.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     for name in ("fish_000.glb", "fish_001.glb", "vase_1.glb"):
    ...         _ = (pathlib.Path(folder) / name).write_bytes(b"")
    ...     database_preset(folder)
    'fish'
    """
    found = database_class(folder)
    return found if found in presets else None


def remove_folder(folder: str | None) -> None:
    """Remove a temporary folder and all in it (nothing if it is gone already)."""
    if folder:
        shutil.rmtree(folder, ignore_errors=True)


class CommandRun:
    """A command in a subprocess, its stderr lines read on a thread (never blocking).

    Parameters
    ----------
    command : list of str
    popen : callable
        ``subprocess.Popen`` (tests pass a stand-in).
    """

    def __init__(self, command: list[str], popen=subprocess.Popen) -> None:
        self.command = list(command)
        self.lines: queue.Queue[str] = queue.Queue()
        self.last = "starting"
        self.progress: Progress | None = None
        self.log: list[str] = []
        self.process = popen(
            self.command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
        )
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        if self.process.stderr is None:
            return
        for line in self.process.stderr:
            self.lines.put(line.rstrip())

    def poll(self) -> int | None:
        """Take the lines written so far (the last one, the progress) and the exit code."""
        while True:
            try:
                line = self.lines.get_nowait()
            except queue.Empty:
                break
            if not line:
                continue
            self.log.append(line)
            step = parse_progress(line)
            if step is not None:
                self.progress = step
                self.last = f"{step.text} ({step.step}/{step.total})"
            else:
                self.last = line.removeprefix("imagemap: ").strip()
        return self.process.poll()

    @property
    def fraction(self) -> float:
        """The share of this command's work done, from its last progress line (0 before)."""
        return self.progress.fraction if self.progress is not None else 0.0

    def wait(self) -> int:
        """Run to the end; every line read."""
        code = self.process.wait()
        self._reader.join(timeout=TERMINATE_SECONDS)
        self.poll()
        return code

    def cancel(self) -> None:
        """End the subprocess: SIGTERM, then SIGKILL if it has not ended in
        :data:`TERMINATE_SECONDS` (its files are then no longer being written)."""
        if self.process.poll() is not None:
            return
        self.process.terminate()
        try:
            self.process.wait(timeout=TERMINATE_SECONDS)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
