//! The MPS2-AN386 board: a driver for the ARM CMSDK APB UART (UART0 at 0x4000_4000 on
//! QEMU's mps2-an386), the board's serial port.
//!
//! One byte each way, no FIFO. Registers: DATA 0x00, STATE 0x04 (bit 0 TX full, bit 1
//! RX full, bits 2/3 TX/RX overrun, write 1 to clear), CTRL 0x08 (bit 0 TX enable, bit 1
//! RX enable, bit 3 RX interrupt enable), INTSTATUS/INTCLEAR 0x0C (bit 1 RX), BAUDDIV
//! 0x10 (at least 16).
//!
//! Implements `embedded_io::{Read, Write, ReadReady, WriteReady}` (blocking) and
//! `embedded_hal_nb::serial::{Read, Write}` (non-blocking).
//!
//! Waiting for input sleeps in WFI woken by the RX interrupt instead of polling STATE:
//! under QEMU a polling guest keeps the emulator's CPU thread busy and the byte arrives
//! later (the firmware notes measured twice the throughput with WFI). The RX interrupt
//! is enabled in the UART only around the WFI, with PRIMASK set, and acknowledged before
//! PRIMASK is cleared again, so no handler ever runs for it and the application needs no
//! interrupt routing. Waiting to transmit polls: QEMU hands a written byte to the host
//! at once, so TX is full only when the host stops reading.

use core::ptr::{read_volatile, write_volatile};
use core::sync::atomic::{AtomicBool, Ordering};
use cortex_m::interrupt::InterruptNumber;
use cortex_m::peripheral::NVIC;
// `Read` waits through the board trait's `wait_readable`.
use crate::board::Serial as _;

const DATA: usize = 0x00;
const STATE: usize = 0x04;
const CTRL: usize = 0x08;
const INTCLEAR: usize = 0x0C;
const BAUDDIV: usize = 0x10;

const STATE_TX_FULL: u32 = 1 << 0;
const STATE_RX_FULL: u32 = 1 << 1;
const STATE_RX_OVERRUN: u32 = 1 << 3;
const CTRL_TX_EN: u32 = 1 << 0;
const CTRL_RX_EN: u32 = 1 << 1;
const CTRL_RX_IRQ_EN: u32 = 1 << 3;
const INT_RX: u32 = 1 << 1;

/// Base address of UART0 on MPS2 boards.
pub const UART0_BASE: usize = 0x4000_4000;
/// NVIC line of UART0's RX interrupt on mps2-an385/386/500.
pub const UART0_RX_IRQ: u16 = 0;

/// BAUDDIV for 115200 baud from the 25 MHz peripheral clock (QEMU ignores the rate).
pub const BAUDDIV_115200: u32 = 25_000_000 / 115_200;

/// UART errors.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum Error {
    /// A received byte was overwritten before it was read (never under QEMU, which
    /// holds input back until RX is read).
    Overrun,
}

impl core::fmt::Display for Error {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("UART receive overrun")
    }
}

impl core::error::Error for Error {}

impl embedded_io::Error for Error {
    fn kind(&self) -> embedded_io::ErrorKind {
        embedded_io::ErrorKind::Other
    }
}

impl embedded_hal_nb::serial::Error for Error {
    fn kind(&self) -> embedded_hal_nb::serial::ErrorKind {
        embedded_hal_nb::serial::ErrorKind::Overrun
    }
}

#[derive(Clone, Copy)]
struct Irq(u16);

// SAFETY: `Irq` only ever holds the RX line given by the `Uart` type's parameter, a valid
// external interrupt number on the board.
unsafe impl InterruptNumber for Irq {
    fn number(self) -> u16 {
        self.0
    }
}

/// A CMSDK APB UART at `BASE` whose RX interrupt is NVIC line `RX_IRQ`.
pub struct Uart<const BASE: usize, const RX_IRQ: u16> {
    _owned: (),
}

/// UART0 of the MPS2 boards.
pub type Uart0 = Uart<UART0_BASE, UART0_RX_IRQ>;

/// The board's serial port: UART0.
pub type Port = Uart0;

