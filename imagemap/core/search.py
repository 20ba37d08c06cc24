"""Nearest-neighbour indexes over feature vectors: build once, query many.

One interface, interchangeable implementations (as trimesh's ray module):

- ``"exact"`` :class:`ExactIndex` — brute force with chunked float32 matrix
  products; the reference, for tests and small inputs.
- ``"kdtree"`` :class:`KDTreeIndex` — exact too: scipy's k-d tree up to
  :data:`KDTREE_MAX_DIMS` dimensions, where it is far faster, brute force beyond.
- ``"pca_kdtree"`` :class:`PCAKDTreeIndex` — approximate: the data (and every
  query) projected on their leading principal components (fit on the data) to
  :data:`KDTREE_MAX_DIMS` dimensions, then an exact k-d tree there. No compile step.
- ``"pynndescent"`` :class:`PynndescentIndex` — pynndescent's approximate
  NN-descent graph. It compiles with numba on first use in a process (tens of
  seconds, cached on disk afterwards) and is seeded for reproducibility.

:func:`make_index` builds any of them by name; the engine (``EngineParams.backend``)
and the BTF pixel-wise method (``PixelwiseParams.backend``) both name their search
with these words. The engine's default, ``"patchmatch"``, is not an index: it
searches the exemplar image domain warm-started from the previous matches (see
``imagemap.core.kernels``).
"""

from __future__ import annotations

import logging
from typing import Any, Protocol

import numpy as np

__all__ = [
    "INDEX_BACKENDS",
    "KDTREE_MAX_DIMS",
    "ExactIndex",
    "KDTreeIndex",
    "NearestNeighborIndex",
    "PCAKDTreeIndex",
    "PynndescentIndex",
    "make_index",
]

log = logging.getLogger("imagemap")

#: Floats per block of queries times data (~128 MB in float32): the query blocks whose
#: norms are taken together, and the data block (the data are split only beyond it).
_BLOCK_FLOATS = 32_000_000
#: Floats per distance matrix actually made (~16 MB in float32): a block of queries is
#: matched in pieces of this size. It was the whole 128 MB block, the engine's peak
#: (the coarsest level's exact start) at 1024^2; the pieces give the same bytes.
_DISTANCE_FLOATS = 4_000_000

