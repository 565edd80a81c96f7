#!/usr/bin/env python3
"""Seed corpora of the fuzz targets, from the checked-in fixtures and from files the
`ribreg` CLI writes (a phantom, its sweep, a prepared template). Standard library only.

    python3 tests/fuzz/seeds.py GENERATED_DIR OUT_DIR

GENERATED_DIR holds `phantom/` (`ribreg phantom`), `sweep/` (`ribreg phantom sweep`) and
`prepared.ply` (`ribreg template --prepared`); run.sh makes them. Targets that read
several formats take a first byte that picks the format (see each target's docs); the
seeds carry it. Seeds are cut to 64 KiB (libFuzzer's -max_len in run.sh).
"""

import gzip
import json
import pathlib
import struct
import sys

REPO = pathlib.Path(__file__).resolve().parents[2]
FIX = REPO / "tests" / "fixtures"
MAX = 64 * 1024


def main() -> None:
    gen, out = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
    seeds: dict[str, list[tuple[str, bytes]]] = {}

    def add(target: str, name: str, data: bytes) -> None:
        seeds.setdefault(target, []).append((name, data[:MAX]))

    ph, sw = gen / "phantom", gen / "sweep"
    clouds, volumes = FIX / "formats" / "clouds", FIX / "formats" / "volumes"

    # PLY: the phantom's binary clouds, an ascii and a big-endian one written here.
    pts = [(1.5 * i, -2.0 * i, 0.25 * i, 2 + i % 4) for i in range(12)]
    head = "ply\nformat {} 1.0\nelement vertex 12\nproperty float x\nproperty float y\n" \
           "property float z\nproperty int label\nend_header\n"
    add("ply", "ascii.ply", (head.format("ascii") + "".join(
        f"{x} {y} {z} {l}\n" for x, y, z, l in pts)).encode())
    add("ply", "be.ply", head.format("binary_big_endian").encode() + b"".join(
        struct.pack(">fffi", *p) for p in pts))
    for f in ("template.ply", "target.ply", "template_mesh.ply"):
        add("ply", f, (ph / f).read_bytes())
    add("prepared", "prepared.ply", (gen / "prepared.ply").read_bytes())
    add("prepared", "template.ply", (ph / "template.ply").read_bytes())

    # Meshes: tag 0 = OBJ, 1 = STL, 2 = PLY.
    obj = b"# SPACE=LPS\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\nf 2/1 3/2 4/3\n"
    add("mesh", "small.obj", b"\x00" + obj)
    add("mesh", "phantom.obj", b"\x00" + (ph / "template_mesh.obj").read_bytes())
    for f in ("slicer_lps_binary.stl", "slicer_ras_ascii.stl"):
        add("mesh", f, b"\x01" + (clouds / f).read_bytes())
    add("mesh", "phantom.ply", b"\x02" + (ph / "template_mesh.ply").read_bytes())

    # Text clouds: tag 0 = cloud CSV, 1 = waypoint CSV, 2 = point CSV, 3 = XYZ.
    add("text_clouds", "cloud.csv", b"\x00x,y,z,label\n1,2,3,2\n4,5,6,1\n")
    add("text_clouds", "waypoints.csv", b"\x01" + (ph / "waypoints.csv").read_bytes())
    add("text_clouds", "slicer.csv", b"\x01" + (clouds / "slicer_markups_lps.csv").read_bytes())
    add("text_clouds", "points.csv", b"\x02" + (ph / "true_waypoints.csv").read_bytes())
    for f in ("o3d.xyz", "o3d.xyzn", "o3d.xyzrgb"):
        add("text_clouds", f, b"\x03" + (clouds / f).read_bytes())
    # A sweep's imaged lines (`compound --imaged`): one line, both ends.
    add("text_clouds", "lines.csv", b"\x04line,end,x,y,z,across_x,across_y,across_z,"
        b"normal_x,normal_y,normal_z,width_mm\n0,0,0,0,0,0,1,0,1,0,0,38.4\n"
        b"0,1,100,0,0,0,1,0,1,0,0,38.4\n")

    # Markups: tag 0 = .mrk.json, 1 = .fcsv.
    for f in ("slicer_lps.mrk.json", "slicer_ras.mrk.json"):
        add("markups", f, b"\x00" + (clouds / f).read_bytes())
    for f in ("slicer_lps.fcsv", "slicer_ras0.fcsv"):
        add("markups", f, b"\x01" + (clouds / f).read_bytes())

    # Volumes: tag 0 = NIfTI-1 (uncompressed bytes), 1 = NRRD.
    for f in sorted(volumes.glob("*.nii")):
        add("volume", f.name, b"\x00" + f.read_bytes())
    for f in sorted(volumes.glob("*.nii.gz")):
        add("volume", f.name[:-3], b"\x00" + gzip.decompress(f.read_bytes()))
    for f in sorted(volumes.glob("*.nrrd")):
        add("volume", f.name, b"\x01" + f.read_bytes())

    for f in ("o3d_ascii.pcd", "o3d_binary.pcd", "o3d_compressed.pcd", "o3d_points_compressed.pcd"):
        add("pcd", f, (clouds / f).read_bytes())

    # PLUS sequences: the sweep's, cut (the reader's header and first frames).
    for f in ("calib.seq.mha", "sweep.seq.mha"):
        add("plus_sequence", f, (sw / f).read_bytes())

    # Wire: the golden frames, one by one and all in a stream.
    cases = json.loads((FIX / "golden" / "wire.json").read_text())["cases"]
    frames = [bytes.fromhex(c["frame"]) for c in cases]
    for c, fr in zip(cases, frames):
        add("wire", c["name"], fr)
    add("wire", "stream", b"".join(frames))

    # Controller: start k (0 fresh, 1..64 a snapshot), then steps. Each golden message to
    # the controller as "next" (tag 0, length, postcard of the message), time passing
    # (tag 3), garbage (tag 2) and a duplicate (tag 1).
    def body(postcard_hex: str) -> bytes:
        b = bytes.fromhex(postcard_hex)
        i = 0
        while b[i] & 0x80:  # the envelope's seq varint
            i += 1
        return b[i + 1:]

    to_ctrl = [body(c["postcard"]) for c in cases if c["direction"] == "to_controller"]
    steps = b"".join(bytes([0, len(m)]) + m for m in to_ctrl if len(m) < 256)
    for k in (0, 8, 16, 24, 32, 40, 48, 56, 64):
        add("controller", f"snapshot{k}", bytes([k]) + steps[:600] + b"\x03\x0a")
    add("controller", "garbage", b"\x20\x02\x04\x01\x02\x03\x04\x01\x05\x00\x02\x00\x03\xff")

    # Register: arbitrary bytes (the structured input is drawn from them).
    add("register", "zeros", bytes(4096))
    add("register", "phantom", (ph / "template.ply").read_bytes()[:16384])

    for target, files in seeds.items():
        d = out / target
        d.mkdir(parents=True, exist_ok=True)
        for name, data in files:
            (d / name).write_bytes(data)
    print(f"seeds: {sum(len(v) for v in seeds.values())} files for {len(seeds)} targets in {out}")


if __name__ == "__main__":
    main()
