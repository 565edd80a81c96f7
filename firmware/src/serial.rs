//! Interrupt-driven serial I/O, the same on every board: the UART's interrupt handler
//! moves received bytes into a lock-free queue and transmits from another, so the main
//! loop never waits on the UART's registers. A board supplies the register access
//! ([`Uart`]) and an interrupt handler that calls [`Irq::service`]; [`split`] makes the
//! two halves: [`Irq`] for the handler, [`Port`] for the application.
//!
//! * **RX**: each received byte is pushed into a `heapless::spsc::Queue` of
//!   [`RX_QUEUE`] slots; the loop's receive step pops them. A byte that finds the queue
//!   full is dropped and counted; overrun (ORE) and framing (FE, noise, parity) errors
//!   are counted ([`counters`]; reported on `Command::Cost` and at `QUIT`).
//! * **TX**: the flush step pushes encoded replies into a queue of [`TX_QUEUE`] slots
//!   as far as they fit and pends the UART's interrupt; the handler writes while the
//!   transmitter has room and keeps its TX interrupt enabled while bytes remain.
//!
//! The queue sizes are derived in the constants' comments. The handler runs at the
//! default priority, so it preempts the loop but never itself.

use core::cell::RefCell;
use core::sync::atomic::{AtomicU32, Ordering};
use critical_section::Mutex;
use heapless::spsc::{Consumer, Producer, Queue};
use static_cell::ConstStaticCell;

/// Slots of the RX queue (capacity one less: 511 bytes).
///
/// Derivation: the loop's receive step drains the queue at least every other turn
/// (it is skipped only in the turn after one that took a frame), and a turn lasts at
/// most 168,000 instructions, 1 ms at 168 MHz (`meter::LONG_CALL`, enforced by
/// `ribreg hil`; measured worst 140,595 on the F405). At the recommended 921,600 baud
/// (10 bits a byte, 92.16 bytes/ms) at most 2 × 92.16 = 185 bytes arrive back to back
/// between two drains. A drain stops at the end of the first complete frame, so the
/// bytes of the next frames wait too: replaying the default sweep's real frames (up to
/// `wire::MAX_FRAME` = 604 bytes) at that rate with every turn at the budget, the host
/// test `link_budget` finds at most 327 bytes queued. 512 slots hold that with 1.56×
/// margin for 512 B of RAM, taken from the stack (whose margin stays above 2 KiB).
pub const RX_QUEUE: usize = 512;

/// Slots of the TX queue (capacity 127 bytes).
///
/// Derivation: the flush step moves encoded replies in as far as they fit and keeps the
/// rest of a frame (up to `wire::MAX_FRAME`) in the link for the next turn, so the queue
/// need not hold a whole frame. The busiest period's replies, while executing a setpoint
/// (49 bytes) and an ack (13) every 10 ms, fit twice over; 127 bytes drain in 1.4 ms at
/// 921,600 baud, so a turn of at most 1 ms finds room again. Every byte here is taken
/// from the stack, whose margin on the F405 was 2.4 KiB with 256 slots.
pub const TX_QUEUE: usize = 128;

/// A receive error the UART reported (the byte is lost).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RxError {
    /// A byte arrived before the previous one was read (ORE).
    Overrun,
    /// A missing stop bit (FE), noise or a parity error.
    #[cfg_attr(
        not(feature = "f405"),
        expect(dead_code, reason = "MPS2's CMSDK UART reports no framing errors")
    )]
    Framing,
}

impl core::fmt::Display for RxError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            RxError::Overrun => "receive overrun",
            RxError::Framing => "framing error",
        })
    }
}

impl core::error::Error for RxError {}

/// What the interrupt handler needs of a board's UART registers.
pub trait Uart {
    /// Acknowledges the UART's interrupt before it is serviced (MPS2's INTCLEAR; a
    /// no-op where reading and writing the data register clears the flags).
    fn acknowledge(&mut self) {}
    /// Takes the received byte or error, if any (an error is cleared by this).
    fn receive(&mut self) -> Option<Result<u8, RxError>>;
    /// The transmitter has room for a byte.
    fn can_send(&self) -> bool;
    /// Writes a byte (only after [`Uart::can_send`]).
    fn send(&mut self, byte: u8);
    /// Enables or disables the TX-room interrupt.
    fn listen_tx(&mut self, on: bool);
}

/// Error counts since boot: overruns, framing errors and bytes dropped on a full queue.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Overrun errors (ORE).
    pub overruns: u32,
    /// Framing, noise and parity errors (FE, NF, PE).
    pub framing: u32,
    /// Bytes received while the RX queue was full.
    pub dropped: u32,
}

static OVERRUNS: AtomicU32 = AtomicU32::new(0);
static FRAMING: AtomicU32 = AtomicU32::new(0);
static DROPPED: AtomicU32 = AtomicU32::new(0);

/// The error counts so far.
pub fn counters() -> Counters {
    Counters {
        overruns: OVERRUNS.load(Ordering::Relaxed),
        framing: FRAMING.load(Ordering::Relaxed),
        dropped: DROPPED.load(Ordering::Relaxed),
    }
}

