"""The engine's properties: hard-EM descent, reproduction, non-stationarity, determinism."""

from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage

from imagemap import Database, DepthConfig, Example, colorize
from imagemap.core.engine import EngineParams, Mapping, synthesize, uniform_levels
from imagemap.depth.config import PRESETS
from imagemap.depth.units import query_in_database


def slab(shape, top_left, size, left_colour=(0.9, 0.1, 0.1), right_colour=(0.1, 0.1, 0.9)):
    """A flat slab with the same bump pattern everywhere, coloured by half."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w]
    y0, x0 = top_left
    hh, ww = size
    mask = (yy >= y0) & (yy < y0 + hh) & (xx >= x0) & (xx < x0 + ww)
    bumps = 0.1 * np.sin(2 * np.pi * xx / 6) * np.sin(2 * np.pi * yy / 6)
    depth = np.where(mask, 0.5 + bumps, 0).astype(np.float32)
    image = np.zeros((h, w, 3), np.float32)
    left = xx < x0 + ww / 2
    image[mask & left] = left_colour
    image[mask & ~left] = right_colour
    return depth, image, left


def test_self_reproduction(blob_database, query_blob):
    """With the query's own mapping in the database the map comes back (bound: 0.02 mean)."""
    depth, truth = query_blob
    db = Database([*blob_database.examples, Example.from_arrays("twin", depth, truth)])
    with query_in_database():  # the twin is the query itself, on purpose
        result = colorize(depth, db, "busts", backend="exact")
    assert result.example_names[0] == "twin"
    error = np.abs(result.image - truth)[depth > 0].mean()
    assert error < 0.02, error


@pytest.mark.parametrize("backend", ["exact", "patchmatch"])
def test_target_never_increases(blob_database, query_blob, backend):
    depth, _ = query_blob
    result = colorize(depth, blob_database, "busts", backend=backend, seed=3)
    # Something to check: a level runs several iterations (a level may stop after one).
    assert any(len(values) >= 2 for values in result.objective), result.objective
    for level, values in enumerate(result.objective):
        steps = np.diff(values)
        assert np.all(steps <= 1e-6 * np.abs(values[:-1])), (level, values)


@pytest.mark.slow  # pynndescent compiles with numba in every fresh process: 40-90 s
def test_pynndescent_target_never_increases(blob_database, query_blob):
    depth, _ = query_blob
    result = colorize(depth, blob_database, "busts", backend="pynndescent", m=1)
    for values in result.objective:
        assert np.all(np.diff(values) <= 1e-6 * np.abs(values[:-1]))


def test_position_term_makes_synthesis_non_stationary():
    """Identical depth patterns carry red on the left, blue on the right of each example."""
    d1, i1, _ = slab((64, 128), (8, 8), (48, 112))
    d2, i2, _ = slab((64, 128), (10, 12), (44, 104))
    db = Database([Example.from_arrays("a", d1, i1), Example.from_arrays("b", d2, i2)])
    depth, _, left = slab((64, 128), (9, 10), (46, 108))
    inner = ndimage.binary_erosion(depth > 0, iterations=12)
    accuracy = {}
    for weight in (1.0, 0.0):
        # The paper's relative position (centroid frame), not the registered one.
        params = DepthConfig().replace_fields(m=2, position_weight=weight, registration=False)
        image = colorize(depth, db, params).image
        red = image[..., 0] > image[..., 2]
        accuracy[weight] = float((red == left)[inner].mean())
    assert accuracy[1.0] > 0.97, accuracy
    assert accuracy[0.0] < 0.9, accuracy


def test_same_seed_same_bytes_and_seed_matters(blob_database, query_blob):
    depth, _ = query_blob
    a = colorize(depth, blob_database, "busts", seed=7)
    b = colorize(depth, blob_database, "busts", seed=7)
    c = colorize(depth, blob_database, "busts", seed=8)
    assert a.image.tobytes() == b.image.tobytes()
    assert a.source.tobytes() == b.source.tobytes()
    assert a.source.tobytes() != c.source.tobytes()


