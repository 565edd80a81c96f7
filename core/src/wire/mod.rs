//! The serial protocol between the robot PC (host) and the probe-positioning controller:
//! one versioned set of message types, shared by the firmware and the host.
//!
//! # Framing
//! ```text
//! frame   = COBS( postcard(Envelope { seq: u16, msg }) ‖ CRC-32 ) ‖ 0x00
//! ```
//! * `postcard` encodes the envelope (varint integers, little-endian `f32`, enum
//!   discriminants and sequence lengths as varints).
//! * CRC-32/ISO-HDLC (the Ethernet/zlib CRC: reflected poly 0xEDB88320, init and final
//!   xor 0xFFFF_FFFF) of the postcard bytes, appended little-endian. A CRC-16 was tried
//!   first: a dropped byte or a flipped COBS code byte shifts the data, a burst error a
//!   16-bit CRC misses about once in 65,536 — the property tests met one in 42,589.
//! * COBS removes every zero byte; a single `0x00` ends the frame, so a receiver that
//!   lost sync (a garbled byte, a burst of garbage) resynchronises at the next zero.
//! * A frame longer than [`MAX_FRAME`] bytes (delimiter included) is garbage: the
//!   receiver drops bytes up to the next zero and reports [`FrameError::TooLong`].
//!
//! # Session
//! 1. The host sends [`ToController::Hello`] with [`MAGIC`] and [`VERSION`]; the
//!    controller answers [`FromController::HelloAck`] (or NACKs
//!    [`NackCode::Version`]). The Hello carries sequence 0, the next message 1.
//! 2. Every host message carries the next sequence number (wrapping `u16`). The
//!    controller applies a message only if its number is the one it expects, then ACKs
//!    it; a number already applied is ACKed again and not re-applied (a duplicate); a
//!    later number means something was lost: it is NACKed with [`NackCode::OutOfOrder`]
//!    naming the number expected, and dropped. A corrupt frame is NACKed with
//!    [`NackCode::Corrupt`] and the number expected. The host re-sends from the number
//!    a NACK names (go-back-N), and re-sends unacknowledged frames after a timeout.
//! 3. Controller messages carry their own sequence numbers so the host can see gaps.
//!
//! # Sizes
//! Every message has a maximum encoded size derived next to its type ([`MAX_TO_CONTROLLER`],
//! [`MAX_FROM_CONTROLLER`]); buffers are sized from them and `const` assertions tie
//! them together. Golden byte vectors of every message are in `tests/tests/wire.rs`.

use crate::limits::MAX_FRAME_PIXELS;
use serde::{Deserialize, Serialize};

/// Protocol magic, ASCII "RBRG" read as a little-endian `u32`.
pub const MAGIC: u32 = u32::from_le_bytes(*b"RBRG");
/// Protocol version; bumped on any change of a message's encoding.
pub const VERSION: u16 = 1;

/// Pixels travel as `u16` in 1/16 pixel: up to 4095.94 px at 0.0625 px resolution.
pub const PIXEL_SUBDIVISIONS: f32 = 16.0;
/// Template SOM-1 nodes per upload chunk (400 nodes in 13 chunks).
pub const NODES_PER_CHUNK: usize = 32;
/// Waypoints per upload chunk and per plan.
pub const WAYPOINTS_PER_CHUNK: usize = 8;
/// Most planned waypoints.
pub const MAX_WAYPOINTS: usize = 32;

// Worst-case postcard sizes of the primitives (varints: 7 bits a byte).
const U8: usize = 1;
const U16: usize = 3;
const U32: usize = 5;
const I32: usize = 5;
const U64: usize = 10;
const F32: usize = 4;
/// An enum discriminant below 128, or a sequence length below 128.
const TAG: usize = 1;

/// A point or vector, mm.
pub type P3 = [f32; 3];
/// A rigid transform on the wire: rotation row-major (9) then translation (3).
pub type RigidW = [f32; 12];

/// Probe image geometry: the core's [`crate::acquisition::probe::ProbeModel`] itself.
pub use crate::acquisition::probe::ProbeModel as ProbeW;
const PROBE_W: usize = 2 * U16 + 2 * F32;

