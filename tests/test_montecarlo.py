"""Monte Carlo on Dask: determinism, statistics, consistency of the static-latitude estimator."""
import json

import numpy as np
import pytest
from scipy import stats

from selfnav import montecarlo as mc
from selfnav.cli import main


def _gauss_run(seed, params):
    """An analytic pair: error ~ N(0, sigma²) with the predicted sigma exact."""
    rng = np.random.default_rng(seed)
    s = params["sigma"] * (1.0 + rng.uniform())
    return {"error": s * rng.normal(), "sigma": s}


mc.register_pair("test-gauss", _gauss_run, unit="m", defaults={"sigma": 2.0},
                 description="test only")


@pytest.fixture(scope="module")
def cluster():
    c = mc.local_cluster(2)
    yield c
    c.close()


def test_summarize_by_hand():
    e = np.array([1.0, -2.0, 3.0, 0.5])
    s = np.array([1.0, 2.0, 1.0, 1.0])
    m = mc.summarize(e, s, bound=np.array([1.0, 1.0, 2.0, 2.0]))
    assert m["rms_error"] == pytest.approx(np.sqrt((1 + 4 + 9 + 0.25) / 4))
    assert m["mean_error"] == pytest.approx(0.625)
    assert m["std_error"] == pytest.approx(np.std(e, ddof=1))
    assert m["rms_normalized_error"] == pytest.approx(np.sqrt((1 + 1 + 9 + 0.25) / 4))
    assert m["fraction_within_2sigma"] == 0.75  # |3/1| > 2 only
    assert m["fraction_within_2sigma_se"] == pytest.approx(np.sqrt(0.75 * 0.25 / 4))
    assert m["rms_bound"] == pytest.approx(np.sqrt(10 / 4))
    assert m["rms_error_over_bound"] == pytest.approx(m["rms_error"] / np.sqrt(2.5))

    # a run without a result (a drive that never started: NaN) is left out and counted, not
    # allowed to make every figure NaN (the road campaign of master seed 103 printed
    # "RMS(error/σ) nan" for one such drive)
    m2 = mc.summarize(np.r_[e, np.nan], np.r_[s, np.nan],
                      bound=np.array([1.0, 1.0, 2.0, 2.0, 3.0]))
    assert m2["n"] == 4 and m2["n_without_result"] == 1 and m["n_without_result"] == 0
    for k in ("rms_error", "rms_normalized_error", "fraction_within_2sigma", "rms_bound"):
        assert m2[k] == pytest.approx(m[k])
    none = mc.summarize(np.array([np.nan]), np.array([1.0]))
    assert none["n"] == 0 and none["n_without_result"] == 1 and np.isnan(none["rms_error"])


def test_seeds_are_deterministic_and_distinct():
    a, b = mc.run_seeds(7, 500), mc.run_seeds(7, 500)
    assert np.array_equal(a, b) and len(np.unique(a)) == 500
    assert not np.array_equal(a, mc.run_seeds(8, 500))
    assert np.array_equal(mc.run_seeds(7, 10), a[:10])  # run i's seed does not depend on N


@pytest.mark.slow
def test_same_seed_same_results_in_process_and_on_cluster(cluster):
    from dask.distributed import Client

    r0 = mc.run_montecarlo("static-latitude", 12, seed=3, workers=0, chunk_size=5)
    with Client(cluster) as client:
        r1 = mc.run_montecarlo("static-latitude", 12, seed=3, client=client, chunk_size=2)
    # and through --scheduler ADDRESS
    r2 = mc.run_montecarlo("static-latitude", 12, seed=3, scheduler=cluster.scheduler_address)
    for r in (r1, r2):
        assert r.workers == 2
        for k in r0.table:
            assert np.array_equal(r0.table[k], r.table[k]), k
    assert np.array_equal(r0.table["run"], np.arange(12))
    r3 = mc.run_montecarlo("static-latitude", 12, seed=4, workers=0)
    assert not np.array_equal(r0.table["error"], r3.table["error"])


@pytest.mark.slow
def test_custom_pair_statistics_on_cluster(cluster):
    """A pair registered in a test module travels to the workers (cloudpickle); its
    statistics match their analytic values."""
    n = 2000
    r = mc.run_montecarlo("test-gauss", n, seed=11, scheduler=cluster.scheduler_address)
    s = r.summary
    assert r.unit == "m" and s["n"] == n
    # RMS(e/σ)² ~ χ²_n / n: 4-sigma band
    assert abs(s["rms_normalized_error"] ** 2 - 1.0) < 4 * np.sqrt(2.0 / n)
    p2 = stats.norm.cdf(2) - stats.norm.cdf(-2)
    assert abs(s["fraction_within_2sigma"] - p2) < 4 * np.sqrt(p2 * (1 - p2) / n)
    # sigma ~ 2 U(1, 2): E[σ²] = 4 · 7/3
    assert s["rms_sigma"] ** 2 == pytest.approx(4 * 7 / 3, rel=0.05)


