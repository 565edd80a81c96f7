//! The procedure the robot PC runs against the controller — upload, sweep, register,
//! execute — and its [`HilReport`]; [`run_emulated`] runs it against the firmware under
//! QEMU and then in this process for comparison; [`Budgets`] holds the emulated
//! controller's costs to its instruction and stack budgets.

use ribreg_core::controller::CONTROLLER_VOXEL_MM;
use ribreg_core::math::geom::Rigid;
use ribreg_core::wire::{
    self, Command, Configure, CostW, FromController, Node, RegistrationW, State, TemplateShape,
    ToController, WaypointW, MAGIC, NODES_PER_CHUNK, VERSION, WAYPOINTS_PER_CHUNK,
};
use serde::Serialize;
use std::io::Write;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use super::emulator::{self, Board, QemuError};
use super::port::{InProcess, Port, Stream};
use super::robot::{self, aim_point, Robot, STANDOFF_MM};
use super::session::{LinkStats, Session};
use super::FaultInjector;
use super::Faults;
use crate::error::CliError;
use crate::phantom::PhantomConfig;
use crate::register::{build_template, to_core, Method};
use crate::sweep::{self, SweepConfig};

/// Setpoint speed limit sent in the configuration, mm/s.
pub const MAX_SPEED_MM_S: f32 = 50.0;
/// Acceleration limit, mm/s².
pub const MAX_ACCEL_MM_S2: f32 = 200.0;
/// Clinical tolerance for a probe placed between ribs, mm.
pub const TOLERANCE_MM: f64 = 5.0;

/// Where the probe ended up for one waypoint.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct WaypointOutcome {
    /// Mapped waypoint the controller reported, mm.
    pub mapped: [f32; 3],
    /// Its quality figure, mm.
    pub quality_mm: f32,
    /// Whether the sweep reaches it (`WaypointW::supported`): `false` only in a partial
    /// plan, and then the probe is not driven there (its aim point and errors are NaN).
    pub supported: bool,
    /// The probe's aim point (TCP + standoff along the beam) when the controller moved on.
    pub reached: [f64; 3],
    /// The phantom's true waypoint.
    pub truth: [f64; 3],
    /// |reached − truth|, mm.
    pub error_mm: f64,
    /// The component of `reached − truth` across the gap toward a rib (signed, toward the
    /// lower rib positive; [`crate::phantom::Gap::split`]), mm.
    pub across_gap_mm: f64,
    /// How far the aim point stays from the outline of the cartilage it moved toward, mm
    /// (negative: over it).
    pub clearance_mm: f64,
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
    /// How clearly the controller's registration found the patient (pose hypotheses'
    /// residuals, least rib-side coverage), as it reported before the waypoints.
    pub confidence: Option<RegistrationW>,
    /// Pose-timeout faults the controller reported.
    pub pose_timeouts: u32,
    /// Setpoints received more than 70 ms into a pose gap (must be 0).
    pub setpoints_in_gap: u32,
}

impl HilReport {
    /// The waypoints the probe was driven to (every one but those a partial plan marks
    /// as not reached by the sweep).
    pub fn driven(&self) -> impl Iterator<Item = &WaypointOutcome> {
        self.waypoints.iter().filter(|w| w.supported)
    }

    /// Largest waypoint error of those driven to, mm.
    pub fn max_error(&self) -> f64 {
        self.driven().map(|w| w.error_mm).fold(0.0, f64::max)
    }

    /// Largest waypoint error across the gap (unsigned), mm.
    pub fn max_across_gap(&self) -> f64 {
        self.driven()
            .map(|w| w.across_gap_mm.abs())
            .fold(0.0, f64::max)
    }

