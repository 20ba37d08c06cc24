"""Batches: every depth map or mesh of a folder, on a local process pool or a Dask cluster.

:func:`run_batch` plans one job per input object (``NAME_depth.png|tif|tiff|npy``
-> ``NAME_image.png``; a mesh ``NAME.glb|obj|ply|...`` -> a textured ``NAME.glb`` or
``NAME.obj``), prepares the database once (every example's arrays loaded, mesh
examples rendered for each requested view) and ships it to the workers once: a
local process pool gets it in its initializer, a Dask cluster by
``client.scatter(..., broadcast=True)``.

Safe: every output (and what it brings: an OBJ's ``.mtl`` and texture) is checked
before any work by the same rule as ``imagemap synthesize``
(:class:`imagemap.outputs.OutputPlan`): none is an input, a file an input mesh reads,
a held-out truth beside an input (``NAME_image.png``...), a database file, or in the
database's folder; two inputs may not make one output; an existing file is replaced
only when an earlier batch here wrote it. The output folder must be writable, and is
locked for the run (a second batch into it stops at once). Paths are absolute before
they are shipped (Dask workers have their own working directories). Local workers end
when the batch's process does, even by ``kill -9``.

Resumable: an object's outputs are written as a set (all or none), then a small
manifest ``OUT/.imagemap-done/SOURCE.json`` holding the input's content hash, the
options, and each output's SHA-256; an object whose manifest matches (same input, same
options, same engine code, every output present with the recorded content) is skipped,
so an output changed or damaged since, even at the same size, is made again. Ctrl-C
writes the report and says how to resume. A failing object is reported and the others
go on. The summary counts done, skipped and failed objects and the throughput (objects
per minute).

Examples
--------
Two depth maps against a database of two painted ellipses (usually a folder),
in this process (``workers=1``), then the same batch again:

>>> import shutil, tempfile
>>> import numpy as np
>>> from pathlib import Path
>>> from imagemap.database import Database, Example
>>> yy, xx = np.mgrid[:24, :32]
>>> def ellipse(height):
...     inside = (yy - 12) ** 2 / (height / 2) ** 2 + (xx - 16) ** 2 / 144 < 1
...     return np.where(inside, 0.7, 0).astype(np.float32)
>>> def paint(depth):
...     return np.where((depth > 0)[..., None] & (yy[..., None] < 12), [0.8, 0.2, 0.1], 0.5)
>>> db = Database([Example.from_arrays(f"e{h}", ellipse(h), paint(ellipse(h))) for h in (12, 18)])
>>> folder = Path(tempfile.mkdtemp())
>>> (folder / "in").mkdir()
>>> for h in (14, 16):
...     np.save(folder / "in" / f"q{h}_depth.npy", ellipse(h))
>>> summary = run_batch(folder / "in", db, folder / "out", BatchOptions(preset="fish"))
>>> summary.done, summary.skipped, summary.failed
(2, 0, 0)
>>> sorted(p.name for p in (folder / "out").iterdir())
['.imagemap-done', 'batch_report.json', 'q14_image.png', 'q16_image.png']
>>> again = run_batch(folder / "in", db, folder / "out", BatchOptions(preset="fish"))
>>> again.done, again.skipped  # complete outputs are skipped
(0, 2)
>>> shutil.rmtree(folder)
"""

from imagemap.batch.plan import BatchOptions, Job, plan_jobs
from imagemap.batch.run import BatchSummary, run_batch
from imagemap.batch.work import prepare_databases

__all__ = ["BatchOptions", "BatchSummary", "Job", "plan_jobs", "prepare_databases", "run_batch"]
