"""The rtklibexplorer logger (issue 20 items 2 and 4): its mounting is a preset, not the reader's;
partial first and last lines are skipped with one warning; bad lines are one line in selfnav's
words."""
import shutil
import warnings

import numpy as np
import pytest

from selfnav import axes_detect as D
from selfnav.errors import InputError, SelfnavWarning
from selfnav.io import rtklibexplorer
from selfnav.io.readers import read_imu


@pytest.fixture(scope="module")
def drive(shared_data):
    return shared_data / "rtklibexplorer_drive_0708"


def _copy(drive, tmp_path, text=None):
    dst = tmp_path / "imu_1934.csv"
    if text is None:
        shutil.copy(drive / "imu_1934.csv", dst)
    else:
        dst.write_text(text)
    shutil.copy(drive / "imu_1934.csv.tag", tmp_path / "imu_1934.csv.tag")
    return dst


def test_default_is_the_drive0708_preset_as_before(drive):
    """Until the navigator detects axes, the default reading is the documented preset, and it
    is the reading of the old hard-coded reader, bit for bit: x_R = y, y_F = −x, z_U = z,
    then the mounting Rz(−5.35°)·Rx(−6.79°) (upstream's imu_misalign)."""
    assert rtklibexplorer.DEFAULT_AXES == "rtklibexplorer-drive0708"
    imu = read_imu(drive / "imu_1934.csv")
    assert imu.meta["axes"] == "BRU" and imu.meta["mount_deg"] == (0.0, -6.79, 5.35)
    assert imu.meta["axes_preset"] == "rtklibexplorer-drive0708"
    raw = rtklibexplorer.read_rtklibexplorer_imu(drive / "imu_1934.csv")
    from selfnav import attitude as att

    P = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    R = att.rotvec_to_dcm(np.array([0, 0, np.radians(-5.35)])) @ att.rotvec_to_dcm(
        np.array([np.radians(-6.79), 0, 0]))
    np.testing.assert_array_equal(imu.f_ib_b, (raw.f_ib_b @ P.T) @ R.T)
    np.testing.assert_array_equal(imu.omega_ib_b, (raw.omega_ib_b @ P.T) @ R.T)
    # the README's check: levelled at rest about (0.19, 0.00, 9.93) m/s²
    f0 = imu.f_ib_b[:300].mean(axis=0)
    assert abs(f0[1]) < 0.1 and f0[2] == pytest.approx(9.93, abs=0.05)
    # the same by name, and another installation of the same logger by its own spec
    same = read_imu(drive / "imu_1934.csv", axes="rtklibexplorer-drive0708")
    np.testing.assert_array_equal(same.f_ib_b, imu.f_ib_b)
    other = read_imu(drive / "imu_1934.csv", axes="x=-F,y=R,z=U")
    np.testing.assert_array_equal(other.f_ib_b, raw.f_ib_b @ P.T)
    det = read_imu(drive / "imu_1934.csv", axes="detect")
    np.testing.assert_array_equal(det.f_ib_b, raw.f_ib_b)
    assert det.meta["axes_source"] == "detect"


def test_up_axis_of_the_raw_logger_is_detected(drive):
    raw = read_imu(drive / "imu_1934.csv", axes="detect")
    up = D.detect_up_axis(raw.f_ib_b[raw.t < raw.t[0] + 30])
    assert up.axis == "+z" and up.confidence > 0.999


def test_partial_first_and_last_lines_one_warning(drive, tmp_path):
    lines = (drive / "imu_1934.csv").read_text().splitlines()
    full = read_imu(_copy(drive, tmp_path))
    # the logger's partial first line (6 of 7 fields) and a last line cut mid-number
    lines[0] = lines[0].split(",", 1)[1]
    lines[-1] = lines[-1][:9]
    p = _copy(drive, tmp_path, "\n".join(lines))
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        imu = read_imu(p)
    mine = [str(x.message) for x in w if issubclass(x.category, SelfnavWarning)]
    assert len(mine) == 1 and "first line (1) and last line" in mine[0] and "partial" in mine[0]
    np.testing.assert_array_equal(imu.f_ib_b, full.f_ib_b)     # as upstream: rows 2..N-1