    /// Least clearance to a cartilage's outline, mm.
    pub fn least_clearance(&self) -> f64 {
        self.driven()
            .map(|w| w.clearance_mm)
            .fold(f64::INFINITY, f64::min)
    }
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

/// Extra robot behaviour for tests of the controller's watchdog, the sweep, and what
/// the robot PC configures.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RunOptions {
    /// The orientation prior the robot PC configures (`Configure::target_up`: the
    /// patient's anterior in the robot base frame); none unless set.
    pub target_up: Option<[f32; 3]>,
    /// Configure a partial plan (`Configure::partial`): the controller maps every
    /// waypoint, marks those the sweep does not reach and drives to the others only.
    pub partial: bool,
    /// Planned points appended to the phantom's plan (template frame, mm): for tests of
    /// what the controller does with a waypoint the sweep cannot reach. They have no
    /// truth: the report leaves them out.
    pub extra_waypoints: Vec<[f32; 3]>,
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

/// What the robot PC prepares before a procedure: the simulated sweep, the lag its
/// temporal calibration measured, and the upload that follows the handshake.
pub struct Prepared {
    /// The simulated sweep and its phantom (truth waypoints in `logs.pair`).
    pub logs: sweep::SweepLogs,
    /// Video lag behind the tracker, s.
    pub lag_s: f64,
    /// In upload order: the configuration, the template's node chunks, its shape and
    /// the planned waypoints' chunks.
    pub upload: Vec<ToController>,
    /// Template nodes uploaded.
    pub nodes: usize,
    /// Waypoints uploaded.
    pub waypoints: usize,
}

/// Simulates the sweep `sweep_cfg` of `phantom`, calibrates its lag and builds the
/// upload [`run_with`] sends after the handshake (the improved method's template).
pub fn prepare(phantom: &PhantomConfig, sweep_cfg: &SweepConfig) -> Result<Prepared, CliError> {
    let logs = sweep::simulate(phantom, sweep_cfg)?;
    let pair = &logs.pair;
    let (tr, vi) = sweep::calibration_samples(&logs.calib_tracker, &logs.calib_video);
    let lag = ribreg_core::acquisition::temporal::calibrate(&tr, &vi)?;

    // Template: compact parts of the improved method's template.
    let labels: Vec<u8> = pair.template.labels.iter().map(|&l| l as u8).collect();
    let ct = to_core(&pair.template.points, ribreg_core::error::Cloud::Template)?;
    let tpl = build_template(&ct, Some(&labels), Method::Improved, &mut |_| {})?;
    let cal = logs.calibration;

    let mut upload = vec![ToController::Configure(Configure {
        probe: cal.probe,
        tcp_t_us: rigid12(&cal.tcp_t_us),
        ee_t_tcp: rigid12(&cal.ee_t_tcp),
        lag_us: (lag.lag_s * 1e6).round() as i32,
        voxel_mm: CONTROLLER_VOXEL_MM,
        max_speed_mm_s: MAX_SPEED_MM_S,
        max_accel_mm_s2: MAX_ACCEL_MM_S2,
        standoff_mm: STANDOFF_MM,
        // No orientation prior: the controller finds the pose from any robot set-up.
        target_up: [0.0; 3],
        // A whole plan or none: the controller refuses a waypoint the sweep misses.
        partial: false,
    })];
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
        upload.push(ToController::TemplateNodes {
            offset: (k * NODES_PER_CHUNK) as u16,
            total: nodes.len() as u16,
            nodes: chunk.iter().copied().collect(),
        });
    }
    let f = tpl.graph.frame;
    let mut skeleton = [[0.0f32; 3]; 30];
    for (o, p) in skeleton.iter_mut().zip(&tpl.skeleton.points) {
        *o = (*p).into();
    }
    upload.push(ToController::TemplateShape(TemplateShape {
        origin: f.origin.into(),
        axes: std::array::from_fn(|i| f.axes[(i / 3, i % 3)]),
        spread: f.spread.into(),
        skeleton,
        midline_fraction: tpl.midline_fraction,
    }));
    let wps: Vec<[f32; 3]> = pair
        .template_waypoints
        .iter()
        .map(|p| p.map(|v| v as f32))
        .collect();
    upload.extend(waypoint_chunks(&wps));
    Ok(Prepared {
        lag_s: lag.lag_s,
        upload,
        nodes: nodes.len(),
        waypoints: wps.len(),
        logs,
    })
}