/// Sweep and motion configuration.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Configure {
    /// Probe image geometry.
    pub probe: ProbeW,
    /// Image frame in the TCP frame.
    pub tcp_t_us: RigidW,
    /// TCP frame in the flange frame.
    pub ee_t_tcp: RigidW,
    /// Video lag behind the tracker, µs.
    pub lag_us: i32,
    /// Finest voxel edge of the compounding, mm.
    pub voxel_mm: f32,
    /// Setpoint speed limit, mm/s.
    pub max_speed_mm_s: f32,
    /// Setpoint acceleration limit, mm/s².
    pub max_accel_mm_s2: f32,
    /// Distance of the probe face from the bone surface at a waypoint, mm.
    pub standoff_mm: f32,
}
const CONFIGURE: usize = PROBE_W + 24 * F32 + I32 + 4 * F32;

/// One template SOM-1 node and its rib label (0 none, 1 sternum, 2..=5 rib).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Node {
    /// Position, template (patient) frame, mm.
    pub p: P3,
    /// Rib label.
    pub label: u8,
}
const NODE: usize = 3 * F32 + U8;

/// The template's shape: frame of its key points, rib skeleton, sternum split.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TemplateShape {
    /// Frame origin, mm.
    pub origin: P3,
    /// Frame axes (columns), row-major.
    pub axes: [f32; 9],
    /// Spread along each axis, mm.
    pub spread: P3,
    /// The 30 rib skeleton points (ribs 2..5: 6, 6, 8, 10).
    pub skeleton: [P3; 30],
    /// Per rib, the fraction of its stations on side 0.
    pub midline_fraction: [f32; 4],
}
const TEMPLATE_SHAPE: usize = (3 + 9 + 3 + 90 + 4) * F32;

/// A tracked flange pose `b_T_ee`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseW {
    /// Tracker time, µs.
    pub t_us: u64,
    /// Position, mm.
    pub position: P3,
    /// Orientation `[w, x, y, z]`.
    pub quat: [f32; 4],
}
const POSE_W: usize = U64 + 7 * F32;

/// One annotated US frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameW {
    /// Video time, µs.
    pub t_us: u64,
    /// Frame number.
    pub frame: u32,
    /// Bone pixels `(u, v)` in 1/[`PIXEL_SUBDIVISIONS`] pixel.
    pub pixels: heapless::Vec<[u16; 2], MAX_FRAME_PIXELS>,
}
const FRAME_W: usize = U64 + U32 + TAG + MAX_FRAME_PIXELS * 2 * U16;

/// Commands of the procedure.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Command {
    /// Start compounding poses and frames.
    StartSweep,
    /// Stop compounding.
    EndSweep,
    /// Register the template onto the compounded cloud.
    Register,
    /// Move the probe through the mapped waypoints.
    Execute,
    /// Stop everything, back to idle (the template is kept).
    Abort,
    /// Send a status.
    Status,
    /// Send the registration result (one message per waypoint).
    Result,
    /// Send the controller's measured costs ([`FromController::Cost`]).
    Cost,
}

/// Robot PC → controller.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum ToController {
    /// Handshake: must be the first message, sequence 0.
    Hello {
        /// [`MAGIC`].
        magic: u32,
        /// [`VERSION`].
        version: u16,
    },
    /// Calibration, lag and motion limits.
    Configure(Configure),
    /// A chunk of template nodes.
    TemplateNodes {
        /// Index of the first node of this chunk.
        offset: u16,
        /// Nodes in the whole template.
        total: u16,
        /// The nodes.
        nodes: heapless::Vec<Node, NODES_PER_CHUNK>,
    },
    /// The template's shape (after its nodes).
    TemplateShape(TemplateShape),
    /// A chunk of planned waypoints (template frame).
    Waypoints {
        /// Index of the first waypoint of this chunk.
        offset: u8,
        /// Waypoints in the whole plan.
        total: u8,
        /// The waypoints, mm.
        points: heapless::Vec<P3, WAYPOINTS_PER_CHUNK>,
    },
    /// A tracked pose (100 Hz).
    Pose(PoseW),
    /// An annotated frame (30 fps).
    Frame(FrameW),
    /// A command.
    Command(Command),
}

