"""Start-up of ``imagemap synthesize``: numba and the engine's imports beside the first stages.

A synthesis reads its inputs, selects, poses and registers the examples and makes their
bands before the engine calls its first numba kernel. Importing numba and linking its
runtime (0.3-0.4 s of CPU, much of it in LLVM's C++ through ctypes, which lets go of the
GIL) needs none of that, so the program starts it on a thread of its own while the main
thread does that work. The main thread's first ``import imagemap.core.kernels`` waits for
the thread's import of it (Python's per-module import locks) and then finds it done.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

__all__ = ["WARM_MODULES", "warm_kernels"]

#: What the thread imports, in this order (NumPy is imported before it starts): numba,
#: set up for :func:`imagemap.cli.lean_kernel_loads` (the kernels' cached code linked
#: without numba's registries), imagemap's kernels, and SciPy's linear algebra (the
#: engine's PCA; the first stages no longer import it).
WARM_MODULES = ("numba", "imagemap.core.kernels", "scipy.linalg")


def warm_kernels(
    on: bool = True, link: Callable[[], object] | None = None
) -> threading.Thread | None:
    """Import numba and imagemap's kernels on a daemon thread (when ``on``); ``link``
    (:func:`imagemap.cli.lean_kernel_loads`) is called on it once numba is imported.

    Only for the program (it owns the process, see :func:`imagemap.cli.main`). NumPy is
    imported first, here on the calling thread: imagemap's argument checks read
    ``sys.modules["numpy"]``, which must not be a module another thread is still
    importing. A failure on the thread is silent: the main thread then imports what it
    needs itself, as without the thread.

    Returns
    -------
    threading.Thread or None
        The started thread (None when not ``on``).

    Examples
    --------
    >>> import sys
    >>> thread = warm_kernels()
    >>> thread.join()
    >>> "imagemap.core.kernels" in sys.modules
    True
    """
    if not on:
        return None
    import numpy  # deferred: start-up (only the program warms up)  # noqa: F401

    thread = threading.Thread(target=_warm, args=(link,), name="imagemap-warm", daemon=True)
    thread.start()
    return thread


def _warm(link: Callable[[], object] | None) -> None:
    import importlib  # deferred: start-up (only the program's thread needs it)

    try:
        for name in WARM_MODULES:
            importlib.import_module(name)
            if name == "numba" and link is not None:
                link()
    except Exception:  # the main thread imports what it needs itself
        return
