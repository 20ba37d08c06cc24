"""The seams' minimum cut in numba (core/flow.grid_cut) against PyMaxflow and scipy."""

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order, maximum_flow

from imagemap.core.flow import grid_arcs, grid_cut, grid_cut_halved, grid_graph, max_flow

maxflow = pytest.importorskip("maxflow")  # the reference (the test extra installs it)

#: Flows compared with PyMaxflow's within this relative gap: both sum float64 pushes, in
#: different orders.
FLOW_RTOL = 1e-9


def random_move(rng, height, width, density, levels=None):
    """A move's terms as :func:`imagemap.core.kernels.expansion_terms` gives them: the
    nodes of a crop (``density`` of its pixels, raster order), unary costs, and one edge
    first -> second to each right and lower neighbour node (a fifth of them 0). With
    ``levels``, every value is a multiple of 1 / levels (ties)."""
    present = rng.random((height, width)) < density
    node = np.full((height, width), -1, np.int64)
    node[present] = np.arange(present.sum())
    right = present[:, :-1] & present[:, 1:]
    down = present[:-1] & present[1:]
    # in expansion_terms' order: by first node, its lower edge then its right one
    first = np.concatenate([node[:-1][down], node[:, :-1][right]])
    second = np.concatenate([node[1:][down], node[:, 1:][right]])
    order = np.lexsort((second, first))
    first, second = first[order], second[order]
    n = len(first)
    cost0, cost1 = 3.0 * rng.random(present.sum()), 3.0 * rng.random(present.sum())
    capacity = np.where(rng.random(n) < 0.2, 0.0, 2.0 * rng.random(n))
    if levels is not None:
        cost0, cost1, capacity = (np.round(v * levels) / levels for v in (cost0, cost1, capacity))
    return node, cost0, cost1, first, second, capacity


def pymaxflow_cut(node, cost0, cost1, first, second, capacity):
    """The cut as core/seams made it with PyMaxflow (before the numba cut)."""
    graph = maxflow.Graph[float](len(cost0), len(first))
    nodes = graph.add_nodes(len(cost0))
    graph.add_edges(first, second, capacity, np.zeros_like(capacity))
    low = np.minimum(cost0, cost1)
    graph.add_grid_tedges(nodes, cost1 - low, cost0 - low)
    flow = graph.maxflow()
    return graph.get_grid_segments(nodes), flow


@pytest.mark.parametrize("levels", [None, 1, 4])  # real values; many ties; some
def test_the_cut_and_flow_are_pymaxflows_on_random_moves(levels):
    rng = np.random.default_rng(7)
    compared = 0
    for size in [(1, 1), (1, 9), (7, 1)] + [tuple(rng.integers(2, 14, 2)) for _ in range(60)]:
        move = random_move(rng, *size, density=rng.uniform(0.3, 1.0), levels=levels)
        if len(move[1]) == 0:
            continue
        expected, expected_flow = pymaxflow_cut(*move)
        takes, flow = grid_cut(*move)
        np.testing.assert_array_equal(takes, expected)
        assert flow == pytest.approx(expected_flow, rel=FLOW_RTOL, abs=1e-12)
        compared += 1
    assert compared > 50


def test_large_moves_with_long_augmenting_paths_match_pymaxflow():
    """Weak unary terms and strong edges: paths run far across the crop, and orphans are
    adopted and freed many times."""
    rng = np.random.default_rng(3)
    for levels in (None, 2):
        node, cost0, cost1, first, second, capacity = random_move(rng, 48, 40, 0.9, levels)
        cost0 *= 0.1
        cost1 *= 0.1
        expected, expected_flow = pymaxflow_cut(node, cost0, cost1, first, second, capacity)
        takes, flow = grid_cut(node, cost0, cost1, first, second, capacity)
        assert 0.05 < expected.mean() < 0.95  # a cut through the middle, not one side
        np.testing.assert_array_equal(takes, expected)
        assert flow == pytest.approx(expected_flow, rel=FLOW_RTOL)


def test_the_flow_is_scipys_maximum_flow_on_integer_capacities():
    rng = np.random.default_rng(11)
    for _ in range(20):
        node, cost0, cost1, first, second, capacity = random_move(
            rng, *rng.integers(2, 16, 2), density=0.8
        )
        cost0, cost1, capacity = (np.floor(8 * v) for v in (cost0, cost1, capacity))
        n = len(cost0)
        low = np.minimum(cost0, cost1)
        source, sink = n, n + 1
        tails = np.concatenate([first, np.full(n, source), np.arange(n)])
        heads = np.concatenate([second, np.arange(n), np.full(n, sink)])
        caps = np.concatenate([capacity, cost1 - low, cost0 - low]).astype(np.int32)
        keep = caps > 0
        graph = csr_matrix((caps[keep], (tails[keep], heads[keep])), shape=(n + 2, n + 2))
        expected = maximum_flow(graph, source, sink).flow_value
        _, flow = grid_cut(node, cost0, cost1, first, second, capacity)
        assert flow == expected


