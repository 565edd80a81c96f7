//! `ribreg hil`: the robot PC's side of a whole procedure against the controller —
//! upload, sweep, register, execute — with a simulated robot and probe, over the real
//! wire protocol, to a controller in this process, in the emulator, or on a serial port.
//!
//! # The robot PC
//! * A go-back-N sender: every message gets the next sequence number and stays in a
//!   window of [`WINDOW`] until ACKed; a transport NACK (corrupt, out of order, too long)
//!   or a silence of [`RESEND_AFTER`] re-sends the window from the number the controller
//!   expects. Application NACKs (bad state, invalid content) are recorded, not re-sent.
//! * The sweep: the simulated logs of [`crate::sweep`] (poses at 100 Hz, annotated
//!   frames at 30 fps with the configured lag), streamed in arrival order; the lag comes
//!   from the temporal calibration of the simulated calibration sweep.
//! * The robot while executing: it follows each setpoint with a first-order lag of
//!   [`ROBOT_LAG_S`] and reports its flange pose every 10 ms. When the controller moves on
//!   from a waypoint, the probe's aim point (TCP + standoff along the beam) is compared
//!   with the phantom's true waypoint.
//!
//! # Link faults (`--faults`)
//! Host → controller frames are, with the configured probabilities, corrupted (one byte
//! flipped), dropped, duplicated, held back behind the next frame (reordered), or preceded
//! by a burst of garbage bytes. Nothing accepted may be lost or applied twice: the run
//! checks that the controller's counters of applied poses and frames equal those of the
//! fault-free stream, and the mapped waypoints are compared with a fault-free run.

use ribreg_core::limits::CONTROLLER_VOXELS;
use std::collections::VecDeque;
use std::io::{Read, Write};
use std::time::{Duration, Instant};

use ribreg_core::acquisition::track::TrackedPose;
use ribreg_core::controller::{Controller, CONTROLLER_VOXEL_MM};
use ribreg_core::math::geom::Rigid;
use ribreg_core::math::rng::Rng;
use ribreg_core::wire::{
    self, Command, Configure, CostW, FrameW, FromController, NackCode, Node, PoseW, State,
    TemplateShape, ToController, WaypointW, MAGIC, MAX_FRAME, NODES_PER_CHUNK, PIXEL_SUBDIVISIONS,
    VERSION, WAYPOINTS_PER_CHUNK,
};
use ribreg_core::Vec3;
use serde::Serialize;

use crate::phantom::PhantomConfig;
use crate::register::{build_template, to_core, CliError, Method};
use crate::sweep::{self, SweepConfig};

/// Frames in flight before the sender waits for ACKs.
pub const WINDOW: usize = 24;
/// Silence after which the unacknowledged window is re-sent.
pub const RESEND_AFTER: Duration = Duration::from_millis(300);
/// The simulated robot follows setpoints with this time constant, s.
pub const ROBOT_LAG_S: f32 = 0.05;
/// Setpoint speed and acceleration limits and standoff sent in the configuration.
pub const MAX_SPEED_MM_S: f32 = 50.0;
/// Acceleration limit, mm/s².
pub const MAX_ACCEL_MM_S2: f32 = 200.0;
/// Probe standoff above the bone surface, mm.
pub const STANDOFF_MM: f32 = 15.0;
/// Clinical tolerance for a probe placed between ribs, mm.
pub const TOLERANCE_MM: f64 = 5.0;

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
}

