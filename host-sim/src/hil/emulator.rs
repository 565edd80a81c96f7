//! The emulator: runs the firmware under QEMU and talks to it over its emulated UART.
//!
//! [`Emulator::start`] spawns
//!
//! ```text
//! qemu-system-arm -machine mps2-an386 -display none -monitor none \
//!   -semihosting-config enable=on,target=native \
//!   -serial tcp:127.0.0.1:PORT,server=on,wait=off,nodelay=on \
//!   [-icount shift=N,align=off,sleep=off] -kernel ELF
//! ```
//!
//! on a free loopback port, connects to UART0 with retries (a [`TcpStream`] with
//! `TCP_NODELAY`: without it each reply costs ~45 ms of Nagle and delayed ACK), and
//! captures QEMU's stdout, which carries the firmware's defmt frames (semihosting), into
//! a buffer and optionally a file for `defmt-print -e ELF`. QEMU is killed when the
//! [`Emulator`] is dropped. [`firmware_elf`] builds the firmware for
//! `thumbv7em-none-eabihf` (release) and returns the ELF's path, normally
//! [`FIRMWARE_ELF`] under the workspace root. A [`Board`] names the other build: the
//! STM32F405 under `-machine netduinoplus2` ([`firmware_elf_for`], [`Board::options`];
//! its first `-serial` is USART1).

use std::fmt;
use std::fs::File;
use std::io::{self, Read, Write};
use std::net::{Ipv4Addr, SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

/// The emulator binary (Debian/Ubuntu package `qemu-system-arm`).
pub const QEMU: &str = "qemu-system-arm";
/// Board: Cortex-M4 with FPU, CMSDK UART0 at 0x4000_4000.
pub const MACHINE: &str = "mps2-an386";
/// Rust target of the firmware.
pub const FIRMWARE_TARGET: &str = "thumbv7em-none-eabihf";
/// Cargo package (and binary) name of the firmware.
pub const FIRMWARE_PACKAGE: &str = "ribreg-firmware";
/// Where `cargo build -p ribreg-firmware --target thumbv7em-none-eabihf --release` puts
/// the ELF, relative to the workspace root (unless `CARGO_TARGET_DIR` says otherwise).
pub const FIRMWARE_ELF: &str = "target/thumbv7em-none-eabihf/release/ribreg-firmware";
/// Environment variable naming a prebuilt firmware ELF for [`firmware_elf`].
pub const FIRMWARE_ELF_ENV: &str = "RIBREG_FIRMWARE_ELF";

/// A board the firmware is built for and QEMU emulates.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Board {
    /// QEMU's `mps2-an386` (Cortex-M4F, CMSDK UART0, SysTick at 25 MHz): the firmware's
    /// default build, `ribreg-firmware`.
    #[default]
    Mps2An386,
    /// The STM32F405RG under QEMU's `netduinoplus2` (USART1, SysTick at 168 MHz): the
    /// firmware's `f405` + `qemu` build, `ribreg-firmware-f405`.
    F405,
}

impl Board {
    /// Every board.
    pub const ALL: [Board; 2] = [Board::Mps2An386, Board::F405];

    /// The name on the command line (`ribreg hil --board NAME`).
    pub fn name(self) -> &'static str {
        match self {
            Board::Mps2An386 => "mps2-an386",
            Board::F405 => "f405",
        }
    }

    /// The board named `name` ([`Board::name`]).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|b| b.name() == name)
    }

    /// QEMU's `-machine`.
    pub fn machine(self) -> &'static str {
        match self {
            Board::Mps2An386 => MACHINE,
            Board::F405 => "netduinoplus2",
        }
    }

    /// The firmware binary's name.
    pub fn binary(self) -> &'static str {
        match self {
            Board::Mps2An386 => FIRMWARE_PACKAGE,
            Board::F405 => "ribreg-firmware-f405",
        }
    }

    /// The cargo feature arguments of its build.
    pub fn cargo_features(self) -> &'static [&'static str] {
        match self {
            Board::Mps2An386 => &[],
            Board::F405 => &["--no-default-features", "--features", "f405,qemu"],
        }
    }

    /// The environment variable naming a prebuilt ELF for it.
    pub fn elf_env(self) -> &'static str {
        match self {
            Board::Mps2An386 => FIRMWARE_ELF_ENV,
            Board::F405 => "RIBREG_FIRMWARE_F405_ELF",
        }
    }

    /// [`Options::default`] with this board's machine.
    pub fn options(self) -> Options {
        Options {
            machine: self.machine().to_owned(),
            ..Options::default()
        }
    }
}

