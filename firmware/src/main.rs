//! ribreg-firmware: the probe-positioning controller for `thumbv7em-none-eabihf`.
//!
//! The main loop serves the robot PC over UART0 with the protocol of
//! `ribreg_core::wire` and runs `ribreg_core::controller::Controller`: every turn it
//! takes the bytes that arrived up to the first complete frame, which goes to the
//! controller; a turn without one calls the controller's bounded `poll` instead (one
//! registration step, queued sweep points, setpoints, the pose watchdog; while executing
//! it is polled every turn, its poll is small and keeps the setpoints' clock). A turn
//! after one that took a frame only polls, so under a burst of messages the two
//! alternate. Then it sends the replies. So a turn makes one bounded controller call,
//! whatever the host sent meanwhile (the rest waits in the link). When there is nothing
//! to do (`Controller::busy` false, not executing, no byte waiting) it sleeps in WFI until
//! a byte arrives. Every call is measured in instructions with SysTick (`-icount
//! shift=0`: 40 per tick); the worst cases and the registration's total are reported on
//! `Command::Cost`, calls and turns above 1 ms at 168 MHz are logged as they happen.
//!
//! A frame whose bytes are exactly `QUIT` (never valid COBS) ends the run: the firmware
//! logs its measurements through defmt and exits the emulator with success.
//!
//! On the host this binary is only a stub that says how to build it for the target, so
//! `cargo build --workspace` keeps working.
#![cfg_attr(target_os = "none", no_std, no_main)]
// Register access, the fault handler and the stack scan need `unsafe`; it is allowed only
// in `uart`, `cost` and the HardFault handler, each block with a SAFETY comment.
#![deny(unsafe_code)]

#[cfg(any(target_os = "none", test))]
#[allow(unsafe_code)]
mod cost;
#[cfg(target_os = "none")]
#[allow(unsafe_code)]
mod uart;

/// The frame that ends the run.
#[cfg(any(target_os = "none", test))]
const QUIT: [u8; 4] = *b"QUIT";

/// A controller call above this many instructions (1 ms at 168 MHz) is logged.
#[cfg(target_os = "none")]
const LONG_CALL: u64 = 168_000;

/// Iterations of [`cost::spin`] timed at boot (2 instructions each).
#[cfg(any(target_os = "none", test))]
const CALIBRATION_ITERATIONS: u32 = 10_000;

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "ribreg-firmware runs on the Cortex-M4F controller, not on the host.\n\
         Build it with:\n  \
         cargo build -p ribreg-firmware --target thumbv7em-none-eabihf --release\n\
         and run it under QEMU as described in firmware/README.md."
    );
    std::process::exit(2);
}

#[cfg(target_os = "none")]
mod app {
    use crate::cost::{self, Cost};
    use crate::uart::{Uart0, BAUDDIV_115200};
    use core::sync::atomic::{AtomicBool, Ordering};
    use cortex_m_rt::{entry, exception, ExceptionFrame};
    use cortex_m_semihosting::debug;
    use defmt_semihosting as _;
    use embedded_io::{Read, ReadReady, Write};
    use ribreg_core::controller::Controller;
    use ribreg_core::limits::CONTROLLER_VOXELS;
    use ribreg_core::wire::{self, CostW, State};

    defmt::timestamp!("{=u64}", cost::now_ticks());

    /// Counter calibration taken at boot.
    struct Calibration {
        /// Ticks around an empty region (the stamp pair itself).
        overhead_ticks: u64,
        /// Ticks around `spin(CALIBRATION_ITERATIONS)`.
        spin_ticks: u64,
        /// The same in instructions, assuming `-icount shift=0`.
        spin_instructions: u64,
    }

    fn calibrate() -> Calibration {
        let ((), overhead_ticks) = Cost::measure(|| ());
        let stamp = Cost::start();
        cost::spin(core::hint::black_box(crate::CALIBRATION_ITERATIONS));
        let spin_instructions = stamp.elapsed_instructions();
        let spin_ticks = spin_instructions / cost::INSTRUCTIONS_PER_TICK;
        Calibration {
            overhead_ticks,
            spin_ticks,
            spin_instructions,
        }
    }