/// The controller in this process, clocked by the caller.
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
            .map_err(|e| CliError::Usage(format!("link: cannot write: {e}")))
    }

    fn read_into(&mut self, out: &mut Vec<u8>, wait: Duration) -> Result<(), CliError> {
        let _ = self
            .stream
            .set_read_timeout(Some(wait.max(Duration::from_millis(1))));
        let mut buf = [0u8; 4096];
        match self.stream.read(&mut buf) {
            Ok(0) => Err(CliError::Usage(
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
            Err(e) => Err(CliError::Usage(format!("link: cannot read: {e}"))),
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
            .map_err(|e| CliError::Usage(format!("serial port: cannot write: {e}")))
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
                Err(e) => return Err(CliError::Usage(format!("serial port: cannot read: {e}"))),
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
        .map_err(|e| CliError::Usage(format!("{path}: cannot open the serial port: {e}")))
}

/// Probabilities of each link fault per host frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Faults {
    /// One byte of the frame flipped.
    pub corrupt: f64,
    /// The frame not sent.
    pub drop: f64,
    /// The frame sent twice.
    pub duplicate: f64,
    /// The frame held back and sent after the next one.
    pub reorder: f64,
    /// A burst of 1–64 random bytes (ending in a zero) sent before the frame.
    pub garbage: f64,
}

impl Faults {
    /// 2 % of each.
    pub const DEFAULT: Faults = Faults {
        corrupt: 0.02,
        drop: 0.02,
        duplicate: 0.02,
        reorder: 0.02,
        garbage: 0.02,
    };
}

/// Link counters of a run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct LinkStats {
    /// Frames sent the first time.
    pub sent: u64,
    /// Frames re-sent.
    pub resent: u64,
    /// Transport NACKs received.
    pub nacks: u64,
    /// Timeouts that re-sent the window.
    pub timeouts: u64,
    /// Faults injected: corrupted, dropped, duplicated, reordered, garbage bursts.
    pub injected: [u64; 5],
    /// Bytes written.
    pub bytes: u64,
}

/// The robot PC's protocol engine.
pub struct Session<P: Port> {
    /// The controller end.
    pub port: P,
    next_seq: u16,
    window: VecDeque<(u16, Vec<u8>)>,
    rx: wire::Receiver,
    bytes: Vec<u8>,
    inbox: VecDeque<FromController>,
    /// Application NACKs: (sequence, code).
    pub refused: Vec<(u16, NackCode)>,
    /// Counters.
    pub stats: LinkStats,
    faults: Option<(Faults, Rng)>,
    held: Option<Vec<u8>>,
    last_progress: Instant,
}

impl<P: Port> Session<P> {
    /// A session over `port`, optionally injecting `faults` (seeded).
    pub fn new(port: P, faults: Option<(Faults, u64)>) -> Self {
        Session {
            port,
            next_seq: 0,
            window: VecDeque::new(),
            rx: wire::Receiver::new(),
            bytes: Vec::new(),
            inbox: VecDeque::new(),
            refused: Vec::new(),
            stats: LinkStats::default(),
            faults: faults.map(|(f, seed)| (f, Rng::new(seed))),
            held: None,
            last_progress: Instant::now(),
        }
    }

    /// Writes one frame through the fault injector.
    fn transmit(&mut self, frame: &[u8]) -> Result<(), CliError> {
        let Some((f, rng)) = &mut self.faults else {
            self.stats.bytes += frame.len() as u64;
            return self.port.write_all(frame);
        };
        let mut out = Vec::new();
        if rng.next_f64() < f.garbage {
            self.stats.injected[4] += 1;
            let n = 1 + rng.below(64) as usize;
            out.extend((0..n).map(|_| (rng.next_u32() & 0xFF) as u8));
            out.push(0);
        }
        let mut copy = frame.to_vec();
        if rng.next_f64() < f.corrupt && copy.len() > 1 {
            self.stats.injected[0] += 1;
            let i = rng.below((copy.len() - 1) as u32) as usize;
            copy[i] ^= 1 << rng.below(8);
        }
        let roll = rng.next_f64();
        if roll < f.drop {
            self.stats.injected[1] += 1;
        } else if roll < f.drop + f.duplicate {
            self.stats.injected[2] += 1;
            out.extend_from_slice(&copy);
            out.extend_from_slice(&copy);
        } else if roll < f.drop + f.duplicate + f.reorder && self.held.is_none() {
            self.stats.injected[3] += 1;
            self.held = Some(copy);
        } else {
            out.extend_from_slice(&copy);
            if let Some(h) = self.held.take() {
                out.extend_from_slice(&h);
            }
        }
        self.stats.bytes += out.len() as u64;
        self.port.write_all(&out)
    }

    /// Sends a message (waits for room in the window); returns its sequence number.
    pub fn send(&mut self, msg: &ToController) -> Result<u16, CliError> {
        while self.window.len() >= WINDOW {
            self.pump(Duration::from_millis(5))?;
        }
        let seq = self.next_seq;
        self.next_seq = self.next_seq.wrapping_add(1);
        let mut buf = [0u8; MAX_FRAME];
        let n = wire::encode(seq, msg, &mut buf)
            .map_err(|e| CliError::Usage(format!("encode: {e}")))?;
        let frame = buf[..n].to_vec();
        self.transmit(&frame)?;
        self.stats.sent += 1;
        if self.window.is_empty() {
            self.last_progress = Instant::now();
        }
        self.window.push_back((seq, frame));
        Ok(seq)
    }

    /// Re-sends the window from `seq` on.
    fn resend_from(&mut self, seq: u16) -> Result<(), CliError> {
        let frames: Vec<Vec<u8>> = self
            .window
            .iter()
            .filter(|(s, _)| s.wrapping_sub(seq) < 0x8000)
            .map(|(_, f)| f.clone())
            .collect();
        for f in frames {
            self.transmit(&f)?;
            self.stats.resent += 1;
        }
        self.last_progress = Instant::now();
        Ok(())
    }

    /// Everything up to and including `seq` is handled.
    fn handled(&mut self, seq: u16) {
        let before = self.window.len();
        while let Some((s, _)) = self.window.front() {
            if seq.wrapping_sub(*s) < 0x8000 {
                self.window.pop_front();
            } else {
                break;
            }
        }
        if self.window.len() != before {
            self.last_progress = Instant::now();
        }
    }

    /// Reads what arrived (waiting at most `wait`), handles ACKs and NACKs, queues the rest.
    pub fn pump(&mut self, wait: Duration) -> Result<(), CliError> {
        self.port.read_into(&mut self.bytes, wait)?;
        let bytes = std::mem::take(&mut self.bytes);
        let mut nack_from = None;
        for b in bytes {
            if let Some(Ok(frame)) = self.rx.push(b) {
                let Ok((_, msg)) = wire::decode::<FromController>(frame) else {
                    continue;
                };
                match msg {
                    FromController::Ack { seq } => self.handled(seq),
                    FromController::Nack { seq, code } => match code {
                        NackCode::Corrupt | NackCode::OutOfOrder | NackCode::TooLong => {
                            self.stats.nacks += 1;
                            nack_from = Some(seq);
                        }
                        _ => {
                            self.refused.push((seq, code));
                            self.handled(seq);
                        }
                    },
                    FromController::HelloAck { .. } => {
                        self.handled(0);
                        self.inbox.push_back(msg);
                    }
                    other => self.inbox.push_back(other),
                }
            }
        }
        if let Some(seq) = nack_from {
            // Everything before the expected number was applied.
            self.handled(seq.wrapping_sub(1));
            self.resend_from(seq)?;
        } else if !self.window.is_empty() && self.last_progress.elapsed() > RESEND_AFTER {
            self.stats.timeouts += 1;
            let first = self.window.front().map_or(0, |(s, _)| *s);
            self.resend_from(first)?;
        }
        Ok(())
    }

    /// Waits until every message sent is handled.
    pub fn flush(&mut self, deadline: Duration) -> Result<(), CliError> {
        let start = Instant::now();
        while !self.window.is_empty() {
            if start.elapsed() > deadline {
                return Err(CliError::Usage(format!(
                    "link: {} messages unacknowledged after {:.0} s",
                    self.window.len(),
                    deadline.as_secs_f64()
                )));
            }
            self.port.advance(1000);
            self.pump(Duration::from_millis(2))?;
        }
        Ok(())
    }

    /// The next controller message that is not an ACK/NACK.
    pub fn next_message(&mut self) -> Option<FromController> {
        self.inbox.pop_front()
    }
}

/// Where the probe ended up for one waypoint.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct WaypointOutcome {
    /// Mapped waypoint the controller reported, mm.
    pub mapped: [f32; 3],
    /// Its quality figure, mm.
    pub quality_mm: f32,
    /// The probe's aim point (TCP + standoff along the beam) when the controller moved on.
    pub reached: [f64; 3],
    /// The phantom's true waypoint.
    pub truth: [f64; 3],
    /// |reached − truth|, mm.
    pub error_mm: f64,
}

