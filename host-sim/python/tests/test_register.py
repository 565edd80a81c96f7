"""The numpy registration API against the CLI on phantoms, and its refusals."""

import csv
import subprocess
import threading

import numpy as np
import pytest

import ribreg

TOL_MM = 1e-6


def cli_register(ribreg_bin, ph, out, *extra, template=None):
    subprocess.run(
        [ribreg_bin, "register", "-q",
         "--template", template or ph / "template.ply", "--target", ph / "target.ply",
         "--waypoints", ph / "waypoints.csv", "--out", out / "registered.ply",
         "--out-waypoints", out / "mapped.csv", "--report", out / "report.json", *extra],
        check=True,
    )
    registered, _ = ribreg.read_cloud(out / "registered.ply")
    mapped, _ = ribreg.read_waypoints(out / "mapped.csv")
    return registered, mapped


@pytest.mark.parametrize("seed,variant", [(0, "aligned"), (1, "misaligned"), (2, "aligned"),
                                          (3, "misaligned")])
def test_equals_cli(ribreg_bin, phantoms, tmp_path, seed, variant):
    ph = phantoms(seed, variant)
    registered_cli, mapped_cli = cli_register(ribreg_bin, ph, tmp_path)
    template, labels = ribreg.read_cloud(ph / "template.ply")
    target, _ = ribreg.read_cloud(ph / "target.ply")
    waypoints, _ = ribreg.read_waypoints(ph / "waypoints.csv")
    reg = ribreg.register(template, target, labels, waypoints=waypoints)
    assert np.abs(reg.registered - registered_cli).max() <= TOL_MM
    assert np.abs(reg.waypoints - mapped_cli).max() <= TOL_MM
    assert np.abs(reg.transform(waypoints) - mapped_cli).max() <= TOL_MM
    assert reg.supported.dtype == np.bool_ and reg.supported.all()
    assert len(reg.report["waypoint_reach"]["waypoints"]) == len(waypoints)
    report = reg.report
    assert report["method"] == "improved"
    assert len(report["skeleton"]["template"]) == 30 == len(report["skeleton"]["target"])
    assert report["metrics"]["ed_mean_mm"] > 0
    assert set(report["timings_ms"]) >= {"template", "register", "map", "metrics"}


@pytest.mark.parametrize("seed", [0, 1])
def test_paper_method_agrees_with_cli(ribreg_bin, phantoms, tmp_path, seed):
    """The paper's method: the same result as the CLI, or the same refusal."""
    ph = phantoms(seed)
    template, labels = ribreg.read_cloud(ph / "template.ply")
    target, _ = ribreg.read_cloud(ph / "target.ply")
    cli = subprocess.run(
        [ribreg_bin, "register", "-q", "--method", "paper", "--template", ph / "template.ply",
         "--target", ph / "target.ply", "--out", tmp_path / "registered.ply"],
        capture_output=True, text=True,
    )
    try:
        reg = ribreg.register(template, target, labels, method="paper")
    except ValueError as e:
        assert cli.returncode != 0 and str(e) in cli.stderr, (str(e), cli.stderr)
        return
    assert cli.returncode == 0, cli.stderr
    registered_cli, _ = ribreg.read_cloud(tmp_path / "registered.ply")
    assert np.abs(reg.registered - registered_cli).max() <= TOL_MM


def test_rigid_is_a_proper_rigid_transform(phantoms):
    ph = phantoms(1, "misaligned")
    template, labels = ribreg.read_cloud(ph / "template.ply")
    target, _ = ribreg.read_cloud(ph / "target.ply")
    reg = ribreg.register(template, target, labels)
    m = reg.rigid
    assert m.shape == (4, 4) and m.dtype == np.float64
    np.testing.assert_allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-5)
    assert np.linalg.det(m[:3, :3]) == pytest.approx(1.0, abs=1e-5)
    np.testing.assert_array_equal(m[3], [0, 0, 0, 1])
    # The report's rotation is the inverse pose (target -> template).
    np.testing.assert_allclose(np.array(reg.report["endpoint_match"]["rotation"]).T,
                               m[:3, :3], atol=1e-6)
    # The rigid part alone carries the template near the target: within the phantom's
    # misalignment of 20-40 mm it lands within a few mm on the waypoints.
    waypoints, _ = ribreg.read_waypoints(ph / "waypoints.csv")
    rigid_mapped = waypoints @ m[:3, :3].T + m[:3, 3]
    assert np.linalg.norm(rigid_mapped - reg.transform(waypoints), axis=1).max() < 10.0