def test_same_bytes_at_any_thread_count(blob_database, query_blob, monkeypatch):
    """The kernels' work split follows the thread count; the result must not (1 and 3
    threads against this machine's count: the references are made once)."""
    from imagemap.core import kernels as _kernels

    depth, _ = query_blob
    reference = colorize(depth, blob_database, "busts", seed=3)
    rng = np.random.default_rng(0)
    guide = ndimage.gaussian_filter(rng.random((140, 150, 1)), 2).astype(np.float32)
    exemplar = Mapping(guide=guide, appearance=np.concatenate([guide, guide**2], axis=2))
    query = Mapping(guide=np.roll(guide, 5, axis=0))  # 140 rows: two PatchMatch bands
    params = EngineParams(
        levels=uniform_levels((5,)), guide_weights=(1.0,), appearance_weights=(1.0, 1.0)
    )
    engine_reference = synthesize([query], [[exemplar]], params, seed=1)
    for threads in (1, 3):
        monkeypatch.setattr(_kernels, "n_threads", lambda threads=threads: threads)
        again = colorize(depth, blob_database, "busts", seed=3)
        assert again.image.tobytes() == reference.image.tobytes(), threads
        assert again.source.tobytes() == reference.source.tobytes(), threads
        engine_again = synthesize([query], [[exemplar]], params, seed=1)
        appearance = engine_again.appearance[0].tobytes()
        assert appearance == engine_reference.appearance[0].tobytes(), threads
        assert engine_again.source.tobytes() == engine_reference.source.tobytes(), threads


def test_exact_and_patchmatch_agree_on_small_case(blob_database, query_blob):
    depth, truth = query_blob
    exact = colorize(depth, blob_database, "busts", backend="exact")
    approx = colorize(depth, blob_database, "busts", backend="patchmatch")
    mask = depth > 0
    assert np.abs(exact.image - approx.image)[mask].mean() < 0.05
    # PatchMatch's final target stays within 25% of the exact search's.
    assert approx.objective[0][-1] < 1.25 * exact.objective[0][-1]


def test_many_appearance_bands_and_carried_bands():
    """Generic over Ca; a weight-0 band is carried (voted) without being matched."""
    rng = np.random.default_rng(0)
    guide = ndimage.gaussian_filter(rng.random((40, 40)), 1.5).astype(np.float32)
    appearance = np.stack([guide * (i + 1) for i in range(5)] + [1 - guide], axis=-1)
    exemplar = Mapping(guide=guide, appearance=appearance)
    query = Mapping(guide=np.roll(guide, 5, axis=0))
    params = EngineParams(
        levels=uniform_levels((5,)),
        guide_weights=(1.0,),
        appearance_weights=(1.0, 0.5, 0, 0, 0, 0),
        backend="exact",
        pca_fraction=1.0,
    )
    result = synthesize([query], [[exemplar]], params)
    out = result.appearance[0]
    assert out.shape == (40, 40, 6)
    truth = np.roll(appearance, 5, axis=0)
    interior = np.s_[10:-10, 4:-4]
    np.testing.assert_allclose(out[interior], truth[interior], atol=1e-4)
    # The source map points at the shifted rows.
    assert np.all(result.source[15:30, 10:30, 1] == np.arange(10, 25)[:, None])


def test_bad_engine_input():
    rng = np.random.default_rng(0)
    exemplar = Mapping(guide=rng.random((20, 20, 2)), appearance=rng.random((20, 20, 3)))
    query = Mapping(guide=rng.random((20, 20, 1)))
    with pytest.raises(ValueError, match="guide bands"):
        synthesize([query], [[exemplar]], EngineParams(levels=uniform_levels((5,))))
    with pytest.raises(ValueError, match="mask is empty"):
        Mapping(guide=np.zeros((5, 5)), mask=np.zeros((5, 5), bool))
    with pytest.raises(ValueError, match="odd"):
        EngineParams(levels=uniform_levels((4,)))


def test_exemplar_costs_steer_the_source(blob_database, query_blob):
    """A large cost on every example but one leaves that one as the only source. (The
    engine's choice: the seam stage, which may hand a part to one example, is off.)"""
    depth, _ = query_blob
    unseamed = PRESETS["busts"].replace_fields(example_preference=0.0, seam_smoothness=0.0)
    free = colorize(depth, blob_database, unseamed, m=2)
    assert len(set(np.unique(free.source[..., 0][depth > 0]))) == 2
    everywhere = PRESETS["busts"].replace_fields(
        example_preference=100.0,
        preference_at_finest=True,
        free_final_reseed=False,
        seam_smoothness=0.0,
    )
    steered = colorize(depth, blob_database, everywhere, m=2)
    assert set(np.unique(steered.source[..., 0][depth > 0])) == {0}
    # Free at the finest level, the coarse levels' choice is mostly kept.
    coarse_only = PRESETS["busts"].replace_fields(
        example_preference=100.0, preference_at_finest=False, seam_smoothness=0.0
    )
    coarse = colorize(depth, blob_database, coarse_only, m=2)
    share = np.mean(coarse.source[..., 0][depth > 0] == 0)
    assert share > np.mean(free.source[..., 0][depth > 0] == 0)
    with pytest.raises(ValueError, match="exemplar_costs"):
        rng = np.random.default_rng(0)
        exemplar = Mapping(guide=rng.random((20, 20)), appearance=rng.random((20, 20)))
        params = EngineParams(levels=uniform_levels((5,), exemplar_costs=(0.0, 1.0)))
        synthesize([Mapping(guide=rng.random((20, 20)))], [[exemplar]], params)


