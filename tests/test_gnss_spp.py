"""Single-point positioning (selfnav.gnss.spp) and the smartLoc readers (selfnav.io.smartloc)."""
import time

import numpy as np
import pytest

from selfnav.earth import geodetic_to_ecef
from selfnav.errors import InputError
from selfnav.io.smartloc import find_smartloc_files, read_smartloc_input, read_smartloc_truth
from selfnav.earth import enu_rotation
from selfnav.gnss.spp import (C_LIGHT, OMEGA_EARTH, SppConfig, horizontal_error,
                         sagnac_rotate, solve_spp, spp_from_pseudoranges)

LAT0, LON0, H0 = np.radians(52.5046), np.radians(13.3737), 40.0
RX = geodetic_to_ecef(LAT0, LON0, H0)
CLK = {1: 1.2e5, 4: 1.2e5 + 37.0, 8: -3.0e4}


def satellites(n_gps=7, n_glo=4, n_gal=0, seed=0, min_el=15.0):
    """Satellites above the receiver: (ECEF at transmit time, system, elevation)."""
    rng = np.random.default_rng(seed)
    C = enu_rotation(LAT0, LON0)
    sats, syss, els = [], [], []
    for sys_code, n, radius in ((1, n_gps, 26_560e3), (4, n_glo, 25_510e3), (8, n_gal, 29_600e3)):
        for _ in range(n):
            el = np.radians(rng.uniform(min_el, 88.0))
            az = rng.uniform(0, 2 * np.pi)
            u_enu = np.array([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)])
            u = C.T @ u_enu
            # distance along u to the orbit sphere
            b = RX @ u
            d = -b + np.sqrt(b * b - (RX @ RX - radius**2))
            s_rx = RX + d * u          # where the satellite is in the reception-time frame
            # transmit-time frame: rotate back by Ω τ (iterate τ from the transmit-frame range)
            s_tx = s_rx.copy()
            for _ in range(4):
                th = OMEGA_EARTH * np.linalg.norm(s_tx - RX) / C_LIGHT
                c, s = np.cos(th), np.sin(th)
                s_tx = np.array([c * s_rx[0] - s * s_rx[1], s * s_rx[0] + c * s_rx[1], s_rx[2]])
            sats.append(s_tx)
            syss.append(sys_code)
            els.append(el)
    return np.array(sats), np.array(syss), np.array(els)


def ranges(sat, sys_codes, rx=RX):
    return np.linalg.norm(sagnac_rotate(sat, rx) - rx, axis=1) + np.array([CLK[s] for s in sys_codes])


def enu_error(res, rx=RX):
    C = enu_rotation(LAT0, LON0)
    return (res.ecef - rx) @ C.T


def test_exact_ranges_give_exact_position_and_clocks():
    sat, sy, el = satellites(n_gps=7, n_glo=4, n_gal=3)
    pr = ranges(sat, sy)
    res = solve_spp(np.zeros(len(pr)), pr, np.full(len(pr), 25.0), sat, sy, el)
    assert np.linalg.norm(res.ecef[0] - RX) < 1e-4
    assert list(res.systems) == [1, 4, 8]
    assert np.allclose(res.clock[0], [CLK[1], CLK[4], CLK[8]], atol=1e-4)
    assert res.n_used[0] == 14 and res.dof[0] == 14 - 6 and res.passed[0]
    assert res.test_stat[0] < 1e-12
    assert abs(np.degrees(res.lat[0]) - 52.5046) < 1e-9 and abs(res.h[0] - H0) < 1e-4


def test_sagnac_matters_at_metre_level():
    sat, sy, el = satellites(seed=3)
    pr = ranges(sat, sy)
    good = solve_spp(np.zeros(len(pr)), pr, np.full(len(pr), 25.0), sat, sy, el)
    bad = solve_spp(np.zeros(len(pr)), pr, np.full(len(pr), 25.0), sat, sy, el,
                    cfg=SppConfig(sagnac=False, raim=False))
    e_bad = enu_error(bad)[0]
    assert np.linalg.norm(enu_error(good)[0]) < 1e-4
    assert 1.0 < np.hypot(e_bad[0], e_bad[1]) < 100.0
    # the rotation agrees with the first-order correction Ω/c (x_s y_r − y_s x_r)
    s_rot = sagnac_rotate(sat, RX)
    d1 = np.linalg.norm(s_rot - RX, axis=1) - np.linalg.norm(sat - RX, axis=1)
    d_lin = OMEGA_EARTH / C_LIGHT * (sat[:, 0] * RX[1] - sat[:, 1] * RX[0])
    assert np.max(np.abs(d1 - d_lin)) < 2e-3
    assert np.max(np.abs(d_lin)) > 5.0


