"""Snapping the dead ends of unjoined OpenStreetMap ways to the road they touch (issue 21).

Maps as users have them hold ways that do not share a node where they meet: drawn to touch, a
metre or two apart. :func:`snap_dead_ends` joins them for map matching
(:func:`selfnav.roads.graph.read_match_roads`).
"""
from __future__ import annotations

import numpy as np


def snap_dead_ends(xy, su, sv, sw, snap_m):
    """Join the dead ends of unjoined ways to the road they touch (OpenStreetMap ways that do not
    share a node where they meet).

    A *dead end* is a node with a single neighbour. Each dead end within ``snap_m`` of a node of
    another way is merged into the nearest such node; else, within ``snap_m`` of a segment of
    another way, that segment is split at the foot point and the dead end merged there. Only
    ends are snapped: two ways that cross without a shared node (a bridge) stay apart.

    Parameters
    ----------
    xy : (N, 2) node positions, m
    su, sv, sw : (M,) directed segments (node indices) and their way ids

    Returns
    -------
    xy : (N', 2) node positions (split points appended)
    su, sv, sw : the segments after snapping (merged ends relabelled, split segments replaced by
        their two halves)
    n_snapped : int
        Dead ends joined.
    new_nodes : int
        Split points added (appended at the end of ``xy``).
    """
    import shapely

    n = len(xy)
    und = np.unique(np.sort(np.column_stack([su, sv]), axis=1), axis=0)
    deg = np.bincount(und.ravel(), minlength=n)
    ends = np.flatnonzero(deg == 1)
    if snap_m <= 0 or not len(ends):
        return xy, su, sv, sw, 0, 0
    # the ways of each node (a node may belong to several)
    node_way = {}
    for u, v, w in zip(su.tolist(), sv.tolist(), sw.tolist()):
        node_way.setdefault(u, set()).add(w)
        node_way.setdefault(v, set()).add(w)
    kd = shapely.STRtree(shapely.points(xy))
    rep = np.arange(n)
    # undirected segments (one per node pair) for the split search, near each end
    a, b = xy[und[:, 0]], xy[und[:, 1]]
    tree = shapely.STRtree(shapely.linestrings(np.stack([a, b], axis=1)))
    q_end, q_seg = tree.query(shapely.points(xy[ends]), predicate="dwithin", distance=snap_m)
    seg_near = {}
    for qe, qs in zip(q_end.tolist(), q_seg.tolist()):
        seg_near.setdefault(int(ends[qe]), []).append(qs)
    splits = {}                                  # undirected segment -> [(along, end node)]
    n_snapped = 0
    def root(m):
        while rep[m] != m:
            m = rep[m]
        return m

    def nearest_node(e):
        ways_e = node_way.get(e, set())
        best, best_d = -1, np.inf
        for m in kd.query(shapely.points(xy[e]), predicate="dwithin", distance=snap_m).tolist():
            if m == e or node_way.get(m, set()) & ways_e:
                continue
            d = float(np.hypot(*(xy[m] - xy[e])))
            if d < best_d:
                best, best_d = m, d
        return best, best_d

    # the closest pairs first: an end joins the node it nearly touches, not a farther one
    first = sorted(ends.tolist(), key=lambda e: nearest_node(e)[1])
    for e in first:
        ways_e = node_way.get(e, set())
        best, _ = nearest_node(e)
        if best >= 0 and root(best) != root(e):
            rep[root(e)] = root(best)
            n_snapped += 1
            continue
        if best >= 0:                           # already joined to it through another end
            continue
        # the nearest segment of another way
        near = np.asarray([k for k in seg_near.get(e, []) if not (
            (node_way.get(int(und[k, 0]), set()) & node_way.get(int(und[k, 1]), set()))
            & ways_e)], np.int64)
        if not len(near):
            continue
        lines = tree.geometries[near]
        pt = shapely.points(xy[e])
        s = shapely.line_locate_point(lines, pt)
        d = shapely.distance(lines, pt)
        k = int(np.argmin(d))
        if d[k] > snap_m:
            continue
        L = float(np.hypot(*(b[near[k]] - a[near[k]])))
        if s[k] < 1e-3 or s[k] > L - 1e-3:      # at a node of that way
            m = int(und[near[k], 0] if s[k] < 1e-3 else und[near[k], 1])
            if root(m) != root(e):
                rep[root(e)] = root(m)
                n_snapped += 1
            continue
        splits.setdefault(int(near[k]), []).append((float(s[k]), e))
        n_snapped += 1
    new_xy = [xy]
    extra = 0
    pair_split = {}                              # (u, v) of the original pair -> node chain
    for k, lst in splits.items():
        u, v = int(und[k, 0]), int(und[k, 1])
        lst.sort()
        chain = [u]
        for s_k, e in lst:
            p = a[k] + (b[k] - a[k]) * (s_k / max(np.hypot(*(b[k] - a[k])), 1e-9))
            idx = n + extra
            extra += 1
            new_xy.append(p[None])
            rep = np.append(rep, idx)
            rep[e] = idx
            chain.append(idx)
        chain.append(v)
        pair_split[(u, v)] = chain
    for _ in range(8):                           # resolve chains of merges
        nxt = rep[rep]
        if np.array_equal(nxt, rep):
            break
        rep = nxt
    out_u, out_v, out_w = [], [], []
    for u, v, w in zip(su.tolist(), sv.tolist(), sw.tolist()):
        key = (min(u, v), max(u, v))
        chain = pair_split.get(key)
        if chain is None:
            out_u.append(u), out_v.append(v), out_w.append(w)
            continue
        c = chain if u == key[0] else chain[::-1]
        for p, q in zip(c[:-1], c[1:]):
            out_u.append(p), out_v.append(q), out_w.append(w)
    su2 = rep[np.asarray(out_u, np.int64)]
    sv2 = rep[np.asarray(out_v, np.int64)]
    sw2 = np.asarray(out_w, np.int64)
    ok = su2 != sv2
    return np.concatenate(new_xy), su2[ok], sv2[ok], sw2[ok], n_snapped, extra
