//! Shared pieces of the fuzz targets: the controller driven by a recorded procedure and
//! then by the fuzzer's input.
//!
//! # The controller target's input
//! The first byte picks the controller to start from, so every state is reached: a fresh
//! one, or a snapshot taken at one of [`SNAPSHOTS`] evenly spaced points of a whole
//! recorded procedure (`ribreg hil --in-process --quick`, recorded once per process:
//! handshake, configuration, upload, sweep, registration, execution). The rest is a list
//! of steps, each a tag byte and its operands ([`parse_ops`]).

use ribreg_core::wire::{self, Command, FromController, ToController, MAX_FRAME};
use ribreg_sim::error::CliError;
use ribreg_sim::hil::{self, InProcess, Port, RunOptions, Session};
use std::sync::OnceLock;
use std::time::Duration;

/// One step of a controller run.
#[derive(Debug)]
pub enum Op<'a> {
    /// Tag 0, length byte, bytes: a message decoded (postcard) from the bytes, framed
    /// with the number the controller expects, so it is applied (the fuzzer finds the
    /// layouts by coverage).
    Next(&'a [u8]),
    /// Tag 1, u16 LE, length byte, bytes: the same with this sequence number instead
    /// (duplicates, gaps, wrap-around).
    Seq(u16, &'a [u8]),
    /// Tag 2, length byte, bytes: raw bytes on the link, then a delimiter.
    Raw(&'a [u8]),
    /// Tag 3, one byte: that many ms pass, the controller polled once at their end (a
    /// late main loop). One poll, not one a ms: a registering controller's poll is a
    /// registration step, and the states along the registration are reached by the
    /// snapshots, so each input stays cheap (see [`start`]).
    Advance(u8),
}

/// The steps encoded in `data` (a cut-off last step is dropped).
pub fn parse_ops(mut data: &[u8]) -> Vec<Op<'_>> {
    fn take<'a>(d: &mut &'a [u8], n: usize) -> Option<&'a [u8]> {
        if d.len() < n {
            return None;
        }
        let (a, b) = d.split_at(n);
        *d = b;
        Some(a)
    }
    fn bytes<'a>(d: &mut &'a [u8]) -> Option<&'a [u8]> {
        let n = usize::from(*take(d, 1)?.first()?);
        take(d, n)
    }
    let mut ops = Vec::new();
    while let Some(tag) = take(&mut data, 1) {
        let op = match tag[0] % 4 {
            0 => bytes(&mut data).map(Op::Next),
            1 => take(&mut data, 2)
                .map(|s| u16::from_le_bytes([s[0], s[1]]))
                .and_then(|seq| bytes(&mut data).map(|b| Op::Seq(seq, b))),
            2 => bytes(&mut data).map(Op::Raw),
            _ => take(&mut data, 1).map(|m| Op::Advance(m[0])),
        };
        match op {
            Some(op) => ops.push(op),
            None => break,
        }
    }
    ops
}

/// What the robot PC did to the link in a recorded procedure.
#[derive(Clone, Debug)]
pub enum Event {
    /// Bytes written (one frame).
    Write(Vec<u8>),
    /// Controller time advanced, µs.
    Advance(u64),
}

/// A port that records what passes to the in-process controller.
struct Recorder {
    inner: InProcess,
    log: Vec<Event>,
}

impl Port for Recorder {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), CliError> {
        self.log.push(Event::Write(bytes.to_vec()));
        self.inner.write_all(bytes)
    }
    fn read_into(&mut self, out: &mut Vec<u8>, wait: Duration) -> Result<(), CliError> {
        self.inner.read_into(out, wait)
    }
    fn advance(&mut self, us: u64) {
        self.log.push(Event::Advance(us));
        self.inner.advance(us);
    }
    fn simulated_clock(&self) -> bool {
        true
    }
}

/// Snapshots taken along the recorded procedure.
pub const SNAPSHOTS: usize = 64;

/// The events of a whole quick procedure on the default phantom.
fn record() -> Vec<Event> {
    let mut session = Session::new(Recorder {
        inner: InProcess::new(),
        log: Vec::new(),
    });
    // Note: a failing procedure is a bug of its own, found by the host tests.
    hil::run_with(
        &mut session,
        &Default::default(),
        RunOptions::quick(),
        &mut |_| {},
    )
    .expect("the recorded procedure runs");
    session.port.log
}

/// A fresh run, or (`k` = 1..=[`SNAPSHOTS`]) one resumed from snapshot `k` of the
/// recorded procedure (taken once per process).
pub fn start(k: u8) -> Run {
    static SNAPS: OnceLock<Vec<Run>> = OnceLock::new();
    let snaps = SNAPS.get_or_init(|| {
        let log = record();
        let mut run = Run::new();
        let mut snaps = Vec::new();
        let mut done = 0;
        for i in 1..=SNAPSHOTS {
            let upto = log.len() * i / SNAPSHOTS;
            run.replay(&log[done..upto]);
            done = upto;
            snaps.push(run.clone());
        }
        snaps
    });
    match usize::from(k) % (SNAPSHOTS + 1) {
        0 => Run::new(),
        i => snaps[i - 1].clone(),
    }
}

