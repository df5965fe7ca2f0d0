"""The decoding kernels of the GNSS-only map matcher (numba; DESIGN §7, issues 14 and 21):
Viterbi and forward sums with the transitions computed on the fly, backward sums from the
weights stored, the best path. :class:`selfnav.roads.hmm.HmmMatcher` holds the model and calls
them; the model is written out in its module docstring.

Arrays are flat over all candidates of all fixes (``off``: CSR offsets per epoch); epochs are
fixes, or stationary runs of fixes matched as one.
"""
from __future__ import annotations

import numba
import numpy as np

from selfnav.roads.routes import route_gap


@numba.njit(cache=True)
def _epoch_step(t, off, seg, along, foot, res, lim, fastest, seg_u, seg_v, seg_len,
                cache_arrays, beta, backtrack, rho, s2, cut, gap, scratch, stamp, score, back,
                alpha, log_break, pb, inv_temp, pw, pi, pj, k):  # pragma: no cover - numba
    """One step of :func:`forward`, epoch ``t`` to ``t+1``: the transitions computed on the
    fly, the Viterbi scores and back-pointers and the forward sums of epoch ``t+1`` (before
    its emissions) updated, the transition weights stored from ``pw[k]`` on; returns the new
    ``k``.

    A transition's log probability is ``-(d - |foot_j - foot_i|) / β`` -- ``d`` the route
    distance between the two road points (the scalar form of
    :func:`selfnav.roads.routes.transition_route_distance`), ``|foot_j - foot_i|`` the straight
    line between them: the detour the route makes -- plus, where the error is correlated
    (``rho[t] > 0``), the log ratio of the second fix's residual given the first's to its
    residual alone (``res``: fix minus road point, NaN where not used). The end node of each
    candidate segment of epoch ``t`` is a source, the start nodes of epoch ``t+1`` the
    targets; each source's cached row (in distance order) is scanned once up to ``lim`` into a
    small source × target table. A pair more than ``cut`` below a direct route is no
    transition (it loses to a break); a source whose Viterbi score loses to a break from the
    best whatever its transition, and that adds nothing to the sums, is skipped."""
    row_of, row_start, row_len, pool_node, pool_dist = cache_arrays
    tgt_stamp, tgt_slot, src_stamp, src_slot = scratch   # node-sized, stamped, never reset
    i0, i1 = off[t], off[t + 1]
    j0, j1 = off[t + 1], off[t + 2]
    b_t = beta[t]
    bt = backtrack[t + 1]
    r_t = rho[t]
    c_r = 1.0 / (1.0 - r_t * r_t) if r_t > 0 else 0.0
    gain = 4.5 if r_t > 0 else 0.0           # the most the residual term can add (3 σ cap)
    n_tgt = 0
    for j in range(j0, j1):
        u = seg_u[seg[j]]
        if tgt_stamp[u] != stamp:
            tgt_stamp[u] = stamp
            tgt_slot[u] = n_tgt
            n_tgt += 1
    for j in range(j0, j1):
        score[j] = log_break                 # break from the best (score max is 0)
        back[j] = -1
        alpha[j] = pb                        # break: from all of epoch t (alpha sums to 1)
    la_min = np.log(1e-2 * pb)
    n_src = 0
    for i in range(i0, i1):
        s_i = score[i]
        a_i = alpha[i]
        la_i = np.log(a_i) if a_i > 0 else -np.inf
        if s_i + gain < log_break and la_i + gain < la_min:   # loses to a break, adds nothing
            continue
        si, ai = seg[i], along[i]
        rest_i = seg_len[si] - ai
        v_i = seg_v[si]
        if src_stamp[v_i] != stamp:      # scan this source's row once per epoch
            src_stamp[v_i] = stamp
            src_slot[v_i] = n_src
            for m in range(n_tgt):
                gap[n_src, m] = np.inf
            r = row_of[v_i]
            found = 0
            if r >= 0:
                for e in range(row_start[r], row_start[r] + row_len[r]):
                    if pool_dist[e] > lim[t] or found == n_tgt:
                        break
                    w = pool_node[e]
                    if tgt_stamp[w] == stamp:
                        gap[n_src, tgt_slot[w]] = pool_dist[e]
                        found += 1
            n_src += 1
        row = src_slot[v_i]
        use_r = c_r > 0 and not np.isnan(res[i, 0])
        for j in range(j0, j1):
            sj, aj = seg[j], along[j]
            if si == sj and aj >= ai:
                d = aj - ai
            else:
                d = rest_i + gap[row, tgt_slot[seg_u[sj]]] + aj
            if bt > 0:                   # backwards jitter on a slow or stopped car
                if si == sj and aj < ai:
                    db = ai - aj
                else:
                    rest = (seg_len[sj] - aj) + ai
                    db = np.inf
                    if rest <= bt and rest < d:
                        db = rest + route_gap(row_of, row_start, row_len, pool_node,
                                              pool_dist, seg_v[sj], seg_u[si], bt - rest)
                if db <= bt and db < d:
                    d = db
            if not d <= fastest[t]:
                continue
            df = np.hypot(foot[j, 0] - foot[i, 0], foot[j, 1] - foot[i, 1])
            v = -max(d - df, 0.0) / b_t
            if use_r and not np.isnan(res[j, 0]):
                ex = res[j, 0] - r_t * res[i, 0]
                ey = res[j, 1] - r_t * res[i, 1]
                v += (res[j, 0] * res[j, 0] + res[j, 1] * res[j, 1]
                      - c_r * (ex * ex + ey * ey)) / (2.0 * s2[t])
            if v < -cut:
                continue
            if s_i + v > score[j]:
                score[j] = s_i + v
                back[j] = i
            wv = np.exp(v * inv_temp)
            alpha[j] += a_i * wv
            pw[k] = wv
            pi[k] = i - i0
            pj[k] = j - j0
            k += 1
    return k


