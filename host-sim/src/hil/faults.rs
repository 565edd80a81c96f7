//! Link fault injection (`--faults`) as a wrapper around a [`Port`], in the manner of
//! smoltcp's `phy::FaultInjector`: [`FaultInjector`] is a port itself, so the session
//! above it neither knows nor cares.
//!
//! Every write the session makes is one frame. With the configured probabilities the
//! injector precedes it by a burst of garbage bytes, flips one of its bytes, drops it,
//! sends it twice, or holds it back to send after the next frame (reordered). The draws
//! from the seeded generator are, per frame and in this order: garbage (then its length
//! and bytes), corruption (then the byte and bit), and one roll that picks drop,
//! duplicate, reorder or none — so a seed gives the same fault sequence whatever the
//! transport underneath. Replies from the controller pass through untouched.

use ribreg_core::math::rng::Rng;
use serde::Serialize;
use std::time::Duration;

use super::port::Port;
use crate::error::CliError;

/// Probabilities of each link fault per host frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Faults {
    /// One byte of the frame flipped.
    pub corrupt: f64,
    /// The frame not sent.
    pub drop: f64,
    /// The frame sent twice.
    pub duplicate: f64,
    /// The frame held back and sent after the next one.
    pub reorder: f64,
    /// A burst of 1–64 random bytes (ending in a zero) sent before the frame.
    pub garbage: f64,
}

impl Faults {
    /// No faults: the frames pass through.
    pub const NONE: Faults = Faults {
        corrupt: 0.0,
        drop: 0.0,
        duplicate: 0.0,
        reorder: 0.0,
        garbage: 0.0,
    };

    /// 2 % of each.
    pub const DEFAULT: Faults = Faults {
        corrupt: 0.02,
        drop: 0.02,
        duplicate: 0.02,
        reorder: 0.02,
        garbage: 0.02,
    };
}

/// What a [`FaultInjector`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct FaultStats {
    /// Faults injected: corrupted, dropped, duplicated, reordered, garbage bursts.
    pub injected: [u64; 5],
    /// Bytes it wrote to the port underneath (garbage and copies included).
    pub bytes: u64,
}

/// A [`Port`] that passes every frame written to it to `inner` through seeded faults.
pub struct FaultInjector<P: Port> {
    inner: P,
    faults: Faults,
    rng: Rng,
    held: Option<Vec<u8>>,
    stats: FaultStats,
}

impl<P: Port> FaultInjector<P> {
    /// Wraps `inner`, injecting `faults` drawn from a generator seeded with `seed`.
    pub fn new(inner: P, faults: Faults, seed: u64) -> Self {
        FaultInjector {
            inner,
            faults,
            rng: Rng::new(seed),
            held: None,
            stats: FaultStats::default(),
        }
    }

    /// The port underneath.
    pub fn inner(&self) -> &P {
        &self.inner
    }

    /// The port underneath, to write past the faults (such as the emulator's `QUIT`).
    pub fn inner_mut(&mut self) -> &mut P {
        &mut self.inner
    }

    /// What was injected so far.
    pub fn stats(&self) -> FaultStats {
        self.stats
    }
}

impl<P: Port> Port for FaultInjector<P> {
    /// `frame` is one whole frame (the session writes frame by frame).
    fn write_all(&mut self, frame: &[u8]) -> Result<(), CliError> {
        let (f, rng) = (&self.faults, &mut self.rng);
        let mut out = Vec::new();
        if rng.next_f64() < f.garbage {
            self.stats.injected[4] += 1;
            let n = 1 + rng.below(64) as usize;
            out.extend((0..n).map(|_| (rng.next_u32() & 0xFF) as u8));
            out.push(0);
        }
        let mut copy = frame.to_vec();
        if rng.next_f64() < f.corrupt && copy.len() > 1 {
            self.stats.injected[0] += 1;
            let i = rng.below((copy.len() - 1) as u32) as usize;
            copy[i] ^= 1 << rng.below(8);
        }
        let roll = rng.next_f64();
        if roll < f.drop {
            self.stats.injected[1] += 1;
        } else if roll < f.drop + f.duplicate {
            self.stats.injected[2] += 1;
            out.extend_from_slice(&copy);
            out.extend_from_slice(&copy);
        } else if roll < f.drop + f.duplicate + f.reorder && self.held.is_none() {
            self.stats.injected[3] += 1;
            self.held = Some(copy);
        } else {
            out.extend_from_slice(&copy);
            if let Some(h) = self.held.take() {
                out.extend_from_slice(&h);
            }
        }
        self.stats.bytes += out.len() as u64;
        self.inner.write_all(&out)
    }

    fn read_into(&mut self, out: &mut Vec<u8>, wait: Duration) -> Result<(), CliError> {
        self.inner.read_into(out, wait)
    }

    fn advance(&mut self, us: u64) {
        self.inner.advance(us);
    }

    fn simulated_clock(&self) -> bool {
        self.inner.simulated_clock()
    }

    fn fault_stats(&self) -> Option<FaultStats> {
        Some(self.stats)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Records every write.
    #[derive(Default)]
    struct Tap(Vec<Vec<u8>>);

    impl Port for Tap {
        fn write_all(&mut self, bytes: &[u8]) -> Result<(), CliError> {
            self.0.push(bytes.to_vec());
            Ok(())
        }
        fn read_into(&mut self, _: &mut Vec<u8>, _: Duration) -> Result<(), CliError> {
            Ok(())
        }
        fn advance(&mut self, _: u64) {}
        fn simulated_clock(&self) -> bool {
            true
        }
    }

    #[test]
    fn no_faults_pass_frames_through_and_a_seed_repeats_its_faults() {
        let mut clean = FaultInjector::new(Tap::default(), Faults::NONE, 7);
        clean.write_all(b"abc\0").unwrap();
        assert_eq!(clean.inner().0, vec![b"abc\0".to_vec()]);
        assert_eq!(clean.stats().injected, [0; 5]);

        let run = |seed| {
            let mut f = FaultInjector::new(Tap::default(), Faults::DEFAULT, seed);
            for i in 0..2000u32 {
                f.write_all(&i.to_le_bytes()).unwrap();
            }
            (f.stats(), f.inner().0.clone())
        };
        let (a, b) = (run(3), run(3));
        assert_eq!(a, b);
        assert!(a.0.injected.iter().all(|&n| n > 0), "{:?}", a.0);
    }
}