def test_any_dtype_and_memory_order(phantoms):
    ph = phantoms(0)
    template, labels = ribreg.read_cloud(ph / "template.ply")
    target, _ = ribreg.read_cloud(ph / "target.ply")
    reference = ribreg.register(template, target, labels).registered
    as_f32 = ribreg.register(template, target.astype(np.float32), labels.astype(np.uint8))
    fortran = ribreg.register(np.asfortranarray(template), np.asfortranarray(target),
                              labels.astype(np.int64))
    strided = np.zeros((len(template), 6))
    strided[:, ::2] = template
    from_view = ribreg.register(strided[:, ::2], target.tolist(), list(labels))
    # The core computes in f32: an f32 target is the same input.
    for r in (as_f32, fortran, from_view):
        np.testing.assert_array_equal(r.registered, reference)
        assert r.registered.flags["C_CONTIGUOUS"]


def test_prepared_template_equals_the_cloud_and_the_cli(ribreg_bin, phantoms, tmp_path):
    ph = phantoms(2)
    template, labels = ribreg.read_cloud(ph / "template.ply")
    target, _ = ribreg.read_cloud(ph / "target.ply")
    waypoints, _ = ribreg.read_waypoints(ph / "waypoints.csv")
    direct = ribreg.register(template, target, labels)
    tpl = ribreg.Template(template, labels)
    assert len(tpl) == len(template) and tpl.skeleton.shape == (30, 3)
    np.testing.assert_array_equal(tpl.points, template)
    np.testing.assert_array_equal(tpl.labels, labels)
    for reg in (ribreg.register(tpl, target),
                ribreg.register(template, target, labels, prepared=tpl)):
        np.testing.assert_array_equal(reg.registered, direct.registered)
        np.testing.assert_array_equal(reg.transform(waypoints), direct.transform(waypoints))
    # Saved here, loaded by the CLI; prepared by the CLI, loaded here.
    tpl.save(tmp_path / "prepared.ply")
    _, mapped_cli = cli_register(ribreg_bin, ph, tmp_path, template=tmp_path / "prepared.ply")
    assert np.abs(direct.transform(waypoints) - mapped_cli).max() <= TOL_MM
    subprocess.run([ribreg_bin, "template", "-q", "--cloud", ph / "template.ply",
                    "--out", tmp_path / "cli-template.ply",
                    "--prepared", tmp_path / "cli-prepared.ply"], check=True)
    loaded = ribreg.Template.load(tmp_path / "cli-prepared.ply")
    _, mapped_cli = cli_register(ribreg_bin, ph, tmp_path,
                                 template=tmp_path / "cli-prepared.ply")
    assert np.abs(ribreg.register(loaded, target).transform(waypoints) - mapped_cli).max() \
        <= TOL_MM
    again = ribreg.Template.load(tmp_path / "prepared.ply")
    np.testing.assert_array_equal(again.skeleton, tpl.skeleton)


def test_releases_the_interpreter(phantoms):
    """Another Python thread runs while a registration does."""
    ph = phantoms(0)
    template, labels = ribreg.read_cloud(ph / "template.ply")
    target, _ = ribreg.read_cloud(ph / "target.ply")
    tpl = ribreg.Template(template, labels)
    done = threading.Event()

    def work():
        for _ in range(5):
            ribreg.register(tpl, target)
        done.set()

    worker = threading.Thread(target=work)
    ticks = 0
    worker.start()
    while not done.is_set():
        ticks += 1
    worker.join()
    # Holding the interpreter for ~15 ms a call, the loop would run only between calls.
    assert ticks > 10_000


def test_target_up_equals_the_cli(ribreg_bin, phantoms, tmp_path):
    """`target_up` is `ribreg register --target-up`; a turned-away one is refused alike."""
    ph = phantoms(1, "misaligned")
    template, labels = ribreg.read_cloud(ph / "template.ply")
    target, _ = ribreg.read_cloud(ph / "target.ply")
    waypoints, _ = ribreg.read_waypoints(ph / "waypoints.csv")
    up = ribreg.register(template, target, labels).rigid[:3, 2]  # the template's anterior
    registered_cli, mapped_cli = cli_register(
        ribreg_bin, ph, tmp_path, "--target-up", ",".join(f"{c:.6f}" for c in up))
    reg = ribreg.register(template, target, labels, waypoints=waypoints,
                          target_up=np.round(up, 6))
    assert np.abs(reg.registered - registered_cli).max() <= TOL_MM
    assert np.abs(reg.waypoints - mapped_cli).max() <= TOL_MM
    # The opposite direction leaves no pose within 60 degrees of it.
    cli = subprocess.run(
        [ribreg_bin, "register", "-q", "--template", ph / "template.ply",
         "--target", ph / "target.ply", "--out", tmp_path / "r.ply",
         "--target-up", ",".join(f"{-c:.6f}" for c in up)],
        capture_output=True, text=True)
    with pytest.raises(ribreg.RegistrationError) as e:
        ribreg.register(template, target, labels, target_up=-np.round(up, 6))
    assert cli.returncode == 2 and str(e.value) in cli.stderr, (str(e.value), cli.stderr)
    assert ribreg.error_summary(e.value.code) != "unknown error code"


