#!/usr/bin/env python3
"""Generate golden-vector fixtures for ribreg from independent libraries.

Run from the repository root:

    python3 tests/golden/gen_golden.py

Writes tests/fixtures/golden/{mst,hull,polyfit,kabsch,hausdorff}.json.
Every fixture has the shape

    {"generator": {"script": ..., "numpy": ..., "scipy": ..., "python": ...},
     "cases": [ {...}, ... ]}

All random data comes from numpy.random.default_rng(<fixed seed per case>).
Input coordinates are mostly rounded to 3 or 4 decimals (mm) *before* the
reference library is called, so the stored inputs are exactly the values the
library saw and the files stay small; outputs are stored at full precision
(Python float repr, which round-trips f64 exactly).

Every reference value is also cross-checked here against a second, independent
computation (own Prim, shoelace area, least squares, SVD Kabsch, brute-force
distances); the script aborts if any check fails.  See README.md.
"""

import json
import os
import platform
import sys

import numpy as np
import scipy
from scipy.linalg import orthogonal_procrustes
from scipy.sparse.csgraph import minimum_spanning_tree
from scipy.spatial import ConvexHull, cKDTree
from scipy.spatial.distance import cdist, directed_hausdorff
from scipy.spatial.transform import Rotation

SCRIPT = "tests/golden/gen_golden.py"
OUT_DIR = os.path.join("tests", "fixtures", "golden")
MST_EPS = 1e-6  # mm, stand-in weight for zero-length edges (see mst_case)


def generator_info():
    return {
        "script": SCRIPT,
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "python": platform.python_version(),
    }


def rng(seed):
    return np.random.default_rng(seed)


def fl(a):
    """numpy array / scalar -> nested lists of Python floats."""
    return np.asarray(a, dtype=np.float64).tolist()


def ints(a):
    return [int(v) for v in np.asarray(a).ravel()]


def rounded(a, decimals):
    # np.round then tolist: each value is the f64 nearest to a short decimal,
    # so its repr is short and parses back to the identical f64.
    return np.round(np.asarray(a, dtype=np.float64), decimals)


def rib_skeleton(seed, per_rib=5, noise=1.0):
    """Rib-cartilage-like skeleton key points (mm), patient frame.

    Ribs 2..5, left and right costal cartilage, `per_rib` points each:
    x lateral (0 at midline), y cranial, z anterior.
    """
    g = rng(seed)
    pts = []
    for k in range(2, 6):
        for side in (-1.0, 1.0):
            x = side * np.linspace(22.0, 95.0 + 6.0 * k, per_rib)
            y = 80.0 - 38.0 * (k - 2) - 0.0035 * x**2 - 0.12 * np.abs(x)
            z = 45.0 - 0.0045 * x**2
            pts.append(np.stack([x, y, z], axis=1))
    p = np.concatenate(pts, axis=0)
    return p + g.normal(0.0, noise, p.shape)


def write_fixture(name, cases):
    doc_cases = [json.dumps(c, separators=(",", ":"), allow_nan=False) for c in cases]
    gen = json.dumps(generator_info(), separators=(",", ":"))
    text = '{"generator":' + gen + ',\n"cases":[\n' + ",\n".join(doc_cases) + "\n]}\n"
    json.loads(text)  # sanity: valid JSON
    path = os.path.join(OUT_DIR, name)
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)
    return path


# --------------------------------------------------------------------------
# MST
# --------------------------------------------------------------------------

def prim_total(d):
    """Independent O(n^2) Prim on a dense distance matrix (0 is a real weight)."""
    n = d.shape[0]
    in_tree = np.zeros(n, dtype=bool)
    best = np.full(n, np.inf)
    best[0] = 0.0
    total = 0.0
    for _ in range(n):
        i = int(np.argmin(np.where(in_tree, np.inf, best)))
        in_tree[i] = True
        total += best[i]
        best = np.where(in_tree, best, np.minimum(best, d[i]))
    return total