/// Largest encoded [`ToController`]: the frame message.
pub const MAX_TO_CONTROLLER: usize = TAG
    + max(
        max(U32 + U16, CONFIGURE),
        max(
            max(2 * U16 + TAG + NODES_PER_CHUNK * NODE, TEMPLATE_SHAPE),
            max(
                2 * U8 + TAG + WAYPOINTS_PER_CHUNK * 3 * F32,
                max(POSE_W, max(FRAME_W, TAG)),
            ),
        ),
    );

/// Controller states (see `controller`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum State {
    /// Waiting for a template (and configuration).
    Idle,
    /// Template and configuration loaded.
    TemplateLoaded,
    /// Compounding poses and frames.
    Sweeping,
    /// Registering (incrementally).
    Registering,
    /// Waypoints mapped.
    Ready,
    /// Streaming setpoints.
    Executing,
    /// Every waypoint visited.
    Done,
}

/// Why a frame or a message was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum NackCode {
    /// The frame failed COBS, CRC or decoding.
    Corrupt,
    /// A sequence number was skipped (something was lost).
    OutOfOrder,
    /// The frame was longer than [`MAX_FRAME`].
    TooLong,
    /// Wrong magic or version in the handshake, or no handshake yet.
    Version,
    /// The message is not allowed in the current state.
    BadState,
    /// The message's content was refused; the code is [`error_code`] of the core error.
    Invalid(u8),
}

/// Controller faults, reported unprompted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Fault {
    /// No robot pose for more than the timeout while executing: setpoints stopped.
    PoseTimeout,
    /// Registration failed; the code is [`error_code`] of the core error.
    Registration(u8),
}

/// Controller status.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct StatusW {
    /// State.
    pub state: State,
    /// Sequence number expected next from the host.
    pub expected_seq: u16,
    /// Poses accepted.
    pub poses: u32,
    /// Frames placed in the cloud.
    pub frames_placed: u32,
    /// Frames refused (outside the track or invalid).
    pub frames_refused: u32,
    /// Points in the cloud (voxels).
    pub points: u16,
    /// Registration progress, percent.
    pub progress: u8,
    /// Waypoint being approached while executing.
    pub waypoint: u8,
}
const STATUS_W: usize = TAG + U16 + 3 * U32 + U16 + 2 * U8;

/// One mapped waypoint of the registration result.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WaypointW {
    /// Index in the plan.
    pub index: u8,
    /// Waypoints in the plan.
    pub total: u8,
    /// Mapped position, robot base frame, mm.
    pub position: P3,
    /// Quality: RMS residual of the local rigid fit that mapped it, mm (lower is better).
    pub quality_mm: f32,
}
const WAYPOINT_W: usize = 2 * U8 + 4 * F32;

/// A probe setpoint: TCP pose in the robot base frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SetpointW {
    /// Controller time, µs.
    pub t_us: u64,
    /// TCP position, mm.
    pub position: P3,
    /// TCP orientation `[w, x, y, z]`.
    pub quat: [f32; 4],
    /// Waypoint being approached.
    pub waypoint: u8,
}
const SETPOINT_W: usize = U64 + 7 * F32 + U8;

/// What the controller's work costs on its platform (instructions counted by the
/// firmware; the in-process controller reports zeros).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct CostW {
    /// Instructions spent in registration steps, the last registration.
    pub registration_instructions: u64,
    /// Registration steps (calls) of the last registration.
    pub registration_calls: u32,
    /// Most instructions one control-loop call took (message handling, poll, replies).
    pub worst_call_instructions: u32,
    /// Most instructions one registration step took.
    pub worst_step_instructions: u32,
    /// Most instructions handling one received frame took.
    pub worst_receive_instructions: u32,
    /// Peak stack use, bytes.
    pub peak_stack_bytes: u32,
}
const COST_W: usize = U64 + 5 * U32;

