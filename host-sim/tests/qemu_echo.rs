//! The firmware scaffold under QEMU: UART echo, the `QUIT` exit, the SysTick instruction
//! counter and the stack high-water mark.
//!
//! Builds `ribreg-firmware` for `thumbv7em-none-eabihf` (or takes `RIBREG_FIRMWARE_ELF`)
//! and needs `qemu-system-arm`. Without QEMU the tests are skipped with a message, unless
//! `RIBREG_REQUIRE_QEMU` is set (CI sets it to 1), which makes a missing QEMU a failure.
//! Measurements are printed on stderr: `cargo test -p ribreg-sim --test qemu_echo --
//! --nocapture`.

use ribreg_sim::qemu::{self, Emulator, Icount, Options, QemuError};
use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// SysTick ticks per second (the MPS2 core clock).
const TICKS_PER_SECOND: f64 = 25.0e6;
/// Instructions the firmware's boot calibration spins (`2 * CALIBRATION_ITERATIONS`).
const SPIN_INSTRUCTIONS: u64 = 20_000;

fn qemu_required() -> bool {
    std::env::var("RIBREG_REQUIRE_QEMU").is_ok_and(|v| !v.is_empty() && v != "0")
}

/// The firmware ELF, built once for all tests; `None` (test skipped) only if QEMU is
/// missing and not required.
fn firmware() -> Option<PathBuf> {
    static ELF: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    let program = PathBuf::from(qemu::QEMU);
    if !qemu::qemu_available(&program) {
        let err = QemuError::NotInstalled { program };
        if qemu_required() {
            panic!("RIBREG_REQUIRE_QEMU is set: {err}");
        }
        eprintln!("SKIPPED (set RIBREG_REQUIRE_QEMU=1 to make this a failure): {err}");
        return None;
    }
    let elf = ELF.get_or_init(|| qemu::firmware_elf().map_err(|e| e.to_string()));
    match elf {
        Ok(path) => Some(path.clone()),
        Err(e) => panic!("{e}"),
    }
}

/// Echoes `data` and returns the seconds it took.
fn echo(emu: &mut Emulator, data: &[u8]) -> f64 {
    let serial = emu.serial();
    let t = Instant::now();
    // QEMU passes one byte at a time, and the loopback buffers hold all of `data`, so
    // writing everything before reading cannot deadlock.
    serial.write_all(data).expect("send to the UART");
    let mut back = vec![0u8; data.len()];
    serial.read_exact(&mut back).expect("echo from the UART");
    let seconds = t.elapsed().as_secs_f64();
    assert!(back == data, "echo differs from what was sent");
    seconds
}

/// Sends `QUIT`, reads its echo and the `STATS` line, and parses `name=value` fields.
fn quit(emu: &mut Emulator) -> BTreeMap<String, u64> {
    let serial = emu.serial();
    serial.write_all(b"QUIT").expect("send QUIT");
    let mut text = Vec::new();
    let mut byte = [0u8; 1];
    while !(text.ends_with(b"\n") && text.windows(5).any(|w| w == b"STATS")) {
        match serial.read(&mut byte) {
            Ok(1) => text.push(byte[0]),
            Ok(_) => break,
            Err(e) => panic!("reading the STATS line: {e}"),
        }
    }
    let text = String::from_utf8(text).expect("ASCII report");
    let line = text
        .strip_prefix("QUIT\nSTATS ")
        .unwrap_or_else(|| panic!("expected QUIT's echo then STATS, got {text:?}"));
    line.split_whitespace()
        .map(|field| {
            let (name, value) = field.split_once('=').expect("name=value");
            (name.to_owned(), value.parse().expect("decimal value"))
        })
        .collect()
}

/// Starts the firmware; its defmt stream also goes to `CARGO_TARGET_TMPDIR/NAME.defmt`.
fn start(elf: &Path, icount: Option<Icount>, name: &str) -> Emulator {
    let log = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("{name}.defmt"));
    eprintln!(
        "{name}: defmt log in {} (decode: defmt-print -e {} < that file)",
        log.display(),
        elf.display()
    );
    let opts = Options {
        icount,
        semihosting_log: Some(log),
        ..Options::default()
    };
    let mut emu = Emulator::start(elf, &opts).unwrap_or_else(|e| panic!("{e}"));
    emu.serial()
        .set_read_timeout(Some(Duration::from_secs(20)))
        .expect("read timeout");
    emu
}

