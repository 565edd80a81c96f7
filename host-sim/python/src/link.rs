//! `ribreg.link`: the robot PC's side of the wire protocol, as the `ribreg-sim` host
//! implements it (`ribreg_sim::hil`), with no protocol code of its own.
//!
//! * `encode_frame`, `decode_frame`, [`FrameReceiver`]: the core's framing
//!   (`ribreg_core::wire`).
//! * [`LinkSession`]: `ribreg_sim::hil::Session` (handshake as the first message,
//!   sequence numbers, go-back-N re-sends, NACK handling) over the in-process
//!   controller, a TCP `HOST:PORT` or a serial device.
//! * `sim`: the simulated phantom, sweep, robot and emulator `ribreg hil` uses.
//!
//! Messages cross as their serde form (`convert`); the typed classes are Python's
//! (`ribreg/link.py`). Errors: a frame that cannot be decoded raises `FrameError`
//! (a `ValueError`), a bad message `ValueError`, a link failure `LinkError` (an
//! `OSError`), each with the Rust message.

use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyList};
use ribreg_core::wire::{self, FromController, ToController, MAX_FRAME};
use ribreg_sim::error::CliError;
use ribreg_sim::hil::{self, FaultInjector, Faults, InProcess, Port, Session};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

mod convert;
mod sim;

use convert::{from_py_msg, to_py_msg};

pyo3::create_exception!(
    ribreg._ribreg,
    LinkError,
    PyOSError,
    "The link to the controller failed: it could not be opened, it closed, or messages \
     stayed unacknowledged past a deadline. An `OSError`; the message is the Rust one."
);
pyo3::create_exception!(
    ribreg._ribreg,
    FrameError,
    PyValueError,
    "Bytes that are not a frame of this protocol: over-long, not COBS, CRC mismatch, or \
     not a message of this version. A `ValueError`."
);

/// Adds the link's classes and functions to the module.
pub fn add(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("LinkError", py.get_type::<LinkError>())?;
    m.add("FrameError", py.get_type::<FrameError>())?;
    m.add("MAX_FRAME", MAX_FRAME)?;
    m.add("MAGIC", wire::MAGIC)?;
    m.add("VERSION", wire::VERSION)?;
    m.add("NODES_PER_CHUNK", wire::NODES_PER_CHUNK)?;
    m.add("WAYPOINTS_PER_CHUNK", wire::WAYPOINTS_PER_CHUNK)?;
    m.add("PIXEL_SUBDIVISIONS", wire::PIXEL_SUBDIVISIONS)?;
    m.add("WINDOW", hil::session::WINDOW)?;
    m.add("RESEND_AFTER_S", hil::session::RESEND_AFTER.as_secs_f64())?;
    m.add_function(wrap_pyfunction!(encode_frame, m)?)?;
    m.add_function(wrap_pyfunction!(decode_frame, m)?)?;
    m.add_function(wrap_pyfunction!(error_summary, m)?)?;
    m.add_class::<FrameReceiver>()?;
    m.add_class::<LinkSession>()?;
    sim::add(m)
}

/// A link error as `LinkError` with its message.
fn link_error(e: CliError) -> PyErr {
    LinkError::new_err(e.to_string())
}

fn frame_error(e: wire::FrameError) -> PyErr {
    FrameError::new_err(e.to_string())
}

/// What a core error code (a NACK's `Invalid` or a registration fault's detail) stands
/// for, in a few words.
#[pyfunction]
fn error_summary(code: u8) -> &'static str {
    wire::error_summary(code)
}

/// Encodes a message (its serde form; `to_controller` says which direction's type it
/// is) with sequence number `seq` as one frame, the zero delimiter included.
#[pyfunction]
#[pyo3(signature = (seq, message, to_controller = true))]
fn encode_frame<'py>(
    py: Python<'py>,
    seq: u16,
    message: &Bound<'py, PyAny>,
    to_controller: bool,
) -> PyResult<Bound<'py, PyBytes>> {
    let mut buf = [0u8; MAX_FRAME];
    let n = if to_controller {
        wire::encode(seq, &from_py_msg::<ToController>(message)?, &mut buf)
    } else {
        wire::encode(seq, &from_py_msg::<FromController>(message)?, &mut buf)
    }
    .map_err(frame_error)?;
    Ok(PyBytes::new(py, &buf[..n]))
}

