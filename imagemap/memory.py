"""How much memory this process may still use, and a guard that refuses a run that needs more.

Three limits, the smallest wins:

- ``MemAvailable`` of ``/proc/meminfo``: what the machine can give without swapping;
- a cgroup limit (v2 ``memory.max`` - ``memory.current``; v1 ``memory.limit_in_bytes`` -
  ``memory.usage_in_bytes``): a container's share;
- ``RLIMIT_AS`` (``ulimit -v``) minus the address space already mapped (``VmSize``): an
  allocation past it fails at once with a MemoryError, whatever the machine has free.

Unknown limits are skipped (None when none is known: the guard then lets the run go).
``IMAGEMAP_NO_MEMORY_CHECK=1`` switches the guard off, as for ``imagemap synthesize``.

Example
-------
>>> check_memory(1024, "a small array")  # fits anywhere
>>> format_bytes(3 * 2**30)
'3.0 GB'
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from imagemap.errors import InputError

__all__ = ["MemoryBudgetError", "available_memory", "check_memory", "format_bytes"]


class MemoryBudgetError(InputError):
    """A run whose estimated memory exceeds what this process may use."""


def format_bytes(n: float) -> str:
    """A byte count for a message: GB from 1 GiB, else MB.

    Example
    -------
    >>> format_bytes(5 * 2**20)
    '5 MB'
    """
    if n >= 2**30:
        return f"{n / 2**30:.1f} GB"
    return f"{n / 2**20:.0f} MB"


def _read_int(path: str) -> int | None:
    with contextlib.suppress(OSError, ValueError):
        text = Path(path).read_text().strip()
        if text != "max":
            return int(text)
    return None


def _meminfo_available() -> int | None:
    with contextlib.suppress(OSError, ValueError):
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    return None


def _cgroup_room() -> int | None:
    for limit_file, usage_file in (
        ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
        (
            "/sys/fs/cgroup/memory/memory.limit_in_bytes",
            "/sys/fs/cgroup/memory/memory.usage_in_bytes",
        ),
    ):
        limit, usage = _read_int(limit_file), _read_int(usage_file)
        # cgroup v1 reports "no limit" as a huge page-aligned number.
        if limit is not None and usage is not None and limit < 2**60:
            return limit - usage
    return None


def _address_space_room(mapped_at_least: int = 0) -> int | None:
    """RLIMIT_AS's soft limit minus this process's mapped address space (VmSize), or minus
    ``mapped_at_least`` where that is larger (what a run will have mapped)."""
    try:
        import resource  # deferred: not on every platform (Windows)
    except ImportError:  # not on this platform
        return None
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return None
    mapped = 0
    with contextlib.suppress(OSError, ValueError):
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmSize:"):
                mapped = int(line.split()[1]) * 1024
                break
    return soft - max(mapped, mapped_at_least)


def available_memory(mapped_at_least: int = 0) -> int | None:
    """Bytes this process can still use: the smallest of MemAvailable, the cgroup's room
    and RLIMIT_AS's room (None: none of them known). ``mapped_at_least``: the address space
    counted as mapped under RLIMIT_AS when more than is mapped now (a run's modules and
    threads, mapped later).

    Example
    -------
    >>> room = available_memory()
    >>> room is None or room > 0
    True
    """
    rooms = [
        r
        for r in (_meminfo_available(), _cgroup_room(), _address_space_room(mapped_at_least))
        if r is not None
    ]
    return max(min(rooms), 0) if rooms else None


def _enabled() -> bool:
    return os.environ.get("IMAGEMAP_NO_MEMORY_CHECK", "") in ("", "0")


def check_memory(needed: float, what: str, *, advice: str = "") -> None:
    """Raise :class:`MemoryBudgetError` when ``needed`` bytes exceed :func:`available_memory`.

    Parameters
    ----------
    needed : float
        Estimated peak bytes of the run.
    what : str
        What needs them, for the message (name the option or file).
    advice : str
        The way out, appended to the message (e.g. "use a smaller --size").
    """
    if not _enabled():
        return
    available = available_memory()
    if available is not None and needed > available:
        raise MemoryBudgetError(
            f"{what} needs about {format_bytes(needed)} of memory, but only "
            f"{format_bytes(available)} is available{': ' + advice if advice else ''} "
            "(IMAGEMAP_NO_MEMORY_CHECK=1 runs anyway)"
        )
