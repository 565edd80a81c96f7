//! The MPS2-AN386 board: UART0, an ARM CMSDK APB UART at 0x4000_4000 on QEMU's
//! mps2-an386, interrupt-driven through [`crate::serial`].
//!
//! One byte each way, no FIFO. Registers: DATA 0x00, STATE 0x04 (bit 0 TX full, bit 1
//! RX full, bits 2/3 TX/RX overrun, write 1 to clear), CTRL 0x08 (bit 0 TX enable, bit 1
//! RX enable, bit 2 TX interrupt enable, bit 3 RX interrupt enable), INTSTATUS/INTCLEAR
//! 0x0C (bit 0 TX, bit 1 RX), BAUDDIV 0x10 (at least 16). UART0's RX interrupt is NVIC
//! line 0, its TX interrupt line 1.
//!
//! The board has no device crate, so cortex-m-rt's vector table sends every device
//! interrupt to `DefaultHandler`, which services UART0 on its two lines. The handler
//! acknowledges (INTCLEAR) before it drains RX, so a byte arriving meanwhile raises the
//! line again instead of being stranded.

use crate::serial;
use core::ptr::{read_volatile, write_volatile};
use cortex_m::interrupt::InterruptNumber;
use cortex_m::peripheral::NVIC;
use cortex_m_rt::exception;

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
const CTRL_TX_IRQ_EN: u32 = 1 << 2;
const CTRL_RX_IRQ_EN: u32 = 1 << 3;
const INT_TX: u32 = 1 << 0;
const INT_RX: u32 = 1 << 1;

/// Base address of UART0 on MPS2 boards.
pub const UART0_BASE: usize = 0x4000_4000;
/// NVIC line of UART0's RX interrupt on mps2-an385/386/500.
pub const UART0_RX_IRQ: u16 = 0;
/// NVIC line of UART0's TX interrupt.
pub const UART0_TX_IRQ: u16 = 1;

/// BAUDDIV for 115200 baud from the 25 MHz peripheral clock (QEMU ignores the rate).
pub const BAUDDIV_115200: u32 = 25_000_000 / 115_200;

#[derive(Clone, Copy)]
struct Irq(u16);

// SAFETY: `Irq` only ever holds UART0's RX or TX line, valid external interrupt numbers on
// the board.
unsafe impl InterruptNumber for Irq {
    fn number(self) -> u16 {
        self.0
    }
}

/// UART0's registers, owned by the interrupt handler once set up.
pub struct Uart0 {
    _owned: (),
}

impl Uart0 {
    fn read_reg(&self, offset: usize) -> u32 {
        // SAFETY: `UART0_BASE + offset` is a register of UART0, which only this value
        // (made once, in `take_serial`) accesses; registers are 32-bit and aligned.
        unsafe { read_volatile((UART0_BASE + offset) as *const u32) }
    }

    fn write_reg(&self, offset: usize, value: u32) {
        // SAFETY: as in `read_reg`; register writes are single volatile stores.
        unsafe { write_volatile((UART0_BASE + offset) as *mut u32, value) }
    }
}

impl serial::Uart for Uart0 {
    #[inline]
    fn acknowledge(&mut self) {
        self.write_reg(INTCLEAR, INT_RX | INT_TX);
    }

    #[inline]
    fn receive(&mut self) -> Option<Result<u8, serial::RxError>> {
        let state = self.read_reg(STATE);
        if state & STATE_RX_OVERRUN != 0 {
            self.write_reg(STATE, STATE_RX_OVERRUN);
            return Some(Err(serial::RxError::Overrun));
        }
        (state & STATE_RX_FULL != 0).then(|| Ok(self.read_reg(DATA) as u8))
    }

    #[inline]
    fn can_send(&self) -> bool {
        self.read_reg(STATE) & STATE_TX_FULL == 0
    }

    #[inline]
    fn send(&mut self, byte: u8) {
        self.write_reg(DATA, u32::from(byte));
    }

    #[inline]
    fn listen_tx(&mut self, on: bool) {
        let tx = if on { CTRL_TX_IRQ_EN } else { 0 };
        self.write_reg(CTRL, CTRL_TX_EN | CTRL_RX_EN | CTRL_RX_IRQ_EN | tx);
    }
}

/// The board's serial port: UART0 through the interrupt-driven queues.
pub type Port = serial::Port;

/// The handler's half, installed at set-up.
static IRQ: serial::Slot<Uart0> = serial::Slot::new();

// cortex-m-rt requires `DefaultHandler` to be an `unsafe fn`; its body has no unsafe
// operation.
#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    match irqn {
        n if n == UART0_RX_IRQ as i16 || n == UART0_TX_IRQ as i16 => IRQ.service(),
        n => panic!("unexpected interrupt {}", n),
    }
}

/// UART0 at 115200 baud with its RX interrupt, and the queues: the board's set-up (the
/// MPS2 needs no clock or pin set-up).
pub fn take_serial() -> Port {
    let uart = Uart0 { _owned: () };
    uart.write_reg(CTRL, 0);
    uart.write_reg(BAUDDIV, BAUDDIV_115200.max(16));
    uart.write_reg(INTCLEAR, 0xF);
    uart.write_reg(CTRL, CTRL_TX_EN | CTRL_RX_EN | CTRL_RX_IRQ_EN);
    // Under QEMU a DATA read makes the emulator look at its socket again (enabling RX
    // does not): input that arrived before waited for its next timer event otherwise.
    // The byte read is stale at boot.
    let _ = uart.read_reg(DATA);
    let Some((irq, port)) = serial::split(uart, || NVIC::pend(Irq(UART0_RX_IRQ))) else {
        panic!("UART0 taken twice");
    };
    IRQ.install(irq);
    for line in [UART0_RX_IRQ, UART0_TX_IRQ] {
        NVIC::unpend(Irq(line));
        // SAFETY: the handler is installed (above) before the lines are unmasked, and it
        // takes the shared state only inside a critical section, so unmasking breaks no
        // mask-based critical section.
        unsafe { NVIC::unmask(Irq(line)) };
    }
    port
}
