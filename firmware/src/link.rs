//! The link to the robot PC: the board's serial port, the frame receiver of
//! `ribreg_core::wire` and the buffer replies are encoded into. The loop's receive, flush
//! and sleep steps.

use crate::board::Serial;
use crate::exit;
use crate::meter::Meter;
use ribreg_core::controller::Controller;
use ribreg_core::wire::{self, State};

/// The serial port with its receiver and the reply buffer.
pub struct Link<S: Serial> {
    uart: S,
    rx: wire::Receiver,
    /// The encoded reply being sent: `out[sent..len]` is still to go.
    out: [u8; wire::MAX_FRAME],
    len: usize,
    sent: usize,
}

impl<S: Serial> Link<S> {
    /// The link over `uart`, nothing received yet.
    pub fn new(uart: S) -> Self {
        Link {
            uart,
            rx: wire::Receiver::new(),
            out: [0; wire::MAX_FRAME],
            len: 0,
            sent: 0,
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
                    let rest = &self.out[self.sent..self.len];
                    exit::quit(&mut self.uart, rest, meter);
                }
                meter.receive(controller, frame, now_us);
                return true;
            }
        }
        false
    }

    /// Sends the replies the controller has queued, as far as the port takes them without
    /// waiting; the rest of a frame waits for the next turn, later replies in the
    /// controller. Returns how many replies were started.
    pub fn flush<const V: usize>(&mut self, controller: &mut Controller<V>) -> u32 {
        let mut replies = 0u32;
        loop {
            while self.sent < self.len && matches!(self.uart.write_ready(), Ok(true)) {
                match self.uart.write(&self.out[self.sent..self.len]) {
                    Ok(n) => self.sent += n,
                    Err(_) => {
                        defmt::warn!("serial write failed: reply dropped");
                        self.sent = self.len;
                    }
                }
            }
            if self.sent < self.len {
                return replies;
            }
            let Some((seq, msg)) = controller.next_reply() else {
                return replies;
            };
            replies += 1;
            match wire::encode(seq, &msg, &mut self.out) {
                Ok(n) => (self.len, self.sent) = (n, 0),
                Err(e) => defmt::warn!("encode: {}", e),
            }
        }
    }

    /// Sleeps when there is nothing to do: not while the controller is busy; while it
    /// executes until a byte arrives or the next 1 ms SysTick (so setpoints and the
    /// watchdog keep their time); otherwise until a byte arrives.
    /// A reply still going out sleeps until any interrupt (the port's, as it takes
    /// bytes, or SysTick).
    pub fn sleep<const V: usize>(&mut self, controller: &Controller<V>) {
        match controller.state() {
            _ if controller.busy() => {}
            _ if self.sent < self.len => self.uart.sleep_until_rx_or_interrupt(),
            State::Executing => self.uart.sleep_until_rx_or_interrupt(),
            _ => {
                if !matches!(self.uart.read_ready(), Ok(true)) {
                    self.uart.wait_readable();
                }
            }
        }
    }
}