def test_the_level_plan_moves_the_final_reseed_and_the_free_levels(blob_database, query_blob):
    """A front end's level plan says where the features are drawn: the final reseed
    follows that level's EM (its own trace unchanged, the finer level starting from
    the new matches), the exemplar costs stop there, and the finer levels refine."""
    from imagemap.core.params import LevelPlan
    from imagemap.depth.guides import depth_mappings, example_mappings

    depth, _ = query_blob
    chosen = [blob_database[0], blob_database[3]]
    guides = PRESETS["busts"].guides
    base = EngineParams(guide_weights=(1.0, 2.0, 0.5), appearance_weights=(1.0, 0.5, 0.5))

    def run(*plans):
        params = replace(base, levels=tuple(LevelPlan(5, **plan) for plan in plans))
        query = depth_mappings(depth, 2, guides)
        exemplars = [example_mappings(e, 2, "gaussian", guides) for e in chosen]
        return synthesize(query, exemplars, params, seed=0, quiet=True)

    plain = run({}, {})
    at_finest = run({"final_reseed": 0.95}, {})
    at_coarser = run({}, {"final_reseed": 0.95})
    assert at_finest.objective == plain.objective  # after the last EM: only the copy moves
    assert at_coarser.objective[1] == plain.objective[1]
    assert at_coarser.objective[0] != plain.objective[0]

    mask = depth > 0
    costly = {"exemplar_costs": (0.0, 100.0)}
    finest_free = run({}, costly).source[..., 0][mask]
    both_costly = run(costly, costly).source[..., 0][mask]
    assert np.mean(finest_free == 1) > np.mean(both_costly == 1)
    # A level's iteration cap is its own.
    assert len(run({"max_iterations": 1}, {}).objective[0]) == 1
    with pytest.raises(ValueError, match="final_reseed"):
        LevelPlan(5, final_reseed=1.0)
    with pytest.raises(ValueError, match="exemplar_costs"):
        LevelPlan(5, exemplar_costs=(-1.0,))
    with pytest.raises(ValueError, match="level plans"):
        EngineParams(levels=(LevelPlan(5),)).level_plans(2)


def _rolled_guide_solver(size, shift, axis, appearance_weights):
    """A level's solver (5x5 windows) on one smooth random exemplar, its guide and the
    guide squared as appearance, for a query that is its guide rolled by ``shift``
    along ``axis``; with the guide."""
    from imagemap.core.solver import LevelSolver, Timer

    rng = np.random.default_rng(0)
    guide = ndimage.gaussian_filter(rng.random((size, size, 1)), 2).astype(np.float32)
    exemplar = Mapping(guide=guide, appearance=np.concatenate([guide, guide**2], axis=2))
    query = Mapping(guide=np.roll(guide, shift, axis=axis))
    params = EngineParams(
        levels=uniform_levels((5,)), guide_weights=(1.0,), appearance_weights=appearance_weights
    )
    solver = LevelSolver(query, [exemplar], 5, params, np.random.default_rng(0), Timer())
    return solver, guide


def test_a_search_with_active_centres_moves_only_those():
    """PatchMatch's ``active`` (the reseed's worst fits): only those centres change their
    match, each to one at least as close on the searched dimensions, and with every
    centre active it is the plain search."""
    from imagemap.core import kernels as _kernels

    solver, _ = _rolled_guide_solver(60, 5, 0, (1.0, 1.0))
    start = np.random.default_rng(1).integers(0, len(solver.cand_e), len(solver.query_y))
    active = np.zeros(len(start), dtype=bool)
    active[::3] = True
    found = solver.search(start, init=True, seed=2, rng=None, active=active)
    assert np.array_equal(found[~active], start[~active])
    n = solver.n_init_dims
    features = solver.query_features, solver.candidate_features
    before = _kernels.feature_distances(*features, start, n)[active]
    after = _kernels.feature_distances(*features, found, n)[active]
    assert np.all(after <= before) and np.mean(after < before) > 0.5
    everywhere = solver.search(start, init=True, seed=2, rng=None, active=~np.zeros_like(active))
    assert np.array_equal(everywhere, solver.search(start, init=True, seed=2, rng=None))