/// Decodes the frame bytes (`to_controller`: of the robot PC's direction), its
/// delimiter optional; returns `(seq, message)` in serde form.
fn decode_one<'py>(
    py: Python<'py>,
    frame: &mut [u8],
    to_controller: bool,
) -> PyResult<(u16, Bound<'py, PyAny>)> {
    if to_controller {
        let (seq, msg) = wire::decode::<ToController>(frame).map_err(frame_error)?;
        Ok((seq, to_py_msg(py, &msg)?))
    } else {
        let (seq, msg) = wire::decode::<FromController>(frame).map_err(frame_error)?;
        Ok((seq, to_py_msg(py, &msg)?))
    }
}

/// Decodes one frame (a trailing zero delimiter is optional) into `(seq, message)`.
#[pyfunction]
#[pyo3(signature = (data, to_controller = false))]
fn decode_frame<'py>(
    py: Python<'py>,
    data: &[u8],
    to_controller: bool,
) -> PyResult<(u16, Bound<'py, PyAny>)> {
    let body = data.strip_suffix(&[0]).unwrap_or(data);
    if body.contains(&0) {
        return Err(FrameError::new_err(
            "more than one frame: a zero delimiter inside the bytes",
        ));
    }
    if body.len() >= MAX_FRAME {
        return Err(frame_error(wire::FrameError::TooLong));
    }
    let mut frame = body.to_vec();
    decode_one(py, &mut frame, to_controller)
}

/// The core's frame receiver: cuts a byte stream, fed in chunks of any size, into
/// frames and decodes them.
#[pyclass(module = "ribreg._ribreg")]
pub struct FrameReceiver {
    rx: wire::Receiver,
    to_controller: bool,
}

#[pymethods]
impl FrameReceiver {
    /// A receiver of controller messages (`to_controller=False`) or of robot PC ones.
    #[new]
    #[pyo3(signature = (to_controller = false))]
    fn new(to_controller: bool) -> Self {
        FrameReceiver {
            rx: wire::Receiver::new(),
            to_controller,
        }
    }

    /// Feeds bytes; returns what they completed, in stream order: `(seq, message)` for
    /// a frame, a `FrameError` instance (not raised) for bytes that were not one. A
    /// frame cut short stays buffered until the rest arrives.
    fn feed<'py>(&mut self, py: Python<'py>, data: &[u8]) -> PyResult<Bound<'py, PyList>> {
        let out = PyList::empty(py);
        for &b in data {
            let item = match self.rx.push(b) {
                None => continue,
                Some(Ok(frame)) => match decode_one(py, frame, self.to_controller) {
                    Ok(pair) => pair.into_pyobject(py)?.into_any(),
                    Err(e) => e.into_value(py).into_bound(py).into_any(),
                },
                Some(Err(e)) => frame_error(e).into_value(py).into_bound(py).into_any(),
            };
            out.append(item)?;
        }
        Ok(out)
    }
}

/// The transport of a session, chosen at run time.
type AnyPort = Box<dyn Port + Send>;

/// The robot PC's protocol engine, `ribreg_sim::hil::Session`, over any transport.
#[pyclass(module = "ribreg._ribreg")]
pub struct LinkSession {
    inner: Mutex<Session<AnyPort>>,
}

impl LinkSession {
    pub(crate) fn over(port: AnyPort) -> Self {
        LinkSession {
            inner: Mutex::new(Session::new(port)),
        }
    }

    /// A session over `port`, through `ribreg hil --faults`' fault injector
    /// ([`Faults::DEFAULT`]) seeded `fault_seed` if that is set.
    fn over_faulty<P: Port + Send + 'static>(port: P, fault_seed: Option<u64>) -> Self {
        match fault_seed {
            Some(seed) => Self::over(Box::new(FaultInjector::new(port, Faults::DEFAULT, seed))),
            None => Self::over(Box::new(port)),
        }
    }

    fn lock(&self) -> PyResult<MutexGuard<'_, Session<AnyPort>>> {
        self.inner
            .lock()
            .map_err(|_| LinkError::new_err("the session failed in another thread"))
    }

    /// Runs `f` on the session without the GIL, the session locked inside: every use
    /// of the session goes through here, so a thread waiting for the lock never holds
    /// the GIL its holder needs to return.
    fn detached<T: Send>(
        &self,
        py: Python<'_>,
        f: impl FnOnce(&mut Session<AnyPort>) -> Result<T, CliError> + Send,
    ) -> PyResult<T> {
        py.detach(|| f(&mut *self.lock()?).map_err(link_error))
    }
}

#[pymethods]
impl LinkSession {
    /// A session with the core's controller in this process, on a simulated clock
    /// that passes only through `advance`. `fault_seed` (all constructors): inject
    /// `ribreg hil --faults`' link faults with this seed.
    #[staticmethod]
    #[pyo3(signature = (fault_seed = None))]
    fn in_process(fault_seed: Option<u64>) -> Self {
        Self::over_faulty(InProcess::new(), fault_seed)
    }

