//! The byte transport between the robot PC and the controller: the [`Port`] trait and
//! its implementations — the controller in this process ([`InProcess`]), a serial
//! device ([`open_serial`]) and a TCP stream ([`connect_tcp`], the emulator's UART or a
//! serial port exposed over the network). Link faults are a wrapper around any of them
//! ([`super::faults::FaultInjector`]).

use ribreg_core::controller::Controller;
use ribreg_core::limits::CONTROLLER_VOXELS;
use ribreg_core::wire::{self, MAX_FRAME};
use std::io::{Read, Write};
use std::time::Duration;

use super::faults::FaultStats;
use crate::error::CliError;

/// The controller end of the link.
pub trait Port {
    /// Sends bytes to the controller.
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), CliError>;
    /// Appends what the controller sent, waiting at most `wait` for the first byte.
    fn read_into(&mut self, out: &mut Vec<u8>, wait: Duration) -> Result<(), CliError>;
    /// Lets `us` of controller time pass (in-process: polls the controller; a real or
    /// emulated controller runs on its own clock, so this sleeps).
    fn advance(&mut self, us: u64);
    /// Whether the controller's time passes only through [`Port::advance`].
    fn simulated_clock(&self) -> bool;
    /// What a fault injector between the session and the controller did; `None` for a
    /// plain transport.
    fn fault_stats(&self) -> Option<FaultStats> {
        None
    }
}

/// The controller in this process, clocked by the caller.
#[derive(Clone)]
pub struct InProcess {
    /// The controller (boxed: about 100 KiB).
    pub controller: Box<Controller<CONTROLLER_VOXELS>>,
    rx: wire::Receiver,
    now_us: u64,
    out: Vec<u8>,
}

impl Default for InProcess {
    fn default() -> Self {
        Self::new()
    }
}

impl InProcess {
    /// A fresh controller.
    pub fn new() -> Self {
        InProcess {
            controller: Box::new(Controller::new()),
            rx: wire::Receiver::new(),
            now_us: 0,
            out: Vec::new(),
        }
    }

    /// `us` pass and the controller is polled once, at their end: a main loop that was
    /// late (the fuzz target's time steps; [`Port::advance`] polls every ms).
    pub fn advance_late(&mut self, us: u64) {
        self.now_us += us;
        self.controller.poll(self.now_us);
        self.drain();
    }

    fn drain(&mut self) {
        let mut buf = [0u8; MAX_FRAME];
        while let Some((seq, msg)) = self.controller.next_reply() {
            // Note(unwrap): MAX_FRAME bounds every message.
            let n = wire::encode(seq, &msg, &mut buf).expect("replies fit MAX_FRAME");
            self.out.extend_from_slice(&buf[..n]);
        }
    }
}

impl Port for InProcess {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), CliError> {
        for &b in bytes {
            if let Some(frame) = self.rx.push(b) {
                self.controller.receive(frame, self.now_us);
            }
        }
        self.drain();
        Ok(())
    }

    fn read_into(&mut self, out: &mut Vec<u8>, _wait: Duration) -> Result<(), CliError> {
        out.append(&mut self.out);
        Ok(())
    }

    fn simulated_clock(&self) -> bool {
        true
    }

    fn advance(&mut self, us: u64) {
        let end = self.now_us + us;
        while self.now_us < end {
            self.now_us = (self.now_us + 1000).min(end);
            self.controller.poll(self.now_us);
        }
        self.drain();
    }
}

/// A controller behind a byte stream (the emulator's TCP serial port, a serial device).
pub struct Stream<S: Read + Write> {
    stream: S,
}

impl<S: Read + Write> Stream<S> {
    /// Wraps a connected stream; reads must time out (a read timeout is set by the caller).
    pub fn new(stream: S) -> Self {
        Stream { stream }
    }
}

