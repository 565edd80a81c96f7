"""Shared fixtures: the `ribreg` CLI binary and phantom pairs it writes."""

import os
import pathlib
import subprocess

import pytest

REPO = pathlib.Path(__file__).resolve().parents[3]


@pytest.fixture(scope="session")
def ribreg_bin() -> pathlib.Path:
    """The CLI the package is compared with: $RIBREG_BIN, else the workspace's release
    build (built here if missing)."""
    if "RIBREG_BIN" in os.environ:
        return pathlib.Path(os.environ["RIBREG_BIN"])
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    exe = target / "release" / "ribreg"
    if not exe.exists():
        subprocess.run(
            ["cargo", "build", "--release", "-q", "-p", "ribreg-sim"], cwd=REPO, check=True
        )
    return exe


@pytest.fixture(scope="session")
def phantoms(ribreg_bin, tmp_path_factory):
    """A function (seed, variant) -> folder with template.ply, target.ply, waypoints.csv."""
    cache = {}

    def make(seed: int, variant: str = "aligned") -> pathlib.Path:
        key = (seed, variant)
        if key not in cache:
            out = tmp_path_factory.mktemp(f"phantom-{seed}-{variant}")
            subprocess.run(
                [ribreg_bin, "phantom", "-q", "--seed", str(seed), "--variant", variant,
                 "--out-dir", out],
                check=True,
            )
            cache[key] = out
        return cache[key]

    return make
