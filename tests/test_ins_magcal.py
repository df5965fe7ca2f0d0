"""The magnetometer calibrated in motion (issue 20, selfnav.ins.magcal)."""
from __future__ import annotations

import math

import numpy as np

from selfnav import attitude as att
from selfnav import sensors
from selfnav.ins.magcal import HardIronFit, fit_circle, level_reading

LAT, LON = math.radians(59.4), math.radians(24.7)


def _field():
    b_n = sensors.earth_field_n(LAT, LON, 0.0)
    dec, inc = sensors.declination_inclination(b_n)
    return b_n, float(dec), float(inc)


def test_the_circle_fit_recovers_an_offset_circle_from_a_third_of_it():
    """Analytic: points on a circle of radius 15 000 about (700, −300), 120° of arc, 50 nT
    noise: centre within 3σ of its covariance, radius to 0.5 %."""
    rng = np.random.default_rng(1)
    a = np.linspace(0.3, 0.3 + 2 * math.pi / 3, 200)
    xy = np.column_stack([700 + 15000 * np.cos(a), -300 + 15000 * np.sin(a)])
    xy += 50.0 * rng.normal(size=xy.shape)
    b, R, r, J = fit_circle(xy)
    cov = np.var(r) * np.linalg.inv(J.T @ J)
    assert np.all(np.abs(b - [700, -300]) < 3 * np.sqrt(np.diag(cov)[:2]) + 1e-9)
    assert abs(R / 15000 - 1) < 0.005
    assert 40 < np.std(r) < 60


def _turning(headings_deg, hard_iron, roll_deg=0.0, pitch_deg=0.0, noise=100.0, seed=2):
    """Readings of a (soft-iron free) magnetometer at the given headings, and the truths."""
    b_n, dec, inc = _field()
    rng = np.random.default_rng(seed)
    out = []
    for k, h in enumerate(np.radians(headings_deg)):
        r = math.radians(roll_deg) * math.sin(0.7 * k)
        p = math.radians(pitch_deg) * math.cos(0.4 * k)
        C = att.dcm_nb_from_euler(r, p, h)
        m = C @ b_n + np.asarray(hard_iron) + noise * rng.normal(size=3)
        out.append((m, r, p, h))
    return out, dec, inc


def test_a_fit_from_the_turns_removes_the_hard_iron_and_its_sigma_holds():
    """2 µT of hard iron (8.5° of heading error at 59° N uncorrected) on a platform rolling and
    pitching ±3° while it turns through 360° twice: the fit is trusted after the turns, and the
    corrected headings' errors have RMS error/σ ≤ 1 (the σ a promise, the soft iron floor in)."""
    hi = np.array([1500.0, -1300.0, 400.0])
    hdg = np.concatenate([np.linspace(0, 720, 240), np.full(60, 720.0)])
    rows, dec, inc = _turning(hdg, hi, 3.0, 3.0)
    fit = HardIronFit(inc)
    raw, cor, sig = [], [], []
    for k, (m, r, p, h) in enumerate(rows):
        fit.add(float(k), m, r, p)
        raw.append(math.remainder(float(sensors.magnetic_heading(m, r, p, dec)) - h, 2 * math.pi))
        est = fit.heading(m, r, p, dec)
        if est is not None:
            cor.append(math.remainder(est[0] - h, 2 * math.pi))
            sig.append(est[1])
    assert np.max(np.abs(np.degrees(raw))) > 7.0
    assert fit.ready and len(cor) > 200
    np.testing.assert_allclose(fit.centre, level_reading(hi, 0.0, 0.0)[:2], atol=100.0)
    assert abs(fit.dip - inc) < math.radians(1.0)
    z = np.asarray(cor) / np.asarray(sig)
    assert np.sqrt(np.mean(z * z)) < 1.0
    assert np.max(np.abs(np.degrees(cor))) < 2.0


def test_a_quarter_turn_is_not_enough_to_trust_the_fit():
    """A platform that has turned through 90° only: the centre is not pinned (the fit is not
    used), whatever its formal σ."""
    rows, dec, inc = _turning(np.linspace(0, 90, 300), [1500.0, -1300.0, 400.0])
    fit = HardIronFit(inc)
    for k, (m, r, p, _) in enumerate(rows):
        fit.add(float(k), m, r, p)
    assert fit.fits > 20 and not fit.ready
    assert fit.heading(rows[-1][0], 0.0, 0.0, dec) is None


def test_a_field_with_the_wrong_dip_is_not_trusted():
    """A field whose dip is 10° from IGRF's (a place whose field is disturbed, a wrong field
    model): the fit is refused; the same readings against the right dip are trusted."""
    rows, dec, inc = _turning(np.linspace(0, 720, 300), [0.0, 0.0, 0.0])
    for dip, trusted in ((inc, True), (inc + math.radians(10.0), False)):
        fit = HardIronFit(dip)
        for k, (m, r, p, _) in enumerate(rows):
            fit.add(float(k), m, r, p)
        assert fit.ready is trusted


def test_a_quarter_turn_with_the_gyros_pins_the_hard_iron():
    """The quarter turn the circle fit refuses, with the raw gyros' heading beside each reading
    — their bias 0.4 °/s, the navigator's estimate of it 0.25 °/s off (a consumer part early in a
    drive): the fit through the turns solves for the drift, is trusted, removes the hard iron to
    100 nT, and the corrected headings hold their σ (RMS error/σ ≤ 1, every error under 2°)."""
    hdg = np.concatenate([np.full(60, 10.0), np.linspace(10, 100, 90), np.full(90, 100.0)])
    hi = [1500.0, -1300.0, 400.0]
    rows, dec, inc = _turning(hdg, hi, 2.0, 2.0)
    bias = math.radians(0.4)                     # counter-clockwise about the vertical
    fit = HardIronFit(inc)
    cor, sig = [], []
    for k, (m, r, p, h) in enumerate(rows):
        # the raw gyros' clockwise heading change: the truth's, less the bias' rotation
        yaw = (h - math.radians(10.0)) - bias * k
        fit.add(float(k), m, r, p, yaw, bias - math.radians(0.25))
        est = fit.heading(m, r, p, dec)
        if est is not None:
            cor.append(math.remainder(est[0] - h, 2 * math.pi))
            sig.append(est[1])
    assert fit.ready and fit.source == "turns" and len(cor) > 50
    np.testing.assert_allclose(fit.centre, level_reading(np.asarray(hi), 0.0, 0.0)[:2],
                               atol=100.0)
    z = np.asarray(cor) / np.asarray(sig)
    assert np.sqrt(np.mean(z * z)) < 1.0
    assert np.max(np.abs(np.degrees(cor))) < 2.0


def test_a_drifting_gyro_on_a_straight_line_is_not_a_turn():
    """A platform on a straight line whose raw gyros drift 0.5 °/s (120° over the readings):
    the readings do not turn, so nothing pins the offset and the fit is not trusted."""
    rows, dec, inc = _turning(np.full(240, 30.0), [1500.0, -1300.0, 400.0], 2.0, 2.0)
    fit = HardIronFit(inc)
    for k, (m, r, p, _) in enumerate(rows):
        fit.add(float(k), m, r, p, -math.radians(0.5) * k, math.radians(0.5))
    assert fit.fits > 10 and not fit.ready
