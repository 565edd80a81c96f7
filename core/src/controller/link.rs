//! The link layer of the controller: host sequence numbers (the expected one is applied
//! and ACKed, a duplicate gets its first reply again, a skipped number or a corrupt frame
//! is NACKed with the number expected), the handshake, the recent replies kept for
//! duplicates and the bounded outbox the replies wait in (see [`crate::wire`], "Session").

use super::Controller;
use crate::wire::{FrameError, FromController, NackCode, ToController, MAGIC, MAX_FRAME, VERSION};

/// Replies remembered for duplicates (a re-sent frame gets its first reply again).
pub(super) const RECENT: usize = 16;

impl<const VOXELS: usize> Controller<VOXELS> {
    /// The next reply to send, with its sequence number.
    pub fn next_reply(&mut self) -> Option<(u16, FromController)> {
        self.outbox.pop_front()
    }

    pub(super) fn send(&mut self, msg: FromController) {
        let seq = self.out_seq;
        self.out_seq = self.out_seq.wrapping_add(1);
        if self.outbox.push_back((seq, msg)).is_err() {
            self.dropped_replies = self.dropped_replies.saturating_add(1);
        }
    }

    /// A reply to host message `seq`, remembered for duplicates.
    pub(super) fn reply(&mut self, seq: u16, msg: FromController) {
        if self.recent.is_full() {
            self.recent.pop_front();
        }
        let _ = self.recent.push_back((seq, msg));
        self.send(msg);
    }

    /// The link side of [`Controller::receive`]: decodes the frame, answers the handshake,
    /// NACKs a corrupt, unsequenced or out-of-order frame, answers a duplicate again.
    /// Returns the message to apply (the expected number, now counted), `None` when the
    /// frame was handled here.
    pub(super) fn accept(
        &mut self,
        frame: core::result::Result<&mut [u8], FrameError>,
    ) -> Option<(u16, ToController)> {
        let decoded = frame.and_then(crate::wire::decode::<ToController>);
        let (seq, msg) = match decoded {
            Ok(m) => m,
            Err(e) => {
                let code = if e == FrameError::TooLong {
                    NackCode::TooLong
                } else {
                    NackCode::Corrupt
                };
                self.send(FromController::Nack {
                    seq: self.expected,
                    code,
                });
                return None;
            }
        };
        if let ToController::Hello { magic, version } = msg {
            if seq == 0 && magic == MAGIC && version == VERSION {
                self.connected = true;
                self.expected = 1;
                self.recent.clear();
                self.reply(
                    0,
                    FromController::HelloAck {
                        magic: MAGIC,
                        version: VERSION,
                        max_frame: MAX_FRAME as u16,
                    },
                );
            } else {
                self.send(FromController::Nack {
                    seq,
                    code: NackCode::Version,
                });
            }
            return None;
        }
        if !self.connected {
            self.send(FromController::Nack {
                seq,
                code: NackCode::Version,
            });
            return None;
        }
        if seq != self.expected {
            // Behind the expected number (within half the space): a duplicate.
            if self.expected.wrapping_sub(seq) <= 0x8000 {
                let first = self.recent.iter().find(|(s, _)| *s == seq).map(|(_, m)| *m);
                self.send(first.unwrap_or(FromController::Ack { seq }));
            } else {
                self.send(FromController::Nack {
                    seq: self.expected,
                    code: NackCode::OutOfOrder,
                });
            }
            return None;
        }
        self.expected = self.expected.wrapping_add(1);
        Some((seq, msg))
    }
}

#[cfg(test)]
mod link_tests {
    use super::*;
    use crate::wire::{encode, Command, Configure, State};

    type C = Controller<64>;

    fn frame(seq: u16, msg: &ToController) -> std::vec::Vec<u8> {
        let mut buf = [0u8; MAX_FRAME];
        let n = encode(seq, msg, &mut buf).unwrap();
        buf[..n - 1].to_vec()
    }

