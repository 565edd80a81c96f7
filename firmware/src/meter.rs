//! Cost bookkeeping of the main loop: [`Meter`] times every controller call and every
//! loop turn with the SysTick counter of [`crate::cost`], keeps the worst cases and the
//! registration's total (and the serial error counts) for `Command::Cost`, the
//! registration's calls per stage ([`StageCosts`]) for the `QUIT` report, and logs any
//! call or turn above [`LONG_CALL`] when it happens.
//!
//! The measured regions are exactly the controller call (a receive, or a poll with its
//! clock reading) and the whole turn, so the figures do not depend on how the loop around
//! them is laid out.

/// A controller call or loop turn above this many instructions (1 ms at 168 MHz) is
/// logged.
pub const LONG_CALL: u64 = 168_000;

/// Iterations of `cost::spin` timed at boot (2 instructions each), once and twice over:
/// the difference, 20,000 instructions, is 500 ticks on MPS2 and about 3,360 on the F405.
pub const CALIBRATION_ITERATIONS: u32 = 10_000;

/// An instruction count as reported on the wire (`u32`, saturating).
pub fn clamp(n: u64) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

/// Instructions of the registration's calls per stage (`Controller::registration_stage`):
/// calls, total and worst call, logged at `QUIT`.
pub struct StageCosts {
    rows: [(&'static str, u32, u64, u64); STAGES],
    len: usize,
}

/// Distinct stage names kept (the registration has 16; more are counted as the last).
pub const STAGES: usize = 20;

impl StageCosts {
    /// No calls yet.
    pub const fn new() -> Self {
        StageCosts {
            rows: [("", 0, 0, 0); STAGES],
            len: 0,
        }
    }

    /// Counts one call of `n` instructions in `stage`.
    pub fn add(&mut self, stage: &'static str, n: u64) {
        let i = match self.rows[..self.len].iter().position(|r| r.0 == stage) {
            Some(i) => i,
            None if self.len < STAGES => {
                self.len += 1;
                self.rows[self.len - 1].0 = stage;
                self.len - 1
            }
            None => STAGES - 1,
        };
        let row = &mut self.rows[i];
        row.1 = row.1.saturating_add(1);
        row.2 = row.2.saturating_add(n);
        row.3 = row.3.max(n);
    }

    /// The rows: stage, calls, total and worst instructions.
    pub fn rows(&self) -> &[(&'static str, u32, u64, u64)] {
        &self.rows[..self.len]
    }

    /// Logs every row through defmt.
    #[cfg(target_os = "none")]
    pub fn log(&self) {
        for &(stage, calls, total, worst) in self.rows() {
            defmt::info!(
                "registration stage {=str}: {=u32} calls, {=u64} instructions, worst call {=u64}",
                stage,
                calls,
                total,
                worst
            );
        }
    }
}

#[cfg(target_os = "none")]
pub use target::*;

#[cfg(target_os = "none")]
mod target {
    use super::{clamp, StageCosts, CALIBRATION_ITERATIONS, LONG_CALL};
    use crate::cost::{self, Cost, Stamp};
    use cortex_m::peripheral::SYST;
    use ribreg_core::controller::Controller;
    use ribreg_core::wire::{CostW, FrameError, State};

    /// Counter calibration taken at boot.
    struct Calibration {
        /// Ticks around an empty region (the stamp pair itself).
        overhead_ticks: u64,
        /// Ticks around `spin(CALIBRATION_ITERATIONS)`.
        spin_ticks: u64,
        /// Ticks of `2 * CALIBRATION_ITERATIONS` instructions: `spin` of twice the
        /// iterations minus `spin` of once, so the call and stamps cancel out.
        net_ticks: u64,
    }

    /// Times `spin` and sets the counter's instructions per tick from it
    /// ([`Cost::calibrate`]).
    fn calibrate() -> Calibration {
        let ((), overhead_ticks) = Cost::measure(|| ());
        let spin = |n: u32| Cost::measure(|| cost::spin(core::hint::black_box(n))).1;
        let spin_ticks = spin(CALIBRATION_ITERATIONS);
        let net_ticks = spin(2 * CALIBRATION_ITERATIONS).saturating_sub(spin_ticks);
        Cost::calibrate(2 * CALIBRATION_ITERATIONS, clamp(net_ticks.max(1)));
        Calibration {
            overhead_ticks,
            spin_ticks,
            net_ticks,
        }
    }

    /// The main loop's measurements: what `Command::Cost` reports ([`CostW`]), the
    /// registration's stages, the boot stamp and calibration for the `QUIT` report.
    pub struct Meter {
        boot: Stamp,
        cal: Calibration,
        cost: CostW,
        stages: StageCosts,
        /// The registration counted in `cost` is the one running now (its totals were
        /// reset when it started).
        reg_started: bool,
        /// Loop turns so far (wrapping), for the periodic stack scan.
        turns: u32,
        /// Start of the current turn.
        turn: Stamp,
    }

    impl Meter {
        /// Starts the counter (taking SysTick), calibrates it and logs the boot lines.
        pub fn start(syst: SYST) -> Self {
            Cost::init(syst);
            let boot = Cost::start();
            let cal = calibrate();
            let (stack_lo, stack_hi) = cost::stack_bounds();
            defmt::info!(
                "ribreg-firmware on {=str} up at tick {=u64}; stack {=usize:#x}..{=usize:#x} ({=usize} B)",
                crate::board::NAME,
                boot.ticks(),
                stack_lo,
                stack_hi,
                stack_hi - stack_lo
            );
            defmt::info!(
                "spin of {=u32} instructions = {=u64} ticks, {=u32} more = {=u64} ticks more: {=u64} instructions per 1000 ticks under -icount shift=0; empty region = {=u64} ticks",
                2 * CALIBRATION_ITERATIONS,
                cal.spin_ticks,
                2 * CALIBRATION_ITERATIONS,
                cal.net_ticks,
                Cost::instructions(1_000),
                cal.overhead_ticks
            );
            Meter {
                boot,
                cal,
                cost: CostW::default(),
                stages: StageCosts::new(),
                reg_started: false,
                turns: 0,
                turn: boot,
            }
        }

        /// A loop turn begins.
        #[inline]
        pub fn start_turn(&mut self) {
            self.turn = Cost::start();
        }

        /// `controller.receive(frame, now_us)`, measured; logged if long.
        #[inline]
        pub fn receive<const V: usize>(
            &mut self,
            controller: &mut Controller<V>,
            frame: Result<&mut [u8], FrameError>,
            now_us: u64,
        ) {
            let (before, len) = (controller.state(), frame.as_ref().map_or(0, |f| f.len()));
            let call = Cost::start();
            controller.receive(frame, now_us);
            let n = call.elapsed_instructions();
            if n > LONG_CALL {
                defmt::warn!(
                    "long receive: {=u64} instructions, {=usize}-byte frame, {} -> {}",
                    n,
                    len,
                    before,
                    controller.state()
                );
            }
            self.cost.worst_receive_instructions =
                self.cost.worst_receive_instructions.max(clamp(n));
        }

        /// Follows the registration, once a turn after the receive: its totals restart
        /// when one starts.
        #[inline]
        pub fn track_registration(&mut self, state: State) {
            let registering = state == State::Registering;
            if registering && !self.reg_started {
                self.cost.registration_instructions = 0;
                self.cost.registration_calls = 0;
                self.reg_started = true;
            }
            if !registering {
                self.reg_started = false;
            }
        }

        /// `controller.poll(now)`, measured (the clock reading included); logged if
        /// long, counted in its registration stage and, while registering, in the
        /// registration's totals.
        #[inline]
        pub fn poll<const V: usize>(&mut self, controller: &mut Controller<V>) {
            let (stage, before) = (controller.registration_stage(), controller.state());
            let registering = before == State::Registering;
            let step = Cost::start();
            controller.poll(cost::now_us());
            let n = step.elapsed_instructions();
            if n > LONG_CALL {
                defmt::warn!("long poll: {=u64} instructions, {}", n, before);
            }
            if let Some(stage) = stage {
                self.stages.add(stage, n);
            }
            if registering {
                self.cost.registration_instructions += n;
                self.cost.registration_calls += 1;
                self.cost.worst_step_instructions = self.cost.worst_step_instructions.max(clamp(n));
            }
        }

        /// The turn ends after sending `replies` replies: its cost (logged if long), now
        /// and then the stack's high-water mark, and the figures handed to the
        /// controller for `Command::Cost`.
        #[inline]
        pub fn end_turn<const V: usize>(&mut self, controller: &mut Controller<V>, replies: u32) {
            let n = self.turn.elapsed_instructions();
            if n > LONG_CALL {
                defmt::warn!(
                    "long turn: {=u64} instructions, {=u32} replies, {}",
                    n,
                    replies,
                    controller.state()
                );
            }
            self.cost.worst_call_instructions = self.cost.worst_call_instructions.max(clamp(n));
            // The stack scan reads the whole painted region (~13,500 words): on the
            // first turn and every 256th after, not every turn (the high-water mark only
            // grows, so it lags at most 256 turns; `log_quit` scans once more).
            self.turns = self.turns.wrapping_add(1);
            if self.turns % 256 == 1 {
                self.cost.peak_stack_bytes = cost::peak_stack_bytes() as u32;
            }
            let serial = crate::serial::counters();
            self.cost.serial_overruns = serial.overruns;
            self.cost.serial_framing_errors = serial.framing;
            self.cost.serial_dropped_bytes = serial.dropped;
            controller.set_cost(self.cost);
        }

        /// Logs the registration's calls per stage (the first part of the `QUIT` report).
        pub fn log_stages(&self) {
            self.stages.log();
        }

        /// Logs the `QUIT` line: uptime, the registration, worst cases, peak stack (scanned
        /// now), the calibration and the serial port's error counts.
        pub fn log_quit(&self) {
            let c = &CostW {
                peak_stack_bytes: cost::peak_stack_bytes() as u32,
                ..self.cost
            };
            let serial = crate::serial::counters();
            defmt::info!(
                "QUIT: uptime {=u64} ticks; registration {=u64} instructions in {=u32} steps (worst step {=u32}); worst loop turn {=u32}, worst frame {=u32} instructions; peak stack {=u32} of {=usize} B; spin calibration {=u64} ticks; serial: {=u32} overruns, {=u32} framing errors, {=u32} bytes dropped on a full queue",
                self.boot.elapsed_ticks(),
                c.registration_instructions,
                c.registration_calls,
                c.worst_step_instructions,
                c.worst_call_instructions,
                c.worst_receive_instructions,
                c.peak_stack_bytes,
                cost::stack_size_bytes(),
                self.cal.spin_ticks,
                serial.overruns,
                serial.framing,
                serial.dropped
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_saturate_and_the_calibration_is_20k_instructions() {
        assert_eq!(clamp(7), 7);
        assert_eq!(clamp(u64::from(u32::MAX) + 1), u32::MAX);
        assert_eq!(2 * CALIBRATION_ITERATIONS, 20_000);
        // 1 ms at 168 MHz, one instruction per cycle.
        assert_eq!(LONG_CALL, 168_000_000 / 1_000);
    }

    #[test]
    fn stage_costs_keep_calls_totals_and_worst_per_stage() {
        let mut s = StageCosts::new();
        s.add("som", 10);
        s.add("fit", 7);
        s.add("som", 30);
        assert_eq!(s.rows(), &[("som", 2, 40, 30), ("fit", 1, 7, 7)]);
        // More names than rows: the last row takes the rest.
        let names = [
            "a", "b", "c", "d", "e", "f", "g", "h", "i", "j", "k", "l", "m", "n", "o", "p", "q",
            "r", "s", "t", "u", "v", "w", "x",
        ];
        assert!(names.len() > STAGES);
        for k in 0..2 * STAGES {
            s.add(names[k % names.len()], 1);
        }
        assert_eq!(s.rows().len(), STAGES);
    }
}