    /// A session with a controller at `HOST:PORT` over TCP (the emulator's UART, a
    /// serial port exposed over the network).
    #[staticmethod]
    #[pyo3(signature = (addr, fault_seed = None))]
    fn connect(py: Python<'_>, addr: &str, fault_seed: Option<u64>) -> PyResult<Self> {
        let port = py.detach(|| hil::connect_tcp(addr)).map_err(link_error)?;
        Ok(Self::over_faulty(port, fault_seed))
    }

    /// A session with a controller board on serial device `path` (8N1) at `baud`.
    #[staticmethod]
    #[pyo3(signature = (path, baud = 115_200, fault_seed = None))]
    fn serial(path: &str, baud: u32, fault_seed: Option<u64>) -> PyResult<Self> {
        let port = hil::open_serial(path, baud).map_err(link_error)?;
        Ok(Self::over_faulty(port, fault_seed))
    }

    /// Sends a robot PC message (serde form), waiting for room in the window; returns
    /// its sequence number.
    fn send(&self, py: Python<'_>, message: &Bound<'_, PyAny>) -> PyResult<u16> {
        let msg: ToController = from_py_msg(message)?;
        self.detached(py, |s| s.send(&msg))
    }

    /// Reads what arrived (waiting at most `wait` s), handles ACKs and NACKs (re-sends
    /// on a transport NACK or after a silence), queues the rest.
    #[pyo3(signature = (wait = 0.0))]
    fn pump(&self, py: Python<'_>, wait: f64) -> PyResult<()> {
        let wait = Duration::from_secs_f64(wait.max(0.0));
        self.detached(py, |s| s.pump(wait))
    }

    /// The next queued controller message (not an ACK/NACK), serde form, or `None`.
    /// `timeout=None` only looks at the queue; a number pumps until a message arrives
    /// or that many seconds pass.
    #[pyo3(signature = (timeout = None))]
    fn next_message<'py>(
        &self,
        py: Python<'py>,
        timeout: Option<f64>,
    ) -> PyResult<Option<Bound<'py, PyAny>>> {
        let msg = match timeout {
            None => self.detached(py, |s| Ok(s.next_message()))?,
            Some(t) => {
                // The session is locked for one pump at a time, so that other threads
                // (one sending, say) get their turn while this one waits.
                let deadline = Instant::now() + Duration::from_secs_f64(t.max(0.0));
                loop {
                    let left = deadline.saturating_duration_since(Instant::now());
                    let got = self.detached(py, |s| {
                        if let Some(m) = s.next_message() {
                            return Ok(Some(m));
                        }
                        s.pump(left.min(Duration::from_millis(10)))?;
                        Ok(s.next_message())
                    })?;
                    if got.is_some() || left.is_zero() {
                        break got;
                    }
                }
            }
        };
        msg.map(|m| to_py_msg(py, &m)).transpose()
    }

    /// Waits until every message sent is acknowledged (or refused), at most `timeout`
    /// s, advancing an in-process controller's clock 1 ms at a time meanwhile.
    #[pyo3(signature = (timeout = 120.0))]
    fn flush(&self, py: Python<'_>, timeout: f64) -> PyResult<()> {
        let timeout = Duration::from_secs_f64(timeout.max(0.0));
        self.detached(py, |s| s.flush(timeout))
    }

    /// Lets `us` µs of controller time pass: the in-process controller is polled each
    /// millisecond of it; a real or emulated one runs on its own clock, so this sleeps.
    fn advance(&self, py: Python<'_>, us: u64) -> PyResult<()> {
        self.detached(py, |s| {
            s.port.advance(us);
            Ok(())
        })
    }

    /// Whether the controller's time passes only through `advance` (in-process).
    #[getter]
    fn simulated_clock(&self, py: Python<'_>) -> PyResult<bool> {
        self.detached(py, |s| Ok(s.port.simulated_clock()))
    }

    /// Link counters: `sent`, `resent`, `nacks`, `timeouts`, `injected`, `bytes`.
    #[getter]
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let stats = self.detached(py, |s| Ok(s.link_stats()))?;
        to_py_msg(py, &stats)
    }

    /// Application refusals so far: `(seq, code)` with the NACK code in serde form.
    #[getter]
    fn refused<'py>(&self, py: Python<'py>) -> PyResult<Vec<(u16, Bound<'py, PyAny>)>> {
        self.detached(py, |s| Ok(s.refused.clone()))?
            .iter()
            .map(|(seq, code)| Ok((*seq, to_py_msg(py, code)?)))
            .collect()
    }
}
