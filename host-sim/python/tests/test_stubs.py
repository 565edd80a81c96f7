"""The type stubs say what the extension module really has (mypy's stubtest compares
every name, signature and class in the .pyi with the module at run time)."""

import subprocess
import sys
from pathlib import Path

ROBOT_PC = Path(__file__).resolve().parent.parent / "examples" / "robot_pc.py"


def test_stubs_match_the_extension_module():
    run = subprocess.run(
        [sys.executable, "-m", "mypy.stubtest", "ribreg._ribreg"], capture_output=True, text=True
    )
    assert run.returncode == 0, run.stdout + run.stderr


def test_the_package_type_checks_strictly():
    """The Python modules' own annotations hold (`mypy --strict` over the package, with
    the extension's stubs)."""
    run = subprocess.run(
        [sys.executable, "-m", "mypy", "--strict", "-p", "ribreg"],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stdout + run.stderr


def test_the_robot_pc_example_type_checks_strictly():
    """So does the example a robot PC's code starts from, against the installed package:
    the messages it sends are the typed ones `Session.send` takes."""
    run = subprocess.run(
        [sys.executable, "-m", "mypy", "--strict", str(ROBOT_PC)],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stdout + run.stderr
