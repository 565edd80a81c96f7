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
//!
//! # Layout
//! * `messages`: the message types, their maximum encoded sizes and the `const`
//!   assertions on them, [`error_code`].
//! * `framing`: postcard + CRC-32 + COBS ([`encode`], [`decode`], [`crc32`]), the
//!   [`Receiver`], [`FrameError`], [`MAX_FRAME`]; it builds on `messages`.
//!
//! Everything public is re-exported here: the paths are `ribreg_core::wire::X`.
//!
//! # Dependencies
//! The protocol is the bottom of the controller's stack: it uses [`crate::error`],
//! [`crate::limits`] and the core's probe model ([`ProbeW`]), never the controller or
//! the registration.

mod framing;
mod messages;

pub use self::framing::{crc32, decode, encode, FrameError, Receiver, MAX_FRAME};
pub use self::messages::{
    error_code, error_summary, Command, Configure, CostW, Fault, FrameW, FromController, NackCode,
    Node, PoseW, ProbeW, RegistrationW, RigidW, SetpointW, State, StatusW, TemplateShape,
    ToController, WaypointW, MAGIC, MAX_FROM_CONTROLLER, MAX_TO_CONTROLLER, MAX_WAYPOINTS,
    NODES_PER_CHUNK, P3, PIXEL_SUBDIVISIONS, VERSION, WAYPOINTS_PER_CHUNK,
};
