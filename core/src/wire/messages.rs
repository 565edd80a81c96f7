//! The message types of the protocol, each with its maximum encoded size derived next
//! to it (postcard's worst case per primitive), the direction maxima
//! ([`MAX_TO_CONTROLLER`], [`MAX_FROM_CONTROLLER`]) and the `const` assertions on them,
//! and [`error_code`], the compact code of a core error that NACKs and faults carry.
//! Nothing here knows how a message is framed ([`super::framing`]).

use crate::limits::MAX_FRAME_PIXELS;
use serde::{Deserialize, Serialize};

/// Protocol magic, ASCII "RBRG" read as a little-endian `u32`.
pub const MAGIC: u32 = u32::from_le_bytes(*b"RBRG");
/// Protocol version; bumped on any change of a message's encoding.
pub const VERSION: u16 = 5;

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
pub(super) const U16: usize = 3;
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
    /// The patient's anterior (the chest's front) as a direction in the robot base
    /// frame, roughly: the registration's orientation prior
    /// ([`crate::config::Config::target_up`]). All zeros: none, any pose. (Added in
    /// version 2.)
    pub target_up: P3,
    /// Partial plans: map every waypoint and mark those the sweep does not reach
    /// ([`WaypointW::supported`]; they are never driven to) instead of refusing the
    /// registration; a registration that reaches none is still refused. (Added in
    /// version 4.)
    pub partial: bool,
}
const CONFIGURE: usize = PROBE_W + 24 * F32 + I32 + 4 * F32 + 3 * F32 + U8;

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
    /// Send the registration result: its confidence ([`FromController::Registration`]),
    /// then one message per waypoint.
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
    /// The frame was longer than [`MAX_FRAME`](super::MAX_FRAME).
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
    /// Whether the sweep reaches it ([`crate::registration::reach`]): `false` only in a
    /// partial plan ([`Configure::partial`]), and the controller does not drive there.
    /// (Added in version 4.)
    pub supported: bool,
}
const WAYPOINT_W: usize = 3 * U8 + 4 * F32;

/// How clearly the registration found the patient, sent before its waypoints: the pose
/// hypotheses' residuals ([`crate::registration::guided::PoseConfidence`]) and the
/// target's coverage ([`crate::registration::guided::side_shares`]). (Added in version 2;
/// `support_mm` in version 3.)
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RegistrationW {
    /// Pose hypotheses refined.
    pub hypotheses: u8,
    /// Residual of the pose taken, mm.
    pub residual_mm: f32,
    /// Residual of the best hypothesis distinct from it, mm (infinite when none).
    pub runner_up_mm: f32,
    /// How closely the sweep supports the whole template, mm
    /// ([`crate::registration::guided::PoseConfidence::support_mm`]).
    pub support_mm: f32,
    /// The target's smallest rib-side span, percent of the template's (saturating).
    pub min_side_span_percent: u8,
    /// How far beyond its nearest rib end the sweep imaged, mm
    /// ([`crate::registration::reach::edge_clearances`], at most
    /// [`crate::registration::reach::EDGE_LOOK_MM`]; NaN when not measured). (Added in
    /// version 5.)
    pub min_edge_clearance_mm: f32,
    /// Waypoints mapped (the [`FromController::Waypoint`] messages that follow).
    pub waypoints: u8,
}
const REGISTRATION_W: usize = 3 * U8 + 4 * F32;

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
    /// UART receive overruns (a byte lost in the receive register) since boot.
    pub serial_overruns: u32,
    /// UART framing, noise and parity errors since boot.
    pub serial_framing_errors: u32,
    /// Bytes received while the firmware's RX queue was full (dropped) since boot.
    pub serial_dropped_bytes: u32,
}
const COST_W: usize = U64 + 8 * U32;

/// Controller → robot PC.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum FromController {
    /// Handshake answer.
    HelloAck {
        /// [`MAGIC`].
        magic: u32,
        /// [`VERSION`].
        version: u16,
        /// [`MAX_FRAME`](super::MAX_FRAME) of the controller.
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
    /// The registration's confidence, before its waypoints (on [`Command::Result`]).
    Registration(RegistrationW),
}