def test_of_the_minimum_cuts_the_sink_side_is_the_smallest():
    """source -> a (1), a -> b (1), b -> sink (1): cutting any one of the three arcs is a
    minimum cut; only b's arc to the sink leaves a node that reaches the sink, none."""
    node = np.array([[0, 1]])
    # a: keeping costs 0, taking 1 (an arc from the source); b: keeping costs 1 (to the sink)
    takes, flow = grid_cut(
        node, np.array([0.0, 1.0]), np.array([1.0, 0.0]), np.array([0]), np.array([1]), np.ones(1)
    )
    assert flow == 1.0
    assert takes.tolist() == [False, False]
    # with 2 to the sink b keeps reaching it, and a, through the unsaturated arc, does not
    takes, flow = grid_cut(
        node, np.array([0.0, 2.0]), np.array([1.0, 0.0]), np.array([0]), np.array([1]), np.ones(1)
    )
    assert flow == 1.0
    assert takes.tolist() == [False, True]
    # nodes without terminal arcs or edges stay on the source side
    none = np.zeros(0, np.int64)
    takes, flow = grid_cut(np.array([[0, -1, 1]]), np.ones(2), np.ones(2), none, none, np.zeros(0))
    assert flow == 0.0 and takes.tolist() == [False, False]


def test_the_cut_in_halves_is_pymaxflows_and_the_same_on_one_thread_or_two():
    """The halves' flows (on two threads or in turn), then the whole graph's: PyMaxflow's
    cut and flow where the values are exact in binary (ties decided exactly); the same
    floats with or without the second thread also where they are not (0.1 steps)."""
    rng = np.random.default_rng(13)
    with ThreadPoolExecutor(1) as beside:
        cases = [((48, 40), None, 0.125), ((48, 40), 2, 0.125), ((30, 31), 4, 1)]
        for size, levels, scale in cases:
            node, cost0, cost1, first, second, capacity = random_move(rng, *size, 0.9, levels)
            move = node, scale * cost0, scale * cost1, first, second, capacity
            expected, expected_flow = pymaxflow_cut(*move)
            takes, flow = grid_cut_halved(*move, beside)
            np.testing.assert_array_equal(takes, expected)
            assert flow == pytest.approx(expected_flow, rel=FLOW_RTOL)
        move = random_move(rng, 48, 40, 0.9, 2)
        move = (move[0], 0.1 * move[1], 0.1 * move[2]) + move[3:]
        takes, flow = grid_cut_halved(*move, beside)
        alone, flow_alone = grid_cut_halved(*move)
        np.testing.assert_array_equal(takes, alone)
        assert flow == flow_alone


def test_the_residual_graph_is_a_maximum_flows_and_the_cut_its_sink_reach():
    """max_flow's residual graph, checked arc by arc: a flow (each arc pair's capacity kept,
    no arc over its capacity, every node's inflow its outflow, the terminals not past 0),
    no path left from the source to the sink, and ``sink_side`` exactly the nodes that
    reach the sink in it (a breadth-first search of scipy's)."""
    rng = np.random.default_rng(17)
    for size, density, weak in [((48, 40), 0.9, 0.1), ((30, 31), 0.7, 1.0), ((9, 60), 1.0, 0.3)]:
        node, cost0, cost1, first, second, capacity = random_move(rng, *size, density)
        cost0, cost1 = weak * cost0, weak * cost1
        heads, capacities = grid_arcs(node, first, second, capacity)
        low = np.minimum(cost0, cost1)
        start = (cost1 - low) - (cost0 - low)
        heads, residual, terminal, pushed = grid_graph(node, cost0, cost1, first, second, capacity)
        flow, sink_side = max_flow(heads, residual, terminal)
        n = len(start)
        arcs = np.flatnonzero(heads >= 0)
        opposite = 4 * heads[arcs] + ((arcs & 3) ^ 2)
        assert (residual >= 0.0).all()
        total = capacities[arcs] + capacities[opposite]
        np.testing.assert_allclose(residual[arcs] + residual[opposite], total, atol=1e-9)
        through = capacities - residual  # the flow on each arc (< 0: against it)
        outflow = np.zeros(n)
        np.add.at(outflow, arcs >> 2, through[arcs])
        np.testing.assert_allclose(start - terminal, outflow, atol=1e-9)
        assert (terminal[start > 0] >= 0.0).all() and (terminal[start < 0] <= 0.0).all()
        from_source = (start - terminal)[start > 0].sum()
        assert flow + pushed == pytest.approx(from_source, rel=1e-12)
        assert 0.05 < sink_side.mean() < 0.95
        # Who reaches the sink: a search from it over the residual arcs reversed.
        open_arcs = arcs[residual[arcs] > 0.0]
        drains = np.flatnonzero(terminal < 0.0)
        tails = np.concatenate([heads[open_arcs], np.full(len(drains), n)])
        tips = np.concatenate([open_arcs >> 2, drains])
        reverse = csr_matrix((np.ones(len(tails)), (tails, tips)), shape=(n + 1, n + 1))
        reach = np.zeros(n + 1, bool)
        reach[breadth_first_order(reverse, n, return_predecessors=False)] = True
        np.testing.assert_array_equal(sink_side, reach[:n])
        assert not (reach[:n] & (terminal > 0.0)).any()  # no augmenting path left