/// UART0 at 115200 baud: the board's set-up (the MPS2 needs no clock or pin set-up).
pub fn take_serial() -> Port {
    let Some(uart) = Uart0::take(BAUDDIV_115200) else {
        panic!("UART0 taken twice");
    };
    uart
}

static UART0_TAKEN: AtomicBool = AtomicBool::new(false);

impl Uart0 {
    /// UART0, configured and enabled, the first time; `None` afterwards.
    pub fn take(bauddiv: u32) -> Option<Self> {
        if UART0_TAKEN.swap(true, Ordering::AcqRel) {
            return None;
        }
        // SAFETY: UART0 is a CMSDK APB UART at this address on MPS2, and the flag above
        // lets this happen once.
        Some(unsafe { Self::new_unchecked(bauddiv) })
    }
}

impl<const BASE: usize, const RX_IRQ: u16> Uart<BASE, RX_IRQ> {
    /// Configures the UART at `BASE` (`bauddiv` clamped to the minimum of 16), enables
    /// TX and RX and unmasks `RX_IRQ` in the NVIC for the WFI wake-up.
    ///
    /// # Safety
    /// `BASE` must be a CMSDK APB UART whose RX interrupt is `RX_IRQ`, and no other
    /// `Uart` for it may exist.
    pub unsafe fn new_unchecked(bauddiv: u32) -> Self {
        let uart = Self { _owned: () };
        uart.write_reg(CTRL, 0);
        uart.write_reg(BAUDDIV, bauddiv.max(16));
        uart.write_reg(INTCLEAR, 0xF);
        uart.write_reg(CTRL, CTRL_TX_EN | CTRL_RX_EN);
        // Discard any stale byte. Under QEMU this read also matters: enabling RX does not
        // tell the emulator to look at its socket again, a DATA read does. Without it,
        // input that arrived while RX was still disabled waited for QEMU's next timer
        // event (then the SysTick wrap, 0.67 s later; seen in about 1 run in 7).
        let _ = uart.read_reg(DATA);
        // Drop a request left pending from before (the line has no handler).
        NVIC::unpend(Irq(RX_IRQ));
        // SAFETY: no handler ever runs for this line: its source (CTRL bit 3) is enabled
        // only with PRIMASK set and is acknowledged and unpended before PRIMASK is
        // cleared (`wait_readable`). Unmasking breaks no mask-based critical section.
        unsafe { NVIC::unmask(Irq(RX_IRQ)) };
        uart
    }

    fn read_reg(&self, offset: usize) -> u32 {
        // SAFETY: `BASE + offset` is a register of the UART this value owns (constructor
        // contract); registers are 32-bit and aligned.
        unsafe { read_volatile((BASE + offset) as *const u32) }
    }

    fn write_reg(&self, offset: usize, value: u32) {
        // SAFETY: as in `read_reg`; `&self` suffices because register writes are single
        // volatile stores and only the owner of the `Uart` makes them.
        unsafe { write_volatile((BASE + offset) as *mut u32, value) }
    }

    fn rx_full(&self) -> bool {
        self.read_reg(STATE) & STATE_RX_FULL != 0
    }

    fn tx_full(&self) -> bool {
        self.read_reg(STATE) & STATE_TX_FULL != 0
    }

    /// Takes the received byte, if any; reports (and clears) an overrun.
    fn try_read(&mut self) -> Result<Option<u8>, Error> {
        let state = self.read_reg(STATE);
        if state & STATE_RX_OVERRUN != 0 {
            self.write_reg(STATE, STATE_RX_OVERRUN);
            return Err(Error::Overrun);
        }
        if state & STATE_RX_FULL == 0 {
            return Ok(None);
        }
        Ok(Some(self.read_reg(DATA) as u8))
    }

    fn try_write(&mut self, byte: u8) -> bool {
        if self.tx_full() {
            return false;
        }
        self.write_reg(DATA, u32::from(byte));
        true
    }
}

impl<const BASE: usize, const RX_IRQ: u16> embedded_io::ErrorType for Uart<BASE, RX_IRQ> {
    type Error = Error;
}

