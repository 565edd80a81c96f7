"""Type stubs of the ``ribreg._ribreg`` extension module (see ``host-sim/python/src``)."""

from os import PathLike
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union, final

import numpy as np
import numpy.typing as npt

__version__: str
__all__ = [
    "__version__",
    "Template",
    "Registration",
    "RegistrationError",
    "register",
    "read_cloud",
    "read_waypoints",
    "LinkError",
    "FrameError",
    "MAX_FRAME",
    "MAGIC",
    "VERSION",
    "NODES_PER_CHUNK",
    "WAYPOINTS_PER_CHUNK",
    "PIXEL_SUBDIVISIONS",
    "WINDOW",
    "RESEND_AFTER_S",
    "encode_frame",
    "decode_frame",
    "error_summary",
    "FrameReceiver",
    "LinkSession",
    "STANDOFF_MM",
    "ROBOT_LAG_S",
    "TOLERANCE_MM",
    "SimScenario",
    "SimRobot",
    "SimEmulator",
    "emulator_available",
]

_Points = npt.ArrayLike  # (N, 3), any real dtype, any memory order
_Path = Union[str, PathLike[str]]

@final
class Template:
    """A template prepared once and reused; the format of ``ribreg template --prepared``."""

    def __new__(cls, points: _Points, labels: npt.ArrayLike) -> "Template":
        """Prepares a template from a labelled cloud (1 = sternum, 2..5 = rib)."""
    @staticmethod
    def load(path: _Path) -> "Template":
        """A prepared template file as it is, or a labelled cloud prepared now."""
    def save(self, path: _Path) -> None:
        """Writes the prepared template (binary PLY)."""
    @property
    def points(self) -> npt.NDArray[np.float64]:
        """The template cloud, (N, 3), mm."""
    @property
    def labels(self) -> npt.NDArray[np.int32]:
        """Its labels, (N,)."""
    @property
    def skeleton(self) -> npt.NDArray[np.float64]:
        """The 30 skeleton points, (30, 3), mm."""
    def __len__(self) -> int: ...

class RegistrationError(ValueError):
    """The core refused the registration; ``code`` is its error code."""

    code: int

@final
class Registration:
    """The non-rigid mapping template -> target found by ``register``."""

    def transform(self, points: _Points) -> npt.NDArray[np.float64]:
        """Maps (N, 3) points from the template into the target; checks none of them."""
    @property
    def waypoints(self) -> Optional[npt.NDArray[np.float64]]:
        """The waypoints given to ``register``, mapped, (M, 3); ``None`` without."""
    @property
    def supported(self) -> Optional[npt.NDArray[np.bool_]]:
        """Per mapped waypoint, whether the sweep supports it, (M,); ``None`` without."""
    @property
    def registered(self) -> npt.NDArray[np.float64]:
        """The template's points mapped into the target, (N, 3)."""
    @property
    def report(self) -> dict[str, Any]:
        """The report of ``ribreg register --report`` (skeleton, rigid part, ED/HD, timings)."""
    @property
    def rigid(self) -> npt.NDArray[np.float64]:
        """The rigid part, template -> target, 4 x 4."""

def register(
    template: Union[_Points, Template],
    target: _Points,
    labels: Optional[npt.ArrayLike] = None,
    *,
    waypoints: Optional[_Points] = None,
    partial: bool = False,
    target_up: Optional[npt.ArrayLike] = None,
    method: str = "improved",
    prepared: Optional[Template] = None,
    imaged: Optional[_Path] = None,
) -> Registration:
    """Registers the template onto the target (``method``: "improved" or "paper"),
    mapping and checking ``waypoints`` (and, with ``imaged``, every rib end against the
    sweep's lines from ``ribreg compound --imaged``)."""

def read_cloud(
    path: _Path,
) -> tuple[npt.NDArray[np.float64], Optional[npt.NDArray[np.int32]]]:
    """(points, labels or None) of a PLY, PCD, XYZ or CSV cloud."""

def read_waypoints(path: _Path) -> tuple[npt.NDArray[np.float64], Sequence[str]]:
    """(points, labels) of a CSV, ``.mrk.json`` or ``.fcsv`` waypoint file."""