impl Port for Stream<std::net::TcpStream> {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), CliError> {
        self.stream
            .write_all(bytes)
            .map_err(|e| CliError::Link(format!("link: cannot write: {e}")))
    }

    fn read_into(&mut self, out: &mut Vec<u8>, wait: Duration) -> Result<(), CliError> {
        let _ = self
            .stream
            .set_read_timeout(Some(wait.max(Duration::from_millis(1))));
        let mut buf = [0u8; 4096];
        match self.stream.read(&mut buf) {
            Ok(0) => Err(CliError::Link(
                "link: the controller closed the connection".into(),
            )),
            Ok(n) => {
                out.extend_from_slice(&buf[..n]);
                // Take whatever else is already there without waiting.
                let _ = self.stream.set_nonblocking(true);
                while let Ok(n) = self.stream.read(&mut buf) {
                    if n == 0 {
                        break;
                    }
                    out.extend_from_slice(&buf[..n]);
                }
                let _ = self.stream.set_nonblocking(false);
                Ok(())
            }
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                Ok(())
            }
            Err(e) => Err(CliError::Link(format!("link: cannot read: {e}"))),
        }
    }

    fn advance(&mut self, us: u64) {
        std::thread::sleep(Duration::from_micros(us));
    }

    fn simulated_clock(&self) -> bool {
        false
    }
}

impl Port for Stream<Box<dyn serialport::SerialPort>> {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), CliError> {
        self.stream
            .write_all(bytes)
            .map_err(|e| CliError::Link(format!("serial port: cannot write: {e}")))
    }

    fn read_into(&mut self, out: &mut Vec<u8>, wait: Duration) -> Result<(), CliError> {
        let _ = self.stream.set_timeout(wait.max(Duration::from_millis(1)));
        let mut buf = [0u8; 4096];
        loop {
            match self.stream.read(&mut buf) {
                Ok(0) => return Ok(()),
                Ok(n) => {
                    out.extend_from_slice(&buf[..n]);
                    // Take whatever else is waiting, without waiting again.
                    if self.stream.bytes_to_read().unwrap_or(0) == 0 {
                        return Ok(());
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => return Ok(()),
                Err(e) => return Err(CliError::Link(format!("serial port: cannot read: {e}"))),
            }
        }
    }

    fn advance(&mut self, us: u64) {
        std::thread::sleep(Duration::from_micros(us));
    }

    fn simulated_clock(&self) -> bool {
        false
    }
}

/// Opens a controller board's serial device (8N1) at `baud`.
pub fn open_serial(
    path: &str,
    baud: u32,
) -> Result<Stream<Box<dyn serialport::SerialPort>>, CliError> {
    serialport::new(path, baud)
        .timeout(Duration::from_millis(10))
        .open()
        .map(Stream::new)
        .map_err(|e| CliError::Link(format!("{path}: cannot open the serial port: {e}")))
}

/// Connects to a controller at `addr` (HOST:PORT) over TCP, without Nagle's delay.
pub fn connect_tcp(addr: &str) -> Result<Stream<std::net::TcpStream>, CliError> {
    let stream = std::net::TcpStream::connect(addr)
        .map_err(|e| CliError::Link(format!("{addr}: cannot connect: {e}")))?;
    let _ = stream.set_nodelay(true);
    Ok(Stream::new(stream))
}

/// A boxed port is a port: a session can hold whichever transport is chosen at run time
/// (`Session<Box<dyn Port + Send>>`, as the Python bindings do).
impl<P: Port + ?Sized> Port for Box<P> {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), CliError> {
        (**self).write_all(bytes)
    }

    fn read_into(&mut self, out: &mut Vec<u8>, wait: Duration) -> Result<(), CliError> {
        (**self).read_into(out, wait)
    }

    fn advance(&mut self, us: u64) {
        (**self).advance(us);
    }

    fn simulated_clock(&self) -> bool {
        (**self).simulated_clock()
    }

    fn fault_stats(&self) -> Option<FaultStats> {
        (**self).fault_stats()
    }
}
