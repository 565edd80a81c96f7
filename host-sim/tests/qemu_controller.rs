//! The firmware under QEMU speaks the protocol: handshake, status, a corrupt frame
//! NACKed, measured costs, and the `QUIT` exit. (The whole emulated procedure is
//! `ribreg hil`, run by `.ci/run`.)
//!
//! Builds `ribreg-firmware` for `thumbv7em-none-eabihf` (or takes `RIBREG_FIRMWARE_ELF`)
//! and needs `qemu-system-arm`; the same again for the STM32F405 build under
//! `-machine netduinoplus2` (`ribreg-firmware-f405`, or `RIBREG_FIRMWARE_F405_ELF`). Without QEMU the test is skipped with a message, unless
//! `RIBREG_REQUIRE_QEMU` is set (CI sets it to 1), which makes a missing QEMU a failure.

use ribreg_core::wire::{
    self, Command, FromController, NackCode, State, ToController, MAGIC, MAX_FRAME, VERSION,
};
use ribreg_sim::hil::emulator::{self as qemu, Board, Emulator, Icount, Options, QemuError};
use std::io::{ErrorKind, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

fn qemu_required() -> bool {
    std::env::var("RIBREG_REQUIRE_QEMU").is_ok_and(|v| !v.is_empty() && v != "0")
}

/// The firmware ELF for `board`; `None` (test skipped) only if QEMU is missing and not
/// required.
fn firmware(board: Board) -> Option<PathBuf> {
    let program = PathBuf::from(qemu::QEMU);
    if !qemu::qemu_available(&program) {
        let err = QemuError::NotInstalled { program };
        if qemu_required() {
            panic!("RIBREG_REQUIRE_QEMU is set: {err}");
        }
        eprintln!("SKIPPED (set RIBREG_REQUIRE_QEMU=1 to make this a failure): {err}");
        return None;
    }
    Some(qemu::firmware_elf_for(board).unwrap_or_else(|e| panic!("{e}")))
}

fn send(serial: &mut TcpStream, seq: u16, msg: &ToController) {
    let mut buf = [0u8; MAX_FRAME];
    let n = wire::encode(seq, msg, &mut buf).unwrap();
    serial.write_all(&buf[..n]).unwrap();
}

/// The next controller message (20 s at most; the socket has a read timeout so the
/// deadline is checked even when the firmware says nothing).
fn next(serial: &mut TcpStream, rx: &mut wire::Receiver) -> FromController {
    try_next(serial, rx, Duration::from_secs(20)).expect("no reply from the firmware")
}

fn try_next(
    serial: &mut TcpStream,
    rx: &mut wire::Receiver,
    wait: Duration,
) -> Option<FromController> {
    let deadline = Instant::now() + wait;
    let mut byte = [0u8; 1];
    while Instant::now() < deadline {
        match serial.read(&mut byte) {
            Ok(1) => {
                if let Some(Ok(frame)) = rx.push(byte[0]) {
                    return Some(wire::decode::<FromController>(frame).unwrap().1);
                }
            }
            Ok(_) => panic!("the firmware closed its serial port"),
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(e) => panic!("serial read: {e}"),
        }
    }
    None
}

/// Sends `msg` until the firmware answers, then lets the duplicate answers drain: bytes
/// that arrive before the firmware has enabled its UART are dropped (QEMU's STM32 USART
/// model, like the real part, discards them), which a host meets only at start-up. A
/// frame cut that way is NACKed as corrupt: that answer is not the one wanted.
fn first_reply(
    serial: &mut TcpStream,
    rx: &mut wire::Receiver,
    msg: &ToController,
) -> FromController {
    let deadline = Instant::now() + Duration::from_secs(20);
    while Instant::now() < deadline {
        send(serial, 0, msg);
        while let Some(reply) = try_next(serial, rx, Duration::from_millis(500)) {
            if !matches!(
                reply,
                FromController::Nack {
                    code: NackCode::Corrupt,
                    ..
                }
            ) {
                while try_next(serial, rx, Duration::from_millis(500)).is_some() {}
                return reply;
            }
        }
    }
    panic!("no reply from the firmware within 20 s");
}

#[test]
fn firmware_speaks_the_protocol() {
    speaks_the_protocol(Board::Mps2An386);
}

#[test]
fn f405_firmware_speaks_the_protocol() {
    speaks_the_protocol(Board::F405);
}

fn speaks_the_protocol(board: Board) {
    let Some(elf) = firmware(board) else { return };
    let log = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("qemu_controller-{board}.defmt"));
    let opts = Options {
        icount: Some(Icount {
            shift: 0,
            sleep: true,
        }),
        semihosting_log: Some(log.clone()),
        ..board.options()
    };
    let mut emu = Emulator::start(&elf, &opts).unwrap_or_else(|e| panic!("{e}"));
    eprintln!(
        "defmt log: {} (defmt-print -e {} < it)",
        log.display(),
        elf.display()
    );
    let mut serial = emu.serial().try_clone().unwrap();
    serial
        .set_read_timeout(Some(Duration::from_millis(50)))
        .unwrap();
    let mut rx = wire::Receiver::new();

    // Before the handshake: refused.
    assert!(matches!(
        first_reply(
            &mut serial,
            &mut rx,
            &ToController::Command(Command::Status)
        ),
        FromController::Nack {
            code: NackCode::Version,
            ..
        }
    ));
    send(
        &mut serial,
        0,
        &ToController::Hello {
            magic: MAGIC,
            version: VERSION,
        },
    );
    assert!(matches!(
        next(&mut serial, &mut rx),
        FromController::HelloAck {
            magic: MAGIC,
            version: VERSION,
            max_frame,
        } if usize::from(max_frame) == MAX_FRAME
    ));
    // Garbage, then a frame with a flipped byte: NACKed, the link resynchronises.
    serial.write_all(&[0x13, 0x37, 0x00]).unwrap();
    let mut buf = [0u8; MAX_FRAME];
    let n = wire::encode(1, &ToController::Command(Command::Status), &mut buf).unwrap();
    buf[2] ^= 0x04;
    serial.write_all(&buf[..n]).unwrap();
    for _ in 0..2 {
        assert_eq!(
            next(&mut serial, &mut rx),
            FromController::Nack {
                seq: 1,
                code: NackCode::Corrupt
            }
        );
    }
    send(&mut serial, 1, &ToController::Command(Command::Status));
    match next(&mut serial, &mut rx) {
        FromController::Status(s) => {
            assert_eq!(s.state, State::Idle);
            assert_eq!(s.expected_seq, 2);
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(next(&mut serial, &mut rx), FromController::Ack { seq: 1 });
    send(&mut serial, 2, &ToController::Command(Command::Cost));
    match next(&mut serial, &mut rx) {
        FromController::Cost(c) => {
            eprintln!("firmware cost so far: {c:?}");
            assert!(c.peak_stack_bytes > 0 && c.worst_receive_instructions > 0);
        }
        other => panic!("{other:?}"),
    }
    serial.write_all(b"QUIT\0").unwrap();
    let status = emu
        .wait(Duration::from_secs(20))
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(
        status.success(),
        "firmware exit {status}; QEMU stderr: {}",
        emu.stderr_output()
    );
    assert!(!emu.semihosting_output().is_empty(), "no defmt frames");
}