impl fmt::Display for Board {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// How to run the emulator.
#[derive(Clone, Debug)]
pub struct Options {
    /// The QEMU binary; [`QEMU`] (looked up in `PATH`) by default.
    pub qemu: PathBuf,
    /// `-machine`; [`MACHINE`] by default.
    pub machine: String,
    /// `Some` adds `-icount` (see [`Icount`]); `None` (default): the virtual clock
    /// follows the host's.
    pub icount: Option<Icount>,
    /// How long to keep trying to connect to the UART; 10 s by default.
    pub connect_timeout: Duration,
    /// Also write QEMU's stdout (the defmt stream) to this file as it arrives.
    pub semihosting_log: Option<PathBuf>,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            qemu: PathBuf::from(QEMU),
            machine: MACHINE.to_owned(),
            icount: None,
            connect_timeout: Duration::from_secs(10),
            semihosting_log: None,
        }
    }
}

/// `-icount shift=N,align=off,sleep=on|off`: every guest instruction advances the
/// virtual clock by 2^N ns, so the firmware's SysTick (25 MHz) counts instructions
/// deterministically: 40 a tick at N = 0, 10 at N = 2. The default is N = 0, `sleep=off`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Icount {
    /// N: 2^N ns of virtual time per instruction.
    pub shift: u8,
    /// `sleep=on`: while the guest idles in WFI the virtual clock follows the host's.
    /// `sleep=off` (default, as in the firmware notes): it jumps to the next timer
    /// deadline, so a guest waiting for the UART wakes at every SysTick wrap (0.67 s of
    /// virtual time each), keeps a host core busy and its uptime runs far ahead.
    /// Instruction counts of code that does not wait are the same either way.
    pub sleep: bool,
}

impl Icount {
    /// The argument of `-icount`.
    pub fn arg(self) -> String {
        let sleep = if self.sleep { "on" } else { "off" };
        format!("shift={},align=off,sleep={sleep}", self.shift)
    }
}

/// What went wrong running the emulator or building the firmware.
#[derive(Debug)]
pub enum QemuError {
    /// The QEMU binary is not installed (or not in `PATH`).
    NotInstalled {
        /// The program that was looked for.
        program: PathBuf,
    },
    /// An I/O operation failed.
    Io {
        /// What was being done.
        context: String,
        /// The underlying error.
        source: io::Error,
    },
    /// QEMU exited before the UART connection was made.
    Exited {
        /// Its exit status.
        status: ExitStatus,
        /// What it printed on stderr.
        stderr: String,
    },
    /// QEMU kept running but its UART port never accepted a connection.
    Connect {
        /// The port tried.
        port: u16,
        /// How long it was tried.
        waited: Duration,
    },
    /// [`Emulator::wait`] timed out: the firmware did not exit.
    Timeout {
        /// How long it was waited for.
        waited: Duration,
    },
    /// `cargo build` of the firmware failed.
    Build {
        /// The command that was run.
        command: String,
        /// Its exit status.
        status: ExitStatus,
        /// The end of what it printed on stderr.
        stderr: String,
    },
    /// The firmware ELF is not where it was expected.
    MissingElf {
        /// The path looked at.
        path: PathBuf,
    },
    /// The firmware ELF lacks what was looked for in it (a 32-bit little-endian ELF with
    /// its symbol table).
    Elf {
        /// The ELF.
        path: PathBuf,
        /// What is missing or malformed.
        what: String,
    },
    /// The procedure failed while the emulator ran (or after it stopped).
    Failed {
        /// What failed.
        during: String,
        /// The emulator's state then (`wait`'s result).
        status: String,
        /// What QEMU printed on stderr.
        stderr: String,
    },
    /// The firmware exited with a failure status (a panic or a semihosting failure exit).
    Unclean {
        /// QEMU's exit status.
        status: ExitStatus,
        /// What QEMU printed on stderr.
        stderr: String,
    },
}

