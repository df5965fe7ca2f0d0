"""The two smartLoc Berlin Potsdamer Platz files against each other (docs/gnss.md, Errata).

The original file and the RTKLIB-preprocessed one hold the same drive. Their pseudoranges
differ by a constant per satellite; this prints those constants, and how far they move a
least-squares fix of the satellites the smoother chose as line of sight — the original
file's constant offset of the solution::

    python experiments/smartloc_files.py [DATA_DIR]     # DATA_DIR: ../shared/data (default)

Real data; about 10 s (one smoothed run of ``navigate_raw``).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from selfnav.api_gnss import navigate_raw
from selfnav.earth import ecef_to_enu, ecef_to_geodetic
from selfnav.io.smartloc import SYSTEM_NAMES, read_smartloc_input, read_smartloc_truth

ORIGINAL = "smartloc_berlin_potsdamer_platz/Berlin_Potsdamer_Platz_Input.txt"
RTKLIB = "smartloc_berlin_potsdamer_platz_rtklib/Berlin_Potsdamer_Platz_RTK_Input.txt"
TRUTH = "smartloc_berlin_potsdamer_platz/Berlin_Potsdamer_Platz_GT.txt"
SAME_SATELLITE_M = 100.0     # the two files' positions of one satellite differ by ~1 m


def matched_rows(a, b):
    """Row pairs ``(i, j)`` of the same epoch and satellite in files ``a`` and ``b`` (GLONASS
    is numbered differently in the two: matched by the satellite's position)."""
    rows_b = {}
    for j, t in enumerate(np.round(b.t * 100).astype(int)):
        rows_b.setdefault(int(t), []).append(j)
    pairs = []
    for i, t in enumerate(np.round(a.t * 100).astype(int)):
        js = rows_b.get(int(t))
        if not js:
            continue
        d = np.linalg.norm(b.sat_ecef[js] - a.sat_ecef[i], axis=1)
        k = int(np.argmin(d))
        if d[k] < SAME_SATELLITE_M and a.system[i] == b.system[js[k]]:
            pairs.append((i, js[k]))
    return np.array(pairs, int)


def main(data: Path) -> None:
    orig, _ = read_smartloc_input(data / ORIGINAL)
    rtk, _ = read_smartloc_input(data / RTKLIB)
    truth = read_smartloc_truth(data / TRUTH)
    pairs = matched_rows(orig, rtk)
    diff = orig.pr[pairs[:, 0]] - rtk.pr[pairs[:, 1]]
    epoch = np.round(orig.t[pairs[:, 0]] * 100).astype(int)
    sat = orig.system[pairs[:, 0]] * 1000 + orig.sat_id[pairs[:, 0]]
    # difference = the receiver's clock of that epoch and system (the files' clocks differ)
    # + a constant of the satellite: the two fitted by turns, by medians
    system = orig.system[pairs[:, 0]]
    cell = epoch * 100 + system
    bias = np.zeros(len(diff))
    for _ in range(10):
        clock = diff - bias
        for c in np.unique(cell):
            m = cell == c
            clock[m] = np.median(clock[m])
        for s in np.unique(sat):
            m = sat == s
            bias[m] = np.median(diff[m] - clock[m])
        for y in np.unique(system):                  # a constant per system is the clock's
            m = system == y
            bias[m] -= np.median(bias[m])
    diff = diff - clock
    print("satellite  epochs  original − RTKLIB pseudorange less the epoch's clock, m "
          "(median ± std)")
    for s in np.unique(sat):
        m = sat == s
        if m.sum() >= 50:
            print(f"{SYSTEM_NAMES.get(int(s) // 1000, '?'):8s} {int(s) % 1000:3d} {m.sum():6d}"
                  f"  {np.median(diff[m]):+6.2f} ± {np.std(diff[m]):.2f}")

    # the smoother's line-of-sight satellites, and what the differences do to their fix
    sol = navigate_raw(data / ORIGINAL, smooth=True)
    r, prs = sol.detail
    los = r.obs_component == 0
    lat0, lon0, h0 = (float(v) for v in ecef_to_geodetic(truth.ecef[0]))
    shifts = []
    for e in np.unique(epoch):
        m = (epoch == e) & los[pairs[:, 0]]
        i, j = pairs[m, 0], pairs[m, 1]
        systems = np.unique(orig.system[i])
        if len(i) < 4 + len(systems):
            continue
        rx = np.array([np.interp(e / 100, truth.t, truth.ecef[:, c]) for c in range(3)])
        u = rtk.sat_ecef[j] - rx
        u /= np.linalg.norm(u, axis=1)[:, None]
        H = np.column_stack([-u] + [(orig.system[i] == s).astype(float) for s in systems])
        x = np.linalg.lstsq(H, orig.pr[i] - rtk.pr[j], rcond=None)[0]
        shifts.append(ecef_to_enu(rx + x[:3], lat0, lon0, h0) - ecef_to_enu(rx, lat0, lon0, h0))
    shifts = np.array(shifts)
    mean, median = shifts.mean(axis=0), np.median(shifts, axis=0)
    print(f"\nthe differences through a fix of the smoother's line-of-sight satellites "
          f"({len(shifts)} epochs): mean E {mean[0]:+.1f}, N {mean[1]:+.1f}, U {mean[2]:+.1f} m;"
          f" median E {median[0]:+.1f}, N {median[1]:+.1f}, U {median[2]:+.1f} m")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else
         Path(__file__).resolve().parents[2] / "shared" / "data")