def test_the_e_steps_choice_keeps_the_lower_exact_cost():
    """``LevelSolver.choose`` (one pass of the exact costs' kernel) gives what the costs of
    the matches and of the candidates, made apart and compared, give: each centre's lower
    cost, its candidate only where that is strictly lower, and the count of changes."""

    solver, guide = _rolled_guide_solver(50, 4, 1, (1.0, 0.5))
    r = solver.r
    estimate = np.pad(np.concatenate([guide, guide**2], axis=2), ((r, r), (r, r), (0, 0)))
    solver.set_appearance(np.roll(estimate, 4, axis=1))
    n, n_cand = len(solver.query_y), len(solver.cand_e)
    matches = np.random.default_rng(1).integers(0, n_cand, n)
    candidates = np.random.default_rng(2).integers(0, n_cand, n)
    candidates[::4] = matches[::4]  # some candidates are the match itself
    old, new = solver.costs(matches), solver.costs(candidates)
    better = new < old
    chosen = matches.copy()
    cost, changed = solver.choose(chosen, candidates)
    assert np.array_equal(chosen, np.where(better, candidates, matches))
    assert np.array_equal(cost, np.where(better, new, old))
    assert changed == int(better.sum()) and 0 < changed < n


def test_the_heap_is_trimmed_around_the_finest_levels_features_alone(monkeypatch):
    """The heap's free pages go back (``trim_heap``) just before and after the features of
    each of the ``engine.TRIMMED_LEVELS`` finest levels and after their E-steps, at no
    other point of a call: the coarser levels are made without a trim."""
    from imagemap.core import engine

    events: list = []
    monkeypatch.setattr(engine, "trim_heap", lambda: events.append("trim"))
    prepare = engine.LevelSolver.prepare

    def recorded(solver, rng):
        events.append(solver.query_shape)
        prepare(solver, rng)

    monkeypatch.setattr(engine.LevelSolver, "prepare", recorded)
    guide = ndimage.gaussian_filter(np.random.default_rng(0).random((64, 64, 1)), 2)
    guide = guide.astype(np.float32)
    levels = engine.TRIMMED_LEVELS + 2
    exemplar = [
        Mapping(guide=guide[:: 2**i, :: 2**i], appearance=guide[:: 2**i, :: 2**i] ** 2)
        for i in range(levels)
    ]
    query = [Mapping(guide=np.roll(guide, 3, axis=1)[:: 2**i, :: 2**i]) for i in range(levels)]
    params = EngineParams(
        levels=uniform_levels((5,) * levels), guide_weights=(1.0,), appearance_weights=(1.0,)
    )
    synthesize(query, [exemplar], params, seed=1)
    shapes = [event for event in events if event != "trim"]  # coarse to fine
    assert len(shapes) > engine.TRIMMED_LEVELS, shapes  # some level is not trimmed
    expected: list = []
    for level, shape in zip(range(len(shapes) - 1, -1, -1), shapes, strict=True):
        trimmed = level < engine.TRIMMED_LEVELS
        expected += ["trim", shape, "trim", "trim"] if trimmed else [shape]
    assert events == expected


def test_nearest_candidates_on_a_box_are_the_whole_frames():
    """The propagation snaps a coordinate that is no candidate to the nearest one by the
    feature transform of a box holding the candidates and the points: the same candidate
    (ties included) as the transform of the exemplar's whole frame gives."""
    from imagemap.core.solver import _box, _nearest_candidates

    rng = np.random.default_rng(0)
    for trial in range(200):
        h, w = (int(v) for v in rng.integers(8, 50, 2))
        seeds = rng.random((h, w)) < rng.uniform(0.002, 0.05)
        seeds[rng.integers(0, h), rng.integers(0, w)] = True
        valid = ndimage.binary_dilation(seeds, iterations=int(rng.integers(0, 4)) or 1)
        if trial % 2:  # ragged edges: more ties
            valid &= rng.random((h, w)) < 0.9
        valid[rng.integers(0, h), rng.integers(0, w)] = True
        y0, y1, x0, x1 = _box(valid)
        lookup = np.full((y1 - y0 + int(rng.integers(0, 3)), x1 - x0), -1, dtype=np.int64)
        ys, xs = np.nonzero(valid)
        lookup[ys - y0, xs - x0] = np.arange(len(ys))
        py, px = rng.integers(0, h, 30), rng.integers(0, w, 30)
        ny, nx = ndimage.distance_transform_edt(~valid, return_distances=False, return_indices=True)
        expected = lookup[ny[py, px] - y0, nx[py, px] - x0]
        assert np.array_equal(_nearest_candidates(lookup, py - y0, px - x0), expected)