impl fmt::Display for QemuError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NotInstalled { program } => write!(
                f,
                "{} not found: install with `apt-get install qemu-system-arm`",
                program.display()
            ),
            Self::Io { context, source } => write!(f, "{context}: {source}"),
            Self::Exited { status, stderr } => write!(
                f,
                "QEMU exited ({status}) before its UART accepted a connection: {}",
                stderr.trim()
            ),
            Self::Connect { port, waited } => write!(
                f,
                "QEMU's UART on 127.0.0.1:{port} accepted no connection within {waited:?}"
            ),
            Self::Timeout { waited } => {
                write!(f, "the firmware did not exit within {waited:?}")
            }
            Self::Build {
                command,
                status,
                stderr,
            } => write!(
                f,
                "`{command}` failed ({status}); the firmware needs `rustup target add \
                 thumbv7em-none-eabihf` and `cargo install flip-link --locked`:\n{}",
                stderr.trim()
            ),
            Self::Elf { path, what } => write!(f, "{}: {what}", path.display()),
            Self::Failed {
                during,
                status,
                stderr,
            } => write!(f, "{during}; the emulator: {status}, {stderr}"),
            Self::Unclean { status, stderr } => write!(
                f,
                "the firmware did not exit cleanly ({status}); QEMU said: {stderr}"
            ),
            Self::MissingElf { path } => write!(
                f,
                "firmware ELF {} not found: build it with `cargo build -p {FIRMWARE_PACKAGE} \
                 --target {FIRMWARE_TARGET} --release`",
                path.display()
            ),
        }
    }
}

impl std::error::Error for QemuError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}

fn io_error(context: impl Into<String>) -> impl FnOnce(io::Error) -> QemuError {
    let context = context.into();
    move |source| QemuError::Io { context, source }
}

