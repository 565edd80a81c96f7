//! Cost measurement on the target: instruction counts from SysTick, and the stack's
//! high-water mark from stack painting.
//!
//! # Instruction counts
//!
//! DWT CYCCNT reads 0 under QEMU 7.2, so the counter is SysTick clocked from the core
//! (`CLKSOURCE = 1`, [`CORE_CLOCK_HZ`]: 25 MHz on MPS2, 168 MHz on the F405),
//! free-running with a 1 ms period and extended to 64 bits by counting wraps in the
//! SysTick exception. The 1 ms wrap is also the controller's wake-up: while it executes
//! it sleeps in WFI between bytes, so under `-icount ...,sleep=on` its clock follows the
//! host's instead of the emulator's speed.
//!
//! Under `qemu-system-arm -icount shift=0,align=off,sleep=off` every guest instruction
//! advances the virtual clock by 2^0 ns: a 25 MHz tick (40 ns) is 40 instructions, a
//! 168 MHz tick about 5.95, deterministically. The ratio is calibrated at boot, not
//! assumed ([`Cost::calibrate`]): the firmware times [`spin`] (exactly 2 instructions per
//! iteration) for N and 2N iterations, and the difference of the two, free of the call
//! and stamp overhead, gives the instructions per tick ([`instructions_from`]); the host
//! test `qemu_echo` checks 20,000 instructions read as 500 ticks on MPS2. The resolution
//! is one tick (40 instructions on MPS2, about 6 on the F405), and a
//! [`Stamp`]/[`Stamp::elapsed_ticks`] pair itself costs about one MPS2 tick.
//! Without `-icount` the ticks follow the host's clock and say nothing about cost.
//! Instructions are not cycles: quote the count and the cycles per instruction assumed.
//!
//! The 64-bit count stays right as long as interrupts are never masked for longer than
//! one period (1 ms: 1 M instructions under `-icount shift=0`; the firmware's critical
//! sections are a few dozen instructions):
//! a wrap that happens while they are masked is seen through the SysTick pending bit, a
//! second one would be lost.
//!
//! # Stack
//!
//! cortex-m-rt's `paint-stack` feature fills the stack region, `_stack_end` (lowest
//! address) to `_stack_start` (initial SP), with [`STACK_PAINT`] before `main`. With
//! flip-link the stack sits at the bottom of RAM, below `.data`/`.bss` (flip-link
//! defines `_stack_end` as the RAM origin and `_stack_start` as the start of the statics);
//! with the default layout it sits above them. Either way the stack grows down towards
//! `_stack_end`, so the high-water mark is the first word above `_stack_end` that is no
//! longer painted. A frame that happens to store 0xCCCC_CCCC at its deepest word makes
//! the figure one word short; nothing else is approximate.

/// SysTick clock (the core clock), Hz: the board's ([`crate::board::SYSTICK_HZ`]).
pub const CORE_CLOCK_HZ: u32 = crate::board::SYSTICK_HZ;

/// SysTick reload value: a period of 1 ms (24,999 down to 0 at 25 MHz, 167,999 at
/// 168 MHz; both fit the 24-bit counter).
pub const RELOAD: u32 = CORE_CLOCK_HZ / 1_000 - 1;
const _: () = assert!(RELOAD <= 0x00FF_FFFF);

/// Ticks in one SysTick period.
pub const PERIOD_TICKS: u64 = RELOAD as u64 + 1;

/// Instructions in `ticks` SysTick ticks, given that `cal_instructions` instructions took
/// `cal_ticks` ticks (the boot calibration; a zero `cal_ticks` counts as one).
pub const fn instructions_from(ticks: u64, cal_instructions: u32, cal_ticks: u32) -> u64 {
    let per = if cal_ticks == 0 { 1 } else { cal_ticks as u64 };
    ticks * cal_instructions as u64 / per
}

/// The calibration assumed until [`Cost::calibrate`] runs: `-icount shift=0`'s 1 ns per
/// instruction over one second, `(instructions, ticks)` = (10^9, [`CORE_CLOCK_HZ`]).
pub const NOMINAL_CALIBRATION: (u32, u32) = (1_000_000_000, CORE_CLOCK_HZ);

