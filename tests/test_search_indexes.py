"""The shared nearest-neighbour indexes: the exact ones agree, PCA + k-d tree is close."""

from __future__ import annotations

import numpy as np
import pytest

from imagemap.core.search import INDEX_BACKENDS, ExactIndex, make_index


@pytest.mark.parametrize("dims", [6, 40])
def test_kdtree_is_exact_and_pca_kdtree_close(dims):
    rng = np.random.default_rng(0)
    # Redundant vectors, as neighbourhood constraint vectors are: 5 factors, then noise.
    data = rng.normal(size=(2000, 5)) @ rng.normal(size=(5, dims))
    data += 0.01 * rng.normal(size=data.shape)
    queries = data[rng.integers(0, 2000, 300)] + 0.05 * rng.normal(size=(300, dims))
    exact_idx, exact_d = ExactIndex(data).query(queries)
    kd_idx, kd_d = make_index("kdtree", data).query(queries)
    np.testing.assert_array_equal(kd_idx, exact_idx)
    np.testing.assert_allclose(kd_d, exact_d, rtol=1e-3, atol=1e-3)
    pca_idx, _ = make_index("pca_kdtree", data).query(queries)
    assert np.mean(pca_idx == exact_idx) > 0.95


def test_unknown_backend_names_the_choices():
    with pytest.raises(ValueError, match="pca_kdtree"):
        make_index("approximate", np.zeros((3, 2)))
    assert set(INDEX_BACKENDS) == {"exact", "kdtree", "pca_kdtree", "pynndescent"}