static RX: ConstStaticCell<Queue<u8, RX_QUEUE>> = ConstStaticCell::new(Queue::new());
static TX: ConstStaticCell<Queue<u8, TX_QUEUE>> = ConstStaticCell::new(Queue::new());

/// The interrupt handler's half: the UART, the RX producer and the TX consumer.
pub struct Irq<U: Uart> {
    uart: U,
    rx: Producer<'static, u8>,
    tx: Consumer<'static, u8>,
}

impl<U: Uart> Irq<U> {
    /// The handler's work: every received byte into the RX queue (errors counted), then
    /// queued bytes out while the transmitter has room, the TX interrupt left enabled
    /// only while bytes remain.
    #[inline]
    pub fn service(&mut self) {
        self.uart.acknowledge();
        while let Some(r) = self.uart.receive() {
            match r {
                Ok(b) => {
                    if self.rx.enqueue(b).is_err() {
                        DROPPED.fetch_add(1, Ordering::Relaxed);
                    }
                }
                Err(RxError::Overrun) => {
                    OVERRUNS.fetch_add(1, Ordering::Relaxed);
                }
                Err(RxError::Framing) => {
                    FRAMING.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
        while self.uart.can_send() {
            match self.tx.dequeue() {
                Some(b) => self.uart.send(b),
                None => break,
            }
        }
        self.uart.listen_tx(self.tx.ready());
    }
}

/// Where a board's interrupt handler finds the handler's half: installed once at set-up,
/// then taken in a critical section by every interrupt.
pub struct Slot<U: Uart> {
    irq: Mutex<RefCell<Option<Irq<U>>>>,
}

impl<U: Uart> Slot<U> {
    /// Nothing installed yet.
    pub const fn new() -> Self {
        Slot {
            irq: Mutex::new(RefCell::new(None)),
        }
    }

    /// Installs the handler's half (before its interrupt is unmasked).
    pub fn install(&self, irq: Irq<U>) {
        critical_section::with(|cs| self.irq.borrow(cs).replace(Some(irq)));
    }

    /// The interrupt handler's body: [`Irq::service`], if installed.
    #[inline]
    pub fn service(&self) {
        critical_section::with(|cs| {
            if let Some(irq) = self.irq.borrow_ref_mut(cs).as_mut() {
                irq.service();
            }
        });
    }
}

/// The application's half: the RX consumer, the TX producer and how to start the
/// handler (pending its interrupt).
pub struct Port {
    rx: Consumer<'static, u8>,
    tx: Producer<'static, u8>,
    kick: fn(),
}

/// The two halves over `uart`, the first time; `None` afterwards. `kick` pends the
/// interrupt whose handler calls [`Irq::service`].
pub fn split<U: Uart>(uart: U, kick: fn()) -> Option<(Irq<U>, Port)> {
    let (rx_p, rx_c) = RX.try_take()?.split();
    let (tx_p, tx_c) = TX.try_take()?.split();
    Some((
        Irq {
            uart,
            rx: rx_p,
            tx: tx_c,
        },
        Port {
            rx: rx_c,
            tx: tx_p,
            kick,
        },
    ))
}

/// Sleeps until an interrupt unless `wake` already holds; interrupts masked around the
/// check, so one arriving after it still ends the WFI.
fn sleep_unless(wake: impl Fn() -> bool) {
    cortex_m::interrupt::free(|_| {
        if !wake() {
            cortex_m::asm::wfi();
        }
    });
}

impl embedded_io::ErrorType for Port {
    type Error = core::convert::Infallible;
}

impl embedded_io::ReadReady for Port {
    fn read_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(self.rx.ready())
    }
}

impl embedded_io::Read for Port {
    /// Sleeps until at least one byte is queued, then returns what is queued.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        if buf.is_empty() {
            return Ok(0);
        }
        crate::board::Serial::wait_readable(self);
        let mut n = 0;
        while n < buf.len() {
            match self.rx.dequeue() {
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

impl embedded_io::WriteReady for Port {
    fn write_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(self.tx.ready())
    }
}

impl embedded_io::Write for Port {
    /// Queues as much of `buf` as fits, sleeping until at least one byte does, and
    /// starts the handler.
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        if buf.is_empty() {
            return Ok(0);
        }
        while !self.tx.ready() {
            (self.kick)();
            sleep_unless(|| false);
        }
        let n = buf
            .iter()
            .take_while(|&&b| self.tx.enqueue(b).is_ok())
            .count();
        (self.kick)();
        Ok(n)
    }

    /// Sleeps until the handler has taken every queued byte.
    fn flush(&mut self) -> Result<(), Self::Error> {
        while !self.tx.is_empty() {
            (self.kick)();
            sleep_unless(|| false);
        }
        Ok(())
    }
}

impl crate::board::Serial for Port {
    fn wait_readable(&mut self) {
        while !self.rx.ready() {
            sleep_unless(|| self.rx.ready());
        }
    }

    fn sleep_until_rx_or_interrupt(&mut self) {
        sleep_unless(|| self.rx.ready());
    }
}