    fn feed(c: &mut C, seq: u16, msg: &ToController) -> std::vec::Vec<FromController> {
        let mut f = frame(seq, msg);
        c.receive(Ok(&mut f), 0);
        core::iter::from_fn(|| c.next_reply().map(|(_, m)| m)).collect()
    }

    const HELLO: ToController = ToController::Hello {
        magic: MAGIC,
        version: VERSION,
    };
    const STATUS: ToController = ToController::Command(Command::Status);

    #[test]
    fn handshake_first_and_version_checked() {
        let mut c = C::new();
        assert_eq!(
            feed(&mut c, 0, &STATUS),
            [FromController::Nack {
                seq: 0,
                code: NackCode::Version
            }]
        );
        let wrong = ToController::Hello {
            magic: MAGIC,
            version: VERSION + 1,
        };
        assert!(matches!(
            feed(&mut c, 0, &wrong)[..],
            [FromController::Nack {
                code: NackCode::Version,
                ..
            }]
        ));
        assert!(matches!(
            feed(&mut c, 0, &HELLO)[..],
            [FromController::HelloAck { .. }]
        ));
    }

    #[test]
    fn duplicates_are_not_reapplied_gaps_and_corruption_are_nacked() {
        let mut c = C::new();
        feed(&mut c, 0, &HELLO);
        // Seq 1: a status (its reply: a Status, then the ACK).
        let r = feed(&mut c, 1, &STATUS);
        assert!(matches!(
            r[..],
            [FromController::Status(_), FromController::Ack { seq: 1 }]
        ));
        // The same frame again: only its ACK again, no second Status.
        assert_eq!(feed(&mut c, 1, &STATUS), [FromController::Ack { seq: 1 }]);
        // Seq 3 skips 2: NACK naming 2, nothing applied.
        assert_eq!(
            feed(&mut c, 3, &STATUS),
            [FromController::Nack {
                seq: 2,
                code: NackCode::OutOfOrder
            }]
        );
        // A corrupt frame: NACK naming the number expected.
        let mut f = frame(2, &STATUS);
        f[1] ^= 0x10;
        c.receive(Ok(&mut f), 0);
        assert_eq!(
            c.next_reply().map(|(_, m)| m),
            Some(FromController::Nack {
                seq: 2,
                code: NackCode::Corrupt
            })
        );
        c.receive(Err(FrameError::TooLong), 0);
        assert_eq!(
            c.next_reply().map(|(_, m)| m),
            Some(FromController::Nack {
                seq: 2,
                code: NackCode::TooLong
            })
        );
        // A message in the wrong state is refused with its own number and consumed.
        let r = feed(&mut c, 2, &ToController::Command(Command::EndSweep));
        assert_eq!(
            r,
            [FromController::Nack {
                seq: 2,
                code: NackCode::BadState
            }]
        );
        assert!(
            matches!(feed(&mut c, 3, &STATUS)[..], [FromController::Status(s), FromController::Ack { seq: 3 }] if s.expected_seq == 4)
        );
    }

    #[test]
    fn bad_configuration_is_invalid_and_nothing_changes() {
        let mut c = C::new();
        feed(&mut c, 0, &HELLO);
        let bad = ToController::Configure(Configure {
            probe: crate::wire::ProbeW {
                width_px: 0,
                height_px: 10,
                footprint_mm: 30.0,
                depth_mm: 30.0,
            },
            tcp_t_us: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
            ee_t_tcp: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
            lag_us: 0,
            voxel_mm: 2.0,
            max_speed_mm_s: 10.0,
            max_accel_mm_s2: 10.0,
            standoff_mm: 10.0,
            target_up: [0.0; 3],
            partial: false,
        });
        assert!(matches!(
            feed(&mut c, 1, &bad)[..],
            [FromController::Nack {
                seq: 1,
                code: NackCode::Invalid(12)
            }]
        ));
        assert_eq!(c.state(), State::Idle);
    }
}