/// Largest encoded [`FromController`].
pub const MAX_FROM_CONTROLLER: usize = TAG
    + max(
        max(U32 + 2 * U16, U16),
        max(
            U16 + 2 * TAG,
            max(
                STATUS_W,
                max(
                    WAYPOINT_W,
                    max(SETPOINT_W, max(2 * TAG, max(COST_W, REGISTRATION_W))),
                ),
            ),
        ),
    );

const _: () = assert!(MAX_TO_CONTROLLER == 593);

pub(super) const fn max(a: usize, b: usize) -> usize {
    if a > b {
        a
    } else {
        b
    }
}

/// What an [`error_code`] stands for, in a few words (the code travels without the
/// error's fields); `"unknown error"` for a code no error has.
pub fn error_summary(code: u8) -> &'static str {
    match code {
        1 => "too few points",
        2 => "too many points",
        3 => "a coordinate is not finite",
        4 => "a coordinate is out of range",
        5 => "the cloud is degenerate (flat, a line or a point)",
        6 => "the labels do not match the points",
        7 => "the rib endpoints were not found",
        8 => "the rib order is inconsistent",
        9 => "a rib path was not found",
        10 => "a rigid fit failed",
        11 => "a capacity was exceeded",
        12 => "invalid configuration or state",
        13 => "too few calibration samples",
        14 => "an invalid sample (a robot pose, a frame or a calibration row)",
        15 => "the calibration motion is too small",
        16 => "the temporal calibration did not correlate",
        17 => "a frame lies outside the tracked poses",
        18 => "a gap in the tracked poses",
        19 => "a pixel outside the image",
        20 => "a rib side was not seen in the sweep (scan it and register again)",
        21 => "the target's pose is ambiguous (scan more of both sides and register again)",
        22 => "no pose agrees with the configured patient orientation",
        23 => "the sweep does not support the mapped template (scan both sides and register again)",
        24 => {
            "the sweep does not reach a waypoint (scan its gap out to the lateral ends, or \
               configure a partial plan)"
        }
        25 => {
            "the sweep looks cut short on one side (scan that side out to the cartilages' \
               ends and register again)"
        }
        26 => {
            "the sweep looks cut short on both sides (scan both sides out to the \
               cartilages' ends and register again)"
        }
        27 => {
            "a rib runs to the edge of the sweep (scan that side past the cartilages' ends \
               and register again, or configure a partial plan)"
        }
        28 => {
            "a rib's two sides meet the sternum at different heights: one side was taken \
               for the next rib (scan both sides and register again)"
        }
        _ => "unknown error",
    }
}

impl core::fmt::Display for NackCode {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            NackCode::Corrupt => f.write_str("corrupt frame (COBS, CRC or decoding)"),
            NackCode::OutOfOrder => f.write_str("sequence number skipped"),
            NackCode::TooLong => f.write_str("frame too long"),
            NackCode::Version => f.write_str("wrong magic or version, or no handshake yet"),
            NackCode::BadState => f.write_str("not allowed in the controller's state"),
            NackCode::Invalid(code) => write!(
                f,
                "content refused: {} (error code {code})",
                error_summary(*code)
            ),
        }
    }
}

impl core::fmt::Display for Fault {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Fault::PoseTimeout => f.write_str("robot poses stopped while executing"),
            Fault::Registration(code) => write!(
                f,
                "registration refused: {} (error code {code})",
                error_summary(*code)
            ),
        }
    }
}

/// A compact code for a core error (for NACKs and faults): its variant's position.
pub fn error_code(e: &crate::error::Error) -> u8 {
    use crate::error::Error as E;
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
        E::NotSeen { .. } => 20,
        E::Ambiguous { .. } => 21,
        E::AgainstPrior { .. } => 22,
        E::Unsupported { .. } => 23,
        E::NotReached { .. } => 24,
        E::SideShort { .. } => 25,
        E::SweepShort { .. } => 26,
        E::SweepEdge { .. } => 27,
        E::RibLevels { .. } => 28,
    }
}
