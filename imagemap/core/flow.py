"""A minimum cut of a move's grid graph, in numba: :func:`grid_cut` (and
:func:`grid_cut_halved`, its halves on two threads).

One module for one job: the maximum flow / minimum cut of the alpha-expansion moves of
:mod:`imagemap.core.seams` (Boykov & Kolmogorov 2004, "An experimental comparison of
min-cut/max-flow algorithms for energy minimization in vision"), written for their graphs:
the free pixels of a crop, each joined to its four neighbours. It runs without the GIL.

The graph: node p's arcs are numbered 4 p + d, d = 0 right, 1 down, 2 left, 3 up (the
order in which they are searched); the arc opposite to 4 p + d is 4 q + (d ^ 2), q its
head. Each node's terminal capacity is one number, ``terminal``: > 0 from the source,
< 0 to the sink (only their difference matters to the cut). The cut: the nodes that can
still reach the sink in the residual graph after a maximum flow are on the sink side, all
others on the source side. That set is the same for every maximum flow (it is the
smallest sink side of a minimum cut), and it is the one PyMaxflow's ``get_grid_segments``
gives (True: sink side). The arithmetic is float64, as PyMaxflow's ``Graph[float]``; the
flows are pushed in another order than PyMaxflow's, so the flow may differ from its in the
last bits, and where two cuts cost the same (a tie that exact arithmetic would leave a
residual capacity of exactly 0 at) rounding may pick the other one, of the same cost up
to rounding: not seen on the seams' moves (every cut of the 512^2 and 200x150 dumps is
PyMaxflow's), seen on random moves whose ties are inexact sums (0.1 steps).
"""

from __future__ import annotations

import numpy as np
from numba import njit

# The kernels' index type: every index of max_flow's arrays is >= 0, and numba checks a
# signed index for a negative value to wrap around, not an unsigned one (0.85x the flow's
# CPU on the 512^2 moves).
from imagemap.core.kernels import _U

__all__ = ["grid_cut", "grid_cut_halved"]

#: ``parent`` values besides a node number: in no tree, a tree's root (joined to its
#: terminal), and an orphan (cut off from its tree during an augmentation).
_FREE = -1
_ROOT = -2
_ORPHAN = -3
#: Distance of a node from its terminal when that is not known (larger than any path).
_FAR = 1 << 30
#: A node's flags in ``info``: in the sink's tree (else the source's, if in one), and in
#: the queue of active nodes.
_SINK = 1
_QUEUED = 2
#: The flags' bits from this one up: the direction d of the node's arc to its parent (the
#: arc 4 p + d). Kept beside the parent's number, so that a walk up a tree reads one field
#: a step (the parent) instead of the arc and then its head: 0.87x the flow's CPU.
_TURN = 2
#: The augmentations' time stamps are int32: past this many, every stamp is set back to 0
#: (they only mark which distances are of the current augmentation).
_STAMP_LIMIT = (1 << 31) - 2


@njit(cache=True, nogil=True)
def grid_arcs(node, first, second, capacity):
    """The arcs of a move's graph: each node's four neighbours (``heads``, (4 n,) int32,
    -1: none) and residual capacities (``residual``, (4 n,) float64), from the crop's node
    map ``node`` ((h, w), -1: no node; numbered in raster order) and the edges first ->
    second of ``capacity`` (each between 4-neighbours; the reverse arc 0)."""
    h, w = node.shape
    n = 0
    for i in range(h):
        for j in range(w):
            if node[i, j] >= 0:
                n += 1
    heads = np.full(4 * n, -1, np.int32)
    residual = np.zeros(4 * n)
    for i in range(h):
        for j in range(w):
            p = node[i, j]
            if p < 0:
                continue
            if j + 1 < w:
                heads[4 * p] = node[i, j + 1]
            if i + 1 < h:
                heads[4 * p + 1] = node[i + 1, j]
            if j > 0:
                heads[4 * p + 2] = node[i, j - 1]
            if i > 0:
                heads[4 * p + 3] = node[i - 1, j]
    for m in range(len(first)):
        p, q = first[m], second[m]
        for d in range(4):
            if heads[4 * p + d] == q:
                residual[4 * p + d] += capacity[m]
                break
    return heads, residual