@pytest.mark.parametrize("columns", [(1,), (2,), (3,), (3, 1), (1, 1, 2)])
def test_masked_std_is_numpys_std_of_the_stacked_columns(columns):
    """The band scales' standard deviations (kernels.masked_std) have the bits of NumPy's
    std of the gathered (pixels, columns) array, whatever the columns' parts, masks,
    dtypes and counts (above NumPy's 8192-element buffer too)."""
    from imagemap.core.kernels import masked_std

    rng = np.random.default_rng(len(columns) * 10 + sum(columns))
    for shape, dtypes in [((40, 30), None), ((150, 90), None), ((7, 5), ("f8",))]:
        parts, masks, gathered = [], [], []
        picks = [rng.permutation(n + 2)[:n] for n in columns]  # alike for every image
        for image in range(3):
            image_parts = []
            for k, n in enumerate(columns):
                dtype = np.float32 if dtypes is None or k else np.float64
                array = (rng.random((*shape, n + 2)) * (k + 2) + 5 * k).astype(dtype)
                image_parts.append((array, picks[k]))
            mask = None if image == 1 else rng.random(shape) < 0.4
            parts.append(image_parts)
            masks.append(mask)
            bands = np.concatenate([a[..., c] for a, c in image_parts], axis=2)
            gathered.append(bands[mask] if mask is not None else bands.reshape(-1, sum(columns)))
        expected = np.concatenate(gathered, axis=0).std(axis=0)
        got = masked_std(parts, masks)
        assert got.dtype == expected.dtype and np.array_equal(got, expected), (shape, dtypes)


@pytest.mark.parametrize("channels", [1, 2, 3, 5])
def test_the_vote_is_the_weighted_mean_of_the_covering_windows(channels):
    """kernels.vote (three channels summed in scalars, the rest in an array): every
    covered pixel is the window-weighted mean of the estimates its windows give, in
    every channel; pixels no window covers keep their value."""
    from imagemap.core import kernels

    rng = np.random.default_rng(channels)
    k, r, (h, w) = 3, 1, (9, 11)
    exemplar = rng.random((2, 14, 15, channels)).astype(np.float32)
    weights = rng.random((k, k)).astype(np.float32)
    lookup = np.full((h, w), -1, dtype=np.int32)
    centred = rng.random((h, w)) < 0.6
    centred[3:6] = False  # no window covers the padded row 5
    centres = np.argwhere(centred)
    lookup[centres[:, 0], centres[:, 1]] = np.arange(len(centres))
    cand_e = rng.integers(0, 2, 40).astype(np.int32)
    cand_y = rng.integers(0, 12, 40).astype(np.int32)  # windows' top-left, padded bands
    cand_x = rng.integers(0, 13, 40).astype(np.int32)
    matches = rng.integers(0, 40, len(centres)).astype(np.int64)
    out = np.full((h + 2 * r, w + 2 * r, channels), -7.0, dtype=np.float32)
    kernels.vote(exemplar, weights, lookup, cand_e, cand_y, cand_x, matches, out)
    total = np.zeros(out.shape, dtype=np.float64)
    weight = np.zeros(out.shape[:2], dtype=np.float64)
    for (cy, cx), c in zip(centres, matches, strict=True):
        # The window of centre (cy, cx) covers padded pixels cy..cy+k-1, cx..cx+k-1.
        window = exemplar[cand_e[c], cand_y[c] : cand_y[c] + k, cand_x[c] : cand_x[c] + k]
        total[cy : cy + k, cx : cx + k] += weights[..., None] * window
        weight[cy : cy + k, cx : cx + k] += weights
    covered = weight > 0
    assert np.allclose(out[covered], (total[covered] / weight[covered][:, None]), rtol=1e-6)
    assert np.all(out[~covered] == -7.0) and (~covered).any()
