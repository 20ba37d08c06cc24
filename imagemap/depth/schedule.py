"""Each example's own work on the kernels' threads, or one example after the other.

The registration's guides and fit, the bands and the examples' small features are each
example's own arrays: :func:`each_example` runs them on the kernels' thread pool
(:func:`imagemap.core.kernels.run_each`; SciPy's filters, distance transforms and
interpolation release the GIL) where the examples' frames are between
:data:`THREADED_MIN_PIXELS` and :data:`THREADED_FRAME_PIXELS`, else in order on the
calling thread. Either way the outputs are the same bytes.
"""

from __future__ import annotations

from collections.abc import Sequence

from imagemap.core.kernels import run_each

__all__ = ["THREADED_FRAME_PIXELS", "THREADED_MIN_PIXELS", "each_example"]

#: Examples' frames of at least THREADED_MIN_PIXELS and at most THREADED_FRAME_PIXELS have
#: their own work (the registration's guides and fit, the bands, the small features) done
#: on the kernels' threads at once; others one example at a time. The bound is the side by
#: side's 200x150 frame, the crossover measured (the fish, 2 examples; these three stages'
#: wall, threaded against one at a time in one process, rotated pairs, medians): with the
#: second core free x0.81 and x0.90 at 200x150 (two runs), x0.80 at 256x192, x0.74 at
#: 320x240 and 400x300, x0.68 at 448x336 (2^17 was half the 512^2 frame, not measured);
#: below 200x150 only the small features gain (x0.69), the bands lose (x1.12-1.17 at
#: 160x120 and 128x96) and the sum is within noise (x0.92-0.95). With one core busy with
#: other work about even at every size (x1.04 at 200x150, x1.05, x1.00, x0.93 at 512^2);
#: with both busy a loss (x1.7 at 200x150, x1.2 at 512^2: the GIL's handovers wait for
#: the OS), accepted as before: #44's side by side runs on a quiet machine.
THREADED_MIN_PIXELS = 200 * 150
#: The upper bound: two examples' transients at once, and what the worker threads' malloc
#: arenas keep (benchmarks/memory.py): the 512^2 task's peak 259 -> 271 MB (reached in the
#: engine; the bands' 175 -> 188), the 1024^2 fish's 327 -> 329 MB (the bands' 269 -> 306,
#: the registration's 191 -> 241: still under the engine's). Above it the bands' peak would
#: pass the engine's.
THREADED_FRAME_PIXELS = 2**20


def each_example(function, shapes: Sequence[tuple[int, ...]]) -> None:
    """Call ``function(index)`` for each example, threaded or in order.

    Parameters
    ----------
    function : callable
        Called once with each index of ``shapes``; each call writes only its own
        example's results.
    shapes : sequence of tuple of int
        The examples' frame shapes (rows, columns, ...).

    Notes
    -----
    On the kernels' threads (:func:`imagemap.core.kernels.run_each`) where every frame has
    at most :data:`THREADED_FRAME_PIXELS` pixels and the largest at least
    :data:`THREADED_MIN_PIXELS`; else one after the other, in order, on the calling thread.
    """
    indices = list(range(len(shapes)))
    pixels = [shape[0] * shape[1] for shape in shapes]
    if pixels and THREADED_MIN_PIXELS <= max(pixels) <= THREADED_FRAME_PIXELS:
        run_each(function, indices)
    else:
        for index in indices:
            function(index)