def uniqueness_margin(d, edges):
    """min over non-tree pairs (i,j) of d[i,j] - (max edge on the tree path i..j).

    > 0 means the MST is unique and any edge swap costs at least this much;
    0 means ties (e.g. duplicate points) so the edge set is not unique.
    """
    n = d.shape[0]
    if n <= 2:
        return None
    adj = [[] for _ in range(n)]
    for i, j in edges:
        adj[i].append(j)
        adj[j].append(i)
    margin = np.inf
    tree = {(min(i, j), max(i, j)) for i, j in edges}
    for s in range(n):
        maxw = np.full(n, -1.0)
        maxw[s] = 0.0
        stack = [s]
        while stack:
            u = stack.pop()
            for v in adj[u]:
                if maxw[v] < 0:
                    maxw[v] = max(maxw[u], d[u, v])
                    stack.append(v)
        for t in range(s + 1, n):
            if (s, t) not in tree:
                margin = min(margin, d[s, t] - maxw[t])
    return float(margin)


def mst_case(name, desc, points):
    p = np.asarray(points, dtype=np.float64)
    n = p.shape[0]
    d = cdist(p, p)  # dense Euclidean distance matrix
    # scipy's csgraph reads a dense entry as "no edge" when it is 0 -- and in
    # fact whenever |w| <= 1e-8 (the dense->masked conversion uses
    # np.ma.masked_values with its default atol=1e-8), so a stand-in like
    # 1e-300 or 1e-12 is silently dropped too and yields a WRONG tree.
    # Off-diagonal zeros (duplicate points) are therefore replaced by
    # MST_EPS = 1e-6 mm: above scipy's null tolerance, far below every genuine
    # distance (asserted), so the selected tree is a true MST.  The total
    # weight is then summed from the TRUE distances d[i, j] of the edges scipy
    # selected, so the stand-in never enters it.
    off = ~np.eye(n, dtype=bool)
    nonzero = d[off & (d > 0.0)]
    if nonzero.size:
        assert nonzero.min() > 1e4 * MST_EPS, (name, "genuine distance too close to MST_EPS")
    dz = d.copy()
    n_zero_pairs = int(np.count_nonzero((dz == 0.0) & off) // 2)
    dz[(dz == 0.0) & off] = MST_EPS
    t = minimum_spanning_tree(dz).tocoo()
    edges = sorted((min(int(i), int(j)), max(int(i), int(j))) for i, j in zip(t.row, t.col))
    assert len(edges) == n - 1, (name, len(edges))
    total = float(sum(d[i, j] for i, j in edges))
    check = prim_total(d)
    assert abs(total - check) <= 1e-9 * max(1.0, total), (name, total, check)
    if n_zero_pairs == 0:
        # plain scipy call on the untouched matrix gives the same number
        plain = float(minimum_spanning_tree(d).sum())
        assert abs(plain - total) <= 1e-9 * max(1.0, total), (name, plain, total)
    return {
        "name": name,
        "description": desc,
        "points": fl(p),
        "total_weight": total,
        "edges": n - 1,
        "tree_edges": [list(e) for e in edges],
        "uniqueness_margin": uniqueness_margin(d, edges),
        "duplicate_pairs": n_zero_pairs,
    }


def gen_mst():
    cases = []
    cases.append(mst_case("n2", "two points", rounded([[12.5, -40.25, 30.0], [-33.0, 17.75, 61.5]], 4)))
    cases.append(mst_case("n3_triangle", "three points, scalene triangle",
                          rounded(rng(101).uniform(-80, 80, (3, 3)), 4)))
    cases.append(mst_case("n10_random", "10 points uniform in a 200 mm cube",
                          rounded(rng(102).uniform(-100, 100, (10, 3)), 4)))
    cases.append(mst_case("n40_rib_skeleton",
                          "40 rib-cartilage-like skeleton key points (ribs 2..5, both sides, 5 per rib, 1 mm noise)",
                          rounded(rib_skeleton(103), 4)))
    cases.append(mst_case("n40_random", "40 points uniform in x[-120,120] y[-100,100] z[0,60]",
                          rounded(rng(104).uniform([-120, -100, 0], [120, 100, 60], (40, 3)), 4)))
    cases.append(mst_case("n100_gaussian", "100 points, isotropic Gaussian sd 50 mm around (10, 200, 900)",
                          rounded(rng(105).normal([10, 200, 900], 50, (100, 3)), 4)))
    base = rounded(rng(106).uniform(-60, 60, (14, 3)), 4)
    # duplicates: point 0 twice more (a triple), points 3 and 7 once more each
    dup = np.concatenate([base, base[[0, 3, 7, 0]]], axis=0)
    dup = dup[rng(107).permutation(dup.shape[0])]
    cases.append(mst_case("n18_duplicates",
                          "14 distinct points + 4 exact copies (one point appears 3 times, two appear twice), shuffled",
                          dup))
    g = rng(108)
    s = np.sort(g.uniform(0, 150, 12))
    direction = np.array([0.8, 0.36, 0.48])
    line = np.array([-70.0, 20.0, 35.0]) + s[:, None] * direction[None, :]
    cases.append(mst_case("n12_nearly_collinear",
                          "12 points on a 150 mm line with 0.01 mm Gaussian noise",
                          rounded(line + g.normal(0, 0.01, line.shape), 4)))
    return cases


# --------------------------------------------------------------------------
# Convex hull (2-D)
# --------------------------------------------------------------------------

def shoelace(poly):
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def hull_case(name, desc, points):
    p = np.asarray(points, dtype=np.float64)
    h = ConvexHull(p)
    v = ints(h.vertices)
    signed = shoelace(p[v])
    assert signed > 0, (name, "vertices not counter-clockwise")
    assert abs(signed - h.volume) <= 1e-9 * max(1.0, h.volume), (name, signed, h.volume)
    # every point inside or on the hull (half-plane test from qhull's equations)
    assert np.all(h.equations[:, :2] @ p.T + h.equations[:, 2:3] <= 1e-9 * np.abs(p).max()), name
    return {
        "name": name,
        "description": desc,
        "points": fl(p),
        "vertices": v,
        "vertex_points": fl(p[v]),
        "area": float(h.volume),
        "perimeter": float(h.area),
    }


def gen_hull():
    cases = []
    cases.append(hull_case("triangle", "three points", rounded([[-40.0, -10.0], [55.5, -20.25], [5.0, 70.0]], 4)))
    cases.append(hull_case("random20", "20 points uniform in a 200 mm square",
                           rounded(rng(201).uniform(-100, 100, (20, 2)), 4)))
    cases.append(hull_case("gaussian200", "200 points, anisotropic Gaussian (sd 70 x 40 mm) around (0, 30)",
                           rounded(rng(202).normal([0, 30], [70, 40], (200, 2)), 4)))
    # square with points exactly on its edges (collinear on hull edges) + interior
    corners = [[-50.0, -50.0], [50.0, -50.0], [50.0, 50.0], [-50.0, 50.0]]
    on_edges = ([[x, -50.0] for x in (-30.0, -10.0, 20.0, 45.0)]
                + [[50.0, y] for y in (-25.0, 0.0, 35.0)]
                + [[x, 50.0] for x in (40.0, 0.0, -12.5)]
                + [[-50.0, y] for y in (30.0, -5.0, -40.0)])
    interior = rounded(rng(203).uniform(-45, 45, (10, 2)), 4).tolist()
    sq = np.array(on_edges[:5] + corners[:2] + interior + corners[2:] + on_edges[5:], dtype=np.float64)
    cases.append(hull_case("square_collinear_edges",
                           "100 mm square: 4 corners, 13 points exactly on the edges, 10 interior points",
                           sq))
    base = rounded(rng(204).uniform(-80, 80, (25, 2)), 4)
    h0 = ConvexHull(base)
    dups = np.concatenate([base, base[h0.vertices[:3]], base[h0.vertices[:1]], base[[0, 1, 2]]], axis=0)
    dups = dups[rng(205).permutation(dups.shape[0])]
    cases.append(hull_case("duplicates",
                           "25 distinct points + copies of 3 hull vertices (one of them twice) and of 3 other points, shuffled",
                           dups))
    gx, gy = np.meshgrid(np.arange(10) * 10.0 - 45.0, np.arange(10) * 10.0 - 45.0)
    grid = np.stack([gx.ravel(), gy.ravel()], axis=1)
    cases.append(hull_case("grid10x10", "10 x 10 square grid, 10 mm pitch, row-major from (-45,-45)", grid))
    rib = rounded(rib_skeleton(206), 4)[:, :2]
    cases.append(hull_case("rib_skeleton_coronal",
                           "40 rib-like skeleton key points projected to the coronal (x, y) plane",
                           rib))
    ang = np.arange(12) * (2 * np.pi / 12) + 0.1
    circ = rounded(np.stack([60 * np.cos(ang) + 5, 60 * np.sin(ang) - 3], axis=1), 4)
    circ = np.concatenate([circ, [[5.0, -3.0]]], axis=0)
    cases.append(hull_case("dodecagon_center", "12 points on a 60 mm circle (all on hull) + centre", circ))
    return cases


# --------------------------------------------------------------------------
# Polynomial fit
# --------------------------------------------------------------------------

def polyfit_case(name, desc, x, y, degree, n_eval, coeffs_true=None):
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    c = np.polyfit(x, y, degree)
    # independent check: plain least squares on the Vandermonde matrix
    c2, *_ = np.linalg.lstsq(np.vander(x, degree + 1), y, rcond=None)
    fit_y = np.polyval(c, x)
    fit2_y = np.polyval(c2, x)
    assert np.max(np.abs(fit_y - fit2_y)) <= 1e-7 * max(1.0, np.abs(y).max()), name
    xe = np.linspace(x.min(), x.max(), n_eval)
    ye = np.polyval(c, xe)
    case = {
        "name": name,
        "description": desc,
        "x": fl(x),
        "y": fl(y),
        "degree": int(degree),
        "coeffs": fl(c),
        "residual_rms": float(np.sqrt(np.mean((fit_y - y) ** 2))),
        "x_eval": fl(xe),
        "y_eval": fl(ye),
    }
    if coeffs_true is not None:
        case["coeffs_true"] = fl(coeffs_true)
    return case


def gen_polyfit():
    cases = []
    g = rng(301)
    x = rounded(np.sort(g.uniform(-120, 110, 40)), 4)
    ct = np.array([-2.0e-5, -3.5e-3, 0.12, 60.0])  # y (cranial) along the cartilage
    cases.append(polyfit_case("cubic_noisy_y", "40 samples, x in [-120,110] mm, cubic y(x) + N(0, 0.8 mm)",
                              x, rounded(np.polyval(ct, x) + g.normal(0, 0.8, x.size), 4), 3, 10, ct))
    g = rng(302)
    x = rounded(np.sort(g.uniform(-118, 105, 30)), 4)
    ct = np.array([1.5e-6, -4.5e-3, 0.02, 42.0])  # z (anterior) along the cartilage
    cases.append(polyfit_case("cubic_noisy_z", "30 samples, x in [-118,105] mm, cubic z(x) + N(0, 0.5 mm)",
                              x, rounded(np.polyval(ct, x) + g.normal(0, 0.5, x.size), 4), 3, 8, ct))
    x = np.linspace(-100.0, 100.0, 12)
    ct = np.array([3.0e-5, -2.0e-3, 0.25, -15.0])
    cases.append(polyfit_case("cubic_exact", "12 equally spaced x in [-100,100], y exactly cubic (no noise, y stored unrounded)",
                              x, np.polyval(ct, x), 3, 6, ct))
    cases.append(polyfit_case("cubic_four_points", "exactly 4 points, degree 3 (interpolating cubic)",
                              [-95.0, -30.5, 22.25, 88.0], [31.0, 52.5, 49.75, 18.0], 3, 6))
    g = rng(305)
    x = rounded(np.sort(g.uniform(-110, 100, 15)), 4)
    ct = np.array([-3.2e-3, 0.05, 70.0])
    cases.append(polyfit_case("quadratic_noisy", "15 samples, degree 2, N(0, 0.6 mm) noise",
                              x, rounded(np.polyval(ct, x) + g.normal(0, 0.6, x.size), 4), 2, 6, ct))
    g = rng(306)
    x = rounded(np.sort(g.uniform(-60, 90, 8)), 4)
    ct = np.array([0.35, -12.0])
    cases.append(polyfit_case("linear_noisy", "8 samples, degree 1, N(0, 0.4 mm) noise",
                              x, rounded(np.polyval(ct, x) + g.normal(0, 0.4, x.size), 4), 1, 6, ct))
    g = rng(307)
    x = rounded(np.sort(g.uniform(25, 95, 10)), 4)
    ct = np.array([-1.0e-5, -2.5e-3, -0.1, 20.0])
    cases.append(polyfit_case("cubic_one_sided_short",
                              "10 samples on one side only, x in [25,95] mm (poorly conditioned Vandermonde), N(0, 0.3 mm)",
                              x, rounded(np.polyval(ct, x) + g.normal(0, 0.3, x.size), 4), 3, 6, ct))
    g = rng(308)
    xs = rounded(g.uniform(-120, 110, 16), 4)
    x = np.concatenate([xs, xs[[2, 5, 9, 11]]])
    x = x[g.permutation(x.size)]
    ct = np.array([2.5e-5, 1.0e-3, -0.3, 10.0])
    cases.append(polyfit_case("cubic_unsorted_repeated_x",
                              "20 samples, x unsorted with 4 repeated x values (different y), N(0, 1.0 mm)",
                              x, rounded(np.polyval(ct, x) + g.normal(0, 1.0, x.size), 4), 3, 10, ct))
    return cases


# --------------------------------------------------------------------------
# Kabsch
# --------------------------------------------------------------------------

def kabsch_svd(a, b):
    """Independent textbook Kabsch (proper rotation) for b ~ R a + t."""
    ac, bc = a - a.mean(0), b - b.mean(0)
    u, s, vt = np.linalg.svd(ac.T @ bc)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return r, b.mean(0) - r @ a.mean(0)


def kabsch_case(name, desc, a, r_true, t_true, noise_sd=0.0, seed=None, reflection=False):
    a = np.asarray(a, dtype=np.float64)
    r_true = np.asarray(r_true, dtype=np.float64)
    t_true = np.asarray(t_true, dtype=np.float64)
    b = a @ r_true.T + t_true
    if noise_sd > 0:
        b = b + rng(seed).normal(0, noise_sd, b.shape)
    ma, mb = a.mean(0), b.mean(0)
    rot, rssd = Rotation.align_vectors(b - mb, a - ma)
    r = rot.as_matrix()
    t = mb - r @ ma
    res = b - (a @ r.T + t)
    rmsd = float(np.sqrt(np.mean(np.sum(res**2, axis=1))))
    assert abs(np.linalg.det(r) - 1.0) < 1e-12, name
    h_sv = np.linalg.svd((a - ma).T @ (b - mb), compute_uv=False)
    r2, t2 = kabsch_svd(a, b)
    rmsd2 = float(np.sqrt(np.mean(np.sum((b - (a @ r2.T + t2)) ** 2, axis=1))))
    assert abs(rmsd - rmsd2) <= 1e-9 * max(1.0, rmsd), (name, rmsd, rmsd2)
    well_posed = h_sv[1] > 1e-6 * h_sv[0]
    if well_posed:
        assert np.max(np.abs(r - r2)) < 1e-8, (name, r, r2)
    # scipy's rssd comes from sum|a|^2 + sum|b|^2 - 2 trace(...): it suffers
    # cancellation (~1e-6 mm for exact data), so it is only checked loosely
    # here and NOT stored; rmsd above is computed from the residuals directly.
    spread = float(np.sum((a - ma) ** 2) + np.sum((b - mb) ** 2))
    assert abs(rssd**2 - rmsd**2 * a.shape[0]) <= 1e-12 * spread, (name, rssd, rmsd)
    case = {
        "name": name,
        "description": desc,
        "a": fl(a),
        "b": fl(b),
        "rotation": fl(r),
        "translation": fl(t),
        "rmsd": rmsd,
        "rotation_true": fl(r_true),
        "translation_true": fl(t_true),
        "det_true": float(round(np.linalg.det(r_true))),
        "noise_sd": float(noise_sd),
        "h_singular_values": fl(h_sv),
    }
    if reflection:
        # best orthogonal matrix (det may be -1), column convention b ~ Q a
        q, _ = orthogonal_procrustes(a - ma, b - mb)
        q = q.T
        case["orthogonal_best"] = fl(q)
        case["orthogonal_best_det"] = float(round(np.linalg.det(q)))
        case["orthogonal_best_rmsd"] = float(np.sqrt(np.mean(np.sum(((b - mb) - (a - ma) @ q.T) ** 2, axis=1))))
    return case


def rot(seed, angle_deg):
    g = rng(seed)
    axis = g.normal(size=3)
    axis /= np.linalg.norm(axis)
    return Rotation.from_rotvec(np.deg2rad(angle_deg) * axis).as_matrix()


def gen_kabsch():
    cases = []
    a10 = rounded(rib_skeleton(401, per_rib=5)[rng(402).choice(40, 10, replace=False)], 4)
    cases.append(kabsch_case("n10_typical", "10 rib-like skeleton points, 25 deg rotation, exact",
                             a10, rot(403, 25.0), [4.5, -12.0, 7.25]))
    cases.append(kabsch_case("n10_noisy_b", "same kind of set, 18 deg rotation, N(0, 0.5 mm) noise on b",
                             rounded(rib_skeleton(404)[rng(405).choice(40, 10, replace=False)], 4),
                             rot(406, 18.0), [-3.0, 8.0, -2.0], noise_sd=0.5, seed=407))
    cases.append(kabsch_case("n3_minimal", "3 points (minimum), 40 deg rotation, exact",
                             rounded(rng(408).uniform(-60, 60, (3, 3)), 4), rot(409, 40.0), [10.0, 0.0, -5.0]))
    cases.append(kabsch_case("n40_noisy", "40 rib-like points, 10 deg rotation, N(0, 1.0 mm) noise on b",
                             rounded(rib_skeleton(410), 4), rot(411, 10.0), [1.0, 2.0, 3.0], noise_sd=1.0, seed=412))
    cases.append(kabsch_case("large_rotation_170", "12 points, 170 deg rotation about a random axis, exact",
                             rounded(rng(413).uniform(-80, 80, (12, 3)), 4), rot(414, 170.0), [60.0, -45.0, 120.0]))
    cases.append(kabsch_case("large_rotation_179", "8 points, 179 deg rotation, N(0, 0.2 mm) noise on b",
                             rounded(rng(415).uniform(-80, 80, (8, 3)), 4), rot(416, 179.0), [-5.0, 5.0, 0.0],
                             noise_sd=0.2, seed=417))
    g = rng(418)
    s = g.uniform(-60, 60, 10)
    line = np.array([30.0, 10.0, 50.0]) + s[:, None] * np.array([0.6, 0.0, 0.8])[None, :]
    cases.append(kabsch_case("nearly_collinear",
                             "10 points on a 120 mm line + N(0, 0.05 mm) noise on a; rotation about the line axis is"
                             " poorly determined (see h_singular_values)",
                             rounded(line + g.normal(0, 0.05, line.shape), 4), rot(419, 30.0), [0.0, -20.0, 10.0]))
    g = rng(420)
    plane = np.concatenate([g.uniform(-70, 70, (9, 2)), np.full((9, 1), 40.0)], axis=1)
    cases.append(kabsch_case("coplanar_exact", "9 exactly coplanar points (z = 40), 60 deg rotation, exact",
                             rounded(plane, 4), rot(421, 60.0), [15.0, 25.0, -35.0]))
    cases.append(kabsch_case("identity_translation", "15 points, R = I, pure translation",
                             rounded(rng(422).uniform(-100, 100, (15, 3)), 4), np.eye(3), [-12.5, 3.0, 250.0]))
    big = rounded(rng(423).normal([-150.0, 300.0, 1200.0], [60, 40, 25], (20, 3)), 4)
    cases.append(kabsch_case("far_from_origin", "20 points centred at (-150, 300, 1200) mm, 35 deg, N(0, 0.3 mm)",
                             big, rot(424, 35.0), [200.0, -100.0, -900.0], noise_sd=0.3, seed=425))
    mirror = np.diag([1.0, 1.0, -1.0])
    aniso = rounded(rng(426).normal(0, [50, 25, 10], (12, 3)), 4)
    cases.append(kabsch_case("reflection_trap",
                             "b is a mirror image of a (z -> -z) + translation; best orthogonal matrix is the reflection"
                             " (orthogonal_best, det -1, rmsd 0); scipy returns the best PROPER rotation (det +1, rmsd > 0)",
                             aniso, mirror, [5.0, 5.0, 5.0], reflection=True))
    return cases


# --------------------------------------------------------------------------
# Hausdorff / ED
# --------------------------------------------------------------------------

def hausdorff_case(name, desc, a, b):
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    dab = directed_hausdorff(a, b)[0]
    dba = directed_hausdorff(b, a)[0]
    ed, _ = cKDTree(b).query(a)
    # brute-force cross-check
    d = cdist(a, b)
    assert abs(dab - d.min(1).max()) <= 1e-9 * max(1.0, dab), name
    assert abs(dba - d.min(0).max()) <= 1e-9 * max(1.0, dba), name
    assert np.max(np.abs(ed - d.min(1))) <= 1e-9 * max(1.0, ed.max()), name
    return {
        "name": name,
        "description": desc,
        "a": fl(a),
        "b": fl(b),
        "directed_ab": float(dab),
        "directed_ba": float(dba),
        "hausdorff": float(max(dab, dba)),
        "ed_mean": float(np.mean(ed)),
        "ed_sd": float(np.std(ed, ddof=0)),
        "ed_max": float(np.max(ed)),
    }


def surface_cloud(seed, n, offset=0.0, anterior_only=False):
    """Points on a curved rib-cartilage-like band (mm)."""
    g = rng(seed)
    x = g.uniform(-110, 110, n)
    y = g.uniform(-40, 80, n)
    z = 45.0 - 0.0045 * x**2 + 3.0 * np.sin(y / 12.0)
    if not anterior_only:
        z = z - g.uniform(0, 6.0, n)  # full thickness (~6 mm) as in CT
    return np.stack([x, y, z + offset], axis=1)


def gen_hausdorff():
    cases = []
    a = rounded(rng(501).uniform(-80, 80, (50, 3)), 3)
    cases.append(hausdorff_case("identical", "a == b (50 points): every distance is 0", a, a.copy()))
    cases.append(hausdorff_case("single_point_a", "a is a single point, b has 40 points",
                                [[10.0, -20.0, 35.0]], rounded(rng(502).uniform(-60, 60, (40, 3)), 3)))
    cases.append(hausdorff_case("single_point_b", "a has 60 points, b is a single point",
                                rounded(rng(503).normal([0, 50, 20], 30, (60, 3)), 3), [[-5.5, 42.0, 18.25]]))
    g = rng(504)
    a = g.uniform([0, 0, 0], [100, 80, 30], (300, 3))
    b = g.uniform([50, 0, 0], [150, 80, 30], (200, 3))
    cases.append(hausdorff_case("partial_overlap",
                                "300 points in box x[0,100] vs 200 points in box x[50,150] (y[0,80], z[0,30])",
                                rounded(a, 3), rounded(b, 3)))
    a = rounded(rib_skeleton(505, per_rib=15, noise=0.5), 3)
    b = rounded(a + rng(506).normal(0, 1.5, a.shape), 3)
    cases.append(hausdorff_case("perturbed_copy", "120 rib-like points vs the same points + N(0, 1.5 mm)", a, b))
    cases.append(hausdorff_case("ct_vs_us_surface",
                                "CT-like full-thickness band (150 pts) vs US-like anterior-surface band (100 pts)",
                                rounded(surface_cloud(507, 150), 3),
                                rounded(surface_cloud(508, 100, anterior_only=True), 3)))
    g = rng(509)
    cases.append(hausdorff_case("disjoint_far", "20 vs 30 points, clouds 200 mm apart",
                                rounded(g.normal(0, 10, (20, 3)), 3),
                                rounded(g.normal([200, 0, 0], 10, (30, 3)), 3)))
    return cases


def main():
    if not os.path.isdir(os.path.join("tests", "golden")):
        sys.exit("run from the repository root: python3 tests/golden/gen_golden.py")
    os.makedirs(OUT_DIR, exist_ok=True)
    for fname, gen in (("mst.json", gen_mst), ("hull.json", gen_hull), ("polyfit.json", gen_polyfit),
                       ("kabsch.json", gen_kabsch), ("hausdorff.json", gen_hausdorff)):
        cases = gen()
        path = write_fixture(fname, cases)
        print(f"{path}: {len(cases)} cases, {os.path.getsize(path)} bytes")


if __name__ == "__main__":
    main()
