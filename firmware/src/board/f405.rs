//! The STM32F405RG board: clocks, USART1 on PA9 (TX) / PA10 (RX) at 921,600 baud, through
//! `stm32f4xx-hal`.
//!
//! Clocks: with the `qemu` feature the HSI (16 MHz, no PLL): QEMU's `netduinoplus2` does
//! not model RCC, and any HSE or PLL set-up polls RCC_CR forever. Without it, the real
//! part's configuration: HSE 8 MHz, PLL to SYSCLK 168 MHz, APB1 42 MHz, APB2 84 MHz
//! (USART1's clock), the flash wait states the HAL derives for 168 MHz. SysTick counts
//! the core clock, 168 MHz in both cases under QEMU (its model clocks SysTick at
//! 168 MHz whatever RCC says) and on the real part.
//!
//! Serial I/O is interrupt-driven ([`crate::serial`]): USART1's handler (RXNE, and TXE
//! while bytes are queued) services the queues; the main loop never touches the
//! registers.

use crate::serial;
use cortex_m::peripheral::NVIC;
use stm32f4xx_hal::pac::{self, interrupt, Interrupt, USART1};
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::rcc::Config;
use stm32f4xx_hal::serial::{self as hal_serial, Rx, RxListen, Tx, TxISR, TxListen};

/// Baud rate of USART1: the rate the link budget recommends (host test `link_budget`;
/// 115,200 does not carry the default sweep's busiest second, 16.6 kB). From APB2's
/// 84 MHz the divider is 5.6875 (BRR 0x5B), 0.02 % off.
pub const BAUD: u32 = 921_600;

/// USART1's registers through the HAL's halves, for the interrupt handler.
pub struct Usart1 {
    tx: Tx<USART1>,
    rx: Rx<USART1>,
}

impl serial::Uart for Usart1 {
    #[inline]
    fn receive(&mut self) -> Option<Result<u8, serial::RxError>> {
        // The HAL reads SR, and after an error DR too, which clears the error flags.
        match embedded_hal_nb::serial::Read::read(&mut self.rx) {
            Ok(b) => Some(Ok(b)),
            Err(embedded_hal_nb::nb::Error::WouldBlock) => None,
            Err(embedded_hal_nb::nb::Error::Other(hal_serial::Error::Overrun)) => {
                Some(Err(serial::RxError::Overrun))
            }
            Err(embedded_hal_nb::nb::Error::Other(_)) => Some(Err(serial::RxError::Framing)),
        }
    }

    #[inline]
    fn can_send(&self) -> bool {
        self.tx.is_tx_empty()
    }

    #[inline]
    fn send(&mut self, byte: u8) {
        // Only called after `can_send`, so TXE is set and the write cannot block.
        let _ = embedded_hal_nb::serial::Write::write(&mut self.tx, byte);
    }

    #[inline]
    fn listen_tx(&mut self, on: bool) {
        if on {
            self.tx.listen();
        } else {
            self.tx.unlisten();
        }
    }
}

/// The board's serial port: USART1 through the interrupt-driven queues.
pub type Port = serial::Port;

/// The handler's half, installed at set-up.
static IRQ: serial::Slot<Usart1> = serial::Slot::new();

#[interrupt]
fn USART1() {
    IRQ.service();
}

/// The clock configuration (see the module documentation).
fn clocks() -> Config {
    #[cfg(feature = "qemu")]
    let config = Config::hsi();
    #[cfg(not(feature = "qemu"))]
    let config = Config::hse(8.MHz())
        .sysclk(168.MHz())
        .pclk1(42.MHz())
        .pclk2(84.MHz());
    config
}

/// Clocks, pins, USART1 with its RX interrupt, the queues: the board's set-up.
pub fn take_serial() -> Port {
    let Some(dp) = pac::Peripherals::take() else {
        panic!("device peripherals taken twice");
    };
    let mut rcc = dp.RCC.freeze(clocks());
    let gpioa = dp.GPIOA.split(&mut rcc);
    let config = hal_serial::Config::default().baudrate(BAUD.bps());
    let Ok(usart) = dp.USART1.serial((gpioa.pa9, gpioa.pa10), config, &mut rcc) else {
        panic!("USART1: no divider for {} baud", BAUD);
    };
    let (tx, mut rx) = usart.split();
    rx.listen();
    let Some((irq, port)) = serial::split(Usart1 { tx, rx }, || NVIC::pend(Interrupt::USART1))
    else {
        panic!("serial queues taken twice");
    };
    IRQ.install(irq);
    NVIC::unpend(Interrupt::USART1);
    // SAFETY: the handler is installed (above) before the line is unmasked, and it takes
    // the shared state only inside a critical section, so unmasking breaks no
    // mask-based critical section.
    unsafe { NVIC::unmask(Interrupt::USART1) };
    port
}
