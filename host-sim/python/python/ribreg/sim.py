"""What ``ribreg hil`` simulates around the protocol, for tests and simulation: the
phantom and its sweep with the upload prepared from them (:class:`Scenario`), the robot
and probe that follow setpoints (:class:`Robot`), and the firmware under QEMU
(:class:`Emulator`). All of it is the Rust ``ribreg_sim::hil`` code; the procedure that
uses it is ``host-sim/python/examples/robot_pc.py``.
"""

from __future__ import annotations

from typing import List, Optional, Tuple

from . import _ribreg as _rs
from .link import Pose, Session, Setpoint, ToController, from_wire

__all__ = ["Scenario", "Robot", "Emulator", "emulator_available", "STANDOFF_MM",
           "ROBOT_LAG_S", "TOLERANCE_MM"]

#: Probe standoff above the bone surface, mm (the aim point is the TCP plus this).
STANDOFF_MM: float = _rs.STANDOFF_MM
#: The simulated robot follows setpoints with this time constant, s.
ROBOT_LAG_S: float = _rs.ROBOT_LAG_S
#: Clinical tolerance for a probe placed between ribs, mm (as ``ribreg hil``).
TOLERANCE_MM: float = _rs.TOLERANCE_MM

class Robot:
    """The simulated robot and probe: stands still where the sweep ended; while
    executing, its TCP follows each setpoint with a first-order lag of
    :data:`ROBOT_LAG_S`."""

    def __init__(self, inner: "_rs.SimRobot") -> None:
        """Wraps an extension robot; use :meth:`Scenario.robot`."""
        self._r = inner

    def pose(self, t_us: int) -> Pose:
        """Its flange pose report stamped ``t_us``."""
        pose = from_wire(self._r.pose(t_us), to_controller=True)
        if not isinstance(pose, Pose):
            raise TypeError(f"the simulated robot reported {pose!r}, not a Pose")
        return pose

    def start_executing(self) -> None:
        """Starts executing: the TCP is where the standing flange holds it."""
        self._r.start_executing()

    def follow(self, setpoint: Setpoint) -> None:
        """Moves the TCP 10 ms toward ``setpoint``."""
        self._r.follow(setpoint.to_wire())

    def update_flange(self) -> None:
        """Updates the flange from the TCP (before a pose report while executing)."""
        self._r.update_flange()

    def aim_point(self) -> Tuple[float, float, float]:
        """Where the probe aims now: TCP plus :data:`STANDOFF_MM` along its beam, mm."""
        x, y, z = self._r.aim_point()
        return (x, y, z)


class Scenario:
    """A phantom, its simulated sweep and the upload ``ribreg hil`` prepares from them:
    the same as ``ribreg hil --seed SEED [--variant V] [--quick]``."""

    def __init__(self, seed: int = 0, quick: bool = True, variant: str = "aligned") -> None:
        """Simulates the phantom of ``seed`` (``variant``: ``"aligned"`` or
        ``"misaligned"``) and its sweep (``quick``: the lighter sweep of ``--quick``),
        calibrates the lag and builds the template. ``ValueError`` if refused."""
        self.seed = seed
        self.quick = quick
        self.variant = variant
        self._s = _rs.SimScenario(seed, quick, variant)

    @property
    def lag_ms(self) -> float:
        """The video lag the temporal calibration measured, ms."""
        return self._s.lag_ms

    @property
    def nodes(self) -> int:
        """Template nodes in the upload."""
        return self._s.nodes

    @property
    def waypoints(self) -> int:
        """Planned waypoints in the upload."""
        return self._s.waypoints

    @property
    def sweep_end_s(self) -> float:
        """Time of the sweep's last pose, s."""
        return self._s.sweep_end_s

    @property
    def true_waypoints(self) -> List[Tuple[float, float, float]]:
        """The phantom's true waypoints (robot base frame), mm."""
        return [(p[0], p[1], p[2]) for p in self._s.true_waypoints]

    def upload(self) -> List[ToController]:
        """What follows the handshake, in order: :class:`~ribreg.link.Configure`, the
        :class:`~ribreg.link.TemplateNodes` chunks, :class:`~ribreg.link.TemplateShape`,
        the :class:`~ribreg.link.Waypoints` chunks."""
        return [from_wire(w, to_controller=True) for w in self._s.upload()]

    def sweep_messages(self) -> List[ToController]:
        """The sweep's :class:`~ribreg.link.Pose` (100 Hz) and
        :class:`~ribreg.link.Frame` (30 fps) messages in arrival order."""
        return [from_wire(w, to_controller=True) for w in self._s.sweep_messages()]

    def robot(self) -> Robot:
        """A robot standing where the sweep ended."""
        return Robot(self._s.robot())


def emulator_available() -> bool:
    """Whether ``qemu-system-arm`` runs here."""
    return _rs.emulator_available()


class Emulator:
    """The firmware under QEMU as ``ribreg hil`` runs it (``-icount shift=0,sleep=on``),
    its UART on a loopback TCP port. A context manager; QEMU is killed on
    :meth:`close`."""

    def __init__(self) -> None:
        """Builds the firmware if needed (``cargo``; or ``RIBREG_FIRMWARE_ELF`` names
        it), starts QEMU and connects to its UART. :class:`~ribreg.link.LinkError` if
        QEMU is missing or fails."""
        self._e = _rs.SimEmulator.start()

    @property
    def address(self) -> str:
        """``127.0.0.1:PORT`` of the UART (for :meth:`Session.connect` after
        :meth:`release_uart`)."""
        return f"127.0.0.1:{self._e.port}"

    def session(self) -> Session:
        """A session over the UART connection this emulator holds."""
        return Session(self._e.session())

    def release_uart(self) -> None:
        """Lets go of the UART connection: QEMU takes the next one, at :attr:`address`."""
        self._e.release_uart()

    def quit(self, timeout: float = 30.0) -> Optional[int]:
        """Ends the firmware (``QUIT`` on the held UART connection) and waits up to
        ``timeout`` s; returns QEMU's exit code (0: clean)."""
        return self._e.quit(timeout)

    def stderr_output(self) -> str:
        """QEMU's stderr so far."""
        return self._e.stderr_output()

    def close(self) -> None:
        """Kills QEMU if it still runs."""
        self._e.close()

    def __enter__(self) -> "Emulator":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