/// A whole procedure's result.
#[derive(Clone, Debug, Serialize)]
pub struct HilReport {
    /// Per waypoint.
    pub waypoints: Vec<WaypointOutcome>,
    /// Link counters.
    pub link: LinkStats,
    /// Poses and frames the controller applied (its status), then poses and frames sent
    /// (each counted once, however often the link made the host re-send it).
    pub applied: [u64; 4],
    /// Application refusals by code.
    pub refused: Vec<String>,
    /// Lag used, ms.
    pub lag_ms: f64,
    /// Points compounded on the controller.
    pub points: u16,
    /// Wall time of the procedure, s.
    pub wall_s: f64,
    /// The controller's measured costs (zeros in-process).
    pub cost: CostW,
    /// Pose-timeout faults the controller reported.
    pub pose_timeouts: u32,
    /// Setpoints received more than 70 ms into a pose gap (must be 0).
    pub setpoints_in_gap: u32,
}

impl HilReport {
    /// Largest waypoint error, mm.
    pub fn max_error(&self) -> f64 {
        self.waypoints
            .iter()
            .map(|w| w.error_mm)
            .fold(0.0, f64::max)
    }
}

/// The rows of a phantom sweep as wire messages in arrival order (time-sorted).
fn sweep_messages(logs: &sweep::SweepLogs) -> Vec<ToController> {
    let mut events: Vec<(f64, ToController)> = logs
        .poses
        .iter()
        .map(|p| {
            (
                p.t,
                ToController::Pose(PoseW {
                    t_us: (p.t * 1e6).round() as u64,
                    position: p.position.map(|v| v as f32),
                    quat: p.quaternion.map(|v| v as f32),
                }),
            )
        })
        .collect();
    let mut i = 0;
    while i < logs.frames.len() {
        let f = logs.frames[i];
        let mut pixels = heapless::Vec::new();
        while i < logs.frames.len() && logs.frames[i].frame == f.frame {
            let r = logs.frames[i];
            let q = |v: f64| {
                (v * f64::from(PIXEL_SUBDIVISIONS))
                    .round()
                    .clamp(0.0, f64::from(u16::MAX)) as u16
            };
            let _ = pixels.push([q(r.u), q(r.v)]);
            i += 1;
        }
        events.push((
            f.t,
            ToController::Frame(FrameW {
                t_us: (f.t.max(0.0) * 1e6).round() as u64,
                frame: f.frame,
                pixels,
            }),
        ));
    }
    // Stable: a pose and a frame stamped alike arrive pose first.
    events.sort_by(|a, b| a.0.total_cmp(&b.0));
    events.into_iter().map(|(_, m)| m).collect()
}

