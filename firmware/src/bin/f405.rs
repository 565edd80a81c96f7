//! The controller on the STM32F405RG (feature `f405`; add `qemu` for QEMU's
//! `netduinoplus2`): the library's entry point and loop (`ribreg_firmware::app`) with
//! the F405 board layer. Every controller call and loop turn within 168,000 instructions
//! (1 ms at 168 MHz).
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
use ribreg_firmware as _;

#[cfg(not(target_os = "none"))]
fn main() {
    ribreg_firmware::host_stub(
        "ribreg-firmware-f405",
        " --no-default-features --features f405,qemu",
    );
}
