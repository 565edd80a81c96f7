//! The controller on QEMU's `mps2-an386` board (feature `mps2-an386`, the default): the
//! library's entry point and loop (`ribreg_firmware::app`) with the MPS2 board layer.
//! Every controller call and loop turn within 168,000 instructions (1 ms at 168 MHz).
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
use ribreg_firmware as _;

#[cfg(not(target_os = "none"))]
fn main() {
    ribreg_firmware::host_stub("ribreg-firmware", "");
}