fn rigid12(r: &Rigid) -> [f32; 12] {
    let m = r.rotation;
    [
        m[(0, 0)],
        m[(0, 1)],
        m[(0, 2)],
        m[(1, 0)],
        m[(1, 1)],
        m[(1, 2)],
        m[(2, 0)],
        m[(2, 1)],
        m[(2, 2)],
        r.translation.x,
        r.translation.y,
        r.translation.z,
    ]
}

/// Extra robot behaviour for tests of the controller's watchdog.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RunOptions {
    /// While executing, the robot stops reporting poses from this many ms after Execute
    /// for the second number of ms.
    pub pose_gap_ms: Option<(u64, u64)>,
    /// The simulated sweep ([`SweepConfig::default`] unless set).
    pub sweep: SweepConfig,
}

impl RunOptions {
    /// A lighter sweep for quick runs on the emulator's slow link: lines 15 mm apart at
    /// 30 mm/s, every 8th column annotated (about a third of the bytes).
    pub fn quick() -> Self {
        RunOptions {
            sweep: SweepConfig {
                line_spacing_mm: 15.0,
                speed_mm_s: 30.0,
                column_step_px: 8,
                ..SweepConfig::default()
            },
            ..RunOptions::default()
        }
    }
}

/// Runs the whole procedure on phantom `phantom` through `session`.
pub fn run<P: Port>(
    session: &mut Session<P>,
    phantom: &PhantomConfig,
    progress: &mut dyn FnMut(&str),
) -> Result<HilReport, CliError> {
    run_with(session, phantom, RunOptions::default(), progress)
}

