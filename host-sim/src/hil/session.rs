//! The robot PC's side of the protocol: the handshake is the first message like any
//! other, every message gets the next sequence number and stays in a go-back-N window of
//! [`WINDOW`] until ACKed; a transport NACK (corrupt, out of order, too long) or a
//! silence of [`RESEND_AFTER`] re-sends the window from the number the controller
//! expects. Application NACKs (bad state, invalid content) are recorded, not re-sent.
//! Everything else the controller says is queued for [`Session::next_message`].

use ribreg_core::wire::{self, FromController, NackCode, ToController, MAX_FRAME};
use serde::Serialize;
use std::collections::VecDeque;
use std::time::{Duration, Instant};

use super::port::Port;
use crate::error::CliError;

/// Frames in flight before the sender waits for ACKs.
pub const WINDOW: usize = 24;
/// Silence after which the unacknowledged window is re-sent.
pub const RESEND_AFTER: Duration = Duration::from_millis(300);

/// Link counters of a run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct LinkStats {
    /// Frames sent the first time.
    pub sent: u64,
    /// Frames re-sent.
    pub resent: u64,
    /// Transport NACKs received.
    pub nacks: u64,
    /// Timeouts that re-sent the window.
    pub timeouts: u64,
    /// Faults injected: corrupted, dropped, duplicated, reordered, garbage bursts.
    pub injected: [u64; 5],
    /// Bytes written.
    pub bytes: u64,
}

/// The robot PC's protocol engine.
pub struct Session<P: Port> {
    /// The controller end.
    pub port: P,
    next_seq: u16,
    window: VecDeque<(u16, Vec<u8>)>,
    rx: wire::Receiver,
    bytes: Vec<u8>,
    inbox: VecDeque<FromController>,
    /// Application NACKs: (sequence, code).
    pub refused: Vec<(u16, NackCode)>,
    /// Counters.
    pub stats: LinkStats,
    last_progress: Instant,
}

impl<P: Port> Session<P> {
    /// A session over `port` (wrap it in a [`super::FaultInjector`] for link faults).
    pub fn new(port: P) -> Self {
        Session {
            port,
            next_seq: 0,
            window: VecDeque::new(),
            rx: wire::Receiver::new(),
            bytes: Vec::new(),
            inbox: VecDeque::new(),
            refused: Vec::new(),
            stats: LinkStats::default(),
            last_progress: Instant::now(),
        }
    }

    /// Writes one frame to the port (one write a frame: a fault injector counts on it).
    fn transmit(&mut self, frame: &[u8]) -> Result<(), CliError> {
        self.stats.bytes += frame.len() as u64;
        self.port.write_all(frame)
    }

    /// Sends a message (waits for room in the window); returns its sequence number.
    pub fn send(&mut self, msg: &ToController) -> Result<u16, CliError> {
        while self.window.len() >= WINDOW {
            self.pump(Duration::from_millis(5))?;
        }
        let seq = self.next_seq;
        self.next_seq = self.next_seq.wrapping_add(1);
        let mut buf = [0u8; MAX_FRAME];
        let n =
            wire::encode(seq, msg, &mut buf).map_err(|e| CliError::Link(format!("encode: {e}")))?;
        let frame = buf[..n].to_vec();
        self.transmit(&frame)?;
        self.stats.sent += 1;
        if self.window.is_empty() {
            self.last_progress = Instant::now();
        }
        self.window.push_back((seq, frame));
        Ok(seq)
    }

    /// Re-sends the window from `seq` on.
    fn resend_from(&mut self, seq: u16) -> Result<(), CliError> {
        let frames: Vec<Vec<u8>> = self
            .window
            .iter()
            .filter(|(s, _)| s.wrapping_sub(seq) < 0x8000)
            .map(|(_, f)| f.clone())
            .collect();
        for f in frames {
            self.transmit(&f)?;
            self.stats.resent += 1;
        }
        self.last_progress = Instant::now();
        Ok(())
    }

    /// Everything up to and including `seq` is handled.
    fn handled(&mut self, seq: u16) {
        let before = self.window.len();
        while let Some((s, _)) = self.window.front() {
            if seq.wrapping_sub(*s) < 0x8000 {
                self.window.pop_front();
            } else {
                break;
            }
        }
        if self.window.len() != before {
            self.last_progress = Instant::now();
        }
    }

    /// Reads what arrived (waiting at most `wait`), handles ACKs and NACKs, queues the rest.
    pub fn pump(&mut self, wait: Duration) -> Result<(), CliError> {
        self.port.read_into(&mut self.bytes, wait)?;
        let bytes = std::mem::take(&mut self.bytes);
        let mut nack_from = None;
        for b in bytes {
            if let Some(Ok(frame)) = self.rx.push(b) {
                let Ok((_, msg)) = wire::decode::<FromController>(frame) else {
                    continue;
                };
                match msg {
                    FromController::Ack { seq } => self.handled(seq),
                    FromController::Nack { seq, code } => match code {
                        NackCode::Corrupt | NackCode::OutOfOrder | NackCode::TooLong => {
                            self.stats.nacks += 1;
                            nack_from = Some(seq);
                        }
                        _ => {
                            self.refused.push((seq, code));
                            self.handled(seq);
                        }
                    },
                    FromController::HelloAck { .. } => {
                        self.handled(0);
                        self.inbox.push_back(msg);
                    }
                    other => self.inbox.push_back(other),
                }
            }
        }
        if let Some(seq) = nack_from {
            // Everything before the expected number was applied.
            self.handled(seq.wrapping_sub(1));
            self.resend_from(seq)?;
        } else if !self.window.is_empty() && self.last_progress.elapsed() > RESEND_AFTER {
            self.stats.timeouts += 1;
            let first = self.window.front().map_or(0, |(s, _)| *s);
            self.resend_from(first)?;
        }
        Ok(())
    }

    /// Waits until every message sent is handled.
    pub fn flush(&mut self, deadline: Duration) -> Result<(), CliError> {
        let start = Instant::now();
        while !self.window.is_empty() {
            if start.elapsed() > deadline {
                return Err(CliError::Link(format!(
                    "link: {} messages unacknowledged after {:.0} s",
                    self.window.len(),
                    deadline.as_secs_f64()
                )));
            }
            self.port.advance(1000);
            self.pump(Duration::from_millis(2))?;
        }
        Ok(())
    }

    /// The link counters, with what a fault injector under the session did (its faults,
    /// and the bytes it wrote instead of those handed to it).
    pub fn link_stats(&self) -> LinkStats {
        let mut stats = self.stats;
        if let Some(f) = self.port.fault_stats() {
            stats.injected = f.injected;
            stats.bytes = f.bytes;
        }
        stats
    }

    /// The next controller message that is not an ACK/NACK.
    pub fn next_message(&mut self) -> Option<FromController> {
        self.inbox.pop_front()
    }
}