@njit(cache=True, nogil=True)
def _push_neighbours(heads, residual, terminal):
    """The paths source -> p -> q -> sink of one arc, each pushed once (nodes in order),
    in place: a flow to start from, which the trees' search would find one augmentation
    (and one orphan) at a time. The maximum flow, and so the cut, is the same. Returns
    the flow pushed."""
    total = 0.0
    for p in range(len(terminal)):
        if terminal[p] <= 0.0:
            continue
        for d in range(4):
            a = 4 * p + d
            q = heads[a]
            if q < 0 or terminal[q] >= 0.0 or residual[a] <= 0.0:
                continue
            pushed = min(terminal[p], residual[a], -terminal[q])
            terminal[p] -= pushed
            terminal[q] += pushed
            residual[a] -= pushed
            residual[4 * q + (d ^ 2)] += pushed
            total += pushed
            if terminal[p] == 0.0:
                break
    return total


@njit(cache=True, nogil=True, inline="always")
def _origin(start, info, now):
    """The number of arcs from ``start`` up its tree to its terminal, or ``_FAR`` where the
    path ends at an orphan; the nodes on a path found are stamped ``now`` with their
    distances (a later walk stops at them)."""
    steps = 0
    j = start
    while True:
        if info[_U(4 * j + 1)] == now:
            steps += info[_U(4 * j + 2)]
            break
        parent = info[_U(4 * j)]
        steps += 1
        if parent == _ROOT:
            info[_U(4 * j + 1)] = now
            info[_U(4 * j + 2)] = 1
            break
        if parent < 0:
            return _FAR
        j = parent
    d = steps
    j = start
    while info[_U(4 * j + 1)] != now:
        info[_U(4 * j + 1)] = now
        info[_U(4 * j + 2)] = d
        d -= 1
        j = info[_U(4 * j)]
    return steps


@njit(cache=True, nogil=True, inline="always")
def _orphan(info, orphans, n_orphans, node):
    """Cut ``node`` off from its tree (its arc to its parent, or its terminal's, saturated)
    and list it as the ``n_orphans``-th orphan of the augmentation; the new count."""
    info[_U(4 * node)] = _ORPHAN
    orphans[_U(n_orphans)] = node
    return n_orphans + 1