/// [`run`] with [`RunOptions`].
pub fn run_with<P: Port>(
    session: &mut Session<P>,
    phantom: &PhantomConfig,
    options: RunOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<HilReport, CliError> {
    let t0 = Instant::now();
    let logs = sweep::simulate(phantom, &options.sweep)?;
    let pair = &logs.pair;
    let (tr, vi) = sweep::calibration_samples(&logs.calib_tracker, &logs.calib_video);
    let lag = ribreg_core::acquisition::temporal::calibrate(&tr, &vi)?;
    progress(&format!(
        "temporal calibration: lag {:.1} ms",
        lag.lag_s * 1e3
    ));

    // Template: compact parts of the improved method's template.
    let labels: Vec<u8> = pair.template.labels.iter().map(|&l| l as u8).collect();
    let ct = to_core(&pair.template.points, ribreg_core::error::Cloud::Template)?;
    let tpl = build_template(&ct, Some(&labels), Method::Improved, &mut |_| {})?;
    let cal = logs.calibration;

    let timeout = Duration::from_secs(120);
    session.send(&ToController::Hello {
        magic: MAGIC,
        version: VERSION,
    })?;
    session.flush(timeout)?;
    session.send(&ToController::Configure(Configure {
        probe: cal.probe,
        tcp_t_us: rigid12(&cal.tcp_t_us),
        ee_t_tcp: rigid12(&cal.ee_t_tcp),
        lag_us: (lag.lag_s * 1e6).round() as i32,
        voxel_mm: CONTROLLER_VOXEL_MM,
        max_speed_mm_s: MAX_SPEED_MM_S,
        max_accel_mm_s2: MAX_ACCEL_MM_S2,
        standoff_mm: STANDOFF_MM,
    }))?;
    let nodes: Vec<Node> = tpl
        .graph
        .som1
        .iter()
        .zip(&tpl.node_labels)
        .map(|(p, l)| Node {
            p: (*p).into(),
            label: *l,
        })
        .collect();
    for (k, chunk) in nodes.chunks(NODES_PER_CHUNK).enumerate() {
        session.send(&ToController::TemplateNodes {
            offset: (k * NODES_PER_CHUNK) as u16,
            total: nodes.len() as u16,
            nodes: chunk.iter().copied().collect(),
        })?;
    }
    let f = tpl.graph.frame;
    let mut skeleton = [[0.0f32; 3]; 30];
    for (o, p) in skeleton.iter_mut().zip(&tpl.skeleton.points) {
        *o = (*p).into();
    }
    session.send(&ToController::TemplateShape(TemplateShape {
        origin: f.origin.into(),
        axes: std::array::from_fn(|i| f.axes[(i / 3, i % 3)]),
        spread: f.spread.into(),
        skeleton,
        midline_fraction: tpl.midline_fraction,
    }))?;
    let wps: Vec<[f32; 3]> = pair
        .template_waypoints
        .iter()
        .map(|p| p.map(|v| v as f32))
        .collect();
    for (k, chunk) in wps.chunks(WAYPOINTS_PER_CHUNK).enumerate() {
        session.send(&ToController::Waypoints {
            offset: (k * WAYPOINTS_PER_CHUNK) as u8,
            total: wps.len() as u8,
            points: chunk.iter().copied().collect(),
        })?;
    }
    session.flush(timeout)?;
    progress(&format!(
        "template uploaded: {} nodes, {} waypoints",
        nodes.len(),
        wps.len()
    ));

    // Sweep.
    session.send(&ToController::Command(Command::StartSweep))?;
    let msgs = sweep_messages(&logs);
    let (n_poses, n_frames) = msgs.iter().fold((0u64, 0u64), |(p, f), m| match m {
        ToController::Pose(_) => (p + 1, f),
        _ => (p, f + 1),
    });
    let mut last_t = 0u64;
    for (i, m) in msgs.iter().enumerate() {
        if let ToController::Pose(p) = m {
            if p.t_us >= last_t + 10_000 {
                session
                    .port
                    .advance(p.t_us.saturating_sub(last_t).min(10_000));
                last_t = p.t_us;
            }
        }
        session.send(m)?;
        session.pump(Duration::ZERO)?;
        if i % 20_000 == 0 {
            progress(&format!("sweep: {i} of {} messages", msgs.len()));
        }
    }
    session.send(&ToController::Command(Command::EndSweep))?;
    session.flush(timeout)?;
    let last_pose = logs.poses.last().map(|p| p.t).unwrap_or(0.0);

    // Register: the robot stands still and keeps reporting its pose.
    let standing = logs.poses.last().map(|p| (p.position, p.quaternion));
    let mut robot_t_us = (last_pose * 1e6) as u64 + 10_000;
    let mut flange = match standing {
        Some((p, q)) => {
            TrackedPose::new(0.0, Vec3::from(p.map(|v| v as f32)), q.map(|v| v as f32))?.to_rigid()
        }
        None => Rigid::identity(),
    };
    let mut poses_sent = n_poses;
    let mut send_pose =
        |session: &mut Session<P>, t_us: u64, flange: &Rigid| -> Result<(), CliError> {
            poses_sent += 1;
            let q = TrackedPose::from_rigid(0.0, flange)
                .orientation
                .into_inner();
            session.send(&ToController::Pose(PoseW {
                t_us,
                position: flange.translation.into(),
                quat: [q.w, q.i, q.j, q.k],
            }))?;
            Ok(())
        };
    session.send(&ToController::Command(Command::Register))?;
    let mut mapped: Vec<WaypointW> = Vec::new();
    let reg_start = Instant::now();
    while mapped.len() < wps.len() {
        if reg_start.elapsed() > timeout {
            return Err(CliError::Usage(
                "registration did not finish in time".into(),
            ));
        }
        send_pose(session, robot_t_us, &flange)?;
        robot_t_us += 10_000;
        session.port.advance(10_000);
        session.pump(Duration::from_millis(2))?;
        while let Some(m) = session.next_message() {
            match m {
                FromController::Waypoint(w) => mapped.push(w),
                FromController::Fault(f) => {
                    return Err(CliError::Usage(format!("controller fault: {f:?}")))
                }
                _ => {}
            }
        }
    }
    mapped.sort_by_key(|w| w.index);
    progress(&format!("registered: {} waypoints mapped", mapped.len()));

    // Execute.
    session.send(&ToController::Command(Command::Execute))?;
    let ee_t_tcp = cal.ee_t_tcp;
    let tcp_t_ee = ee_t_tcp.inverse();
    let mut tcp = flange.after(&ee_t_tcp);
    let mut current: Option<u8> = None;
    let mut reached: Vec<Option<Rigid>> = vec![None; wps.len()];
    let exec_start = Instant::now();
    let mut last_report = Instant::now();
    let alpha = 1.0 - (-0.01 / ROBOT_LAG_S).exp();
    let mut done = false;
    let mut quiet_ticks = 0;
    let mut exec_ms = 0u64;
    let (mut pose_timeouts, mut setpoints_in_gap) = (0u32, 0u32);
    while !done {
        if exec_start.elapsed() > timeout {
            return Err(CliError::Usage("execution did not finish in time".into()));
        }
        let tick = if session.port.simulated_clock() {
            10_000
        } else {
            2_000
        };
        session.port.advance(tick);
        session.pump(Duration::from_millis(2))?;
        // The robot answers every setpoint: it moves 10 ms toward it, then reports (so its
        // pose stream follows the controller's clock, emulated or not).
        let mut setpoints = Vec::new();
        while let Some(m) = session.next_message() {
            match m {
                FromController::Setpoint(sp) => setpoints.push(sp),
                FromController::Status(s) if s.state == State::Done => done = true,
                FromController::Fault(wire::Fault::PoseTimeout) => {
                    pose_timeouts += 1;
                    progress("controller: robot poses stopped, setpoints stopped");
                }
                FromController::Fault(f) => progress(&format!("controller fault: {f:?}")),
                _ => {}
            }
        }
        if session.port.simulated_clock() && setpoints.is_empty() {
            // In-process the robot's clock is the controller's: it keeps reporting.
            exec_ms += 10;
        }
        for sp in &setpoints {
            exec_ms += 10;
            if options
                .pose_gap_ms
                .is_some_and(|(from, len)| exec_ms > from + 70 && exec_ms <= from + len)
            {
                setpoints_in_gap += 1;
            }
            let target = TrackedPose::new(0.0, Vec3::from(sp.position), sp.quat)?.to_rigid();
            if current.is_some_and(|c| c != sp.waypoint) {
                if let Some(c) = current {
                    reached[usize::from(c)] = Some(tcp);
                }
            }
            current = Some(sp.waypoint);
            let q0 = TrackedPose::from_rigid(0.0, &tcp);
            let q1 = TrackedPose::from_rigid(1.0, &target);
            tcp = q0.interpolate(&q1, alpha);
        }
        let in_gap = options
            .pose_gap_ms
            .is_some_and(|(from, len)| exec_ms >= from && exec_ms < from + len);
        // Besides answering setpoints, a real robot reports at 100 Hz of its own clock
        // whatever happens: after a watchdog stop, that is what lets setpoints resume.
        let due = if session.port.simulated_clock() {
            true
        } else {
            last_report.elapsed() >= Duration::from_millis(10)
        };
        if !setpoints.is_empty() || (due && !in_gap) {
            if !in_gap {
                flange = tcp.after(&tcp_t_ee);
                send_pose(session, robot_t_us, &flange)?;
                last_report = Instant::now();
            }
            robot_t_us += 10_000;
        }
        quiet_ticks = if !setpoints.is_empty() || in_gap {
            0
        } else {
            quiet_ticks + 1
        };
        if quiet_ticks > 50 {
            session.send(&ToController::Command(Command::Status))?;
            quiet_ticks = 0;
        }
    }
    if let Some(c) = current {
        reached[usize::from(c)].get_or_insert(tcp);
    }
    session.send(&ToController::Command(Command::Status))?;
    session.send(&ToController::Command(Command::Cost))?;
    session.flush(timeout)?;
    let (mut status, mut cost) = (None, None);
    for _ in 0..400 {
        session.port.advance(1000);
        session.pump(Duration::from_millis(5))?;
        while let Some(m) = session.next_message() {
            match m {
                FromController::Status(s) => status = Some(s),
                FromController::Cost(c) => cost = Some(c),
                _ => {}
            }
        }
        if status.is_some() && cost.is_some() {
            break;
        }
    }
    let status = status.ok_or_else(|| CliError::Usage("no final status".into()))?;

    let waypoints = mapped
        .iter()
        .zip(&reached)
        .zip(&pair.true_waypoints)
        .map(|((m, r), truth)| {
            let aim = r.map_or([f64::NAN; 3], |t| {
                let p = t.translation + t.rotation.column(2) * STANDOFF_MM;
                [f64::from(p.x), f64::from(p.y), f64::from(p.z)]
            });
            let e = ((aim[0] - truth[0]).powi(2)
                + (aim[1] - truth[1]).powi(2)
                + (aim[2] - truth[2]).powi(2))
            .sqrt();
            WaypointOutcome {
                mapped: m.position,
                quality_mm: m.quality_mm,
                reached: aim,
                truth: *truth,
                error_mm: e,
            }
        })
        .collect();
    Ok(HilReport {
        waypoints,
        link: session.stats,
        applied: [
            u64::from(status.poses),
            u64::from(status.frames_placed) + u64::from(status.frames_refused),
            poses_sent,
            n_frames,
        ],
        refused: session
            .refused
            .iter()
            .map(|(s, c)| format!("{s}: {c:?}"))
            .collect(),
        lag_ms: lag.lag_s * 1e3,
        points: status.points,
        wall_s: t0.elapsed().as_secs_f64(),
        pose_timeouts,
        setpoints_in_gap,
        cost: cost.unwrap_or_default(),
    })
}