@pytest.mark.parametrize("edit,needle", [
    (lambda ln: ln[:500] + ["0.1,0.2,0.3"] + ln[501:], "line 501: has 3 fields where an "
     "rtklibexplorer IMU log has 7"),
    (lambda ln: ln[:700] + ["0.1,0.2,x,1,2,3,999"] + ln[701:], "line 701, column 'az': value "
     "'x' is not a number"),
    (lambda ln: ln[:5], "has 5 lines"),
])
def test_bad_lines_are_one_line_in_selfnav_words(drive, tmp_path, edit, needle):
    lines = (drive / "imu_1934.csv").read_text().splitlines()
    p = _copy(drive, tmp_path, "\n".join(edit(lines)))
    with pytest.raises(InputError) as e:
        read_imu(p)
    msg = str(e.value)
    assert needle in msg and "usecols" not in msg and "\n" not in msg


# ------------------------------------------------- the axes checked before navigating (item 2)
def _drive_records(drive):
    from selfnav.io.readers import read_gnss

    return read_imu(drive / "imu_1934.csv"), read_gnss(drive / "gnss_1934_sf.pos")


def test_the_real_drive_agrees_with_its_preset_and_turns_with_its_track(drive):
    """drive_0708 as read (its preset): up +z by gravity, forward +y by the GNSS accelerations,
    the RTK course turning 1.00 rad per gyro radian (±0.003), nothing to warn about."""
    imu, gnss = _drive_records(drive)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SelfnavWarning)
        rep = D.imu_axes_report(imu, gnss)
    assert rep["agrees"] is True and rep["axes_found"] == "RFU"
    f = rep["forward"]
    assert abs(f["turn_gain"] - 1.0) < 0.01 and f["sigma_turn_gain"] < 0.01
    assert f["turn_r2"] > 0.9


@pytest.mark.parametrize("scale, words", [(np.degrees(1.0), "look like deg/s"),
                                          (-1.0, "the GNSS track the other")])
def test_gyros_in_deg_per_s_or_turning_the_wrong_way_are_refused_by_navigate(drive, scale,
                                                                             words):
    """The same drive with its gyros in deg/s (below the reader's 35 rad/s alarm: a car's
    corners read 20-30) or with their signs flipped (a logger that inverts the gyros, or
    latitude and longitude swapped): one InputError naming the file before any navigation —
    not a solution 400 m off with exit 0."""
    import selfnav
    from selfnav.types import ImuData

    imu, gnss = _drive_records(drive)
    bad = ImuData(imu.t, imu.omega_ib_b * scale, imu.f_ib_b, source="imu_1934.csv",
                  meta=dict(imu.meta))
    with pytest.raises(InputError, match=words) as e:
        selfnav.navigate(bad, gnss)
    assert str(e.value).startswith("imu_1934.csv")


def test_platforms_that_yaw_about_their_course_raise_no_alarm():
    """Simulated ship (yawing ±5° about a straight course in the waves), boat, walker and drone:
    a course that does not follow the yaw is no evidence of units (too little of the course
    explained, or the gain too uncertain): no error."""
    import selfnav

    for kind in ("ship", "boat", "pedestrian", "drone"):
        sim = selfnav.simulate(kind, seed=7, duration=240)
        f = D.detect_forward_axis(sim.imu, sim.gnss.as_gnss())
        D.check_turn_gain(f, kind)