/// The upload of a plan: chunks of [`WAYPOINTS_PER_CHUNK`].
fn waypoint_chunks(wps: &[[f32; 3]]) -> Vec<ToController> {
    wps.chunks(WAYPOINTS_PER_CHUNK)
        .enumerate()
        .map(|(k, chunk)| ToController::Waypoints {
            offset: (k * WAYPOINTS_PER_CHUNK) as u8,
            total: wps.len() as u8,
            points: chunk.iter().copied().collect(),
        })
        .collect()
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
    let prepared = prepare(phantom, &options.sweep)?;
    progress(&format!(
        "temporal calibration: lag {:.1} ms",
        prepared.lag_s * 1e3
    ));
    let Prepared {
        logs,
        lag_s,
        mut upload,
        nodes,
        waypoints: mut n_waypoints,
    } = prepared;
    if !options.extra_waypoints.is_empty() {
        let mut wps: Vec<[f32; 3]> = Vec::new();
        upload.retain(|m| match m {
            ToController::Waypoints { points, .. } => {
                wps.extend(points.iter().copied());
                false
            }
            _ => true,
        });
        wps.extend(options.extra_waypoints.iter().copied());
        n_waypoints = wps.len();
        upload.extend(waypoint_chunks(&wps));
    }
    if let Some(ToController::Configure(c)) = upload.first_mut() {
        if let Some(up) = options.target_up {
            c.target_up = up;
        }
        c.partial = options.partial;
    }
    let pair = &logs.pair;
    let cal = logs.calibration;

    let timeout = Duration::from_secs(120);
    session.send(&ToController::Hello {
        magic: MAGIC,
        version: VERSION,
    })?;
    session.flush(timeout)?;
    for m in &upload {
        session.send(m)?;
    }
    session.flush(timeout)?;
    progress(&format!(
        "template uploaded: {nodes} nodes, {n_waypoints} waypoints"
    ));

    // Sweep.
    session.send(&ToController::Command(Command::StartSweep))?;
    let msgs = robot::sweep_messages(&logs);
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
    let mut robot = Robot::standing(standing, cal.ee_t_tcp)?;
    let mut poses_sent = n_poses;
    let mut send_pose =
        |session: &mut Session<P>, t_us: u64, robot: &Robot| -> Result<(), CliError> {
            poses_sent += 1;
            session.send(&robot.pose(t_us))?;
            Ok(())
        };
    session.send(&ToController::Command(Command::Register))?;
    let mut mapped: Vec<WaypointW> = Vec::new();
    let mut confidence = None;
    let reg_start = Instant::now();
    while mapped.len() < n_waypoints {
        if reg_start.elapsed() > timeout {
            return Err(CliError::Link("registration did not finish in time".into()));
        }
        send_pose(session, robot_t_us, &robot)?;
        robot_t_us += 10_000;
        session.port.advance(10_000);
        session.pump(Duration::from_millis(2))?;
        while let Some(m) = session.next_message() {
            match m {
                FromController::Waypoint(w) => mapped.push(w),
                FromController::Registration(c) => confidence = Some(c),
                FromController::Fault(f) => {
                    return Err(CliError::Link(format!("controller fault: {f}")))
                }
                _ => {}
            }
        }
    }
    mapped.sort_by_key(|w| w.index);
    match confidence {
        Some(c) => progress(&format!(
            "registered: {} waypoints mapped; pose residual {:.2} mm (runner-up {:.2} mm, {} \
             hypotheses), template support {:.2} mm, least rib-side coverage {} %, imaged \
             {:.1} mm past the nearest rib end",
            mapped.len(),
            c.residual_mm,
            c.runner_up_mm,
            c.hypotheses,
            c.support_mm,
            c.min_side_span_percent,
            c.min_edge_clearance_mm
        )),
        None => progress(&format!("registered: {} waypoints mapped", mapped.len())),
    }

    // Execute.
    session.send(&ToController::Command(Command::Execute))?;
    robot.start_executing();
    let mut current: Option<u8> = None;
    let mut reached: Vec<Option<Rigid>> = vec![None; n_waypoints];
    let exec_start = Instant::now();
    let mut last_report = Instant::now();
    let mut done = false;
    let mut quiet_ticks = 0;
    let mut exec_ms = 0u64;
    let (mut pose_timeouts, mut setpoints_in_gap) = (0u32, 0u32);
    // The robot sends nothing the controller should refuse: a refused pose report stops
    // the setpoints for good (the watchdog sees no pose), so say which at once rather
    // than wait for the timeout.
    let refused_before = session.refused.len();
    while !done {
        if let Some((seq, code)) = session.refused.get(refused_before) {
            return Err(CliError::Link(format!(
                "the controller refused message {seq} while executing: {code}"
            )));
        }
        if exec_start.elapsed() > timeout {
            return Err(CliError::Link("execution did not finish in time".into()));
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
                FromController::Fault(f) => progress(&format!("controller fault: {f}")),
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
            if current.is_some_and(|c| c != sp.waypoint) {
                if let Some(c) = current {
                    reached[usize::from(c)] = Some(robot.tcp());
                }
            }
            current = Some(sp.waypoint);
            robot.follow(sp)?;
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
                robot.update_flange();
                send_pose(session, robot_t_us, &robot)?;
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
        reached[usize::from(c)].get_or_insert(robot.tcp());
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
    let status = status.ok_or_else(|| CliError::Link("no final status".into()))?;

    let waypoints = mapped
        .iter()
        .zip(&reached)
        .zip(&pair.true_waypoints)
        .zip(pair.true_gaps())
        .map(|(((m, r), truth), gap)| {
            let aim = r.map_or([f64::NAN; 3], |t| aim_point(&t));
            let d = [aim[0] - truth[0], aim[1] - truth[1], aim[2] - truth[2]];
            let (across_gap_mm, clearance_mm) = gap.split(d);
            WaypointOutcome {
                mapped: m.position,
                quality_mm: m.quality_mm,
                supported: m.supported,
                reached: aim,
                truth: *truth,
                error_mm: (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt(),
                across_gap_mm,
                clearance_mm,
            }
        })
        .collect();
    Ok(HilReport {
        waypoints,
        link: session.link_stats(),
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
        lag_ms: lag_s * 1e3,
        points: status.points,
        wall_s: t0.elapsed().as_secs_f64(),
        pose_timeouts,
        setpoints_in_gap,
        cost: cost.unwrap_or_default(),
        confidence,
    })
}

/// Budget of one control-loop turn on the emulated Cortex-M4F: 1 ms at 168 MHz, so no
/// turn holds up the 100 Hz pose stream or the 1 ms setpoint clock (README, "Goals").
pub const TURN_BUDGET_INSTRUCTIONS: u32 = 168_000;
/// Budget of a whole registration: 150 M instructions (under a second at 168 MHz).
pub const REGISTRATION_BUDGET_INSTRUCTIONS: u64 = 150_000_000;
/// Stack the firmware must leave untouched at its peak, bytes: the margin for what the
/// measurement misses (the high-water mark is sampled every 256 turns) and for
/// interrupt frames.
pub const STACK_HEADROOM_BYTES: u32 = 2048;

/// The emulated controller's costs against the budgets above; `stack_size_bytes` is the
/// firmware's stack region (what it logs at boot, from the same linker symbols).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Budgets {
    /// Worst control-loop turn, instructions.
    pub worst_turn: u32,
    /// Instructions of the registration.
    pub registration: u64,
    /// Peak stack use, bytes.
    pub peak_stack_bytes: u32,
    /// The stack region, bytes.
    pub stack_size_bytes: u32,
}

impl Budgets {
    /// The figures of `cost` against a stack of `stack_size_bytes`.
    pub fn new(cost: &CostW, stack_size_bytes: u32) -> Self {
        Budgets {
            worst_turn: cost.worst_call_instructions,
            registration: cost.registration_instructions,
            peak_stack_bytes: cost.peak_stack_bytes,
            stack_size_bytes,
        }
    }

    /// Stack never used, bytes.
    pub fn stack_left_bytes(&self) -> u32 {
        self.stack_size_bytes.saturating_sub(self.peak_stack_bytes)
    }

    /// The measured figures next to their budgets, one line.
    pub fn summary(&self) -> String {
        format!(
            "budgets: worst turn {} of {} instructions; registration {} of {} instructions; \
             stack {} of {} B used, {} B left (at least {})",
            thousands(u64::from(self.worst_turn)),
            thousands(u64::from(TURN_BUDGET_INSTRUCTIONS)),
            thousands(self.registration),
            thousands(REGISTRATION_BUDGET_INSTRUCTIONS),
            thousands(u64::from(self.peak_stack_bytes)),
            thousands(u64::from(self.stack_size_bytes)),
            thousands(u64::from(self.stack_left_bytes())),
            thousands(u64::from(STACK_HEADROOM_BYTES)),
        )
    }

    /// `Err` ([`CliError::Tolerance`]) naming every budget exceeded.
    pub fn check(&self) -> Result<(), CliError> {
        let mut over = Vec::new();
        if self.worst_turn > TURN_BUDGET_INSTRUCTIONS {
            over.push(format!(
                "worst control-loop turn {} instructions exceeds its budget of {}",
                thousands(u64::from(self.worst_turn)),
                thousands(u64::from(TURN_BUDGET_INSTRUCTIONS))
            ));
        }
        if self.registration > REGISTRATION_BUDGET_INSTRUCTIONS {
            over.push(format!(
                "registration {} instructions exceeds its budget of {}",
                thousands(self.registration),
                thousands(REGISTRATION_BUDGET_INSTRUCTIONS)
            ));
        }
        if self.stack_left_bytes() < STACK_HEADROOM_BYTES {
            over.push(format!(
                "peak stack {} of {} B leaves {} B, less than {}",
                thousands(u64::from(self.peak_stack_bytes)),
                thousands(u64::from(self.stack_size_bytes)),
                thousands(u64::from(self.stack_left_bytes())),
                thousands(u64::from(STACK_HEADROOM_BYTES))
            ));
        }
        if over.is_empty() {
            Ok(())
        } else {
            Err(CliError::Tolerance(format!(
                "the emulated controller is over budget: {}",
                over.join("; ")
            )))
        }
    }
}

/// `1234567` → `1,234,567`.
pub fn thousands(n: u64) -> String {
    let digits = n.to_string();
    let mut out = String::new();
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

/// The procedure against the emulated controller, and the same in-process.
pub struct Emulated {
    /// The board emulated.
    pub board: Board,
    /// Against the firmware under QEMU (its costs filled in).
    pub report: HilReport,
    /// The same procedure in-process, fault-free.
    pub reference: HilReport,
    /// The firmware's costs against the budgets.
    pub budgets: Budgets,
}

impl Emulated {
    /// Largest difference of a mapped waypoint coordinate, emulated vs in-process, mm.
    pub fn mapped_difference(&self) -> f32 {
        self.report
            .waypoints
            .iter()
            .zip(&self.reference.waypoints)
            .flat_map(|(a, b)| (0..3).map(move |i| (a.mapped[i] - b.mapped[i]).abs()))
            .fold(0.0f32, f32::max)
    }
}

/// How [`run_emulated`] runs QEMU: `-icount shift=0,sleep=on`, QEMU's stdout (the
/// defmt log) also written to `defmt_log` if set.
pub fn emulator_options(defmt_log: Option<PathBuf>) -> emulator::Options {
    board_emulator_options(Board::default(), defmt_log)
}

/// [`emulator_options`] for `board`'s machine.
pub fn board_emulator_options(board: Board, defmt_log: Option<PathBuf>) -> emulator::Options {
    emulator::Options {
        icount: Some(emulator::Icount {
            shift: 0,
            sleep: true,
        }),
        semihosting_log: defmt_log,
        ..board.options()
    }
}

/// The procedure against the firmware built for `board` under QEMU
/// (`-icount shift=0,sleep=on`: SysTick counts instructions while the firmware works, at
/// the instructions per tick the firmware calibrated at boot), ended by `QUIT`, then the
/// same in-process for comparison. `faults`: probabilities and seed of link faults.
pub fn run_emulated(
    board: Board,
    faults: Option<(Faults, u64)>,
    options: &RunOptions,
    defmt_log: Option<PathBuf>,
    phantom: &PhantomConfig,
    progress: &mut dyn FnMut(&str),
) -> Result<Emulated, CliError> {
    progress(&format!("building the firmware for {board}"));
    let elf = emulator::firmware_elf_for(board)?;
    let stack_size_bytes = emulator::stack_size_bytes(&elf)?;
    let mut emu = emulator::Emulator::start(&elf, &board_emulator_options(board, defmt_log))?;
    progress(&format!("emulator up ({})", emu.args().join(" ")));
    let stream = emu.serial().try_clone().map_err(|source| QemuError::Io {
        context: "emulator serial port".into(),
        source,
    })?;
    let port = Stream::new(stream);
    let result = match faults {
        Some((f, seed)) => run_with(
            &mut Session::new(FaultInjector::new(port, f, seed)),
            phantom,
            options.clone(),
            progress,
        ),
        None => run_with(&mut Session::new(port), phantom, options.clone(), progress),
    };
    let report = match result {
        Ok(r) => r,
        Err(e) => {
            let status = emu.wait(Duration::from_secs(2));
            let stderr = emu.stderr_output().trim().to_owned();
            let status_text = format!("{status:?}");
            return Err(match (status, e) {
                // QEMU still runs: the link or the procedure failed, not the emulator.
                (Err(_), CliError::Link(s)) => {
                    CliError::Link(format!("{s}; the emulator: {status_text}, {stderr}"))
                }
                (_, e) => CliError::Emulator(QemuError::Failed {
                    during: e.to_string(),
                    status: status_text,
                    stderr,
                }),
            });
        }
    };
    // Past any fault injector: the session is done.
    emu.serial()
        .write_all(b"QUIT\0")
        .map_err(|e| CliError::Link(format!("link: cannot write: {e}")))?;
    let status = emu.wait(Duration::from_secs(30))?;
    if !status.success() {
        return Err(CliError::Emulator(QemuError::Unclean {
            status,
            stderr: emu.stderr_output().trim().to_owned(),
        }));
    }
    progress("the same procedure in-process, for comparison");
    let mut local = Session::new(InProcess::new());
    let reference = run_with(&mut local, phantom, options.clone(), &mut |_| {})?;
    Ok(Emulated {
        board,
        budgets: Budgets::new(&report.cost, stack_size_bytes),
        report,
        reference,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cost(worst_turn: u32, registration: u64, peak_stack: u32) -> CostW {
        CostW {
            registration_instructions: registration,
            registration_calls: 1959,
            worst_call_instructions: worst_turn,
            worst_step_instructions: 138_600,
            worst_receive_instructions: 101_100,
            peak_stack_bytes: peak_stack,
            serial_overruns: 0,
            serial_framing_errors: 0,
            serial_dropped_bytes: 0,
        }
    }

    const STACK: u32 = 60_000;

    #[test]
    fn a_run_within_every_budget_passes() {
        let b = Budgets::new(&cost(139_012, 127_698_400, 42_212), STACK);
        assert_eq!(b.check().map_err(|e| e.to_string()), Ok(()));
        assert!(
            b.summary()
                .contains("worst turn 139,012 of 168,000 instructions"),
            "{}",
            b.summary()
        );
        // At the limits exactly still passes.
        let edge = Budgets::new(
            &cost(
                TURN_BUDGET_INSTRUCTIONS,
                REGISTRATION_BUDGET_INSTRUCTIONS,
                STACK - STACK_HEADROOM_BYTES,
            ),
            STACK,
        );
        assert!(edge.check().is_ok());
    }

    #[test]
    fn a_run_over_any_budget_fails_with_a_tolerance_error() {
        let over = [
            (
                cost(168_001, 127_698_400, 42_212),
                "worst control-loop turn 168,001",
            ),
            (
                cost(139_012, 150_000_001, 42_212),
                "registration 150,000,001",
            ),
            (cost(139_012, 127_698_400, STACK - 2047), "leaves 2,047 B"),
            (cost(139_012, 127_698_400, STACK + 10), "leaves 0 B"),
        ];
        for (c, says) in over {
            let err = Budgets::new(&c, STACK).check().expect_err(says);
            assert!(matches!(err, CliError::Tolerance(_)), "{err:?}");
            assert!(err.to_string().contains(says), "{err}");
        }
    }

    #[test]
    fn thousands_separators() {
        assert_eq!(thousands(0), "0");
        assert_eq!(thousands(999), "999");
        assert_eq!(thousands(2048), "2,048");
        assert_eq!(thousands(150_000_000), "150,000,000");
    }
}
