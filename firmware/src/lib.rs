//! # ribreg-firmware
//!
//! The probe-positioning controller for `thumbv7em-none-eabihf`: it serves the robot PC
//! over a UART with the protocol of `ribreg_core::wire` and runs
//! `ribreg_core::controller::Controller` in one loop (`app` on the target says what runs
//! when and the deadlines).
//!
//! The application (the loop, `link`, `meter`, `cost`, `exit`) is board-agnostic; what
//! differs between boards (the SysTick clock, the serial port, its clocks, pins and
//! interrupts) is the board layer, [`board`], selected by a cargo feature:
//!
//! | feature | binary | board | memory layout |
//! | --- | --- | --- | --- |
//! | `mps2-an386` (default) | `ribreg-firmware` | QEMU `mps2-an386` (CMSDK UART0) | `../memory.x` |
//! | `f405` (`+ qemu` under QEMU) | `ribreg-firmware-f405` | STM32F405RG, QEMU `netduinoplus2` (USART1) | `boards/f405/memory-f405.x` |
//!
//! On the host the binaries are stubs that say how to build them (`host_stub`), so
//! `cargo build --workspace` keeps working; the target-independent parts (tick
//! arithmetic, calibration, stack scan, stage costs, `QUIT` detection) are unit-tested
//! on the host.
#![cfg_attr(target_os = "none", no_std)]
// Register access, the fault handler and the stack scan need `unsafe`; it is allowed only
// in the board modules, `cost` and the HardFault handler, each block with a SAFETY comment.
#![deny(unsafe_code)]

#[cfg(target_os = "none")]
pub mod app;
pub mod board;
#[cfg(any(target_os = "none", test))]
#[allow(unsafe_code)]
mod cost;
#[cfg(any(target_os = "none", test))]
mod exit;
#[cfg(target_os = "none")]
mod link;
#[cfg(any(target_os = "none", test))]
mod meter;
#[cfg(target_os = "none")]
mod serial;

/// What a firmware binary does on the host: says how to build `bin` for the target (with
/// `features`) and exits with status 2.
#[cfg(not(target_os = "none"))]
pub fn host_stub(bin: &str, features: &str) -> ! {
    eprintln!(
        "{bin} runs on the Cortex-M4F controller, not on the host.\n\
         Build it with:\n  \
         cargo build -p ribreg-firmware --target thumbv7em-none-eabihf --release{features}\n\
         and run it under QEMU as described in firmware/README.md."
    );
    std::process::exit(2);
}