    #[entry]
    fn main() -> ! {
        let Some(cp) = cortex_m::Peripherals::take() else {
            panic!("core peripherals taken twice");
        };
        Cost::init(cp.SYST);
        let boot = Cost::start();
        let cal = calibrate();
        let (stack_lo, stack_hi) = cost::stack_bounds();
        defmt::info!(
            "ribreg-firmware up at tick {=u64}; stack {=usize:#x}..{=usize:#x} ({=usize} B)",
            boot.ticks(),
            stack_lo,
            stack_hi,
            stack_hi - stack_lo
        );
        defmt::info!(
            "spin of {=u32} instructions = {=u64} ticks (= {=u64} instructions if run with -icount shift=0); empty region = {=u64} ticks",
            2 * crate::CALIBRATION_ITERATIONS,
            cal.spin_ticks,
            cal.spin_instructions,
            cal.overhead_ticks
        );

        let Some(mut uart) = Uart0::take(BAUDDIV_115200) else {
            panic!("UART0 taken twice");
        };
        let controller = controller();
        let mut rx = wire::Receiver::new();
        let mut out = [0u8; wire::MAX_FRAME];
        let mut cost = CostW::default();
        let mut reg_started = false;
        let mut stages = cost::StageCosts::new();
        let mut turns: u32 = 0;
        let mut received = false;
        loop {
            let turn = Cost::start();
            let now = now_us();
            // 1. The bytes that have arrived, up to a complete frame for the controller;
            // not right after a turn that took one, so that polls keep up with a burst
            // (queued sweep points, registration) and receiving and polling alternate.
            let took_last_turn = received;
            received = false;
            while !took_last_turn && matches!(uart.read_ready(), Ok(true)) {
                let mut byte = [0u8; 1];
                if !matches!(uart.read(&mut byte), Ok(1)) {
                    break;
                }
                if let Some(frame) = rx.push(byte[0]) {
                    if matches!(&frame, Ok(f) if **f == crate::QUIT[..]) {
                        stages.log();
                        quit(&mut uart, boot, &cal, &cost);
                    }
                    let (before, len) = (controller.state(), frame.as_ref().map_or(0, |f| f.len()));
                    let call = Cost::start();
                    controller.receive(frame, now);
                    let n = call.elapsed_instructions();
                    if n > crate::LONG_CALL {
                        defmt::warn!(
                            "long receive: {=u64} instructions, {=usize}-byte frame, {} -> {}",
                            n,
                            len,
                            before,
                            controller.state()
                        );
                    }
                    cost.worst_receive_instructions = cost.worst_receive_instructions.max(clamp(n));
                    received = true;
                    break;
                }
            }
            // 2. Otherwise (or executing) one bounded step of the periodic work.
            let registering = controller.state() == State::Registering;
            if registering && !reg_started {
                cost.registration_instructions = 0;
                cost.registration_calls = 0;
                reg_started = true;
            }
            if !registering {
                reg_started = false;
            }
            if !received || controller.state() == State::Executing {
                let (stage, before) = (controller.registration_stage(), controller.state());
                let step = Cost::start();
                controller.poll(now_us());
                let n = step.elapsed_instructions();
                if n > crate::LONG_CALL {
                    defmt::warn!("long poll: {=u64} instructions, {}", n, before);
                }
                if let Some(stage) = stage {
                    stages.add(stage, n);
                }
                if registering {
                    cost.registration_instructions += n;
                    cost.registration_calls += 1;
                    cost.worst_step_instructions = cost.worst_step_instructions.max(clamp(n));
                }
            }
            // 3. The replies.
            let mut replies = 0u32;
            while let Some((seq, msg)) = controller.next_reply() {
                replies += 1;
                match wire::encode(seq, &msg, &mut out) {
                    Ok(n) => {
                        if let Err(e) = uart.write_all(&out[..n]) {
                            defmt::warn!("uart write: {}", e);
                        }
                    }
                    Err(e) => defmt::warn!("encode: {}", e),
                }
            }
            let n = turn.elapsed_instructions();
            if n > crate::LONG_CALL {
                defmt::warn!(
                    "long turn: {=u64} instructions, {=u32} replies, {}",
                    n,
                    replies,
                    controller.state()
                );
            }
            cost.worst_call_instructions = cost.worst_call_instructions.max(clamp(n));
            // The stack scan reads the whole painted region (~13,500 words): on the
            // first turn and every 256th after, not every turn (the high-water mark only
            // grows, so it lags at most 256 turns; `quit` scans once more).
            turns = turns.wrapping_add(1);
            if turns % 256 == 1 {
                cost.peak_stack_bytes = cost::peak_stack_bytes() as u32;
            }
            controller.set_cost(cost);
            // 4. Nothing to do: sleep until a byte arrives (executing: or the next 1 ms
            // SysTick, so setpoints and the watchdog keep their time).
            match controller.state() {
                _ if controller.busy() => {}
                State::Executing => uart.sleep_until_rx_or_interrupt(),
                _ => {
                    if !matches!(uart.read_ready(), Ok(true)) {
                        uart.wait_readable();
                    }
                }
            }
        }
    }

