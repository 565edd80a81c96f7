#!/usr/bin/env python3
"""How far past each rib's observed lateral end a simulated sweep imaged (README,
"On the controller's own compounded sweeps the gap is wider").

For each margin and seed: `ribreg phantom sweep --margin-mm M`, `calibrate temporal`,
`compound` and `register --report`, then, from the sweep's `poses.csv` and `probe.json`,
the exact test of whether a point was imaged: some tracked pose's image rectangle
(footprint × depth) lies within 1 mm of it. Walking from each end of the registered
target skeleton (the report's `skeleton.target`: ribs 2..5, 6/6/8/10 points, both ends
lateral) outward along the patient's lateral axis (the phantom's pose, `params.json`),
in 1 mm steps at the end's depth, the first point not imaged gives the clearance.

Usage: python3 host-sim/benches/imaged_past_ends.py target/release/ribreg
           [--margins 10 0 -10 -20] [--seeds 20] [--work DIR]
Needs numpy (any recent version; measured with 2.x).
"""

import argparse
import json
import os
import subprocess
import tempfile

import numpy as np

SAMPLES = [6, 6, 8, 10]  # skeleton points of ribs 2..5
SLAB_MM = 1.0  # a point within this of an image plane is in it
MAX_MM = 40  # clearances are walked up to this


def rotation(q):
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def rigid(d):
    return np.array(d["rotation"]), np.array(d["translation"])


def sweep(ribreg, d, seed, margin):
    """The sweep, its compounded cloud and its registration; True if accepted."""
    os.makedirs(d, exist_ok=True)
    run = lambda *a, **k: subprocess.run([ribreg, *a], capture_output=True, **k)
    run("phantom", "sweep", "-q", "--seed", str(seed), f"--margin-mm={margin}",
        "--out-dir", d, check=True)
    lag = run("calibrate", "temporal", "--tracker", f"{d}/calib_tracker.csv",
              "--video", f"{d}/calib_video.csv", "--json", check=True).stdout
    open(f"{d}/lag.json", "wb").write(lag)
    run("compound", "-q", "--poses", f"{d}/poses.csv", "--frames", f"{d}/frames.csv",
        "--probe", f"{d}/probe.json", "--lag-file", f"{d}/lag.json", "-o", f"{d}/us.ply",
        check=True)
    reg = run("register", "-q", "--template", f"{d}/template.ply", "--target",
              f"{d}/us.ply", "--out", f"{d}/registered.ply", "--report",
              f"{d}/report.json")
    return reg.returncode == 0


def clearances(d):
    """Per rib end (ribs 2..5, both ends), mm imaged past it laterally."""
    probe = json.load(open(f"{d}/probe.json"))
    r_tu, t_tu = rigid(probe["tcp_T_us"])
    r_et, t_et = rigid(probe["ee_T_tcp"])
    width, depth = probe["probe"]["footprint_mm"], probe["probe"]["depth_mm"]
    poses = np.loadtxt(f"{d}/poses.csv", delimiter=",", skiprows=1)
    r_be = np.array([rotation(p[4:8]) for p in poses])
    # b_T_us = b_T_ee · ee_T_tcp · tcp_T_us
    r_bu = r_be @ r_et @ r_tu
    t_bu = poses[:, 1:4] + np.einsum("nij,j->ni", r_be, r_et @ t_tu + t_et)
    across, down, normal = r_bu[:, :, 0], r_bu[:, :, 1], r_bu[:, :, 2]

    def imaged(q):
        v = q - t_bu
        a = np.einsum("ni,ni->n", v, across)
        b = np.einsum("ni,ni->n", v, down)
        n = np.einsum("ni,ni->n", v, normal)
        return bool(np.any((np.abs(n) <= SLAB_MM) & (a >= 0) & (a <= width)
                           & (b >= 0) & (b <= depth)))

    lateral = np.array(json.load(open(f"{d}/params.json"))["pose"]["rotation"])[:, 0]
    skeleton = np.array(json.load(open(f"{d}/report.json"))["skeleton"]["target"])
    out, first = [], 0
    for n in SAMPLES:
        rib = skeleton[first:first + n]
        first += n
        for end, inner in ((rib[0], rib[1]), (rib[-1], rib[-2])):
            out_dir = np.sign((end - inner) @ lateral) * lateral
            k = next((k for k in range(MAX_MM + 1) if not imaged(end + k * out_dir)), MAX_MM)
            out.append(k)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("ribreg")
    ap.add_argument("--margins", type=float, nargs="+", default=[10, 0, -10, -20])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--work", default=None, help="keep the sweeps here")
    a = ap.parse_args()
    work = a.work or tempfile.mkdtemp(prefix="imaged_past_ends_")
    for m in a.margins:
        least = []
        for s in range(a.seeds):
            d = os.path.join(work, f"{m:g}", str(s))
            if not sweep(os.path.abspath(a.ribreg), d, s, m):
                print(f"margin {m:g} mm, seed {s}: refused")
                continue
            c = clearances(d)
            least.append(min(c))
            print(f"margin {m:g} mm, seed {s}: imaged past ribs 2..5 (each end) {c}")
        if least:
            print(f"margin {m:g} mm: least clearance per accepted sweep "
                  f"{min(least)}–{max(least)} mm ({len(least)} sweeps)")


if __name__ == "__main__":
    main()