/// Whether `program` runs (`--version` succeeds).
pub fn qemu_available(program: &Path) -> bool {
    Command::new(program)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// Bytes collected from a child's pipe by a reader thread.
type Captured = Arc<Mutex<Vec<u8>>>;

fn capture(
    mut pipe: impl Read + Send + 'static,
    mut tee: Option<File>,
) -> (Captured, JoinHandle<()>) {
    let buf = Captured::default();
    let sink = Arc::clone(&buf);
    let handle = thread::spawn(move || {
        let mut chunk = [0u8; 4096];
        while let Ok(n) = pipe.read(&mut chunk) {
            if n == 0 {
                break;
            }
            if let Some(file) = tee.as_mut() {
                // The log file is a convenience; the buffer keeps everything anyway.
                let _ = file.write_all(&chunk[..n]).and_then(|()| file.flush());
            }
            sink.lock()
                .unwrap_or_else(|e| e.into_inner())
                .extend_from_slice(&chunk[..n]);
        }
    });
    (buf, handle)
}

fn snapshot(buf: &Captured) -> Vec<u8> {
    buf.lock().unwrap_or_else(|e| e.into_inner()).clone()
}

/// A free loopback port: bind port 0, read the port, release it for QEMU. Another
/// process could take it in between; [`Emulator::start`] retries then.
fn free_port() -> Result<u16, QemuError> {
    let listener =
        TcpListener::bind((Ipv4Addr::LOCALHOST, 0)).map_err(io_error("bind a loopback port"))?;
    Ok(listener
        .local_addr()
        .map_err(io_error("read the bound port"))?
        .port())
}

/// A running emulator with its UART connected.
pub struct Emulator {
    child: Child,
    serial: TcpStream,
    port: u16,
    args: Vec<String>,
    stdout: Captured,
    stderr: Captured,
    readers: Vec<JoinHandle<()>>,
    status: Option<ExitStatus>,
}

impl Emulator {
    /// Starts `elf` under QEMU and connects to its UART0.
    pub fn start(elf: &Path, opts: &Options) -> Result<Self, QemuError> {
        if !elf.is_file() {
            return Err(QemuError::MissingElf {
                path: elf.to_owned(),
            });
        }
        const ATTEMPTS: usize = 5;
        let mut attempt = 0;
        loop {
            attempt += 1;
            match Self::try_start(elf, opts)? {
                Ok(emulator) => return Ok(emulator),
                // The port was taken between `free_port` and QEMU's bind: try another.
                Err(e) if attempt < ATTEMPTS => drop(e),
                Err(e) => return Err(e),
            }
        }
    }

    /// `Ok(Err(_))` when QEMU could not bind its port (worth another try).
    fn try_start(elf: &Path, opts: &Options) -> Result<Result<Self, QemuError>, QemuError> {
        let port = free_port()?;
        let mut args: Vec<String> = [
            "-machine",
            &opts.machine,
            "-display",
            "none",
            "-monitor",
            "none",
            "-semihosting-config",
            "enable=on,target=native",
            "-serial",
            &format!("tcp:127.0.0.1:{port},server=on,wait=off,nodelay=on"),
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        if let Some(icount) = opts.icount {
            args.push("-icount".into());
            args.push(icount.arg());
        }
        args.push("-kernel".into());
        args.push(elf.display().to_string());

        let tee = match &opts.semihosting_log {
            Some(path) => {
                Some(File::create(path).map_err(io_error(format!("create {}", path.display())))?)
            }
            None => None,
        };
        let mut child = match Command::new(&opts.qemu)
            .args(&args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
        {
            Ok(child) => child,
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                return Err(QemuError::NotInstalled {
                    program: opts.qemu.clone(),
                })
            }
            Err(e) => return Err(io_error(format!("start {}", opts.qemu.display()))(e)),
        };
        let (Some(out), Some(err)) = (child.stdout.take(), child.stderr.take()) else {
            unreachable!("both pipes were requested");
        };
        let (stdout, out_reader) = capture(out, tee);
        let (stderr, err_reader) = capture(err, None);

        let addr = SocketAddr::from((Ipv4Addr::LOCALHOST, port));
        let started = Instant::now();
        let serial = loop {
            if let Some(status) = child.try_wait().map_err(io_error("poll QEMU"))? {
                let _ = out_reader.join();
                let _ = err_reader.join();
                let stderr = String::from_utf8_lossy(&snapshot(&stderr)).into_owned();
                let exited = QemuError::Exited { status, stderr };
                let port_taken = matches!(&exited, QemuError::Exited { stderr, .. }
                    if stderr.contains("Address already in use"));
                return if port_taken {
                    Ok(Err(exited))
                } else {
                    Err(exited)
                };
            }
            match TcpStream::connect_timeout(&addr, Duration::from_millis(200)) {
                Ok(stream) => break stream,
                Err(_) if started.elapsed() < opts.connect_timeout => {
                    thread::sleep(Duration::from_millis(20));
                }
                Err(_) => {
                    let _ = child.kill();
                    let _ = child.wait();
                    return Err(QemuError::Connect {
                        port,
                        waited: started.elapsed(),
                    });
                }
            }
        };
        serial
            .set_nodelay(true)
            .map_err(io_error("set TCP_NODELAY on the UART socket"))?;
        Ok(Ok(Self {
            child,
            serial,
            port,
            args,
            stdout,
            stderr,
            readers: vec![out_reader, err_reader],
            status: None,
        }))
    }

    /// The UART0 connection (read and write the firmware's serial port).
    pub fn serial(&mut self) -> &mut TcpStream {
        &mut self.serial
    }

    /// The loopback port of the UART.
    pub fn port(&self) -> u16 {
        self.port
    }

    /// The arguments QEMU was started with.
    pub fn args(&self) -> &[String] {
        &self.args
    }

    /// QEMU's stdout so far: the firmware's defmt frames (decode with
    /// `defmt-print -e ELF`). Complete once [`Emulator::wait`] has returned.
    pub fn semihosting_output(&self) -> Vec<u8> {
        snapshot(&self.stdout)
    }

    /// QEMU's stderr so far.
    pub fn stderr_output(&self) -> String {
        String::from_utf8_lossy(&snapshot(&self.stderr)).into_owned()
    }

    /// Waits up to `timeout` for the firmware to exit (semihosting exit: success is
    /// status 0) and returns QEMU's exit status. On timeout QEMU keeps running until
    /// the emulator is dropped or [`Emulator::kill`]ed.
    pub fn wait(&mut self, timeout: Duration) -> Result<ExitStatus, QemuError> {
        if let Some(status) = self.status {
            return Ok(status);
        }
        let started = Instant::now();
        loop {
            if let Some(status) = self.child.try_wait().map_err(io_error("poll QEMU"))? {
                self.status = Some(status);
                // The pipes close with the process: the captures are complete after this.
                for reader in self.readers.drain(..) {
                    let _ = reader.join();
                }
                return Ok(status);
            }
            if started.elapsed() >= timeout {
                return Err(QemuError::Timeout {
                    waited: started.elapsed(),
                });
            }
            thread::sleep(Duration::from_millis(10));
        }
    }

    /// Kills QEMU (if still running) and reaps it.
    pub fn kill(&mut self) {
        if self.status.is_none() {
            let _ = self.child.kill();
            self.status = self.child.wait().ok();
        }
        for reader in self.readers.drain(..) {
            let _ = reader.join();
        }
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        self.kill();
    }
}

/// The root of this workspace (the parent of `host-sim/`).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("host-sim lives inside the workspace")
        .to_owned()
}

/// The firmware ELF: the file named by `RIBREG_FIRMWARE_ELF` if that is set, otherwise
/// the result of [`build_firmware`].
pub fn firmware_elf() -> Result<PathBuf, QemuError> {
    firmware_elf_for(Board::Mps2An386)
}

/// The firmware ELF for `board`: the file named by [`Board::elf_env`] if that is set,
/// otherwise the result of [`build_firmware_for`].
pub fn firmware_elf_for(board: Board) -> Result<PathBuf, QemuError> {
    match std::env::var_os(board.elf_env()) {
        Some(path) if !path.is_empty() => {
            let path = PathBuf::from(path);
            if path.is_file() {
                Ok(path)
            } else {
                Err(QemuError::MissingElf { path })
            }
        }
        _ => build_firmware_for(board),
    }
}

/// Runs `cargo build -p ribreg-firmware --target thumbv7em-none-eabihf --release` in the
/// workspace and returns the path of the ELF cargo reports (normally [`FIRMWARE_ELF`]).
pub fn build_firmware() -> Result<PathBuf, QemuError> {
    build_firmware_for(Board::Mps2An386)
}

/// [`build_firmware`] for `board`, with its features ([`Board::cargo_features`]).
pub fn build_firmware_for(board: Board) -> Result<PathBuf, QemuError> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut args = vec![
        "build",
        "-p",
        FIRMWARE_PACKAGE,
        "--target",
        FIRMWARE_TARGET,
        "--release",
    ];
    args.extend_from_slice(board.cargo_features());
    let command = format!("cargo {}", args.join(" "));
    args.push("--message-format=json-render-diagnostics");
    let out = Command::new(&cargo)
        .args(args)
        .current_dir(workspace_root())
        .stdin(Stdio::null())
        .output()
        .map_err(io_error(format!("run `{command}`")))?;
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        let tail: Vec<&str> = stderr.lines().rev().take(40).collect();
        return Err(QemuError::Build {
            command,
            status: out.status,
            stderr: tail.into_iter().rev().collect::<Vec<_>>().join("\n"),
        });
    }
    let executable = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|line| serde_json::from_str::<serde_json::Value>(line).ok())
        .filter(|msg| {
            msg["reason"] == "compiler-artifact" && msg["target"]["name"] == board.binary()
        })
        .find_map(|msg| msg["executable"].as_str().map(PathBuf::from));
    let path = executable.unwrap_or_else(|| {
        workspace_root()
            .join(FIRMWARE_ELF)
            .with_file_name(board.binary())
    });
    if path.is_file() {
        Ok(path)
    } else {
        Err(QemuError::MissingElf { path })
    }
}

