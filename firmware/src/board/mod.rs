//! The board layer: what differs between the boards the controller runs on — the SysTick
//! clock and the serial port with its set-up (clocks, pins, UART, interrupts) — behind
//! the `Serial` trait the application uses. A cargo feature selects the board:
//!
//! * `mps2-an386` (default): QEMU's MPS2 board, CMSDK UART0 (`mps2`);
//! * `f405`: the STM32F405RG, USART1 on PA9/PA10, under QEMU's `netduinoplus2` with the
//!   `qemu` feature (HSI clock) or on the real part (HSE 8 MHz + PLL to 168 MHz) (`f405`).
//!
//! Each board's build links against its own memory layout (`build.rs`).

#[cfg(all(target_os = "none", feature = "f405", feature = "mps2-an386"))]
compile_error!(
    "select one board: `--no-default-features --features f405` for the STM32F405, \
     the default (`mps2-an386`) for MPS2"
);
#[cfg(all(target_os = "none", not(feature = "f405"), not(feature = "mps2-an386")))]
compile_error!("select a board: feature `mps2-an386` (the default) or `f405`");

/// The board's name, as logged at boot.
#[cfg(feature = "f405")]
pub const NAME: &str = "stm32f405";
/// The board's name, as logged at boot.
#[cfg(not(feature = "f405"))]
pub const NAME: &str = "mps2-an386";

/// SysTick's clock (the core clock), Hz: 168 MHz on the F405 (QEMU's netduinoplus2
/// clocks SysTick at 168 MHz whatever RCC says; the real part runs from the PLL at
/// 168 MHz).
#[cfg(feature = "f405")]
pub const SYSTICK_HZ: u32 = 168_000_000;
/// SysTick's clock (the core clock), Hz: 25 MHz on MPS2.
#[cfg(not(feature = "f405"))]
pub const SYSTICK_HZ: u32 = 25_000_000;

#[cfg(all(target_os = "none", feature = "f405"))]
#[allow(unsafe_code)]
mod f405;
#[cfg(all(target_os = "none", feature = "f405"))]
pub use f405::{take_serial, Port};

#[cfg(all(target_os = "none", not(feature = "f405")))]
#[allow(unsafe_code)]
mod mps2;
#[cfg(all(target_os = "none", not(feature = "f405")))]
pub use mps2::{take_serial, Port};

/// The serial port as the application uses it: blocking `embedded_io` reads and writes
/// plus the two ways the loop sleeps.
#[cfg(target_os = "none")]
pub trait Serial:
    embedded_io::Read + embedded_io::ReadReady + embedded_io::Write + embedded_io::WriteReady
{
    /// Sleeps until a byte has arrived (without taking it).
    fn wait_readable(&mut self);
    /// Sleeps until a byte arrives or any other interrupt (the 1 ms SysTick) wakes the
    /// core; returns at once if a byte is already waiting.
    fn sleep_until_rx_or_interrupt(&mut self);
}