/// The word cortex-m-rt paints the stack with (`cortex_m_rt::STACK_PAINT_VALUE`).
pub const STACK_PAINT: u32 = 0xCCCC_CCCC;

/// Ticks since SysTick was started, from the wrap count and the current value register.
/// The counter pends its wrap as it reaches 0 and reloads on the next tick, so a period
/// reads 0, [`RELOAD`], …, 1: 0 is the period's first tick, not its last. (Reading 0 as
/// the last tick put a stamp taken just after a wrap one period late, and a call
/// measured to it one period, 1 M instructions, long: the sporadic ~1.0 M "worst" loop
/// turns and frame handlings reported before.)
pub const fn ticks_from(wraps: u64, current: u32) -> u64 {
    let value = current & 0x00FF_FFFF;
    let value = if value > RELOAD { RELOAD } else { value };
    let offset = if value == 0 {
        0
    } else {
        PERIOD_TICKS - value as u64
    };
    wraps * PERIOD_TICKS + offset
}

/// One consistent reading of the free-running counter, taken with interrupts masked:
/// `wraps` is the count kept by the SysTick handler, `before` the value register read
/// first, `pending` the SysTick pending bit read after it, `after` the value register read
/// after that. If the bit is set, the counter wrapped before it was read and the handler
/// has not counted that wrap yet, so `after` belongs to the next period; if it is clear,
/// `before` was read before any uncounted wrap.
pub const fn reading(wraps: u32, before: u32, pending: bool, after: u32) -> u64 {
    if pending {
        ticks_from(wraps as u64 + 1, after)
    } else {
        ticks_from(wraps as u64, before)
    }
}

/// How many words at the low end of a stack of `len` words still hold [`STACK_PAINT`];
/// `word(i)` reads the `i`-th word from the lowest address up.
pub fn painted_words(len: usize, mut word: impl FnMut(usize) -> u32) -> usize {
    (0..len).take_while(|&i| word(i) == STACK_PAINT).count()
}

/// A point on the free-running counter.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
#[cfg_attr(target_os = "none", derive(defmt::Format))]
pub struct Stamp {
    ticks: u64,
}

impl Stamp {
    /// A stamp at `ticks` since the counter started.
    pub const fn at(ticks: u64) -> Self {
        Self { ticks }
    }

    /// Ticks since the counter started.
    pub const fn ticks(self) -> u64 {
        self.ticks
    }

    /// Ticks from `self` to `later` (0 if `later` is earlier).
    pub const fn ticks_until(self, later: Stamp) -> u64 {
        later.ticks.saturating_sub(self.ticks)
    }
}

#[cfg(target_os = "none")]
pub use target::*;

#[cfg(target_os = "none")]
mod target {
    use super::*;
    use core::sync::atomic::{AtomicU32, Ordering};
    use cortex_m::peripheral::{syst::SystClkSource, SCB, SYST};
    use cortex_m_rt::exception;

    const _: () = assert!(cortex_m_rt::STACK_PAINT_VALUE == STACK_PAINT);

    /// SysTick periods completed, counted by the SysTick exception.
    static WRAPS: AtomicU32 = AtomicU32::new(0);

    /// Instructions and ticks of the boot calibration ([`Cost::calibrate`]).
    static CAL_INSTRUCTIONS: AtomicU32 = AtomicU32::new(NOMINAL_CALIBRATION.0);
    static CAL_TICKS: AtomicU32 = AtomicU32::new(NOMINAL_CALIBRATION.1);

    #[exception]
    fn SysTick() {
        WRAPS.fetch_add(1, Ordering::Relaxed);
    }

    /// The free-running instruction counter (SysTick).
    pub struct Cost;

    impl Cost {
        /// Starts SysTick from the core clock with [`RELOAD`] and its wrap interrupt. Taking `SYST` by value keeps anyone else from reprogramming it.
        /// Before this, every stamp reads 0.
        pub fn init(mut syst: SYST) {
            syst.disable_counter();
            syst.set_clock_source(SystClkSource::Core);
            syst.set_reload(RELOAD);
            syst.clear_current();
            syst.enable_interrupt();
            cortex_m::interrupt::free(|_| {
                syst.enable_counter();
                // The value register reads 0 until the counter has loaded the reload
                // value (one tick on hardware, longer under QEMU without -icount), and
                // loading may pend the wrap exception: start from zero wraps after it.
                while SYST::get_current() == 0 {}
                SCB::clear_pendst();
                WRAPS.store(0, Ordering::Relaxed);
            });
        }

