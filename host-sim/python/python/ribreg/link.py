"""The robot PC's side of the ribreg controller protocol.

The protocol itself is the Rust one, compiled into the extension: frames are the
core's (``ribreg_core::wire``: postcard, CRC-32, COBS, a zero delimiter), and
:class:`Session` is the ``ribreg hil`` host's session (``ribreg_sim::hil::Session``):
the handshake is the first message, every message gets the next sequence number and
stays in a go-back-N window of :data:`WINDOW` frames until acknowledged; a transport
NACK (corrupt, out of order, too long) or :data:`RESEND_AFTER_S` of silence re-sends
the window; application NACKs (bad state, invalid content) are recorded in
:attr:`Session.refused`, not re-sent.

This module gives the messages as typed classes:

* robot PC → controller: :class:`Hello`, :class:`Configure`, :class:`TemplateNodes`,
  :class:`TemplateShape`, :class:`Waypoints`, :class:`Pose`, :class:`Frame`,
  :class:`Command`;
* controller → robot PC: :class:`HelloAck`, :class:`Ack`, :class:`Nack`,
  :class:`Status`, :class:`Waypoint`, :class:`Setpoint`, :class:`Fault`,
  :class:`Cost`, :class:`Registration`.

Floats hold the wire's ``f32`` values exactly (a decoded message re-encodes to the
same bytes). Errors:

* :class:`FrameError` (a ``ValueError``): bytes that are not a frame of this protocol;
* ``ValueError``: a message the protocol cannot carry (a field out of range, more
  nodes than a chunk holds, a missing field), with the Rust message;
* :class:`LinkError` (an ``OSError``): the link could not be opened, closed, or
  messages stayed unacknowledged past a deadline, with the Rust message.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field, fields, is_dataclass
from typing import Any, Dict, List, Literal, Optional, Tuple, Type, Union, overload

from . import _ribreg as _rs

__all__ = [
    "LinkError", "FrameError", "MAGIC", "VERSION", "MAX_FRAME", "NODES_PER_CHUNK",
    "WAYPOINTS_PER_CHUNK", "PIXEL_SUBDIVISIONS", "WINDOW", "RESEND_AFTER_S",
    "CommandKind", "State", "NackCode", "FaultKind", "Probe", "Node",
    "Hello", "Configure", "TemplateNodes", "TemplateShape", "Waypoints", "Pose", "Frame",
    "Command", "HelloAck", "Ack", "Nack", "Status", "Waypoint", "Setpoint", "Fault",
    "Cost", "Registration", "ToController", "FromController", "Message", "LinkStats",
    "encode_frame", "decode_frame", "Receiver", "Session",
]

LinkError = _rs.LinkError
FrameError = _rs.FrameError

#: Handshake magic (``b"RBRG"`` little-endian).
MAGIC: int = _rs.MAGIC
#: Protocol version.
VERSION: int = _rs.VERSION
#: Largest frame on the wire in either direction, delimiter included, bytes.
MAX_FRAME: int = _rs.MAX_FRAME
#: Template nodes per :class:`TemplateNodes` chunk, at most.
NODES_PER_CHUNK: int = _rs.NODES_PER_CHUNK
#: Waypoints per :class:`Waypoints` chunk, at most.
WAYPOINTS_PER_CHUNK: int = _rs.WAYPOINTS_PER_CHUNK
#: :attr:`Frame.pixels` are in 1/PIXEL_SUBDIVISIONS pixel.
PIXEL_SUBDIVISIONS: float = _rs.PIXEL_SUBDIVISIONS
#: Frames in flight before :meth:`Session.send` waits for acknowledgements.
WINDOW: int = _rs.WINDOW
#: Silence after which the session re-sends its unacknowledged window, s.
RESEND_AFTER_S: float = _rs.RESEND_AFTER_S

Vec3 = List[float]


class CommandKind(str, enum.Enum):
    """The commands of the procedure (:class:`Command`)."""

    START_SWEEP = "StartSweep"  #: Start compounding poses and frames.
    END_SWEEP = "EndSweep"  #: Stop compounding.
    REGISTER = "Register"  #: Register the template onto the compounded cloud.
    EXECUTE = "Execute"  #: Move the probe through the mapped waypoints.
    ABORT = "Abort"  #: Stop everything, back to idle (the template is kept).
    STATUS = "Status"  #: Send a :class:`Status`.
    RESULT = "Result"  #: Send the registration result (one :class:`Waypoint` each).
    COST = "Cost"  #: Send the controller's measured costs (:class:`Cost`).


class State(str, enum.Enum):
    """Controller states (:attr:`Status.state`)."""

    IDLE = "Idle"
    TEMPLATE_LOADED = "TemplateLoaded"
    SWEEPING = "Sweeping"
    REGISTERING = "Registering"
    READY = "Ready"
    EXECUTING = "Executing"
    DONE = "Done"


class NackCode(str, enum.Enum):
    """Why the controller refused a frame or a message (:attr:`Nack.code`).

    ``CORRUPT``, ``OUT_OF_ORDER`` and ``TOO_LONG`` are transport NACKs (the session
    re-sends); the others are application NACKs (the session records them).
    """

    CORRUPT = "Corrupt"
    OUT_OF_ORDER = "OutOfOrder"
    TOO_LONG = "TooLong"
    VERSION = "Version"
    BAD_STATE = "BadState"
    INVALID = "Invalid"  #: With the core error's code in :attr:`Nack.detail`.


class FaultKind(str, enum.Enum):
    """Controller faults (:attr:`Fault.kind`)."""

    POSE_TIMEOUT = "PoseTimeout"  #: No robot pose for too long: setpoints stopped.
    REGISTRATION = "Registration"  #: Registration failed (code in :attr:`Fault.detail`).


@dataclass
class Probe:
    """Probe image geometry (part of :class:`Configure`)."""

    width_px: int  #: Image width, pixels.
    height_px: int  #: Image height, pixels.
    footprint_mm: float  #: Width the image covers, mm.
    depth_mm: float  #: Depth the image covers, mm.


@dataclass
class Node:
    """One template SOM-1 node and its rib label (0 none, 1 sternum, 2..5 rib)."""

    p: Vec3  #: Position, template frame, mm.
    label: int  #: Rib label.


class Message:
    """Base of every wire message; see :data:`ToController` and :data:`FromController`."""

    _to_controller = True

    def to_wire(self) -> Dict[str, Any]:
        """The message's serde form: ``{"VariantName": body}`` (as the Rust JSON)."""
        return {type(self).__name__: _plain(self)}

    @classmethod
    def _from_body(cls, body: Any) -> "Message":
        return cls(**body)