/// The firmware's stack region, bytes: `_stack_start − _stack_end` from the ELF's symbol
/// table — the linker symbols the firmware itself reads for the size it logs at boot
/// (`stack lo..hi (N B)`) and at `QUIT` (`peak stack P of N B`).
pub fn stack_size_bytes(elf: &Path) -> Result<u32, QemuError> {
    let bytes = std::fs::read(elf).map_err(io_error(format!("read {}", elf.display())))?;
    let bad = |what: &str| QemuError::Elf {
        path: elf.to_owned(),
        what: what.to_owned(),
    };
    let start =
        elf32_symbol(&bytes, "_stack_start").ok_or_else(|| bad("no symbol _stack_start"))?;
    let end = elf32_symbol(&bytes, "_stack_end").ok_or_else(|| bad("no symbol _stack_end"))?;
    start
        .checked_sub(end)
        .ok_or_else(|| bad("_stack_start lies below _stack_end"))
}

/// The value of symbol `name` in a 32-bit little-endian ELF (its `.symtab`), if any.
fn elf32_symbol(elf: &[u8], name: &str) -> Option<u32> {
    let u16_at = |o: usize| Some(u16::from_le_bytes(elf.get(o..o + 2)?.try_into().ok()?));
    let u32_at = |o: usize| Some(u32::from_le_bytes(elf.get(o..o + 4)?.try_into().ok()?));
    // ELFCLASS32, ELFDATA2LSB.
    if elf.get(..6)? != b"\x7fELF\x01\x01" {
        return None;
    }
    let shoff = u32_at(0x20)? as usize;
    let shentsize = usize::from(u16_at(0x2E)?);
    let shnum = usize::from(u16_at(0x30)?);
    let section = |i: usize| shoff + i * shentsize;
    for i in 0..shnum {
        const SHT_SYMTAB: u32 = 2;
        let sh = section(i);
        if u32_at(sh + 4)? != SHT_SYMTAB {
            continue;
        }
        let (offset, size) = (u32_at(sh + 16)? as usize, u32_at(sh + 20)? as usize);
        let entsize = (u32_at(sh + 36)? as usize).max(16);
        let strtab = section(u32_at(sh + 24)? as usize);
        let str_offset = u32_at(strtab + 16)? as usize;
        for sym in (offset..offset + size).step_by(entsize) {
            let at = str_offset + u32_at(sym)? as usize;
            let rest = elf.get(at..)?;
            let len = rest.iter().position(|&b| b == 0)?;
            if &rest[..len] == name.as_bytes() {
                return u32_at(sym + 4);
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_qemu_is_a_typed_error_that_says_how_to_install_it() {
        let opts = Options {
            qemu: PathBuf::from("/nonexistent/qemu-system-arm"),
            ..Options::default()
        };
        assert!(!qemu_available(&opts.qemu));
        // Any existing file passes the ELF check; QEMU itself is what is missing.
        let elf = Path::new(env!("CARGO_MANIFEST_DIR")).join("Cargo.toml");
        let err = Emulator::start(&elf, &opts).err().expect("no QEMU there");
        assert!(matches!(err, QemuError::NotInstalled { .. }), "{err:?}");
        assert!(err
            .to_string()
            .contains("install with `apt-get install qemu-system-arm`"));
    }

    #[test]
    fn boards_name_their_machine_binary_and_build() {
        for b in Board::ALL {
            assert_eq!(Board::from_name(b.name()), Some(b));
            assert_eq!(b.options().machine, b.machine());
        }
        assert_eq!(Board::default(), Board::Mps2An386);
        assert_eq!(
            Board::Mps2An386.options().machine,
            Options::default().machine
        );
        assert_eq!(Board::F405.machine(), "netduinoplus2");
        assert_eq!(Board::F405.binary(), "ribreg-firmware-f405");
        assert!(Board::F405.cargo_features().contains(&"f405,qemu"));
        assert!(Board::Mps2An386.cargo_features().is_empty());
        assert_eq!(Board::from_name("f407"), None);
    }

    #[test]
    fn icount_argument() {
        assert_eq!(Icount::default().arg(), "shift=0,align=off,sleep=off");
        let on = Icount {
            shift: 2,
            sleep: true,
        };
        assert_eq!(on.arg(), "shift=2,align=off,sleep=on");
    }

    #[test]
    fn a_missing_elf_is_reported_before_qemu_starts() {
        let err = Emulator::start(Path::new("/nonexistent.elf"), &Options::default())
            .err()
            .expect("no such ELF");
        assert!(matches!(err, QemuError::MissingElf { .. }), "{err:?}");
    }
}
