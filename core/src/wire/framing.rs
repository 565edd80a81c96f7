//! Framing: a message in an envelope with its sequence number, postcard-encoded,
//! CRC-32 appended, COBS-encoded and ended by a zero ([`encode`], [`decode`]); the
//! [`Receiver`] that cuts the byte stream into frames; [`MAX_FRAME`], derived from the
//! message maxima of [`super::messages`].

use super::messages::{max, MAX_FROM_CONTROLLER, MAX_TO_CONTROLLER, U16};
use serde::{Deserialize, Serialize};

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

const _: () = assert!(MAX_FRAME == 604);
const _: () = assert!(MAX_FRAME <= u16::MAX as usize);

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
#[derive(Clone)]
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::limits::MAX_FRAME_PIXELS;
    use crate::wire::{
        Command, FrameW, FromController, PoseW, SetpointW, State, StatusW, ToController,
    };

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