def beyond_ribs_3_and_4(template, labels):
    """A planned point 20 mm beyond the left lateral ends of cartilages 3 and 4."""
    ends = [template[(labels == rib) & (template[:, 0] > 0)] for rib in (3, 4)]
    tips = [e[np.argmax(e[:, 0])] for e in ends]
    return (tips[0] + tips[1]) / 2 + [20.0, 0.0, 0.0]


def test_a_waypoint_the_sweep_does_not_reach_is_refused_or_marked(ribreg_bin, phantoms,
                                                                   tmp_path):
    """As `ribreg register`: refused (code 24) by default; with `partial=True` mapped and
    marked, with every other waypoint on its side, and the same marks as the CLI's CSV."""
    ph = phantoms(0)
    template, labels = ribreg.read_cloud(ph / "template.ply")
    target, _ = ribreg.read_cloud(ph / "target.ply")
    planned, _ = ribreg.read_waypoints(ph / "waypoints.csv")
    plan = np.vstack([planned, beyond_ribs_3_and_4(template, labels)])
    path = tmp_path / "plan.csv"
    np.savetxt(path, plan, delimiter=",", header="x,y,z", comments="", fmt="%.6f")
    plan, _ = ribreg.read_waypoints(path)

    def cli(*extra):
        return subprocess.run(
            [ribreg_bin, "register", "-q", "--template", ph / "template.ply",
             "--target", ph / "target.ply", "--waypoints", path,
             "--out", tmp_path / "registered.ply", "--out-waypoints", tmp_path / "mapped.csv",
             *extra],
            capture_output=True, text=True)

    refused = cli()
    with pytest.raises(ribreg.RegistrationError) as e:
        ribreg.register(template, target, labels, waypoints=plan)
    assert isinstance(e.value, ValueError) and e.value.code == 24
    assert refused.returncode == 2 and str(e.value) in refused.stderr, refused.stderr
    # Without waypoints the same registration is accepted: only the plan is refused.
    ribreg.register(template, target, labels)

    assert cli("--partial").returncode == 0
    with open(tmp_path / "mapped.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    marks_cli = np.array([r["supported"] == "true" for r in rows])
    reg = ribreg.register(template, target, labels, waypoints=plan, partial=True)
    np.testing.assert_array_equal(reg.supported, marks_cli)
    assert not reg.supported[-1]
    left = plan[:, 0] > 0
    assert not reg.supported[left].any() and reg.supported[~left].all()
    mapped_cli, _ = ribreg.read_waypoints(tmp_path / "mapped.csv")
    assert np.abs(reg.waypoints - mapped_cli).max() <= TOL_MM


def test_bad_input_raises_value_error_with_the_core_message(phantoms):
    ph = phantoms(0)
    template, labels = ribreg.read_cloud(ph / "template.ply")
    target, _ = ribreg.read_cloud(ph / "target.ply")
    cases = [
        (lambda: ribreg.register(template[:, :2], target, labels), "(N, 3)"),
        (lambda: ribreg.register(template, target[:0], labels), "target"),
        (lambda: ribreg.register(template, target, labels[:-1]), "labels"),
        (lambda: ribreg.register(template, target), "needs template labels"),
        (lambda: ribreg.register(template, target, labels * 0 + 9), "not a rib number"),
        (lambda: ribreg.register(template, target, labels, method="icp"), "method"),
    ]
    nan = target.copy()
    nan[7, 1] = np.nan
    cases.append((lambda: ribreg.register(template, nan, labels), "NaN or infinite"))
    huge = target.copy()
    huge[3, 0] = 1e300
    cases.append((lambda: ribreg.register(template, huge, labels), "beyond"))
    tpl = ribreg.Template(template, labels)
    cases.append((lambda: ribreg.register(tpl, target, method="paper"), "improved method"))
    cases.append((lambda: ribreg.register(template[1:], target, labels[1:], prepared=tpl),
                  "another cloud"))
    cases.append((lambda: ribreg.Template(template, labels * 0), "rib"))
    reg = ribreg.register(tpl, target)
    cases.append((lambda: reg.transform([[0.0, np.inf, 0.0]]), "NaN or infinite"))
    cases.append((lambda: ribreg.register(template, "abc", labels), ""))
    cases.append((lambda: ribreg.register(template, target, labels, waypoints=[[1.0, 2.0]]),
                  "waypoints"))
    cases.append((lambda: ribreg.register(template, target, labels, target_up=[0, 0, 0]),
                  "target_up"))
    cases.append((lambda: ribreg.register(template, target, labels, target_up=[0, 1]),
                  "target_up"))
    cases.append((lambda: ribreg.register(template, target, labels, method="paper",
                                          partial=True), "improved method"))
    for call, needle in cases:
        with pytest.raises(ValueError) as e:
            call()
        assert needle in str(e.value), (needle, str(e.value))


def test_readers(tmp_path, phantoms):
    ph = phantoms(0)
    with pytest.raises(OSError):
        ribreg.read_cloud(tmp_path / "missing.ply")
    (tmp_path / "bad.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 2\nend_header\n")
    with pytest.raises(ValueError, match="bad.ply"):
        ribreg.read_cloud(tmp_path / "bad.ply")
    (tmp_path / "plan.csv").write_text("label,l,p,s\nA,1,2,3\nB,4,5,6\n")
    points, names = ribreg.read_waypoints(tmp_path / "plan.csv")
    assert names == ["A", "B"] and points.shape == (2, 3)
    points, names = ribreg.read_waypoints(ph / "waypoints.csv")
    assert points.shape == (10, 3) and names == [""] * 10
    target, labels = ribreg.read_cloud(ph / "target.ply")
    assert labels is None and target.dtype == np.float64


def swept(ribreg_bin, tmp_path, margin):
    """`ribreg phantom sweep --seed 1 --margin-mm MARGIN`, compounded with its lines."""
    d = tmp_path / f"sweep{margin}"
    subprocess.run([ribreg_bin, "-q", "phantom", "sweep", "--seed", "1", "--margin-mm",
                    str(margin), "--out-dir", d], check=True)
    subprocess.run([ribreg_bin, "-q", "compound", "--poses", d / "poses.csv", "--frames",
                    d / "frames.csv", "--probe", d / "probe.json", "--lag-ms", "268",
                    "-o", d / "us.ply", "--imaged", d / "lines.csv"], check=True)
    return d


def test_a_rib_end_at_the_sweep_s_edge_is_refused_as_by_the_cli(ribreg_bin, tmp_path):
    """As `ribreg register --imaged`: a sweep whose lines stop 20 mm inside the
    cartilages is refused (code 27, the CLI's message), with `partial=True` too (both
    sides are cut); the default sweep, 20 mm past them, is registered."""
    for margin in (20, -20):
        d = swept(ribreg_bin, tmp_path, margin)
        template, labels = ribreg.read_cloud(d / "template.ply")
        target, _ = ribreg.read_cloud(d / "us.ply")
        planned, _ = ribreg.read_waypoints(d / "waypoints.csv")
        if margin == 20:
            reg = ribreg.register(template, target, labels, waypoints=planned,
                                  partial=True, imaged=d / "lines.csv")
            assert all(reg.supported)
            continue
        cli = subprocess.run(
            [ribreg_bin, "register", "-q", "--template", d / "template.ply", "--target",
             d / "us.ply", "--waypoints", d / "waypoints.csv", "--out",
             tmp_path / "registered.ply", "--imaged", d / "lines.csv"],
            capture_output=True, text=True)
        for partial in (False, True):
            with pytest.raises(ribreg.RegistrationError) as e:
                ribreg.register(template, target, labels, waypoints=planned,
                                partial=partial, imaged=str(d / "lines.csv"))
            assert e.value.code == 27
            assert cli.returncode == 2 and str(e.value) in cli.stderr, cli.stderr
        # Without the lines the cloud alone passes: what the check is for.
        ribreg.register(template, target, labels, waypoints=planned)
    with pytest.raises(ValueError, match="imaged need the improved method"):
        ribreg.register(template, target, waypoints=planned, method="paper",
                        imaged=d / "lines.csv")
    (tmp_path / "bad.csv").write_text("line,end\n0,0\n")
    with pytest.raises(ValueError, match="bad.csv"):
        ribreg.register(template, target, labels, imaged=tmp_path / "bad.csv")