/// One controller run (the in-process port `ribreg hil` uses), with the link's
/// invariants checked after every frame.
#[derive(Clone)]
pub struct Run {
    /// The controller under test behind its byte link.
    pub port: InProcess,
    /// Cuts the controller's replies into frames.
    replies: wire::Receiver,
}

impl Default for Run {
    fn default() -> Self {
        Self::new()
    }
}

impl Run {
    /// A fresh controller at time 0.
    pub fn new() -> Self {
        Run {
            port: InProcess::new(),
            replies: wire::Receiver::new(),
        }
    }

    /// Frames `msg` with `seq` and feeds it. Checks: the frame is answered; a frame
    /// that is not the expected number (a duplicate, a gap) is not applied (the
    /// expected number and the pose count stay); the expected number moves by at most
    /// one and the pose count by at most one pose.
    pub fn send(&mut self, seq: u16, msg: &ToController) -> Vec<(u16, FromController)> {
        let mut buf = [0u8; MAX_FRAME];
        let Ok(n) = wire::encode(seq, msg, &mut buf) else {
            return Vec::new();
        };
        let before = self.port.controller.status();
        let replies = self.feed(&buf[..n]);
        let after = self.port.controller.status();
        assert!(!replies.is_empty(), "frame {seq} {msg:?} got no reply");
        if !matches!(msg, ToController::Hello { .. }) {
            if seq != before.expected_seq {
                assert_eq!(after.expected_seq, before.expected_seq, "{seq}: {msg:?}");
                assert_eq!(
                    after.poses, before.poses,
                    "{seq}: a pose applied out of order"
                );
            } else {
                assert!(
                    after.expected_seq == before.expected_seq.wrapping_add(1)
                        || after.expected_seq == before.expected_seq,
                    "{seq}: expected {} -> {}",
                    before.expected_seq,
                    after.expected_seq
                );
            }
            if matches!(msg, ToController::Pose(_)) {
                assert!(after.poses <= before.poses + 1, "one pose applied twice");
            }
        }
        replies
    }

    /// Feeds raw bytes; returns the replies.
    pub fn feed(&mut self, bytes: &[u8]) -> Vec<(u16, FromController)> {
        // Note: the in-process port never fails.
        self.port.write_all(bytes).expect("in-process write");
        self.drain()
    }

    /// Takes the replies; each is a frame that decodes.
    fn drain(&mut self) -> Vec<(u16, FromController)> {
        let mut bytes = Vec::new();
        self.port
            .read_into(&mut bytes, Duration::ZERO)
            .expect("in-process read");
        let mut out = Vec::new();
        for b in bytes {
            if let Some(frame) = self.replies.push(b) {
                let frame = frame.expect("a reply fits MAX_FRAME");
                out.push(wire::decode::<FromController>(frame).expect("a reply decodes"));
            }
        }
        out
    }

    /// Replays recorded events (no checks: the host tests check the procedure).
    pub fn replay(&mut self, events: &[Event]) {
        for e in events {
            match e {
                Event::Write(bytes) => {
                    self.feed(bytes);
                }
                Event::Advance(us) => self.advance(*us),
            }
        }
    }

    /// Time passes (the port polls the controller every ms).
    fn advance(&mut self, us: u64) {
        self.port.advance(us);
        self.drain();
    }

    /// Applies one step.
    pub fn step(&mut self, op: &Op<'_>) {
        match op {
            Op::Next(bytes) => {
                if let Ok(msg) = postcard::from_bytes::<ToController>(bytes) {
                    let seq = self.port.controller.status().expected_seq;
                    self.send(seq, &msg);
                }
            }
            Op::Seq(seq, bytes) => {
                if let Ok(msg) = postcard::from_bytes::<ToController>(bytes) {
                    self.send(*seq, &msg);
                }
            }
            Op::Raw(bytes) => {
                // Ends with a delimiter, so the next frame starts clean.
                self.feed(bytes);
                self.feed(&[0]);
            }
            Op::Advance(ms) => {
                self.port.advance_late(u64::from(*ms) * 1000);
                self.drain();
            }
        }
    }

    /// The controller still answers: a Status command with the expected number is
    /// answered whatever came before.
    pub fn check_answers(&mut self) {
        let expected = self.port.controller.status().expected_seq;
        self.send(expected, &ToController::Command(Command::Status));
    }
}

/// A multi-format target's input: the first byte picks one of `formats` readers, the
/// rest is the file's bytes.
pub fn tagged(data: &[u8], formats: u8) -> Option<(u8, &[u8])> {
    let (&which, bytes) = data.split_first()?;
    Some((which % formats, bytes))
}

/// [`tagged`] for text readers: `None` unless the rest is UTF-8 (the readers' own
/// UTF-8 check is a one-liner in front of them).
pub fn tagged_text(data: &[u8], formats: u8) -> Option<(u8, &str)> {
    let (which, bytes) = tagged(data, formats)?;
    Some((which, std::str::from_utf8(bytes).ok()?))
}
