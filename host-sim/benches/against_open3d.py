#!/usr/bin/env python3
"""Whole-process `ribreg register` with a prepared template against one Open3D ICP call
on the same phantom pair, measured in the same run (issue 14's speed goal: ours at most a
quarter of Open3D's ICP).

    python3 host-sim/benches/against_open3d.py [path/to/ribreg] [--repeats 15] [--seeds 0 1 2]
        [--before path/to/other/ribreg]

`ribreg` defaults to target/release/ribreg (build it with `cargo build --release -p
ribreg-sim`). Needs open3d (tests/fixtures/formats/requirements.txt pins the version).

Ours: the wall time of the whole `ribreg register` process (start, read the prepared
template and the target, register, map the template and the waypoints, ED/HD, write
every output). Open3D: the wall time of one `registration_icp` call alone (point to
point, identity start, 20 mm correspondence distance, at most 100 iterations), the
clouds already in memory and no KD-tree reuse between calls. The two alternate, one of
each per repeat; medians over the repeats; the ratio per seed and over all seeds is
printed. `--before` times a second `ribreg` (another version) in the same rotation, so
that a change is measured against the version before it under the same load, and
prints the median of the paired ratios (this repeat's ours / this repeat's before);
`--no-icp` leaves Open3D's call out (the second core then idles between the runs).
"""

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import open3d as o3d


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("ribreg", nargs="?", default="target/release/ribreg")
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--spacing", type=float, default=None,
                    help="template from the phantom's CT labelmap (phantom --ct) at this spacing, mm, "
                         "instead of the phantom's 2.5 mm template cloud")
    ap.add_argument("--before", default=None,
                    help="another ribreg binary, timed in the same rotation (a version before a change)")
    ap.add_argument("--no-icp", action="store_true",
                    help="time the ribregs only (with --before: a change against the version before it)")
    args = ap.parse_args()
    ratios = []
    what = f"template from the CT labelmap at {args.spacing} mm" if args.spacing else "the phantom's template cloud"
    print(f"open3d {o3d.__version__}, ribreg {args.ribreg}, {args.repeats} repeats, {what}")
    if args.before:
        print(f"before: {args.before}")
    header = ["seed", "template / target points", "ribreg register (whole process)"]
    header += ["before", "ours / before, paired"] if args.before else []
    header += [] if args.no_icp else ["Open3D ICP call", "ratio"] + (["before"] if args.before else [])
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    paired_ratios = []
    before_ratios = []
    for seed in args.seeds:
        with tempfile.TemporaryDirectory() as tmp:
            d = Path(tmp)
            run = lambda *a, exe=args.ribreg: subprocess.run([exe, "-q", *a], check=True, capture_output=True)
            run("phantom", "--seed", str(seed), "--variant", "misaligned", "--out-dir", str(d),
                *(["--ct"] if args.spacing else []))
            if args.spacing:
                run("template", "--labelmap", str(d / "ct" / "labelmap.nii.gz"), "--spacing",
                    str(args.spacing), "--out", str(d / "t.ply"), "--prepared", str(d / "prepared.ply"))
            else:
                run("template", "--cloud", str(d / "template.ply"), "--out", str(d / "t.ply"),
                    "--prepared", str(d / "prepared.ply"))
            reg = ["register", "--template", str(d / "prepared.ply"), "--target", str(d / "target.ply"),
                   "--waypoints", str(d / "waypoints.csv"), "--out", str(d / "out.ply"),
                   "--out-waypoints", str(d / "out.csv")]
            src = o3d.io.read_point_cloud(str(d / "t.ply"))
            if args.spacing:
                # Back from the CT's world to the phantom's frame (ribreg_sim::phantom::ct::
                # WORLD_SHIFT_MM), where ICP's identity start is the phantom's pose; ribreg
                # needs no start.
                src.translate([-18.0, 412.0, -75.0])
            tgt = o3d.io.read_point_cloud(str(d / "target.ply"))
            # Interleaved, one of each per repeat, so that a slow spell of a shared machine
            # falls on both.
            ours, theirs, before = [], [], []
            timed = [(args.ribreg, ours)] + ([(args.before, before)] if args.before else [])
            for repeat in range(args.repeats):
                # The two ribregs take turns at running first after Open3D's call (whose
                # OpenMP threads may still spin on the other core).
                for exe, times in timed[::-1] if repeat % 2 else timed:
                    t = time.perf_counter()
                    run(*reg, exe=exe)
                    times.append(time.perf_counter() - t)
                if args.no_icp:
                    continue
                t = time.perf_counter()
                o3d.pipelines.registration.registration_icp(
                    src, tgt, 20.0, np.eye(4),
                    o3d.pipelines.registration.TransformationEstimationPointToPoint(),
                    o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=100))
                theirs.append(time.perf_counter() - t)
            a = statistics.median(ours)
            row = [str(seed), f"{len(src.points)} / {len(tgt.points)}", f"{a * 1e3:.1f} ms"]
            if args.before:
                c = statistics.median(before)
                paired_ratios.append(statistics.median(x / y for x, y in zip(ours, before)))
                row += [f"{c * 1e3:.1f} ms", f"{paired_ratios[-1]:.3f}"]
            if not args.no_icp:
                b = statistics.median(theirs)
                ratios.append(a / b)
                row += [f"{b * 1e3:.1f} ms", f"{a / b:.2f}"]
                if args.before:
                    before_ratios.append(c / b)
                    row.append(f"{c / b:.2f}")
            print("| " + " | ".join(row) + " |")
    if ratios:
        print(f"median ratio ribreg / Open3D: {statistics.median(ratios):.2f}")
    if before_ratios:
        print(f"median ratio before / Open3D: {statistics.median(before_ratios):.2f}")
    if paired_ratios:
        print(f"median paired ratio ribreg / before: {statistics.median(paired_ratios):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