def test_static_latitude_reaches_the_bound_and_sigma_is_honest():
    """Seed 000 estimator at random latitude and attitude, white noise only: the RMS error
    equals the Cramér-Rao bound, and the estimator's own sigma is consistent with its errors."""
    n = 240
    r = mc.run_montecarlo("static-latitude", n, seed=5, workers=0)
    s = r.summary
    t = r.table
    assert np.all(np.abs(t["lat_true_deg"]) <= 89.0)
    assert t["lat_true_deg"].min() < -60 and t["lat_true_deg"].max() > 60
    assert np.all(np.abs(t["pitch_deg"]) <= 90.0) and np.ptp(t["roll_deg"]) > 300
    # error / bound: RMS of n Gaussians with the bound's sigma, 4-sigma band
    band = 4 * np.sqrt(1.0 / (2 * n))
    assert abs(s["rms_error_over_bound"] - 1.0) < band
    # sigma is a 20-block jackknife estimate: e/σ is Student-t with ~19 dof, E[t²] = 19/17
    assert abs(s["rms_normalized_error"] - np.sqrt(19 / 17)) < 0.15
    p2 = stats.t.cdf(2, 19) - stats.t.cdf(-2, 19)  # 0.940
    assert abs(s["fraction_within_2sigma"] - p2) < 4 * np.sqrt(p2 * (1 - p2) / n)
    assert abs(s["mean_error"]) < 4 * s["rms_bound"] / np.sqrt(n)


def test_bias_makes_the_noise_sigma_overconfident():
    """A 1 °/h gyro bias (random direction) is invisible to the data-driven sigma: the errors
    grow to ~bias/Ω and RMS(error/σ) flags the inconsistency."""
    r = mc.run_montecarlo("static-latitude", 60, seed=6, workers=0,
                          params={"gyro_bias_deg_per_h": 1.0})
    s = r.summary
    assert s["rms_normalized_error"] > 2.0
    assert s["fraction_within_2sigma"] < 0.8
    # the bias error is of order bias/Ω = 1/15.04 rad ≈ 3.8°, times a direction factor < 1
    assert 0.5 < s["rms_error"] < 5.0


def test_results_files(tmp_path):
    import pyarrow.parquet as pq

    r = mc.run_montecarlo("test-gauss", 30, seed=1, workers=0)
    p = mc.write_results(tmp_path / "r.parquet", r)
    tab = pq.read_table(p)
    assert b"simulated" in tab.schema.metadata[b"selfnav"]
    assert np.array_equal(tab.column("error").to_numpy(), r.table["error"])
    assert np.array_equal(tab.column("seed").to_numpy(), r.table["seed"])
    c = mc.write_results(tmp_path / "r.csv", r)
    text = c.read_text()
    assert text.startswith("# simulated")
    from selfnav.io.csvio import read_table

    back = read_table(c, ("run", "seed", "error", "sigma"))
    assert np.allclose(back["error"], r.table["error"], rtol=1e-9)
    # a single run is reproducible from its seed column
    k = 17
    assert _gauss_run(int(r.table["seed"][k]), {"sigma": 2.0})["error"] == r.table["error"][k]
    assert not list(tmp_path.glob(".*tmp"))


def test_cli(tmp_path, capsys):
    rc = main(["montecarlo", "static-latitude", "--runs", "8", "--workers", "0", "--json",
               "--seed", "2", "--set", "duration_s=30", "--out", str(tmp_path / "o.csv")])
    assert rc == 0
    d = json.loads(capsys.readouterr().out)
    assert d["n"] == 8 and d["params"]["duration_s"] == 30.0 and d["seed"] == 2
    assert (tmp_path / "o.csv").exists()
    rc = main(["montecarlo", "test-gauss", "--runs", "20", "--workers", "0"])
    cap = capsys.readouterr()
    assert rc == 0 and "RMS(error/sigma)" in cap.out and "20/20" in cap.err  # bar on stderr
    for args, msg in ((["montecarlo", "nope", "--runs", "2"], "unknown Monte Carlo scenario"),
                      (["montecarlo", "static-latitude", "--set", "x=1"], "has no parameter"),
                      (["montecarlo", "static-latitude", "--out", "r.txt"], ".csv or .parquet"),
                      (["montecarlo", "static-latitude", "--runs", "0"], "at least 1")):
        assert main(args) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("selfnav: error:") and msg in err and "\n" not in err