# ---- robot PC → controller ----------------------------------------------------------


@dataclass
class Hello(Message):
    """Handshake: the first message of a session (sequence 0)."""

    magic: int = MAGIC  #: :data:`MAGIC`.
    version: int = VERSION  #: :data:`VERSION`.


@dataclass
class Configure(Message):
    """Calibration, lag and motion limits (rigid transforms: rotation row-major, then
    translation)."""

    probe: Probe  #: Probe image geometry.
    tcp_t_us: List[float]  #: Image frame in the TCP frame (12 numbers).
    ee_t_tcp: List[float]  #: TCP frame in the flange frame (12 numbers).
    lag_us: int  #: Video lag behind the tracker, µs.
    voxel_mm: float  #: Finest voxel edge of the compounding, mm.
    max_speed_mm_s: float  #: Setpoint speed limit, mm/s.
    max_accel_mm_s2: float  #: Setpoint acceleration limit, mm/s².
    standoff_mm: float  #: Probe face to bone surface at a waypoint, mm.
    #: The patient's anterior as a direction in the robot base frame, roughly: the
    #: registration's orientation prior (3 numbers; all zeros: none, any pose).
    target_up: List[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    #: A partial plan: map every waypoint and mark those the sweep does not reach
    #: (:attr:`Waypoint.supported`), never driving there, instead of refusing the plan.
    partial: bool = False

    @classmethod
    def _from_body(cls, body: Any) -> "Configure":
        return cls(**{**body, "probe": Probe(**body["probe"])})


@dataclass
class TemplateNodes(Message):
    """A chunk of at most :data:`NODES_PER_CHUNK` template nodes."""

    offset: int  #: Index of the chunk's first node.
    total: int  #: Nodes in the whole template.
    nodes: List[Node]  #: The nodes.

    @classmethod
    def _from_body(cls, body: Any) -> "TemplateNodes":
        return cls(body["offset"], body["total"], [Node(**n) for n in body["nodes"]])


@dataclass
class TemplateShape(Message):
    """The template's shape (after its nodes): key-point frame, rib skeleton, sternum
    split."""

    origin: Vec3  #: Frame origin, mm.
    axes: List[float]  #: Frame axes (columns), row-major (9 numbers).
    spread: Vec3  #: Spread along each axis, mm.
    skeleton: List[Vec3]  #: The 30 rib skeleton points, mm.
    midline_fraction: List[float]  #: Per rib (4), the fraction of stations on side 0.


@dataclass
class Waypoints(Message):
    """A chunk of at most :data:`WAYPOINTS_PER_CHUNK` planned waypoints (template
    frame, mm)."""

    offset: int  #: Index of the chunk's first waypoint.
    total: int  #: Waypoints in the whole plan.
    points: List[Vec3]  #: The waypoints, mm.


@dataclass
class Pose(Message):
    """A tracked flange pose (100 Hz)."""

    t_us: int  #: Tracker time, µs.
    position: Vec3  #: Position, mm.
    quat: List[float]  #: Orientation ``[w, x, y, z]``.


@dataclass
class Frame(Message):
    """One annotated US frame (30 fps)."""

    t_us: int  #: Video time, µs.
    frame: int  #: Frame number.
    pixels: List[List[int]]  #: Bone pixels ``[u, v]`` in 1/:data:`PIXEL_SUBDIVISIONS` px.


@dataclass
class Command(Message):
    """A command of the procedure."""

    kind: CommandKind  #: Which.

    def to_wire(self) -> Dict[str, Any]:
        """``{"Command": "StartSweep"}`` and so on."""
        return {"Command": CommandKind(self.kind).value}

    @classmethod
    def _from_body(cls, body: Any) -> "Command":
        return cls(CommandKind(body))


# ---- controller → robot PC ----------------------------------------------------------


@dataclass
class HelloAck(Message):
    """The handshake's answer."""

    _to_controller = False
    magic: int  #: :data:`MAGIC`.
    version: int  #: :data:`VERSION`.
    max_frame: int  #: The controller's :data:`MAX_FRAME`.


@dataclass
class Ack(Message):
    """A robot PC message was applied (or was a duplicate of one applied)."""

    _to_controller = False
    seq: int  #: Its sequence number.


@dataclass
class Nack(Message):
    """A robot PC frame was refused."""

    _to_controller = False
    seq: int  #: The sequence number the controller expects next.
    code: NackCode  #: Why.
    detail: Optional[int] = None  #: The core error's code for ``NackCode.INVALID``.

    def to_wire(self) -> Dict[str, Any]:
        """``{"Nack": {"seq": n, "code": "Corrupt"}}``, or ``{"Invalid": detail}`` as code."""
        code = NackCode(self.code)
        wire: Any = {code.value: self.detail} if code is NackCode.INVALID else code.value
        return {"Nack": {"seq": self.seq, "code": wire}}

    @classmethod
    def _from_body(cls, body: Any) -> "Nack":
        code, detail = _unit_or_newtype(body["code"])
        return cls(body["seq"], NackCode(code), detail)


@dataclass
class Status(Message):
    """Controller status."""

    _to_controller = False
    state: State  #: State.
    expected_seq: int  #: Sequence number expected next from the robot PC.
    poses: int  #: Poses accepted.
    frames_placed: int  #: Frames placed in the cloud.
    frames_refused: int  #: Frames refused (outside the track or invalid).
    points: int  #: Points in the cloud (voxels).
    progress: int  #: Registration progress, percent.
    waypoint: int  #: Waypoint being approached while executing.

    @classmethod
    def _from_body(cls, body: Any) -> "Status":
        return cls(**{**body, "state": State(body["state"])})


@dataclass
class Waypoint(Message):
    """One mapped waypoint of the registration result."""

    _to_controller = False
    index: int  #: Index in the plan.
    total: int  #: Waypoints in the plan.
    position: Vec3  #: Mapped position, robot base frame, mm.
    quality_mm: float  #: RMS residual of the local rigid fit that mapped it, mm.
    #: Whether the sweep reaches it: ``False`` only in a partial plan, and the controller
    #: never drives there.
    supported: bool = True


@dataclass
class Setpoint(Message):
    """A probe setpoint: TCP pose in the robot base frame (100 Hz while executing)."""

    _to_controller = False
    t_us: int  #: Controller time, µs.
    position: Vec3  #: TCP position, mm.
    quat: List[float]  #: TCP orientation ``[w, x, y, z]``.
    waypoint: int  #: Waypoint being approached.


@dataclass
class Fault(Message):
    """A controller fault, reported unprompted."""

    _to_controller = False
    kind: FaultKind  #: Which.
    detail: Optional[int] = None  #: The core error's code for ``FaultKind.REGISTRATION``.

    def to_wire(self) -> Dict[str, Any]:
        """``{"Fault": "PoseTimeout"}`` or ``{"Fault": {"Registration": detail}}``."""
        kind = FaultKind(self.kind)
        wire: Any = {kind.value: self.detail} if kind is FaultKind.REGISTRATION else kind.value
        return {"Fault": wire}

    @classmethod
    def _from_body(cls, body: Any) -> "Fault":
        kind, detail = _unit_or_newtype(body)
        return cls(FaultKind(kind), detail)

    def __str__(self) -> str:
        """What happened, in words: ``registration refused: a rib side was not seen ...``."""
        if FaultKind(self.kind) is FaultKind.REGISTRATION:
            code = self.detail if self.detail is not None else 0
            return f"registration refused: {_rs.error_summary(code)} (error code {code})"
        return "robot poses stopped while executing"


@dataclass
class Cost(Message):
    """What the controller's work costs on its platform (zeros in-process)."""

    _to_controller = False
    registration_instructions: int  #: Instructions in the last registration's steps.
    registration_calls: int  #: Registration steps of the last registration.
    worst_call_instructions: int  #: Most instructions of one control-loop call.
    worst_step_instructions: int  #: Most instructions of one registration step.
    worst_receive_instructions: int  #: Most instructions handling one received frame.
    peak_stack_bytes: int  #: Peak stack use, bytes.
    serial_overruns: int = 0  #: UART receive overruns (ORE) since boot.
    serial_framing_errors: int = 0  #: UART framing, noise and parity errors since boot.
    serial_dropped_bytes: int = 0  #: Bytes received while the RX queue was full.


@dataclass
class Registration(Message):
    """How clearly the registration found the patient, sent before its waypoints."""

    _to_controller = False
    hypotheses: int  #: Pose hypotheses refined.
    residual_mm: float  #: Residual of the pose taken, mm.
    runner_up_mm: float  #: Residual of the best distinct hypothesis, mm (inf if none).
    support_mm: float  #: How closely the sweep supports the whole template, mm.
    min_side_span_percent: int  #: Least rib-side span, percent of the template's.
    #: How far beyond its nearest rib end the sweep imaged, mm (nan: not measured).
    min_edge_clearance_mm: float
    waypoints: int  #: Waypoints mapped (the :class:`Waypoint` messages that follow).


#: A robot PC → controller message.
ToController = Union[Hello, Configure, TemplateNodes, TemplateShape, Waypoints, Pose, Frame,
                     Command]
#: A controller → robot PC message.
FromController = Union[HelloAck, Ack, Nack, Status, Waypoint, Setpoint, Fault, Cost,
                       Registration]

_TO: Dict[str, Type[Message]] = {c.__name__: c for c in (
    Hello, Configure, TemplateNodes, TemplateShape, Waypoints, Pose, Frame, Command)}
_FROM: Dict[str, Type[Message]] = {c.__name__: c for c in (
    HelloAck, Ack, Nack, Status, Waypoint, Setpoint, Fault, Cost, Registration)}


def _plain(x: Any) -> Any:
    """A dataclass, enum, list or tuple as plain dicts, strings and lists."""
    if is_dataclass(x) and not isinstance(x, type):
        return {f.name: _plain(getattr(x, f.name)) for f in fields(x)}
    if isinstance(x, enum.Enum):
        return x.value
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    return x


def _unit_or_newtype(v: Any) -> Tuple[str, Optional[int]]:
    """A serde enum value without data (``"Name"``) or with one (``{"Name": n}``)."""
    if isinstance(v, dict):
        ((name, detail),) = v.items()
        return name, detail
    return v, None


@overload
def from_wire(wire: Union[Dict[str, Any], str], to_controller: Literal[True]) -> ToController: ...
@overload
def from_wire(
    wire: Union[Dict[str, Any], str], to_controller: Literal[False] = ...
) -> FromController: ...
@overload
def from_wire(wire: Union[Dict[str, Any], str], to_controller: bool) -> Message: ...


def from_wire(wire: Union[Dict[str, Any], str], to_controller: bool = False) -> Message:
    """The typed message of a serde form (``{"VariantName": body}``): a robot PC
    message (:data:`ToController`) if ``to_controller``, else a controller message
    (:data:`FromController`)."""
    if isinstance(wire, str):  # a variant without data
        wire = {wire: None}
    ((name, body),) = wire.items()
    classes = _TO if to_controller else _FROM
    if name not in classes:
        side = "robot PC" if to_controller else "controller"
        raise ValueError(f"{name!r} is not a {side} message")
    return classes[name]._from_body(body)


def _wire_of(msg: Message) -> Tuple[Dict[str, Any], bool]:
    if not isinstance(msg, Message):
        raise TypeError(f"not a wire message: {msg!r}")
    return msg.to_wire(), msg._to_controller


def encode_frame(seq: int, msg: Message) -> bytes:
    """Encodes ``msg`` (either direction) with sequence number ``seq`` as one frame,
    its zero delimiter included. ``ValueError`` if the protocol cannot carry it."""
    wire, to = _wire_of(msg)
    return _rs.encode_frame(seq, wire, to)


def decode_frame(data: bytes, to_controller: bool = False) -> Tuple[int, Message]:
    """Decodes one frame (the trailing zero delimiter optional) into ``(seq, msg)``;
    ``to_controller=True`` decodes a robot PC message. :class:`FrameError` if the bytes
    are not one frame."""
    seq, wire = _rs.decode_frame(bytes(data), to_controller)
    return seq, from_wire(wire, to_controller)


class Receiver:
    """Cuts a byte stream, fed in chunks of any size, into decoded messages (the core's
    receiver: resynchronises on the zero delimiter, drops over-long frames)."""

    def __init__(self, to_controller: bool = False) -> None:
        """A receiver of controller messages, or of robot PC ones if ``to_controller``."""
        self._rx = _rs.FrameReceiver(to_controller)
        self._to = to_controller

    def feed(self, data: bytes) -> List[Union[Tuple[int, Message], FrameError]]:
        """Feeds bytes; returns what they completed in stream order: ``(seq, msg)`` per
        frame, a :class:`FrameError` instance (returned, not raised) per run of bytes
        that was not a frame, so no message around a bad frame is lost. A frame cut
        short stays buffered until the rest arrives."""
        out: List[Union[Tuple[int, Message], FrameError]] = []
        for item in self._rx.feed(bytes(data)):
            if isinstance(item, BaseException):
                out.append(item)
            else:
                seq, wire = item
                out.append((seq, from_wire(wire, self._to)))
        return out


@dataclass
class LinkStats:
    """Link counters of a session."""

    sent: int  #: Frames sent the first time.
    resent: int  #: Frames re-sent.
    nacks: int  #: Transport NACKs received.
    timeouts: int  #: Silences that re-sent the window.
    injected: List[int]  #: Faults injected: corrupted, dropped, duplicated, reordered, garbage.
    bytes: int  #: Bytes written.


class Session:
    """The robot PC's protocol engine (the Rust ``ribreg_sim::hil::Session``).

    Make one with :meth:`in_process`, :meth:`connect` or :meth:`serial`; start with
    :meth:`handshake`. :meth:`send` numbers and frames a message and keeps it until
    acknowledged; :meth:`pump` reads the controller, handles ACKs and NACKs (re-sending
    as needed) and queues everything else for :meth:`next_message`.
    """

    def __init__(self, inner: "_rs.LinkSession") -> None:
        """Wraps an extension session; use the constructors instead."""
        self._s = inner

    @classmethod
    def in_process(cls, fault_seed: Optional[int] = None) -> "Session":
        """A session with the core's controller compiled into this process, on a
        simulated clock that passes only through :meth:`advance`.

        ``fault_seed`` (every constructor): inject the link faults of ``ribreg hil
        --faults`` with this seed — 2 % each of corrupted, dropped, duplicated and
        reordered frames and garbage bursts, between the session and the controller —
        to exercise the re-sends; :attr:`LinkStats.injected` counts them."""
        return cls(_rs.LinkSession.in_process(fault_seed))

    @classmethod
    def connect(cls, addr: str, fault_seed: Optional[int] = None) -> "Session":
        """A session with a controller at ``HOST:PORT`` over TCP (the emulator's UART,
        a serial port exposed over the network). :class:`LinkError` if it cannot."""
        return cls(_rs.LinkSession.connect(addr, fault_seed))

    @classmethod
    def serial(cls, path: str, baud: int = 115_200,
               fault_seed: Optional[int] = None) -> "Session":
        """A session with a controller board on serial device ``path`` (8N1).
        :class:`LinkError` if it cannot be opened."""
        return cls(_rs.LinkSession.serial(path, baud, fault_seed))

    def handshake(self, timeout: float = 120.0) -> HelloAck:
        """Sends :class:`Hello` (it must be the session's first message), waits until
        it is acknowledged and returns the controller's :class:`HelloAck`.
        :class:`LinkError` if it is refused or does not come in ``timeout`` s."""
        self.send(Hello())
        self.flush(timeout)
        msg = self.next_message()
        if not isinstance(msg, HelloAck):
            refused = self.refused
            raise LinkError(f"handshake: expected HelloAck, got {msg!r} (refused: {refused})")
        return msg

    def send(self, msg: ToController) -> int:
        """Sends a robot PC message (waiting for room in the window); returns its
        sequence number. ``ValueError`` if the protocol cannot carry it."""
        wire, to = _wire_of(msg)
        if not to:
            raise TypeError(f"{type(msg).__name__} is a controller message")
        return self._s.send(wire)

    def pump(self, wait: float = 0.0) -> None:
        """Reads what arrived (waiting at most ``wait`` s for it), handles ACKs and
        NACKs, re-sends on a transport NACK or after :data:`RESEND_AFTER_S` of silence,
        and queues the other messages."""
        self._s.pump(wait)

    def next_message(self, timeout: Optional[float] = None) -> Optional[FromController]:
        """The next queued controller message other than ACK/NACK, or ``None``.

        ``timeout=None`` only looks at the queue (call :meth:`pump` to fill it); a
        number pumps until a message arrives or that many seconds pass."""
        wire = self._s.next_message(timeout)
        return None if wire is None else from_wire(wire)

    def flush(self, timeout: float = 120.0) -> None:
        """Waits until every message sent is acknowledged or refused (advancing an
        in-process controller's clock meanwhile); :class:`LinkError` after ``timeout``
        s."""
        self._s.flush(timeout)

    def advance(self, us: int) -> None:
        """Lets ``us`` µs of controller time pass: the in-process controller is polled
        every millisecond of it; a real or emulated controller keeps its own time, so
        this sleeps."""
        self._s.advance(us)

    @property
    def simulated_clock(self) -> bool:
        """Whether the controller's time passes only through :meth:`advance`."""
        return self._s.simulated_clock

    @property
    def stats(self) -> LinkStats:
        """The link counters."""
        return LinkStats(**self._s.stats)

    @property
    def refused(self) -> List[Tuple[int, NackCode, Optional[int]]]:
        """Application NACKs so far: ``(seq, code, detail)``."""
        out = []
        for seq, code in self._s.refused:
            name, detail = _unit_or_newtype(code)
            out.append((seq, NackCode(name), detail))
        return out