        /// The counter now.
        #[inline]
        pub fn start() -> Stamp {
            Stamp::at(now_ticks())
        }

        /// From now on `instructions` instructions take `ticks` ticks (measured at boot).
        pub fn calibrate(instructions: u32, ticks: u32) {
            CAL_INSTRUCTIONS.store(instructions, Ordering::Relaxed);
            CAL_TICKS.store(ticks, Ordering::Relaxed);
        }

        /// Instructions in `ticks` ticks, by the calibration.
        #[inline]
        pub fn instructions(ticks: u64) -> u64 {
            instructions_from(
                ticks,
                CAL_INSTRUCTIONS.load(Ordering::Relaxed),
                CAL_TICKS.load(Ordering::Relaxed),
            )
        }

        /// Runs `f` and returns its result with the ticks it took.
        #[inline]
        pub fn measure<R>(f: impl FnOnce() -> R) -> (R, u64) {
            let s = Self::start();
            let r = f();
            (r, s.elapsed_ticks())
        }
    }

    /// Ticks since [`Cost::init`].
    #[inline]
    pub fn now_ticks() -> u64 {
        cortex_m::interrupt::free(|_| {
            let wraps = WRAPS.load(Ordering::Relaxed);
            let before = SYST::get_current();
            let pending = SCB::is_pendst_pending();
            let after = if pending { SYST::get_current() } else { before };
            reading(wraps, before, pending, after)
        })
    }

    impl Stamp {
        /// Ticks from this stamp to now.
        #[inline]
        pub fn elapsed_ticks(self) -> u64 {
            self.ticks_until(Cost::start())
        }

        /// Instructions from this stamp to now, by the boot calibration (valid under
        /// `-icount shift=0`); resolution one tick.
        #[inline]
        pub fn elapsed_instructions(self) -> u64 {
            Cost::instructions(self.elapsed_ticks())
        }
    }

    /// The controller's clock, µs since [`Cost::init`] (SysTick at [`CORE_CLOCK_HZ`]).
    #[inline]
    pub fn now_us() -> u64 {
        now_ticks() / u64::from(CORE_CLOCK_HZ / 1_000_000)
    }

    /// Executes exactly `2 * iterations` instructions in its loop (`subs` + `bne`), plus
    /// the call around it: the known workload that calibrates the counter.
    #[inline(never)]
    pub fn spin(iterations: u32) {
        if iterations == 0 {
            return;
        }
        // SAFETY: the loop only decrements a scratch register; it touches no memory and
        // no stack, and terminates because `iterations` is non-zero.
        unsafe {
            core::arch::asm!(
                "2:",
                "subs {n}, #1",
                "bne 2b",
                n = inout(reg) iterations => _,
                options(nomem, nostack),
            );
        }
    }

    extern "C" {
        /// Initial stack pointer (highest address of the stack, exclusive).
        static _stack_start: u32;
        /// Lowest address of the stack.
        static _stack_end: u32;
    }

    /// The stack region `[lowest, highest)`, from the linker's symbols.
    pub fn stack_bounds() -> (usize, usize) {
        // Only the addresses are taken; nothing is read through these pointers here.
        let lo = core::ptr::addr_of!(_stack_end) as usize;
        let hi = core::ptr::addr_of!(_stack_start) as usize;
        (lo, hi)
    }

    /// Size of the stack region, bytes (all RAM left by the statics under flip-link).
    pub fn stack_size_bytes() -> usize {
        let (lo, hi) = stack_bounds();
        hi - lo
    }