@njit(cache=True, nogil=True)
def max_flow(heads, residual, terminal):
    """Boykov & Kolmogorov's maximum flow on the arcs of :func:`grid_arcs`, in place:
    ``residual`` and ``terminal`` (> 0: residual capacity from the source, < 0: to the
    sink) become the residual graph's. Returns the flow and ``sink_side``, (n,) bool: the
    nodes that can still reach the sink.

    Two search trees grow from the terminals over arcs with residual capacity (active
    nodes taken first in, first out; a node that joined the trees is searched again at
    once; a node already in the tree keeps its parent: BK's reparenting of a node found
    nearer its root was dropped, as many augmentations and orphans to within 1 % and 5 %
    fewer CPU seconds, docs/performance.md); where they meet, the path's bottleneck is
    pushed through it (its arcs kept as found, not looked up again on the way back); the
    nodes whose arc to their parent saturated (orphans, the ones nearest the terminals
    first) take the neighbour of their tree whose path reaches the terminal in the fewest
    arcs (distances kept per augmentation by a time stamp), or leave the tree, orphaning
    their children. No active node left: the sink's tree is every node that reaches the sink.
    A node's parent (its number), stamp, distance and flags (with the direction of its arc
    to the parent) are side by side in ``info`` (4 int32 a node: one cache line holds four
    nodes').
    """
    n = len(terminal)
    info = np.zeros(4 * n, np.int32)  # parent node, time stamp, distance, flags
    queue = np.empty(n + 1, np.int32)  # a ring: each node in it at most once
    head = 0
    tail = 0
    for p in range(n):
        if terminal[_U(p)] != 0.0:
            info[_U(4 * p)] = _ROOT
            info[_U(4 * p + 2)] = 1
            info[_U(4 * p + 3)] = (_SINK if terminal[_U(p)] < 0.0 else 0) | _QUEUED
            queue[_U(tail)] = p
            tail += 1
        else:
            info[_U(4 * p)] = _FREE
    orphans = np.empty(n + 1, np.int32)  # a ring as well: each node an orphan once at a time
    path = np.empty(n + 1, np.int32)  # the augmenting path's arcs, as found: walked twice
    now = 0
    flow = 0.0
    current = -1
    while True:
        if current < 0:
            if head == tail:
                break
            i = queue[_U(head)]
            head = head + 1 if head < n else 0
            info[_U(4 * i + 3)] &= ~_QUEUED
            if info[_U(4 * i)] == _FREE:
                continue
        else:
            i = current
        current = -1
        # Growth: the first arc that joins i's tree to the other one.
        meet = -1  # the arc from the source tree's node to the sink tree's
        ts_i = info[_U(4 * i + 1)]
        d_i = info[_U(4 * i + 2)]
        if not (info[_U(4 * i + 3)] & _SINK):
            for d in range(4):
                a = 4 * i + d
                j = heads[_U(a)]
                if j < 0 or residual[_U(a)] <= 0.0:
                    continue
                pj = info[_U(4 * j)]
                fj = info[_U(4 * j + 3)]
                if pj == _FREE:
                    info[_U(4 * j)] = i
                    info[_U(4 * j + 1)] = ts_i
                    info[_U(4 * j + 2)] = d_i + 1
                    info[_U(4 * j + 3)] = _QUEUED | ((d ^ 2) << _TURN)
                    if not (fj & _QUEUED):
                        queue[_U(tail)] = j
                        tail = tail + 1 if tail < n else 0
                elif fj & _SINK:
                    meet = a
                    break
        else:
            for d in range(4):
                a = 4 * i + d
                j = heads[_U(a)]
                if j < 0:
                    continue
                back = 4 * j + (d ^ 2)
                if residual[_U(back)] <= 0.0:
                    continue
                pj = info[_U(4 * j)]
                fj = info[_U(4 * j + 3)]
                if pj == _FREE:
                    info[_U(4 * j)] = i
                    info[_U(4 * j + 1)] = ts_i
                    info[_U(4 * j + 2)] = d_i + 1
                    info[_U(4 * j + 3)] = _SINK | _QUEUED | ((d ^ 2) << _TURN)
                    if not (fj & _QUEUED):
                        queue[_U(tail)] = j
                        tail = tail + 1 if tail < n else 0
                elif not (fj & _SINK):
                    meet = back
                    break
        if meet < 0:
            continue
        current = i  # it may join the trees again: searched once more, first
        now += 1
        if now == _STAMP_LIMIT:
            for p in range(n):
                info[_U(4 * p + 1)] = 0
            now = 1
        # Augmentation: the bottleneck of source -> root ... meet ... root -> sink.
        t = heads[_U(meet)]
        s = meet >> 2  # the arc's own node
        bottleneck = residual[_U(meet)]
        n_source = 0
        j = s
        while info[_U(4 * j)] != _ROOT:
            parent = info[_U(4 * j)]
            turn = (info[_U(4 * j + 3)] >> _TURN) & 3
            back = 4 * parent + (turn ^ 2)
            path[_U(n_source)] = 4 * j + turn
            n_source += 1
            if residual[_U(back)] < bottleneck:
                bottleneck = residual[_U(back)]
            j = parent
        root_s = j
        if terminal[_U(j)] < bottleneck:
            bottleneck = terminal[_U(j)]
        n_sink = n_source
        j = t
        while info[_U(4 * j)] != _ROOT:
            a = 4 * j + ((info[_U(4 * j + 3)] >> _TURN) & 3)
            path[_U(n_sink)] = a
            n_sink += 1
            if residual[_U(a)] < bottleneck:
                bottleneck = residual[_U(a)]
            j = info[_U(4 * j)]
        root_t = j
        if -terminal[_U(j)] < bottleneck:
            bottleneck = -terminal[_U(j)]
        residual[_U(meet)] -= bottleneck
        residual[_U(4 * t + ((meet & 3) ^ 2))] += bottleneck
        n_orphans = 0
        for k in range(n_source):
            a = path[_U(k)]
            back = 4 * heads[_U(a)] + ((a & 3) ^ 2)
            residual[_U(a)] += bottleneck
            residual[_U(back)] -= bottleneck
            if residual[_U(back)] == 0.0:
                n_orphans = _orphan(info, orphans, n_orphans, a >> 2)
        terminal[_U(root_s)] -= bottleneck
        if terminal[_U(root_s)] == 0.0:
            n_orphans = _orphan(info, orphans, n_orphans, root_s)
        for k in range(n_source, n_sink):
            a = path[_U(k)]
            back = 4 * heads[_U(a)] + ((a & 3) ^ 2)
            residual[_U(back)] += bottleneck
            residual[_U(a)] -= bottleneck
            if residual[_U(a)] == 0.0:
                n_orphans = _orphan(info, orphans, n_orphans, a >> 2)
        terminal[_U(root_t)] += bottleneck
        if terminal[_U(root_t)] == 0.0:
            n_orphans = _orphan(info, orphans, n_orphans, root_t)
        flow += bottleneck
        # Adoption, the orphans nearest the terminals first (a child's old parent may
        # then be back in the tree when the child looks for one).
        for k in range(n_orphans // 2):
            tmp = orphans[_U(k)]
            orphans[_U(k)] = orphans[_U(n_orphans - 1 - k)]
            orphans[_U(n_orphans - 1 - k)] = tmp
        first = 0
        last = n_orphans  # orphans[first:last], as a ring of n + 1
        while first != last:
            o = orphans[_U(first)]
            first = first + 1 if first < n else 0
            in_sink = info[_U(4 * o + 3)] & _SINK
            best = -1
            best_distance = _FAR
            for d in range(4):
                a = 4 * o + d
                j = heads[_U(a)]
                if j < 0:
                    continue
                if in_sink:
                    if residual[_U(a)] <= 0.0:
                        continue
                elif residual[_U(4 * j + (d ^ 2))] <= 0.0:
                    continue
                if info[_U(4 * j)] == _FREE or (info[_U(4 * j + 3)] & _SINK) != in_sink:
                    continue
                steps = _origin(j, info, now)
                if steps < best_distance:
                    best = a
                    best_distance = steps
            if best >= 0:
                info[_U(4 * o)] = heads[_U(best)]
                info[_U(4 * o + 3)] = (info[_U(4 * o + 3)] & (_SINK | _QUEUED)) | (
                    (best & 3) << _TURN
                )
                info[_U(4 * o + 1)] = now
                info[_U(4 * o + 2)] = best_distance + 1
                continue
            info[_U(4 * o)] = _FREE
            for d in range(4):
                a = 4 * o + d
                j = heads[_U(a)]
                if j < 0:
                    continue
                pj = info[_U(4 * j)]
                fj = info[_U(4 * j + 3)]
                if pj == _FREE or (fj & _SINK) != in_sink:
                    continue
                reaches = residual[_U(a)] > 0.0 if in_sink else residual[_U(4 * j + (d ^ 2))] > 0.0
                if reaches and not (fj & _QUEUED):
                    info[_U(4 * j + 3)] = fj | _QUEUED
                    queue[_U(tail)] = j
                    tail = tail + 1 if tail < n else 0
                if pj == o:
                    info[_U(4 * j)] = _ORPHAN
                    orphans[_U(last)] = j
                    last = last + 1 if last < n else 0
        if info[_U(4 * i)] == _FREE:
            current = -1
    sink_side = np.zeros(n, np.bool_)
    for p in range(n):
        sink_side[_U(p)] = (info[_U(4 * p + 3)] & _SINK) != 0 and info[_U(4 * p)] != _FREE
    return flow, sink_side


@njit(cache=True, nogil=True)
def grid_graph(node, cost0, cost1, first, second, capacity):
    """A move's graph for :func:`max_flow`: its arcs (:func:`grid_arcs`), each node's
    terminal capacity (cost1 - low from the source, cost0 - low to the sink, ``low`` the
    smaller cost) and the flow already pushed on the paths of one arc
    (:func:`_push_neighbours`)."""
    heads, residual = grid_arcs(node, first, second, capacity)
    n = len(cost0)
    terminal = np.empty(n)
    for p in range(n):
        low = min(cost0[p], cost1[p])
        terminal[p] = (cost1[p] - low) - (cost0[p] - low)
    pushed = _push_neighbours(heads, residual, terminal)
    return heads, residual, terminal, pushed


def grid_cut(node, cost0, cost1, first, second, capacity):
    """The minimum cut of one alpha-expansion move (the terms of
    :func:`imagemap.core.kernels.expansion_terms`): whether each node takes alpha (pays
    ``cost1`` rather than ``cost0``; edges first -> second of ``capacity``, paid when
    first keeps its label and second takes it), and the flow (the cut's cost less the
    sum of the nodes' smaller unary costs). The nodes on the cut's sink side take alpha,
    as with PyMaxflow's ``add_grid_tedges(nodes, cost1 - low, cost0 - low)``,
    ``maxflow()`` and ``get_grid_segments``, ``low`` the smaller of the two costs.

    Not a kernel of its own: it calls :func:`grid_graph` and :func:`max_flow` (both
    without the GIL), which the halved moves call too, so a fresh process loads two
    kernels from numba's cache where a compiled ``grid_cut``, with its own copies of both,
    made it load three (about 12 ms, docs/performance.md).
    """
    heads, residual, terminal, pushed = grid_graph(node, cost0, cost1, first, second, capacity)
    flow, takes = max_flow(heads, residual, terminal)
    return takes, flow + pushed


def _halves(heads, middle):
    """The arcs of the nodes before ``middle`` and of those from it (numbered from 0),
    each half's arcs into the other left out (-1). NumPy, not a kernel: one fewer for a
    fresh process to load from numba's cache (about 5 ms)."""
    before = heads[: 4 * middle].copy()
    before[before >= middle] = -1
    after = heads[4 * middle :] - np.int32(middle)  # into the first half, or none: < 0
    after[after < 0] = -1
    return before, after


def grid_cut_halved(node, cost0, cost1, first, second, capacity, beside=None):
    """:func:`grid_cut` in three parts: the maximum flows of the first half of the nodes
    (rows above the crop's middle; on ``beside``'s thread, an executor, if given) and of
    the second (on this one), each within its half (the arcs between the halves left out;
    the halves' arrays are disjoint), then the maximum flow of the whole graph from the
    sum of theirs (a flow of the whole graph: only paths across the middle are left to
    find). A maximum flow found from any flow is a maximum flow, and the cut, the nodes
    that reach the sink after it, is the same; up to rounding: where two cuts cost the
    same, float64 rounding may decide between them, as with any other order of pushes
    (:mod:`imagemap.core.flow`). The same floats with or without ``beside``.

    ``beside`` must not be the thread calling this (it would wait on itself).
    """
    heads, residual, terminal, pushed = grid_graph(node, cost0, cost1, first, second, capacity)
    middle = len(terminal) // 2
    before, after = _halves(heads, middle)
    parts = (before, residual[: 4 * middle], terminal[:middle])
    first_half = None if beside is None else beside.submit(max_flow, *parts)
    flow_after, _ = max_flow(after, residual[4 * middle :], terminal[middle:])
    flow_before, _ = max_flow(*parts) if first_half is None else first_half.result()
    flow, takes = max_flow(heads, residual, terminal)
    return takes, flow + flow_before + flow_after + pushed