def test_a_second_log_mounted_otherwise_is_not_read_silently(drive, tmp_path):
    """Issue 20's complaint: a log of the same logger with the unit turned 90° on the roof, read
    with the default (drive_0708's preset), used to be read wrongly and silently. Now the
    GNSS accelerations say forward is the rows' +x, in one warning naming --imu-axes."""
    from selfnav.io.readers import read_gnss

    lines = (drive / "imu_1934.csv").read_text().splitlines()
    rows = []
    for ln in lines[1:-1]:
        ax, ay, az, gx, gy, gz, t = ln.split(",")
        rows.append(",".join([ay, str(-float(ax)), az, gy, str(-float(gx)), gz, t]))
    p = _copy(drive, tmp_path, "\n".join([lines[0]] + rows + [lines[-1]]) + "\n")
    imu = read_imu(p)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        rep = D.imu_axes_report(imu, read_gnss(drive / "gnss_1934_sf.pos"))
    said = [str(x.message) for x in w if issubclass(x.category, SelfnavWarning)]
    assert rep["agrees"] is False
    assert len(said) == 1 and "forward is its +x" in said[0] and "--imu-axes" in said[0]


@pytest.mark.slow
def test_imu_axes_detect_navigates_the_real_drive(drive):
    """``--imu-axes detect`` on drive_0708 (its RTK course and accelerations show the axes): the
    rows read as BRU with a yaw mounting of 5.4° (the preset: BRU, yaw 5.35°, pitch −6.79° —
    the pitch is not detected) and the solution within a few cm of the RTK fixes, as with the
    preset (0.020 m)."""
    import selfnav
    from selfnav.io.readers import read_gnss

    imu = read_imu(drive / "imu_1934.csv", axes="detect")
    gnss = read_gnss(drive / "gnss_1934_sf.pos")
    # the pitch mounting it cannot see shows in the vertical constraint's innovations (the
    # velocity leaves the IMU's plane by 6.8°): its σ is widened, and the warning says why
    with pytest.warns(selfnav.errors.SelfnavWarning, match="imu-mount"):
        sol = selfnav.navigate(imu, gnss)
    assert sol.stats["nhc_check"]["largest_widening"][1] > 1.0
    rep = sol.stats["imu_axes"]
    assert rep["axes_found"] == "BRU" and rep["applied"].startswith("BRU, yaw 5.")
    assert abs(rep["forward"]["yaw_mount_deg"] - 5.35) < 3 * rep["forward"]["sigma_yaw_deg"]
    from selfnav.earth import enu_offset

    tr = sol.trajectory
    m = (tr.t >= gnss.t[0]) & (tr.t <= gnss.t[-1])
    d = enu_offset(np.interp(tr.t[m], gnss.t, gnss.lat), np.interp(tr.t[m], gnss.t, gnss.lon),
                   0.0, tr.lat[m], tr.lon[m], 0.0)
    assert np.sqrt(np.mean(d[:, 0] ** 2 + d[:, 1] ** 2)) < 0.05


def test_deg_per_s_gyros_with_noisy_fixes_are_refused_by_the_sideways_acceleration():
    """Simulated car (10 m fixes at 1 Hz, a Gauss–Markov outlier window): the course is too noisy
    for the turn gain to decide (R² ≈ 0), but its gyros in deg/s ask 5 g sideways at over 5 m/s
    (a car's corners: 0.1-0.4 g here): refused. Rad/s: no error."""
    import selfnav
    from selfnav.types import ImuData

    sim = selfnav.simulate("car", seed=3, duration=200)
    gnss = sim.gnss.as_gnss()
    f = D.detect_forward_axis(sim.imu, gnss)
    assert f.lateral_g95 < 1.0
    D.check_turn_gain(f, "car", along_nose=True)
    deg = ImuData(sim.imu.t, np.degrees(sim.imu.omega_ib_b), sim.imu.f_ib_b, source="deg.csv")
    f = D.detect_forward_axis(deg, gnss)
    assert f.lateral_g95 > 3.0
    with pytest.raises(InputError, match="look like deg/s"):
        D.check_turn_gain(f, "deg.csv", along_nose=True)
    D.check_turn_gain(f, "deg.csv", along_nose=False)      # a drone may spin: no verdict