impl<const BASE: usize, const RX_IRQ: u16> embedded_io::Read for Uart<BASE, RX_IRQ> {
    /// Blocks until at least one byte is in, then returns what is available at once.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Error> {
        if buf.is_empty() {
            return Ok(0);
        }
        self.wait_readable();
        let mut n = 0;
        while n < buf.len() {
            match self.try_read()? {
                Some(b) => {
                    buf[n] = b;
                    n += 1;
                }
                None => break,
            }
        }
        Ok(n)
    }
}

impl<const BASE: usize, const RX_IRQ: u16> embedded_io::ReadReady for Uart<BASE, RX_IRQ> {
    fn read_ready(&mut self) -> Result<bool, Error> {
        Ok(self.rx_full())
    }
}

impl<const BASE: usize, const RX_IRQ: u16> embedded_io::Write for Uart<BASE, RX_IRQ> {
    /// Blocks until the first byte is written, then writes while TX has room.
    fn write(&mut self, buf: &[u8]) -> Result<usize, Error> {
        let Some((&first, rest)) = buf.split_first() else {
            return Ok(0);
        };
        while !self.try_write(first) {}
        Ok(1 + rest.iter().take_while(|&&b| self.try_write(b)).count())
    }

    /// Waits until the last byte has left the holding register.
    fn flush(&mut self) -> Result<(), Error> {
        while self.tx_full() {}
        Ok(())
    }
}

impl<const BASE: usize, const RX_IRQ: u16> embedded_io::WriteReady for Uart<BASE, RX_IRQ> {
    fn write_ready(&mut self) -> Result<bool, Error> {
        Ok(!self.tx_full())
    }
}

impl<const BASE: usize, const RX_IRQ: u16> embedded_hal_nb::serial::ErrorType
    for Uart<BASE, RX_IRQ>
{
    type Error = Error;
}

impl<const BASE: usize, const RX_IRQ: u16> embedded_hal_nb::serial::Read<u8>
    for Uart<BASE, RX_IRQ>
{
    fn read(&mut self) -> embedded_hal_nb::nb::Result<u8, Error> {
        self.try_read()?
            .ok_or(embedded_hal_nb::nb::Error::WouldBlock)
    }
}

impl<const BASE: usize, const RX_IRQ: u16> embedded_hal_nb::serial::Write<u8>
    for Uart<BASE, RX_IRQ>
{
    fn write(&mut self, word: u8) -> embedded_hal_nb::nb::Result<(), Error> {
        if self.try_write(word) {
            Ok(())
        } else {
            Err(embedded_hal_nb::nb::Error::WouldBlock)
        }
    }

    fn flush(&mut self) -> embedded_hal_nb::nb::Result<(), Error> {
        if self.tx_full() {
            Err(embedded_hal_nb::nb::Error::WouldBlock)
        } else {
            Ok(())
        }
    }
}

impl<const BASE: usize, const RX_IRQ: u16> crate::board::Serial for Uart<BASE, RX_IRQ> {
    /// Called with interrupts masked it still returns, but other pending interrupts then
    /// turn the sleep into polling.
    fn wait_readable(&mut self) {
        while !self.rx_full() {
            self.sleep_until_rx_or_interrupt();
        }
    }

    fn sleep_until_rx_or_interrupt(&mut self) {
        let unmasked = cortex_m::register::primask::read().is_active();
        cortex_m::interrupt::disable();
        self.write_reg(CTRL, CTRL_TX_EN | CTRL_RX_EN | CTRL_RX_IRQ_EN);
        // A byte that arrives after this check pends the interrupt, and WFI returns
        // at once on a pending interrupt even with PRIMASK set.
        if !self.rx_full() {
            cortex_m::asm::wfi();
        }
        self.write_reg(CTRL, CTRL_TX_EN | CTRL_RX_EN);
        self.write_reg(INTCLEAR, INT_RX);
        NVIC::unpend(Irq(RX_IRQ));
        if unmasked {
            // SAFETY: interrupts were enabled on entry and masked only here, so no
            // critical section is broken; pending handlers (SysTick) run now.
            unsafe { cortex_m::interrupt::enable() };
        }
    }
}