fn exit_success(emu: &mut Emulator) {
    let status = emu
        .wait(Duration::from_secs(20))
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(
        status.success(),
        "firmware exit {status}; QEMU stderr: {}",
        emu.stderr_output()
    );
    assert!(
        !emu.semihosting_output().is_empty(),
        "no defmt frames on QEMU's stdout"
    );
}

fn pattern(len: usize, seed: u8) -> Vec<u8> {
    // Every byte value, never the sequence QUIT.
    (0..len)
        .map(|i| (i as u8).wrapping_mul(7).wrapping_add(seed))
        .collect()
}

/// Real-time run: the echo is exact, and the 64-bit SysTick count keeps up with the
/// host's clock across several 2^24-tick wraps (0.67 s each).
#[test]
fn qemu_echo_and_quit() {
    let Some(elf) = firmware() else { return };
    let spawned = Instant::now();
    let mut emu = start(&elf, None, "qemu_echo_and_quit");

    let first = pattern(300, 1);
    let seconds = echo(&mut emu, &first);
    let first_echoed = Instant::now();
    eprintln!(
        "echo: {} bytes in {:.1} ms = {:.0} B/s (real time, no -icount)",
        first.len(),
        seconds * 1e3,
        first.len() as f64 / seconds
    );
    // Idle long enough for two SysTick wraps while the firmware sleeps in WFI.
    std::thread::sleep(Duration::from_millis(1500));
    echo(&mut emu, &pattern(200, 2));

    let quit_sent = Instant::now();
    let stats = quit(&mut emu);
    let quit_echoed = Instant::now();
    exit_success(&mut emu);
    eprintln!("STATS (real time): {stats:?}");

    // The firmware booted after QEMU was spawned and before it echoed the first bytes,
    // and handled QUIT between its sending and its echo. Without -icount the virtual
    // clock follows the host's, so the uptime it counts lies within these bounds.
    let uptime = stats["uptime_ticks"] as f64 / TICKS_PER_SECOND;
    let low = (quit_sent - first_echoed).as_secs_f64() - 0.01;
    let high = (quit_echoed - spawned).as_secs_f64() + 0.01;
    assert!(
        (low..=high).contains(&uptime),
        "firmware uptime {uptime:.3} s outside the host's bounds {low:.3}..={high:.3} s"
    );
    eprintln!("uptime {uptime:.3} s counted by the firmware, host bounds {low:.3}..={high:.3} s");
    assert!(uptime > 1.4, "the run must span at least two wraps");
    assert!(stats["peak_stack_bytes"] > 0);
    assert!(stats["peak_stack_bytes"] < stats["stack_size_bytes"]);
}

/// Deterministic run (`-icount shift=0`): one SysTick tick is 40 instructions.
#[test]
fn qemu_icount_calibration() {
    let Some(elf) = firmware() else { return };
    let mut emu = start(&elf, Some(Icount::default()), "qemu_icount_calibration");
    let data = pattern(256, 3);
    let seconds = echo(&mut emu, &data);
    eprintln!(
        "echo: {} bytes in {:.1} ms = {:.0} B/s (-icount shift=0)",
        data.len(),
        seconds * 1e3,
        data.len() as f64 / seconds
    );
    let stats = quit(&mut emu);
    exit_success(&mut emu);
    eprintln!("STATS (-icount shift=0): {stats:?}");

    assert_eq!(stats["spin_instructions"], SPIN_INSTRUCTIONS);
    // 20,000 instructions at 40 a tick are 500 ticks; the stamp pair adds at most one
    // tick and the call a few instructions.
    let spin = stats["spin_ticks"];
    assert!(
        (500..=502).contains(&spin),
        "{SPIN_INSTRUCTIONS} instructions took {spin} ticks, expected 500..=502"
    );
    assert!(stats["overhead_ticks"] <= 1);
    assert_eq!(
        stats["spin_measured_instructions"],
        40 * stats["spin_ticks"]
    );
    let peak = stats["peak_stack_bytes"];
    assert!(
        peak > 0 && peak < 4096,
        "peak stack {peak} B for the echo loop"
    );
}