    /// Deepest stack use since reset, bytes: the stack region minus the words at its low
    /// end that still hold the paint.
    pub fn peak_stack_bytes() -> usize {
        let (lo, hi) = stack_bounds();
        let len = (hi - lo) / 4;
        let base = lo as *const u32;
        let painted = painted_words(len, |i| {
            // SAFETY: `i < len`, so the word lies in the stack region the linker reserved
            // (RAM, word aligned by cortex-m-rt's asserts). Words below the current stack
            // pointer belong to no live frame; the scan stops at the first word ever
            // written, so it reads live frames only when the stack is at its peak now,
            // and a volatile read of a plain RAM word has no side effect.
            unsafe { core::ptr::read_volatile(base.add(i)) }
        });
        (len - painted) * 4
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_count_down_within_a_period() {
        // A period reads 0 (the wrap), RELOAD, ..., 1.
        assert_eq!(ticks_from(0, 0), 0);
        assert_eq!(ticks_from(0, RELOAD), 1);
        assert_eq!(ticks_from(0, 1), u64::from(RELOAD));
        assert_eq!(ticks_from(1, 0), PERIOD_TICKS);
        assert_eq!(ticks_from(3, RELOAD - 10), 3 * PERIOD_TICKS + 11);
        // Bits above the 24-bit counter are ignored.
        assert_eq!(ticks_from(0, 0xFF00_0000 | RELOAD), 1);
    }

    #[test]
    fn a_wrap_not_yet_counted_is_seen_through_the_pending_bit() {
        // The counter wrapped between the two value reads: `before` is just above zero,
        // `after` just below the reload, the handler has not run yet.
        let near_end = ticks_from(7, 2);
        let next = reading(7, 2, true, RELOAD - 1);
        assert_eq!(next, 8 * PERIOD_TICKS + 2);
        assert!(next > near_end);
        // Pending read as clear: `before` is valid and `after` is ignored.
        assert_eq!(reading(7, 2, false, 12345), near_end);
        // Monotone across a whole simulated run of wraps.
        let mut last = 0;
        for wraps in 0..4u32 {
            for value in [0, RELOAD, RELOAD / 2, 1] {
                let t = reading(wraps, value, false, value);
                assert!(t >= last);
                last = t;
            }
            // The wrap pended, the handler not run yet: the next period's first tick.
            let t = reading(wraps, 1, true, 0);
            assert!(t > last);
            assert_eq!(t, reading(wraps + 1, 0, false, 0));
            last = t;
        }
        // The u32 wrap count (2^32 periods of 1 ms, about 49 days) plus a pending wrap
        // does not overflow.
        assert_eq!(reading(u32::MAX, 1, true, 0), (1 << 32) * PERIOD_TICKS);
    }

    #[test]
    fn stamps_subtract_without_underflow() {
        let a = Stamp::at(100);
        let b = Stamp::at(1_000);
        assert_eq!(a.ticks_until(b), 900);
        assert_eq!(b.ticks_until(a), 0);
        assert_eq!(b.ticks(), 1_000);
    }

    #[test]
    fn instructions_follow_the_calibration() {
        // MPS2: 20,000 instructions in 500 ticks, 40 a tick.
        assert_eq!(instructions_from(3_475, 20_000, 500), 139_000);
        // F405 under -icount shift=0: 168 MHz ticks, 1 ns instructions, 125/21 a tick.
        assert_eq!(
            instructions_from(168_000, 1_000_000_000, 168_000_000),
            1_000_000
        );
        assert_eq!(instructions_from(28_224, 20_000, 3_360), 168_000);
        // The nominal calibration is 1 ns per instruction on the board's clock.
        let (i, t) = NOMINAL_CALIBRATION;
        assert_eq!(
            instructions_from(u64::from(CORE_CLOCK_HZ), i, t),
            1_000_000_000
        );
        assert_eq!(instructions_from(5, 7, 0), 35);
        // A 1 ms period at the board's clock.
        assert_eq!(u64::from(CORE_CLOCK_HZ) / 1_000, PERIOD_TICKS);
    }

    #[test]
    fn high_water_mark_is_the_first_unpainted_word() {
        // Stack of 8 words, lowest address first; the stack grows down, so used words
        // are at the high end.
        let mut stack = [STACK_PAINT; 8];
        assert_eq!(painted_words(8, |i| stack[i]), 8);
        stack[5] = 0;
        stack[7] = 1;
        assert_eq!(painted_words(8, |i| stack[i]), 5);
        stack[0] = 42;
        assert_eq!(painted_words(8, |i| stack[i]), 0);
        assert_eq!(painted_words(0, |_| unreachable!()), 0);
    }
}