    fn clamp(n: u64) -> u32 {
        u32::try_from(n).unwrap_or(u32::MAX)
    }

    /// The controller's clock, µs since boot (SysTick at 25 MHz).
    fn now_us() -> u64 {
        cost::now_ticks() / u64::from(cost::CORE_CLOCK_HZ / 1_000_000)
    }

    /// The controller, in a static (about 100 KiB: it must not pass through the stack).
    fn controller() -> &'static mut Controller<CONTROLLER_VOXELS> {
        static TAKEN: AtomicBool = AtomicBool::new(false);
        static mut CONTROLLER: Controller<CONTROLLER_VOXELS> = Controller::new();
        if TAKEN.swap(true, Ordering::AcqRel) {
            panic!("controller taken twice");
        }
        // SAFETY: the flag above hands out this one reference once, for the program's
        // lifetime; nothing else names CONTROLLER.
        #[allow(unsafe_code)]
        unsafe {
            &mut *core::ptr::addr_of_mut!(CONTROLLER)
        }
    }

    /// Reports and leaves the emulator with success.
    fn quit(uart: &mut Uart0, boot: cost::Stamp, cal: &Calibration, c: &CostW) -> ! {
        let _ = uart.flush();
        let c = &CostW {
            peak_stack_bytes: cost::peak_stack_bytes() as u32,
            ..*c
        };
        defmt::info!(
            "QUIT: uptime {=u64} ticks; registration {=u64} instructions in {=u32} steps (worst step {=u32}); worst loop turn {=u32}, worst frame {=u32} instructions; peak stack {=u32} of {=usize} B; spin calibration {=u64} ticks",
            boot.elapsed_ticks(),
            c.registration_instructions,
            c.registration_calls,
            c.worst_step_instructions,
            c.worst_call_instructions,
            c.worst_receive_instructions,
            c.peak_stack_bytes,
            cost::stack_size_bytes(),
            cal.spin_ticks
        );
        debug::exit(debug::EXIT_SUCCESS);
        loop {
            cortex_m::asm::wfi();
        }
    }

    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo) -> ! {
        defmt::error!("panic: {}", defmt::Display2Format(info));
        debug::exit(debug::EXIT_FAILURE);
        loop {
            cortex_m::asm::wfi();
        }
    }

    #[allow(unsafe_code)]
    #[exception]
    unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
        defmt::error!(
            "HardFault at pc {=u32:#x}, lr {=u32:#x}",
            frame.pc(),
            frame.lr()
        );
        debug::exit(debug::EXIT_FAILURE);
        loop {
            cortex_m::asm::wfi();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `QUIT` can never be a protocol frame: its first byte, a COBS code of 0x51, would
    /// need 80 bytes after it.
    #[test]
    fn quit_is_never_a_protocol_frame() {
        let mut f = QUIT;
        assert!(ribreg_core::wire::decode::<ribreg_core::wire::ToController>(&mut f).is_err());
        assert_eq!(QUIT[0] as usize - 1, 80);
        assert_eq!(2 * CALIBRATION_ITERATIONS, 20_000);
    }
}
