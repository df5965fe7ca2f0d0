"""Are the fixes healthy again? A sequential likelihood-ratio test on a run of fixes while the
navigator dead-reckons (DESIGN §10; issue 19).

While a fault episode is open the filter ``M`` does not take fixes; each fix's offset from it,
``o_i = fix_i − M(t_i)`` (ENU, horizontal), is the dead reckoning's error plus whatever the
fix carries. Over a run of the last seconds the evidence for each hypothesis is its marginal
likelihood, Gaussian and linear in its parameters, so in closed form:

``healthy``
    ``o_i = e + v τ_i + ½ a τ_i² + ψ (d_N, −d_E)_i + n_i`` — the dead reckoning's error now
    ``e`` and its rate ``v``, its heading error ``ψ`` turning the path ``d_i`` driven since
    ``t_i`` (a turn bends the error: a quadratic in time alone cannot follow it, and took clean
    fixes after a turn for a fault) — prior: ``M``'s covariance of the five —, an acceleration
    error ``a`` (prior: what ``P`` admits,
    :meth:`~selfnav.ins.ekf.InsGnssFilter.acceleration_sigma`), the velocity random walk over
    the run, and the fixes' own white noise ``n_i`` (their σ);
``white`` (σ ``s``)
    healthy, plus white errors of σ ``s`` — outliers;
``Gauss–Markov`` (σ ``s``, correlation time ``τ``)
    healthy, plus a correlated error ``s² e^{−|Δt|/τ}`` — multipath, a wandering receiver;
``ramp`` (rate σ ``r``)
    healthy, plus a rate of its own and the offset that rate built since the fault began — a
    drag;
``drift`` (rate σ ``r``)
    a ramp whose rate changes over ``fault_ramp_change_s`` (an acceleration of σ ``r`` over
    it) and wanders as a random walk of density ``r²/fault_ramp_change_s`` (its rate moves by
    about ``r`` over that time): the offsets an integrated random walk about the ramp,
    covariance ``q (m² M / 2 − m³ / 6)`` between fixes ``m ≤ M`` s before now — a receiver
    drifting off smoothly (a critically damped second-order Gauss–Markov error, whose rate
    is such a walk over seconds). Without it the curvature of such a drift was left to
    ``lost``, and drive_0708 restarted on the drifting fixes, 500 m off; with a wander about
    the quadratic of the fault floor (1 m, correlated over 10 s) in its place, the wander's
    own cost at an RTK fix's 0.1 m (tens of nats) gave ``lost`` the run again: drive_0708
    with a drift of σ 50 m (its velocities clean) was restarted on it and ran 53 m off for
    minutes after it;
``lost``
    the fixes healthy, the dead reckoning off by much more than ``P`` says (offset σ
    ``lost_m``, rate σ ``lost_mps`` added to its prior): the INS, not the GNSS, failed.

The faults are families (grids of ``s``, ``τ``, ``r`` in :class:`selfnav.ins.config.Integrity`),
each member with an equal share of the family's prior. The log Bayes factor of ``healthy``
against the faults grows with every clean fix and falls with every faulty one; a run is
accepted once it passes ``ln(1/α)``, α the configured false-alarm probability. Where a
receiver's error wanders slowly (a Gauss–Markov error of 200 m over a minute moves ~50 m a
second), a few fixes cannot tell it from a clean run whose dead reckoning is 90 m wide: the
likelihoods say so, and the test waits for more fixes instead of taking them back after five
(the run test it replaces did: a simulated drive followed such a window 400 m off).
"""
from __future__ import annotations

import math

import numpy as np

_LOG2PI = math.log(2.0 * math.pi)


def _loglik(o, C) -> float:
    """log N(o; 0, C) (``o`` flattened), −inf where ``C`` is not positive definite."""
    try:
        L = np.linalg.cholesky(C)
    except np.linalg.LinAlgError:
        return -np.inf
    z = np.linalg.solve(L, o)
    return float(-0.5 * (z @ z) - np.sum(np.log(np.diag(L))) - 0.5 * len(o) * _LOG2PI)


def _logmeanexp(x) -> float:
    x = np.asarray(x, float)
    m = float(np.max(x))
    if not np.isfinite(m):
        return m
    return m + math.log(float(np.mean(np.exp(x - m))))