#: Beyond this many dimensions a k-d tree is no faster than brute force.
KDTREE_MAX_DIMS = 16


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
        piece = max(1, _DISTANCE_FLOATS // max(min(n_data, data_block), 1))
        for q0 in range(0, queries.shape[0], query_block):
            q = queries[q0 : q0 + query_block]
            q_norms = np.einsum("ij,ij->i", q, q)
            best = np.full(q.shape[0], np.inf, dtype=np.float32)
            best_index = np.zeros(q.shape[0], dtype=np.int64)
            for d0 in range(0, n_data, data_block):
                block = self.data[d0 : d0 + data_block]
                for p0, p1 in _pieces(q.shape[0], piece):
                    # |d|^2 - 2 q.d, in place: one piece-sized array, not three (the same
                    # float32 operations as ``norms - 2.0 * (q @ block.T)``).
                    dist = q[p0:p1] @ block.T
                    np.multiply(dist, np.float32(2.0), out=dist)
                    np.subtract(self.data_norms[None, d0 : d0 + data_block], dist, out=dist)
                    local = np.argmin(dist, axis=1)
                    local_best = dist[np.arange(p1 - p0), local] + q_norms[p0:p1]
                    del dist
                    better = local_best < best[p0:p1]
                    best[p0:p1][better] = local_best[better]
                    best_index[p0:p1][better] = local[better] + d0
            indices[q0 : q0 + q.shape[0]] = best_index
            distances[q0 : q0 + q.shape[0]] = np.maximum(best, 0.0)
        return indices, distances


def _pieces(n: int, size: int) -> list[tuple[int, int]]:
    """Rows 0:n in pieces of ``size`` rows, a last piece of one row joined to the one
    before: BLAS computes a single row by another routine (gemv), whose sums may differ
    in the last bit from the matrix product's (gemm); a block of n > 1 rows then gives
    the same products in pieces as whole.

    Examples
    --------
    >>> _pieces(7, 3), _pieces(6, 3), _pieces(1, 3)
    ([(0, 3), (3, 7)], [(0, 3), (3, 6)], [(0, 1)])
    """
    starts = list(range(0, n, size))
    if len(starts) > 1 and n - starts[-1] == 1:
        starts.pop()
    return list(zip(starts, starts[1:] + [n], strict=True))


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
        from pynndescent import NNDescent  # deferred: optional backend

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


class KDTreeIndex:
    """Exact nearest neighbours: scipy's k-d tree, or brute force beyond 16 dimensions.

    Examples
    --------
    >>> KDTreeIndex(np.eye(3, dtype=np.float32)).query(np.array([[0.1, 0.9, 0.0]]))[0]
    array([1])
    """

    name = "kdtree"

    def __init__(self, data: np.ndarray, seed: int = 0) -> None:
        self.data = np.ascontiguousarray(data, dtype=np.float32)
        self.tree: Any = None
        self.exact: ExactIndex | None = None
        if self.data.shape[1] > KDTREE_MAX_DIMS:
            self.tree, self.exact = None, ExactIndex(self.data)
        else:
            from scipy.spatial import (
                cKDTree,
            )  # deferred: start-up: scipy.spatial only where a k-d tree is built

            self.tree, self.exact = cKDTree(self.data), None

    def query(self, queries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        queries = np.ascontiguousarray(queries, dtype=np.float32)
        if self.exact is not None:  # too many dimensions for a k-d tree
            return self.exact.query(queries)
        distances, indices = self.tree.query(queries, k=1, workers=-1)
        return indices.astype(np.int64), (distances**2).astype(np.float32)

    def query_k(self, queries: np.ndarray, k: int) -> np.ndarray:
        """Indices (n, k) of the ``k`` nearest rows of every query, nearest first."""
        from scipy.spatial import (
            cKDTree,
        )  # deferred: start-up: scipy.spatial only where a k-d tree is built

        tree = self.tree if self.tree is not None else cKDTree(self.data)
        queries = np.ascontiguousarray(queries, dtype=np.float32)
        return tree.query(queries, k=k, workers=-1)[1].astype(np.int64).reshape(len(queries), k)


class PCAKDTreeIndex:
    """Approximate nearest neighbours: PCA (fit on the data) to ``dims``, then a k-d tree.

    Neighbourhood vectors are highly redundant, so a few principal components keep
    nearly all their spread; with at most ``dims`` dimensions nothing is projected and
    the search is exact. Distances are those in the projected space.

    Parameters
    ----------
    data : ndarray, shape (N, D)
    seed : int
        Unused (the index is deterministic); accepted like the other indexes'.
    dims : int
        Principal components kept.
    """

    name = "pca_kdtree"

    def __init__(self, data: np.ndarray, seed: int = 0, dims: int = KDTREE_MAX_DIMS) -> None:
        data = np.ascontiguousarray(data, dtype=np.float32)
        self.mean, self.basis = None, None
        if data.shape[1] > dims:
            self.mean = data.mean(axis=0)
            # Principal directions from the D x D covariance (eigh): for N >> D several
            # times faster than an SVD of the N x D data, the same subspace.
            centred = (data - self.mean).astype(np.float64)
            _, vectors = np.linalg.eigh(centred.T @ centred)
            self.basis = np.ascontiguousarray(vectors[:, ::-1][:, :dims], dtype=np.float32)
            data = (data - self.mean) @ self.basis
        self.tree = KDTreeIndex(data)

    def _project(self, queries: np.ndarray) -> np.ndarray:
        queries = np.asarray(queries, dtype=np.float32)
        if self.basis is not None:
            queries = (queries - self.mean) @ self.basis
        return queries

    def query(self, queries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.tree.query(self._project(queries))

    def query_k(self, queries: np.ndarray, k: int) -> np.ndarray:
        """Indices (n, k) of the ``k`` nearest rows (in the projected space), nearest first."""
        return self.tree.query_k(self._project(queries), k)


#: The index names :func:`make_index` knows.
INDEX_BACKENDS = ("exact", "kdtree", "pca_kdtree", "pynndescent")

_BACKENDS: dict[str, Any] = {
    "exact": ExactIndex,
    "kdtree": KDTreeIndex,
    "pca_kdtree": PCAKDTreeIndex,
    "pynndescent": PynndescentIndex,
}


def make_index(backend: str, data: np.ndarray, seed: int = 0) -> NearestNeighborIndex:
    """Build the index named ``backend`` (one of :data:`INDEX_BACKENDS`) over ``data``."""
    try:
        cls = _BACKENDS[backend]
    except KeyError:
        raise ValueError(
            f"unknown search backend {backend!r}; use one of {sorted(_BACKENDS)}"
        ) from None
    return cls(data, seed=seed)
