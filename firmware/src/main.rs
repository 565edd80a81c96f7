//! ribreg-firmware: the probe-positioning controller for `thumbv7em-none-eabihf`.
//!
//! For now a scaffold that proves the link, the UART driver and the cost counters under
//! QEMU (`mps2-an386`): it echoes every byte it receives on UART0, and when the last four
//! bytes received are `QUIT` it sends one `STATS ...` line (peak stack, uptime, counter
//! calibration), logs the same through defmt and exits the emulator with success.
//! The serial protocol replaces the echo loop; [`uart`] and [`cost`] stay.
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

/// The bytes that end the echo loop.
#[cfg(any(target_os = "none", test))]
const QUIT: [u8; 4] = *b"QUIT";

/// Iterations of [`cost::spin`] timed at boot (2 instructions each).
#[cfg(any(target_os = "none", test))]
const CALIBRATION_ITERATIONS: u32 = 10_000;

/// Shifts `byte` into the window of the last four bytes; true when they spell [`QUIT`].
#[cfg(any(target_os = "none", test))]
fn push_and_check_quit(window: &mut [u8; 4], byte: u8) -> bool {
    window.rotate_left(1);
    window[3] = byte;
    *window == QUIT
}

/// Writes `value` in decimal into `buf`, returning the digits (no `core::fmt`).
#[cfg(any(target_os = "none", test))]
fn decimal(mut value: u64, buf: &mut [u8; 20]) -> &[u8] {
    let mut i = buf.len();
    loop {
        i -= 1;
        buf[i] = b'0' + (value % 10) as u8;
        value /= 10;
        if value == 0 {
            return &buf[i..];
        }
    }
}

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
    use cortex_m_rt::{entry, exception, ExceptionFrame};
    use cortex_m_semihosting::debug;
    use defmt_semihosting as _;
    use embedded_io::{Read, Write};

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
        let mut window = [0u8; 4];
        let mut buf = [0u8; 32];
        let mut echoed: u64 = 0;
        loop {
            let n = match uart.read(&mut buf) {
                Ok(n) => n,
                Err(e) => {
                    defmt::warn!("uart read: {}", e);
                    continue;
                }
            };
            if let Err(e) = uart.write_all(&buf[..n]) {
                defmt::warn!("uart write: {}", e);
            }
            echoed += n as u64;
            if buf[..n]
                .iter()
                .any(|&b| crate::push_and_check_quit(&mut window, b))
            {
                quit(&mut uart, boot, &cal, echoed);
            }
        }
    }

    /// Reports and leaves the emulator with success.
    fn quit(uart: &mut Uart0, boot: cost::Stamp, cal: &Calibration, echoed: u64) -> ! {
        let uptime_ticks = boot.elapsed_ticks();
        let peak = cost::peak_stack_bytes();
        let size = cost::stack_size_bytes();
        defmt::info!(
            "QUIT after {=u64} bytes echoed: peak stack {=usize} of {=usize} B, uptime {=u64} ticks ({=u64} ms of emulated time)",
            echoed,
            peak,
            size,
            uptime_ticks,
            uptime_ticks / u64::from(cost::CORE_CLOCK_HZ / 1000)
        );
        let fields: [(&[u8], u64); 7] = [
            (b"peak_stack_bytes", peak as u64),
            (b"stack_size_bytes", size as u64),
            (b"uptime_ticks", uptime_ticks),
            (
                b"spin_instructions",
                2 * u64::from(crate::CALIBRATION_ITERATIONS),
            ),
            (b"spin_ticks", cal.spin_ticks),
            (b"spin_measured_instructions", cal.spin_instructions),
            (b"overhead_ticks", cal.overhead_ticks),
        ];
        let mut line = || -> Result<(), crate::uart::Error> {
            uart.write_all(b"\nSTATS")?;
            for (name, value) in fields {
                uart.write_all(b" ")?;
                uart.write_all(name)?;
                uart.write_all(b"=")?;
                uart.write_all(crate::decimal(value, &mut [0; 20]))?;
            }
            uart.write_all(b"\n")?;
            uart.flush()
        };
        if let Err(e) = line() {
            defmt::warn!("uart write: {}", e);
        }
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

    #[test]
    fn quit_is_found_across_reads() {
        let mut w = [0u8; 4];
        let seen: Vec<bool> = b"xQUQUIT"
            .iter()
            .map(|&b| push_and_check_quit(&mut w, b))
            .collect();
        assert_eq!(seen, [false, false, false, false, false, false, true]);
        assert!(!push_and_check_quit(&mut w, b'Q'));
    }

    #[test]
    fn decimal_digits() {
        assert_eq!(decimal(0, &mut [0; 20]), b"0");
        assert_eq!(decimal(40, &mut [0; 20]), b"40");
        assert_eq!(
            decimal(u64::MAX, &mut [0; 20]),
            u64::MAX.to_string().as_bytes()
        );
        assert_eq!(2 * CALIBRATION_ITERATIONS, 20_000);
    }
}