def test_nlos_bias_is_excluded():
    rng = np.random.default_rng(7)
    sat, sy, el = satellites(n_gps=8, n_glo=5, seed=11)
    sig = 2.0
    pr = ranges(sat, sy) + rng.normal(0, sig, len(sy))
    k_bad = 2
    pr[k_bad] += 100.0
    var = np.full(len(pr), sig**2)
    res = solve_spp(np.zeros(len(pr)), pr, var, sat, sy, el)
    raw = solve_spp(np.zeros(len(pr)), pr, var, sat, sy, el, cfg=SppConfig(raim=False))
    assert not res.obs_used[k_bad] and res.obs_used.sum() == len(pr) - 1
    assert res.n_excluded[0] == 1 and res.passed[0]
    assert not raw.passed[0]
    e, e_raw = enu_error(res)[0], enu_error(raw)[0]
    assert np.hypot(e[0], e[1]) < 8.0
    assert np.linalg.norm(e) < np.linalg.norm(e_raw)
    # the excluded satellite's residual shows the bias
    assert abs(res.obs_residual[k_bad] - 100.0) < 15.0


def test_many_epochs_batched_with_missing_system_and_too_few():
    sat, sy, el = satellites(n_gps=6, n_glo=3, seed=5)
    pr = ranges(sat, sy)
    t = np.zeros(len(pr))
    # epoch 1: GPS only; epoch 2: only 4 satellites of two systems (dof < 0: no fix)
    g = sy == 1
    t_all = np.concatenate([t, np.ones(g.sum()), np.full(4, 2.0)])
    idx = np.concatenate([np.arange(len(pr)), np.flatnonzero(g), [0, 1, 6, 7]])
    res = solve_spp(t_all, pr[idx], np.full(len(idx), 25.0), sat[idx], sy[idx], el[idx])
    assert np.allclose(res.t, [0, 1, 2])
    assert np.all(np.linalg.norm(res.ecef[:2] - RX, axis=1) < 1e-4)
    assert np.isnan(res.clock[1, 1]) and np.isfinite(res.clock[1, 0])  # GPS-only epoch
    assert np.isnan(res.lat[2]) and not res.valid[2]
    assert res.to_gnss().t.tolist() == [0.0, 1.0]


def test_reader_errors(tmp_path):
    p = tmp_path / "x_Input.txt"
    p.write_text("odom3 0 5 0 0 0 0 0.1 1 1 1 1 1 1\n"
                 "pseudorange3 0 2e7 25 1.4e7 2.8e6 2.1e7 12 1 80 49\n"
                 "pseudorange3 0 2e7 abc 1.4e7 2.8e6 2.1e7 12 1 80 49\n")
    with pytest.raises(InputError, match=r"line 3, column 'variance'"):
        read_smartloc_input(p)
    p.write_text("odom3 0 5 0 0 0 0 0.1 1 1 1 1 1 1\npseudorange3 0 2e7 25 1.4e7\n")
    with pytest.raises(InputError, match=r"line 2: .*needs 10 numbers"):
        read_smartloc_input(p)
    q = tmp_path / "x_GT.txt"
    q.write_text("point3 0 3785108.1 899901.5 5037234.4 0 0 0\npoint3 0 3785108 899901 5037234 0\n")
    with pytest.raises(InputError, match="line 2, column 't'.*increasing"):
        read_smartloc_truth(q)


@pytest.fixture(scope="module")
def smartloc(shared_data):
    inp, gt = find_smartloc_files(shared_data / "smartloc_berlin_potsdamer_platz")
    prs, odo = read_smartloc_input(inp)
    return prs, odo, read_smartloc_truth(gt)


def test_smartloc_reader(smartloc):
    prs, odo, truth = smartloc
    assert len(prs) == 20038 and len(odo.t) == 1372 and len(truth.t) == 1372
    assert set(np.unique(prs.system)) == {1, 4}
    assert np.allclose(odo.t, truth.t)


def test_smartloc_spp_against_truth(smartloc):
    """Measured (2026-11-23): C/N0 weighting RMS 27.6 m, 95 % 52.2 m, max 71.8 m;
    the file's variances RMS 37.2 / 71.0 / 115.4 m; without Sagnac 47.0 m RMS."""
    prs, odo, truth = smartloc
    t0 = time.perf_counter()
    res = spp_from_pseudoranges(prs, SppConfig(weighting="cn0"))
    assert time.perf_counter() - t0 < 5.0
    assert res.valid.all() and len(res.t) == 1372
    e = horizontal_error(res, truth.t, truth.ecef)
    rms, p95, mx = np.sqrt(np.mean(e**2)), np.percentile(e, 95), e.max()
    assert 25.0 < rms < 30.0 and 48.0 < p95 < 56.0 and mx < 80.0
    assert res.stats["excluded"] > 300 and res.passed.all()
    e_var = horizontal_error(spp_from_pseudoranges(prs), truth.t, truth.ecef)
    assert 34.0 < np.sqrt(np.mean(e_var**2)) < 40.0
    e_nosag = horizontal_error(spp_from_pseudoranges(prs, SppConfig(weighting="cn0", sagnac=False)),
                               truth.t, truth.ecef)
    assert np.sqrt(np.mean(e_nosag**2)) > rms + 5.0