# --- ribreg.link and ribreg.sim (src/link.rs, src/link/sim.rs). Messages cross in their
# serde form: `{"VariantName": body}` dicts shaped like the Rust types' JSON; the typed
# classes are in `ribreg.link`.
_Wire = Union[Dict[str, Any], str]

class LinkError(OSError):
    """The link to the controller failed (could not open, closed, deadline passed)."""

class FrameError(ValueError):
    """Bytes that are not a frame of this protocol."""

MAX_FRAME: int
MAGIC: int
VERSION: int
NODES_PER_CHUNK: int
WAYPOINTS_PER_CHUNK: int
PIXEL_SUBDIVISIONS: float
WINDOW: int
RESEND_AFTER_S: float
STANDOFF_MM: float
ROBOT_LAG_S: float
TOLERANCE_MM: float

def encode_frame(seq: int, message: _Wire, to_controller: bool = True) -> bytes:
    """Encodes a message (serde form) with sequence `seq` as one frame, delimiter included."""

def error_summary(code: int) -> str:
    """What a core error code (a NACK's or a registration fault's) stands for, in a few words."""

def decode_frame(data: bytes, to_controller: bool = False) -> Tuple[int, _Wire]:
    """Decodes one frame (delimiter optional) into `(seq, message)`."""

@final
class FrameReceiver:
    """The core's frame receiver over a byte stream fed in chunks."""
    def __new__(cls, to_controller: bool = False) -> "FrameReceiver": ...
    def feed(self, data: bytes) -> List[Union[Tuple[int, _Wire], FrameError]]:
        """What the bytes completed: `(seq, message)` or a `FrameError` instance."""

@final
class LinkSession:
    """`ribreg_sim::hil::Session` over the in-process controller, TCP or serial."""
    @staticmethod
    def in_process(fault_seed: Optional[int] = None) -> LinkSession: ...
    @staticmethod
    def connect(addr: str, fault_seed: Optional[int] = None) -> LinkSession: ...
    @staticmethod
    def serial(path: str, baud: int = 115200, fault_seed: Optional[int] = None) -> LinkSession: ...
    def send(self, message: _Wire) -> int: ...
    def pump(self, wait: float = 0.0) -> None: ...
    def next_message(self, timeout: Optional[float] = None) -> Optional[_Wire]: ...
    def flush(self, timeout: float = 120.0) -> None: ...
    def advance(self, us: int) -> None: ...
    @property
    def simulated_clock(self) -> bool: ...
    @property
    def stats(self) -> Dict[str, Any]: ...
    @property
    def refused(self) -> List[Tuple[int, _Wire]]: ...

@final
class SimScenario:
    """A phantom, its sweep and the upload `ribreg hil` prepares (`hil::prepare`)."""
    def __new__(cls, seed: int = 0, quick: bool = True, variant: str = "aligned") -> "SimScenario": ...
    @property
    def lag_ms(self) -> float: ...
    @property
    def nodes(self) -> int: ...
    @property
    def waypoints(self) -> int: ...
    @property
    def sweep_end_s(self) -> float: ...
    @property
    def true_waypoints(self) -> List[List[float]]: ...
    def upload(self) -> List[_Wire]: ...
    def sweep_messages(self) -> List[_Wire]: ...
    def robot(self) -> SimRobot: ...

@final
class SimRobot:
    """The simulated robot and probe (`hil::robot::Robot`)."""
    def pose(self, t_us: int) -> _Wire: ...
    def start_executing(self) -> None: ...
    def follow(self, setpoint: _Wire) -> None: ...
    def update_flange(self) -> None: ...
    def aim_point(self) -> List[float]: ...

def emulator_available() -> bool:
    """Whether `qemu-system-arm` runs here."""

@final
class SimEmulator:
    """The firmware under QEMU as `ribreg hil` runs it."""
    @staticmethod
    def start() -> SimEmulator: ...
    @property
    def port(self) -> int: ...
    def session(self) -> LinkSession: ...
    def release_uart(self) -> None: ...
    def quit(self, timeout: float = 30.0) -> Optional[int]: ...
    def stderr_output(self) -> str: ...
    def close(self) -> None: ...