/// Controller → robot PC.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum FromController {
    /// Handshake answer.
    HelloAck {
        /// [`MAGIC`].
        magic: u32,
        /// [`VERSION`].
        version: u16,
        /// [`MAX_FRAME`] of the controller.
        max_frame: u16,
    },
    /// A host message was applied (or was a duplicate of one applied).
    Ack {
        /// Its sequence number.
        seq: u16,
    },
    /// A host frame was refused.
    Nack {
        /// The sequence number the controller expects next (re-send from it).
        seq: u16,
        /// Why.
        code: NackCode,
    },
    /// Status.
    Status(StatusW),
    /// One mapped waypoint.
    Waypoint(WaypointW),
    /// A setpoint (100 Hz while executing).
    Setpoint(SetpointW),
    /// A fault.
    Fault(Fault),
    /// Measured costs (zero where the platform does not measure them).
    Cost(CostW),
}

/// Largest encoded [`FromController`].
pub const MAX_FROM_CONTROLLER: usize = TAG
    + max(
        max(U32 + 2 * U16, U16),
        max(
            U16 + 2 * TAG,
            max(
                STATUS_W,
                max(WAYPOINT_W, max(SETPOINT_W, max(2 * TAG, COST_W))),
            ),
        ),
    );

/// Envelope overhead: the sequence number.
const SEQ: usize = U16;
/// CRC bytes.
const CRC: usize = 4;
/// COBS adds one byte per 254 and the delimiter one more.
const fn framed(payload: usize) -> usize {
    payload + payload.div_ceil(254) + 1
}

/// Largest frame on the wire in either direction, delimiter included: the frame message
/// (`593 + 3 + 4 = 600` bytes before COBS, 604 after).
pub const MAX_FRAME: usize = framed(max(MAX_TO_CONTROLLER, MAX_FROM_CONTROLLER) + SEQ + CRC);

const _: () = assert!(MAX_TO_CONTROLLER == 593);
const _: () = assert!(MAX_FRAME == 604);
const _: () = assert!(MAX_FRAME <= u16::MAX as usize);

const fn max(a: usize, b: usize) -> usize {
    if a > b {
        a
    } else {
        b
    }
}

#[derive(Serialize, Deserialize)]
struct Envelope<T> {
    seq: u16,
    msg: T,
}

/// Why a frame could not be decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameError {
    /// More bytes before the delimiter than [`MAX_FRAME`]; dropped up to the next zero.
    TooLong,
    /// Not valid COBS.
    Cobs,
    /// CRC mismatch.
    Crc,
    /// Valid CRC but not a message of this version.
    Decode,
    /// The output buffer is too small to encode into.
    Buffer,
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            FrameError::TooLong => "frame longer than the protocol's maximum",
            FrameError::Cobs => "frame is not valid COBS",
            FrameError::Crc => "frame CRC mismatch",
            FrameError::Decode => "frame does not hold a message of this protocol version",
            FrameError::Buffer => "buffer too small for the frame",
        })
    }
}

impl core::error::Error for FrameError {}

/// CRC-32/ISO-HDLC (reflected poly 0xEDB88320, init and final xor 0xFFFF_FFFF): check
/// value of `"123456789"` is 0xCBF43926.
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// Encodes `msg` with sequence `seq` into `out` as one frame (delimiter included);
/// returns the frame's length.
pub fn encode<T: Serialize>(seq: u16, msg: &T, out: &mut [u8]) -> Result<usize, FrameError> {
    let mut raw = [0u8; MAX_FRAME];
    let n = postcard::to_slice(&Envelope { seq, msg }, &mut raw)
        .map_err(|_| FrameError::Buffer)?
        .len();
    if n + CRC > raw.len() {
        return Err(FrameError::Buffer);
    }
    let crc = crc32(&raw[..n]).to_le_bytes();
    raw[n..n + CRC].copy_from_slice(&crc);
    let len = n + CRC;
    if out.len() < framed(len) {
        return Err(FrameError::Buffer);
    }
    let k = cobs::encode(&raw[..len], out);
    out[k] = 0;
    Ok(k + 1)
}

