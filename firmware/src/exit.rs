//! How a run ends: the `QUIT` frame (report, then semihosting exit with success), a
//! panic or a HardFault (logged through defmt, then semihosting exit with failure).
//!
//! Exit status under QEMU: 0 after `QUIT`, 1 after a panic or HardFault. A stack
//! overflow does not get here: under QEMU it ends in a CPU lockup (exit 134).

/// The frame that ends the run. It can never be a protocol frame (see the test).
pub const QUIT: [u8; 4] = *b"QUIT";

/// True if a received frame is [`QUIT`].
pub fn is_quit(frame: &[u8]) -> bool {
    *frame == QUIT[..]
}

#[cfg(target_os = "none")]
pub use target::*;

#[cfg(target_os = "none")]
mod target {
    use crate::meter::Meter;
    use cortex_m_rt::{exception, ExceptionFrame};
    use cortex_m_semihosting::debug;
    use embedded_io::Write;

    /// The end of a run on `QUIT`: the stages, the reply still going out (`rest`) and
    /// what the port still holds, the `QUIT` line, then the emulator exits with success.
    pub fn quit(uart: &mut impl Write, rest: &[u8], meter: &Meter) -> ! {
        meter.log_stages();
        let _ = uart.write_all(rest);
        let _ = uart.flush();
        meter.log_quit();
        exit(debug::EXIT_SUCCESS)
    }

    /// Leaves the emulator through semihosting with `status`; on hardware, where no
    /// debugger answers, sleeps forever.
    fn exit(status: debug::ExitStatus) -> ! {
        debug::exit(status);
        loop {
            cortex_m::asm::wfi();
        }
    }

    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo) -> ! {
        defmt::error!("panic: {}", defmt::Display2Format(info));
        exit(debug::EXIT_FAILURE)
    }

    // cortex-m-rt requires the HardFault handler to be an `unsafe fn`; its body has no
    // unsafe operation.
    #[allow(unsafe_code)]
    #[exception]
    unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
        defmt::error!(
            "HardFault at pc {=u32:#x}, lr {=u32:#x}",
            frame.pc(),
            frame.lr()
        );
        exit(debug::EXIT_FAILURE)
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
        assert!(is_quit(b"QUIT"));
        assert!(!is_quit(b"QUIT\x01"));
        assert!(!is_quit(b"QUI"));
    }
}
