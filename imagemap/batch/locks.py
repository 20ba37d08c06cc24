"""The output folder's lock: one batch at a time writes into a folder."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from imagemap.batch.plan import DONE_DIR
from imagemap.io import InputError

__all__ = ["LOCK_NAME"]


#: The lock file of an output folder (inside :data:`DONE_DIR`): held while a batch writes.
LOCK_NAME = "lock"


@contextlib.contextmanager
def _locked(out_dir: Path):
    """Hold ``out_dir``'s lock for the batch; another batch holding it is an InputError.

    An advisory ``flock`` on ``OUT/.imagemap-done/lock``: the system releases it when the
    holder ends, however it ends, so a killed batch never leaves a stale lock."""
    try:
        import fcntl  # deferred: optional dependency (POSIX only; no lock elsewhere)
    except ImportError:
        yield
        return
    folder = out_dir / DONE_DIR
    folder.mkdir(parents=True, exist_ok=True)
    handle = open(folder / LOCK_NAME, "a+")  # noqa: SIM115 (held for the whole batch)
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.seek(0)
            holder = handle.read().strip() or "unknown"
            raise InputError(
                f"{out_dir}: another batch is writing into this folder (process {holder}); "
                "wait for it to finish, or give another -o"
            ) from None
        handle.seek(0)
        handle.truncate()
        handle.write(f"{os.getpid()}\n")
        handle.flush()
        yield
    finally:
        handle.close()