/// Decodes one frame's bytes (without the delimiter), in place. The frame must hold exactly
/// one envelope: bytes after it are [`FrameError::Decode`].
pub fn decode<'de, T: Deserialize<'de>>(frame: &'de mut [u8]) -> Result<(u16, T), FrameError> {
    let n = cobs::decode_in_place(frame).map_err(|_| FrameError::Cobs)?;
    if n < CRC + 1 {
        return Err(FrameError::Cobs);
    }
    let (body, crc) = frame[..n].split_at(n - CRC);
    if crc32(body).to_le_bytes()[..] != crc[..] {
        return Err(FrameError::Crc);
    }
    // Exactly one envelope: trailing bytes are not a message of this version.
    match postcard::take_from_bytes::<Envelope<T>>(body) {
        Ok((env, [])) => Ok((env.seq, env.msg)),
        _ => Err(FrameError::Decode),
    }
}

/// Collects bytes from the link into frames: resynchronises on the zero delimiter and
/// drops over-long frames.
pub struct Receiver {
    buf: [u8; MAX_FRAME],
    len: usize,
    overflow: bool,
}

impl Default for Receiver {
    fn default() -> Self {
        Self::new()
    }
}

impl Receiver {
    /// An empty receiver.
    pub const fn new() -> Self {
        Receiver {
            buf: [0; MAX_FRAME],
            len: 0,
            overflow: false,
        }
    }

    /// Feeds one byte. Returns `Some(Ok(frame))` (the frame's bytes without the delimiter,
    /// to [`decode`]) when a delimiter ends a frame, `Some(Err(TooLong))` when it ends an
    /// over-long one, `None` otherwise (also for empty frames: consecutive zeros).
    pub fn push(&mut self, byte: u8) -> Option<Result<&mut [u8], FrameError>> {
        if byte == 0 {
            let (len, overflow) = (self.len, self.overflow);
            self.len = 0;
            self.overflow = false;
            return match (overflow, len) {
                (true, _) => Some(Err(FrameError::TooLong)),
                (false, 0) => None,
                (false, n) => Some(Ok(&mut self.buf[..n])),
            };
        }
        if self.len < self.buf.len() - 1 {
            self.buf[self.len] = byte;
            self.len += 1;
        } else {
            self.overflow = true;
        }
        None
    }
}