def run_evidence(tt, o, sigma, p_ins, P_rvh, acc_sigma, q_v, ig, *, fix_sigma: float,
                 fault_age: float = 0.0, max_fixes: int = 30) -> dict:
    """Log marginal likelihoods of a run of offsets under each hypothesis (module docstring).

    Parameters
    ----------
    tt : (n,) s, the fixes' times (the last is "now")
    o : (n, 2) m, ENU offsets fix − M
    sigma : (n,) m, each fix's σ per axis
    p_ins : (n, 2) m, ENU positions of ``M`` at the fixes' times (any origin)
    P_rvh : (5, 5) M's covariance of (δr_E, δr_N, δv_E, δv_N, ψ_U) now
    acc_sigma : m/s², the horizontal acceleration error σ ``P`` admits
    q_v : (m/s)²/s, the velocity random-walk density (the wander over the run)
    ig : :class:`selfnav.ins.config.Integrity` (the fault families, ``lost_m``, ``lost_mps``)
    fix_sigma : m, the fixes' σ the white and Gauss–Markov families scale with (a fault is an
        error several times the receiver's own)
    fault_age : s since the fault began (the episode's start): a drag's offset is its rate
        times that
    max_fixes : the run is thinned evenly to at most this many fixes (cost)

    Returns
    -------
    dict with ``healthy``, ``fault`` (the faults' mixture), ``scattered`` (white and
    Gauss–Markov), ``ramp`` (the drags), ``lost``, ``fault_variance`` and ``each`` (every
    fault model's value, for the reasons).
    """
    tt = np.asarray(tt, float)
    o = np.asarray(o, float)
    sigma = np.asarray(sigma, float)
    n = len(tt)
    if n > max_fixes:
        keep = np.unique(np.round(np.linspace(0, n - 1, max_fixes)).astype(int))
        tt, o, sigma, p_ins = tt[keep], o[keep], sigma[keep], np.asarray(p_ins)[keep]
        n = len(tt)
    tau = tt - tt[-1]
    # design: per fix, rows (E, N); parameters (e_E, e_N, v_E, v_N, ψ_U, a_E, a_N)
    d = np.asarray(p_ins, float) - np.asarray(p_ins, float)[-1]
    A = np.zeros((2 * n, 7))
    for ax in range(2):
        A[ax::2, ax] = 1.0
        A[ax::2, 2 + ax] = tau
        A[ax::2, 5 + ax] = 0.5 * tau * tau
    A[0::2, 4] = d[:, 1]
    A[1::2, 4] = -d[:, 0]
    S = np.zeros((7, 7))
    S[:5, :5] = 0.5 * (P_rvh + P_rvh.T)
    S[5, 5] = S[6, 6] = acc_sigma ** 2
    noise = np.repeat(sigma ** 2 + q_v * np.abs(tau) ** 3 / 3.0, 2)
    C0 = A @ S @ A.T + np.diag(noise)
    y = o.reshape(-1)
    out = {"healthy": _loglik(y, C0)}
    dtm = np.abs(tau[:, None] - tau[None, :])
    I2 = np.eye(2)
    each = {}
    # each member's variance a fused fix would have to carry to be honest under it: an error
    # common to the run's fixes counts once per fix it is common to (N fixes tell no more of
    # an offset they share than one): white 1×, Gauss–Markov N / (1 + span / τ), a ramp N×
    span = float(tau[-1] - tau[0]) if n > 1 else 0.0
    carry = {}
    for k in ig.fault_white_sigmas:
        s = k * fix_sigma
        each[f"white {s:.3g} m"] = _loglik(y, C0 + np.eye(2 * n) * s * s)
        carry[f"white {s:.3g} m"] = s * s
    for k in ig.fault_gm_sigmas:
        s = k * fix_sigma
        for tc in ig.fault_gm_s:
            each[f"Gauss–Markov {s:.3g} m / {tc:g} s"] = _loglik(
                y, C0 + np.kron(s * s * np.exp(-dtm / tc), I2))
            carry[f"Gauss–Markov {s:.3g} m / {tc:g} s"] = s * s * n / (1.0 + span / tc)
    age = max(float(fault_age), ig.fault_ramp_onset_s)
    # a drift is a drag that is smooth, not straight: its rate changes over
    # ``fault_ramp_change_s`` — a random walk of the rate, so the offsets walk about the ramp
    # as an integrated random walk back from now (a straight ramp left a second-order drift's
    # curvature to the INS-lost hypothesis)
    back = np.abs(tau)
    near, far = np.minimum.outer(back, back), np.maximum.outer(back, back)
    walk = near * near * far / 2.0 - near ** 3 / 6.0
    for r in ig.fault_ramp_mps:
        Sr = np.diag([r * age] * 2 + [r] * 2) ** 2
        each[f"ramp {r:g} m/s"] = _loglik(y, C0 + A[:, :4] @ Sr @ A[:, :4].T)
        carry[f"ramp {r:g} m/s"] = (r * ig.fault_ramp_onset_s) ** 2 * n
        Sd = np.diag([r * age] * 2 + [r] * 2 + [0.0] + [r / ig.fault_ramp_change_s] * 2) ** 2
        q = r * r / ig.fault_ramp_change_s
        each[f"drift {r:g} m/s"] = _loglik(y, C0 + A @ Sd @ A.T + np.kron(q * walk, I2))
        carry[f"drift {r:g} m/s"] = (r * ig.fault_ramp_onset_s) ** 2 * n
    fam = {}
    for k, v in each.items():
        fam.setdefault(k.split(" ")[0], []).append(k)
    logprior = {k: -math.log(len(fam)) - math.log(len(ks)) for ks in fam.values() for k in ks}
    lw = np.array([each[k] + logprior[k] for k in each])
    out["fault"] = float(np.max(lw) + math.log(np.sum(np.exp(lw - np.max(lw)))))
    ks = [k for f in ("white", "Gauss–Markov") for k in fam.get(f, [])]
    out["scattered"] = _logmeanexp([each[k] for k in ks]) if ks else -np.inf
    # the drags: the straight or the smooth, whichever explains the run better
    out["ramp"] = max(_logmeanexp([each[k] for k in fam[f]]) if fam.get(f) else -np.inf
                      for f in ("ramp", "drift"))
    # the variance the faults that still explain the run ask a fused fix to carry (their
    # posterior within the family mixture)
    w = np.exp(lw - out["fault"])
    out["fault_variance"] = float(sum(wk * carry[k] for wk, k in zip(w, each)))
    SL = S.copy()
    SL[:4, :4] += np.diag([ig.lost_m ** 2] * 2 + [ig.lost_mps ** 2] * 2)
    SL[4, 4] += ig.lost_rad ** 2
    SL[5, 5] += ig.lost_mps2 ** 2
    SL[6, 6] += ig.lost_mps2 ** 2
    out["lost"] = _loglik(y, A @ SL @ A.T + np.diag(noise))
    out["each"] = each
    return out


def strongest_fault(ev) -> str:
    """The name of the fault model that explains the run best."""
    return max(ev["each"], key=ev["each"].get) if ev["each"] else "none"


__all__ = ["run_evidence", "strongest_fault"]