@numba.njit(cache=True)
def forward(a, b, off, seg, along, foot, em, res, forced, lim, fastest, seg_u, seg_v, seg_len,
            cache_arrays, beta, backtrack, rho, s2, log_break, cut, score, back, alpha, gap,
            scratch, stamp0, inv_temp, pw, pi, pj, pstart):  # pragma: no cover - numba
    """Viterbi (``score``, ``back``) and forward sums (``alpha``, linear, each epoch summing
    to 1) over the transitions ``a -> a+1 ... b-1 -> b`` (epoch ``a`` already done). Besides
    the road transitions, every candidate can be reached by a **break** from any candidate of
    the epoch before, with log probability ``log_break`` (the chain restarts there: a map that
    lacks a connection, a jump no road explains); ``forced[t]`` (a time gap, a new track)
    allows only the break. ``back[j] = -1`` marks a break. Scores are kept near 0 (the best of
    each epoch is subtracted).

    The sums use every log probability times ``inv_temp``; the weights ``exp(inv_temp · log
    p)`` of the road transitions are stored (``pw`` with local indices ``pi``, ``pj``; epoch
    ``t``'s from ``pstart[t - a]``) for :func:`backward`, which so needs no route look-up.
    Returns the number of weights stored."""
    pb = np.exp(log_break * inv_temp)
    k = 0
    for t in range(a, b):
        j0, j1 = off[t + 1], off[t + 2]
        pstart[t - a] = k
        em_max = -np.inf
        for j in range(j0, j1):
            em_max = max(em_max, em[j])
        if forced[t]:
            best_s = -np.inf
            tot = 0.0
            for j in range(j0, j1):
                score[j] = em[j]
                back[j] = -1
                alpha[j] = np.exp((em[j] - em_max) * inv_temp)
                tot += alpha[j]
                best_s = max(best_s, score[j])
            for j in range(j0, j1):
                score[j] -= best_s
                alpha[j] /= tot
            continue
        k = _epoch_step(t, off, seg, along, foot, res, lim, fastest, seg_u, seg_v, seg_len,
                        cache_arrays, beta, backtrack, rho, s2, cut, gap, scratch, stamp0 + t,
                        score, back, alpha, log_break, pb, inv_temp, pw, pi, pj, k)
        best_s = -np.inf
        tot = 0.0
        for j in range(j0, j1):
            score[j] += em[j]
            best_s = max(best_s, score[j])
            alpha[j] *= np.exp((em[j] - em_max) * inv_temp)
            tot += alpha[j]
        for j in range(j0, j1):      # keep scores near 0 (no drift over long tracks)
            score[j] -= best_s
            alpha[j] /= tot
    pstart[b - a] = k
    return k


@numba.njit(cache=True)
def backward(a, b, off, em, forced, log_break, bet, inv_temp, pw, pi, pj,
             pstart):  # pragma: no cover - numba
    """Backward sums (``bet``, linear, each epoch's maximum 1) over the transitions
    ``b-1 -> b ... a -> a+1`` (epoch ``b`` already done), from the weights :func:`forward`
    stored: the same model."""
    pb = np.exp(log_break * inv_temp)
    ww = np.empty(max(1, np.max(off[a + 1:b + 2] - off[a:b + 1])))
    for t in range(b - 1, a - 1, -1):
        i0, i1 = off[t], off[t + 1]
        j0, j1 = off[t + 1], off[t + 2]
        em_max = -np.inf
        for j in range(j0, j1):
            em_max = max(em_max, em[j])
        tot = 0.0
        for j in range(j0, j1):
            ww[j - j0] = np.exp((em[j] - em_max) * inv_temp) * bet[j]
            tot += ww[j - j0]
        if forced[t]:
            for i in range(i0, i1):
                bet[i] = 1.0
            continue
        for i in range(i0, i1):
            bet[i] = pb * tot
        for k in range(pstart[t - a], pstart[t - a + 1]):
            bet[i0 + pi[k]] += pw[k] * ww[pj[k]]
        mx = 0.0
        for i in range(i0, i1):
            mx = max(mx, bet[i])
        for i in range(i0, i1):
            bet[i] = bet[i] / mx if mx > 0 else 1.0


@numba.njit(cache=True)
def best_path(off, score, back):  # pragma: no cover - numba
    """Best path: from the best candidate of the last epoch (and of the epoch before each
    break) along the back-pointers."""
    n = len(off) - 1
    path = np.empty(n, np.int64)
    t = n - 1
    while t >= 0:
        b0, b1 = off[t], off[t + 1]
        k = b0
        for m in range(b0, b1):
            if score[m] > score[k]:
                k = m
        path[t] = k
        while t > 0 and back[path[t]] >= 0:
            path[t - 1] = back[path[t]]
            t -= 1
        t -= 1
    return path