/// A compact code for a core error (for NACKs and faults): its variant's position.
pub fn error_code(e: &crate::Error) -> u8 {
    use crate::Error as E;
    match e {
        E::TooFewPoints { .. } => 1,
        E::TooManyPoints { .. } => 2,
        E::NonFinite { .. } => 3,
        E::OutOfRange { .. } => 4,
        E::Degenerate { .. } => 5,
        E::LabelCount { .. } => 6,
        E::Endpoints { .. } => 7,
        E::RibOrder { .. } => 8,
        E::RibPath { .. } => 9,
        E::RigidFit => 10,
        E::Capacity { .. } => 11,
        E::Config(_) => 12,
        E::TooFewSamples { .. } => 13,
        E::Sample { .. } => 14,
        E::Swing { .. } => 15,
        E::Correlation { .. } => 16,
        E::OutsideTrack { .. } => 17,
        E::TrackGap { .. } => 18,
        E::Pixel { .. } => 19,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn round_trip_and_resync() {
        let msg = ToController::Pose(PoseW {
            t_us: 123_456_789,
            position: [1.0, -2.5, 300.0],
            quat: [1.0, 0.0, 0.0, 0.0],
        });
        let mut out = [0u8; MAX_FRAME];
        let n = encode(7, &msg, &mut out).unwrap();
        assert_eq!(out[n - 1], 0);
        assert!(!out[..n - 1].contains(&0));
        // Garbage first, then the frame twice: the garbage is one bad frame, both copies decode.
        let mut rx = Receiver::new();
        let mut got = std::vec::Vec::new();
        for &b in [0x13u8, 0x37, 0xFF, 0x00]
            .iter()
            .chain(&out[..n])
            .chain(&out[..n])
        {
            if let Some(r) = rx.push(b) {
                got.push(r.and_then(decode::<ToController>));
            }
        }
        assert_eq!(got.len(), 3);
        assert!(got[0].is_err());
        assert_eq!(got[1], Ok((7, msg.clone())));
        assert_eq!(got[2], Ok((7, msg)));
    }

    #[test]
    fn corrupt_and_too_long_frames_are_reported() {
        let mut out = [0u8; MAX_FRAME];
        let n = encode(1, &ToController::Command(Command::Status), &mut out).unwrap();
        let mut bad = out;
        bad[2] ^= 0x40;
        let mut rx = Receiver::new();
        let r: std::vec::Vec<_> = bad[..n]
            .iter()
            .filter_map(|&b| {
                rx.push(b)
                    .map(|r| r.and_then(|f| decode::<ToController>(f).map(|_| ())))
            })
            .collect();
        assert!(matches!(
            r[..],
            [Err(FrameError::Crc | FrameError::Cobs | FrameError::Decode)]
        ));
        let mut rx = Receiver::new();
        let mut seen = None;
        for _ in 0..MAX_FRAME + 10 {
            assert!(rx.push(0x55).is_none());
        }
        if let Some(r) = rx.push(0) {
            seen = Some(r.map(|_| ()));
        }
        assert_eq!(seen, Some(Err(FrameError::TooLong)));
        // The next frame decodes.
        let r = out[..n]
            .iter()
            .filter_map(|&b| rx.push(b).map(|r| r.map(|f| f.len())))
            .next();
        assert!(matches!(r, Some(Ok(_))));
    }

    /// A frame holds exactly one envelope: bytes after it (under a valid CRC) are refused.
    #[test]
    fn trailing_bytes_are_refused() {
        let msg = ToController::Command(Command::Abort);
        let mut raw = [0u8; 16];
        let n = postcard::to_slice(&Envelope { seq: 5, msg: &msg }, &mut raw)
            .unwrap()
            .len();
        for extra in [0u8, 1, 0x80] {
            let mut body = std::vec::Vec::from(&raw[..n]);
            body.push(extra);
            let crc = crc32(&body).to_le_bytes();
            body.extend_from_slice(&crc);
            let mut frame = [0u8; 32];
            let k = cobs::encode(&body, &mut frame);
            assert_eq!(
                decode::<ToController>(&mut frame[..k]),
                Err(FrameError::Decode),
                "trailing {extra:#04x}"
            );
        }
        // Without the extra byte the same construction decodes.
        let mut body = std::vec::Vec::from(&raw[..n]);
        body.extend_from_slice(&crc32(&raw[..n]).to_le_bytes());
        let mut frame = [0u8; 32];
        let k = cobs::encode(&body, &mut frame);
        assert_eq!(decode(&mut frame[..k]), Ok((5, msg)));
    }

    /// The largest messages of each direction encode to exactly their derived maxima.
    #[test]
    fn maxima_are_tight() {
        let mut pixels = heapless::Vec::new();
        for _ in 0..MAX_FRAME_PIXELS {
            pixels.push([u16::MAX, u16::MAX]).unwrap();
        }
        let big = ToController::Frame(FrameW {
            t_us: u64::MAX,
            frame: u32::MAX,
            pixels,
        });
        let mut buf = [0u8; 2 * MAX_FRAME];
        let n = postcard::to_slice(&big, &mut buf).unwrap().len();
        assert_eq!(n, MAX_TO_CONTROLLER);
        let sp = FromController::Setpoint(SetpointW {
            t_us: u64::MAX,
            position: [0.0; 3],
            quat: [0.0; 4],
            waypoint: u8::MAX,
        });
        let n = postcard::to_slice(&sp, &mut buf).unwrap().len();
        assert!(n <= MAX_FROM_CONTROLLER);
        let st = FromController::Status(StatusW {
            state: State::Executing,
            expected_seq: u16::MAX,
            poses: u32::MAX,
            frames_placed: u32::MAX,
            frames_refused: u32::MAX,
            points: u16::MAX,
            progress: u8::MAX,
            waypoint: u8::MAX,
        });
        assert!(postcard::to_slice(&st, &mut buf).unwrap().len() <= MAX_FROM_CONTROLLER);
        let n = encode(u16::MAX, &big, &mut buf).unwrap();
        assert_eq!(n, MAX_FRAME);
    }
}
