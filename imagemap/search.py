"""Nearest-neighbour indexes over feature vectors: build once, query many.

One interface, interchangeable implementations (as trimesh's ray module):

- :class:`ExactIndex` — brute force with chunked float32 matrix products; the
  reference, for tests and small inputs.
- :class:`PynndescentIndex` — pynndescent's approximate NN-descent graph. It
  compiles with numba on first use in a process (tens of seconds, cached on
  disk afterwards) and is seeded for reproducibility.

The engine's default, PatchMatch, is not an index: it searches the exemplar
image domain warm-started from the previous matches (see ``imagemap._kernels``).
"""

from __future__ import annotations

import logging
from typing import Protocol

import numpy as np

__all__ = ["ExactIndex", "NearestNeighborIndex", "PynndescentIndex", "make_index"]

log = logging.getLogger("imagemap")

#: Floats per block of the brute-force distance matrix (~128 MB in float32).
_BLOCK_FLOATS = 32_000_000


class NearestNeighborIndex(Protocol):
    """What every backend offers."""

    name: str

    def query(self, queries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nearest data row of each query: (indices int64, squared distances float32)."""
        ...


class ExactIndex:
    """Exact nearest neighbours by brute force in float32 (BLAS matrix products).

    Parameters
    ----------
    data : ndarray, shape (N, D)

    Examples
    --------
    >>> index = ExactIndex(np.eye(3, dtype=np.float32))
    >>> index.query(np.array([[0.9, 0.1, 0.0]], dtype=np.float32))[0]
    array([0])
    """

    name = "exact"

    def __init__(self, data: np.ndarray, seed: int = 0) -> None:
        self.data = np.ascontiguousarray(data, dtype=np.float32)
        self.data_norms = np.einsum("ij,ij->i", self.data, self.data)

    def query(self, queries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        queries = np.ascontiguousarray(queries, dtype=np.float32)
        n_data = self.data.shape[0]
        indices = np.empty(queries.shape[0], dtype=np.int64)
        distances = np.empty(queries.shape[0], dtype=np.float32)
        query_block = max(1, _BLOCK_FLOATS // max(n_data, 1))
        data_block = max(1, _BLOCK_FLOATS // query_block)
        for q0 in range(0, queries.shape[0], query_block):
            q = queries[q0 : q0 + query_block]
            q_norms = np.einsum("ij,ij->i", q, q)
            best = np.full(q.shape[0], np.inf, dtype=np.float32)
            best_index = np.zeros(q.shape[0], dtype=np.int64)
            for d0 in range(0, n_data, data_block):
                block = self.data[d0 : d0 + data_block]
                dist = self.data_norms[None, d0 : d0 + data_block] - 2.0 * (q @ block.T)
                local = np.argmin(dist, axis=1)
                local_best = dist[np.arange(q.shape[0]), local] + q_norms
                better = local_best < best
                best[better] = local_best[better]
                best_index[better] = local[better] + d0
            indices[q0 : q0 + q.shape[0]] = best_index
            distances[q0 : q0 + q.shape[0]] = np.maximum(best, 0.0)
        return indices, distances


class PynndescentIndex:
    """Approximate nearest neighbours with pynndescent's NNDescent graph.

    Parameters
    ----------
    data : ndarray, shape (N, D)
    seed : int
        ``random_state`` of the graph construction, for reproducible results.
    n_neighbors : int
        Graph degree; more is slower to build and more accurate.
    """

    name = "pynndescent"

    def __init__(self, data: np.ndarray, seed: int = 0, n_neighbors: int = 15) -> None:
        from pynndescent import NNDescent

        self.data = np.ascontiguousarray(data, dtype=np.float32)
        self.index = NNDescent(
            self.data,
            n_neighbors=min(n_neighbors, max(2, self.data.shape[0] - 1)),
            random_state=seed % (2**32),
            n_jobs=1,  # a fixed work split: the same seed gives the same graph
            compressed=False,
        )
        self.index.prepare()

    def query(self, queries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        queries = np.ascontiguousarray(queries, dtype=np.float32)
        indices, distances = self.index.query(queries, k=1, epsilon=0.1)
        return indices[:, 0].astype(np.int64), (distances[:, 0] ** 2).astype(np.float32)


_BACKENDS = {"exact": ExactIndex, "pynndescent": PynndescentIndex}


def make_index(backend: str, data: np.ndarray, seed: int = 0) -> NearestNeighborIndex:
    """Build the index of the named backend (``"exact"`` or ``"pynndescent"``) over ``data``."""
    try:
        cls = _BACKENDS[backend]
    except KeyError:
        raise ValueError(
            f"unknown search backend {backend!r}; use one of {sorted(_BACKENDS)}"
        ) from None
    return cls(data, seed=seed)
