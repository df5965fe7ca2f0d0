"""Allan variance (issue 3): against allantools, and identification of simulated noise terms."""
import json

import allantools
import numpy as np

from selfnav import allan
from selfnav.types import ImuData
from selfnav.sensors import (DEG_PER_H, DEG_PER_SQRT_H, MPS_PER_SQRT_H, ImuErrorModel,
                             SensorTriad)



def test_overlapping_adev_equals_allantools():
    rng = np.random.default_rng(0)
    y = rng.normal(size=20000) * 0.01 + np.cumsum(rng.normal(size=20000)) * 1e-4 + 3.0
    tau, ad, cnt = allan.allan_deviation(y, 0.01)
    t2, a2, e2, n2 = allantools.oadev(y, rate=100.0, data_type="freq", taus=tau)
    np.testing.assert_allclose(t2, tau)
    np.testing.assert_allclose(ad, a2, rtol=1e-9)
    np.testing.assert_array_equal(cnt, n2)
    # several columns at once give the same as one by one
    Y = np.column_stack([y, 2 * y, -y])
    _, AD, _ = allan.allan_deviation(Y, 0.01)
    np.testing.assert_allclose(AD, np.column_stack([ad, 2 * ad, ad]), rtol=1e-12)


def _simulated_static(seconds, dt, model, seed):
    n = int(seconds / dt)
    t = dt * np.arange(1, n + 1)
    w, f = model.apply(t, np.zeros((n, 3)), np.tile([0.0, 0.0, 9.81], (n, 1)), seed)
    return ImuData(t, w, f, source="simulated static")


def test_identification_recovers_arw_vrw_and_bias_instability():
    arw, bi_g = 0.05, 1.0                 # °/√h, °/h
    vrw, bi_a = 0.02, 2e-4                # m/s/√h, m/s²
    model = ImuErrorModel(
        SensorTriad(white=arw * DEG_PER_SQRT_H, bias_instability=bi_g * DEG_PER_H, bias_tau=100.0),
        SensorTriad(white=vrw * MPS_PER_SQRT_H, bias_instability=bi_a, bias_tau=100.0))
    imu = _simulated_static(4 * 3600.0, 0.05, model, 21)
    res = allan.analyze_imu(imu)
    for k in range(3):
        g, a = res["gyro"][k], res["accel"][k]
        assert abs(g.white / (arw * DEG_PER_SQRT_H) - 1) < 0.10
        assert abs(a.white / (vrw * MPS_PER_SQRT_H) - 1) < 0.10
        assert abs(g.bias_instability / (bi_g * DEG_PER_H) - 1) < 0.30
        assert abs(a.bias_instability / bi_a - 1) < 0.30
        assert not g.bias_instability_bound


def test_identification_of_rate_random_walk_and_white_only_bound():
    K = 10.0 * DEG_PER_H / 60.0           # 10 °/h/√h: slope +1/2 from ~600 s
    model = ImuErrorModel(SensorTriad(white=0.1 * DEG_PER_SQRT_H, random_walk=K),
                          SensorTriad(white=0.05 * MPS_PER_SQRT_H))
    imu = _simulated_static(6 * 3600.0, 0.1, model, 5)
    res = allan.analyze_imu(imu)
    for k in range(3):
        assert abs(res["gyro"][k].random_walk / K - 1) < 0.35
        assert abs(res["gyro"][k].white / (0.1 * DEG_PER_SQRT_H) - 1) < 0.10
        # accelerometers: white noise only, σ still falls: the bias instability is a bound
        a = res["accel"][k]
        assert a.bias_instability_bound
        assert abs(a.white / (0.05 * MPS_PER_SQRT_H) - 1) < 0.10


def test_cli_allan_on_psins_laser_gyro(tmp_path, capsys, shared_data):
    from selfnav.cli import main

    png = tmp_path / "a.png"
    psins = shared_data / "psins_lasergyro_static" / "lasergyro.imu"
    assert main(["allan", str(psins), "--json", "--plot", str(png)]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("arw_deg_per_sqrt_h", "bias_instability_deg_per_h", "vrw_m_per_s_per_sqrt_h",
                "accel_bias_instability_m_per_s2"):
        assert len(out[key]) == 3
    assert out["samples"] == 184718
    assert png.stat().st_size > 10000
    # a navigation-grade RLG: the gyro curve goes below 0.5 °/h, nowhere near MEMS levels
    assert min(out["bias_instability_deg_per_h"]) < 0.5
    assert all(x < 1.0 for x in out["vrw_m_per_s_per_sqrt_h"])


def test_cli_allan_rejects_short_file(tmp_path, capsys):
    from selfnav.cli import main

    p = tmp_path / "short.csv"
    p.write_text("t,wx,wy,wz,fx,fy,fz\n" + "".join(
        f"{0.01 * (k + 1)},0,0,0,0,0,9.8\n" for k in range(10)))
    assert main(["allan", str(p), "--no-plot"]) == 2
    assert "too short" in capsys.readouterr().err
