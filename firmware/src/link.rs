//! The link to the robot PC: UART0, the frame receiver of `ribreg_core::wire` and the
//! buffer replies are encoded into. The loop's receive, flush and sleep steps.

use crate::exit;
use crate::meter::Meter;
use crate::uart::Uart0;
use embedded_io::{Read, ReadReady, Write};
use ribreg_core::controller::Controller;
use ribreg_core::wire::{self, State};

/// UART0 with its receiver and the reply buffer.
pub struct Link {
    uart: Uart0,
    rx: wire::Receiver,
    out: [u8; wire::MAX_FRAME],
}

impl Link {
    /// The link over `uart`, nothing received yet.
    pub fn new(uart: Uart0) -> Self {
        Link {
            uart,
            rx: wire::Receiver::new(),
            out: [0; wire::MAX_FRAME],
        }
    }

    /// Reads the bytes that have arrived, up to the first complete frame, and hands that
    /// frame to the controller (measured by `meter`); the rest waits in the link. True if
    /// a frame was handed over. The frame `QUIT` ends the run instead ([`exit::quit`]).
    pub fn receive<const V: usize>(
        &mut self,
        controller: &mut Controller<V>,
        meter: &mut Meter,
        now_us: u64,
    ) -> bool {
        while matches!(self.uart.read_ready(), Ok(true)) {
            let mut byte = [0u8; 1];
            if !matches!(self.uart.read(&mut byte), Ok(1)) {
                break;
            }
            if let Some(frame) = self.rx.push(byte[0]) {
                if matches!(&frame, Ok(f) if exit::is_quit(f)) {
                    exit::quit(&mut self.uart, meter);
                }
                meter.receive(controller, frame, now_us);
                return true;
            }
        }
        false
    }

    /// Sends every reply the controller has queued; returns how many.
    pub fn flush<const V: usize>(&mut self, controller: &mut Controller<V>) -> u32 {
        let mut replies = 0u32;
        while let Some((seq, msg)) = controller.next_reply() {
            replies += 1;
            match wire::encode(seq, &msg, &mut self.out) {
                Ok(n) => {
                    if let Err(e) = self.uart.write_all(&self.out[..n]) {
                        defmt::warn!("uart write: {}", e);
                    }
                }
                Err(e) => defmt::warn!("encode: {}", e),
            }
        }
        replies
    }

    /// Sleeps when there is nothing to do: not while the controller is busy; while it
    /// executes until a byte arrives or the next 1 ms SysTick (so setpoints and the
    /// watchdog keep their time); otherwise until a byte arrives.
    pub fn sleep<const V: usize>(&mut self, controller: &Controller<V>) {
        match controller.state() {
            _ if controller.busy() => {}
            State::Executing => self.uart.sleep_until_rx_or_interrupt(),
            _ => {
                if !matches!(self.uart.read_ready(), Ok(true)) {
                    self.uart.wait_readable();
                }
            }
        }
    }
}
