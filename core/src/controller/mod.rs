//! The probe-positioning controller: the state machine the firmware runs, host-testable.
//!
//! ```text
//! Idle ──(Configure + template + waypoints)──▶ TemplateLoaded ──StartSweep──▶ Sweeping
//!   ▲                                            ▲      │                      │ EndSweep
//!   │                                            │      └──────Register◀───────┘ (cloud kept)
//!   │ Abort (from anywhere: back to             │              ▼
//!   │ TemplateLoaded, or Idle without a          │         Registering ──(bounded steps)──▶ Ready
//!   │ template)                                  └──── Done ◀── Executing ◀──Execute──────┘
//! ```
//!
//! * **Link**: [`Controller::receive`] takes one decoded-or-failed frame; every host
//!   message is sequenced (see [`crate::wire`]): the expected one is applied and ACKed,
//!   a duplicate gets its first reply again and is not re-applied, a skipped number or a
//!   corrupt frame is NACKed with the number expected. A message received intact but
//!   refused (wrong state, bad content) is NACKed with its own number and
//!   [`NackCode::BadState`] / [`NackCode::Invalid`]: it counts as handled, the host must
//!   not re-send it.
//! * **Sweep**: poses and frames go into a [`Compounder`] (lag-corrected poses); a frame
//!   message only places its points in a queue, [`Controller::poll`] moves them into the
//!   voxel cloud ([`SWEEP_WORK_PER_POLL`] a call).
//! * **Registration** runs in [`Controller::poll`] in bounded steps — the last queued
//!   sweep points, the voxel centroids ([`VOXELS_FINISHED_PER_POLL`] a call), then
//!   [`SOM_ITERATIONS_PER_POLL`] units of registration work a call (see [`Registering`]),
//!   then each waypoint's transform (widening, fit) and probe pose in calls of their own —
//!   so pose handling between calls is never starved (on the emulated Cortex-M4F no call
//!   exceeds 139 k instructions, README); the mapped waypoints become probe
//!   targets (on the skin side of the local bone surface, beam
//!   along its inward normal, footprint along the gap) and are reported with a quality
//!   figure (the local rigid fit's RMS residual).
//! * **Execution**: setpoints every [`SETPOINT_PERIOD_US`] along straight segments with
//!   a trapezoidal speed profile (configured speed and acceleration limits), a dwell of
//!   [`DWELL_US`] at each target; if no robot pose arrived for more than
//!   [`POSE_TIMEOUT_US`], setpoints stop and [`crate::wire::Fault::PoseTimeout`] is reported once; they
//!   resume, from where they stopped, when poses do.
//!
//! Time is the caller's monotonic clock in µs (`now_us`). Nothing allocates or panics on
//! input; replies wait in a bounded outbox ([`Controller::next_reply`]).
//!
//! # Layout
//! * this module: the [`Controller`], its state machine ([`Controller::receive`] applies
//!   a message, [`Controller::poll`] does the periodic work), the sweep and the
//!   registration in bounded steps;
//! * `link`: sequence numbers, ACK/NACK, duplicates, the recent replies, the outbox;
//! * `motion`: segments, the trapezoid profile, interpolation, setpoint streaming, the
//!   pose watchdog;
//! * `target`: probe targets ([`probe_pose`], [`PATCH_RADIUS_MM`], the standoff).
//!
//! Everything public is re-exported here: the paths are `ribreg_core::controller::X`.

mod link;
mod motion;
mod target;

pub use self::motion::{DWELL_US, POSE_TIMEOUT_US, SETPOINT_PERIOD_US};
pub use self::target::{probe_pose, ProbeTarget, PATCH_RADIUS_MM};

use self::link::RECENT;
use self::motion::Segment;
use self::target::target;
use crate::acquisition::compound::{Compounder, DEFAULT_MAX_COARSENINGS};
use crate::acquisition::probe::Calibration;
use crate::config::{Config, RIBS};
use crate::error::{Error, Result};
use crate::limits::{MIN_CLOUD_POINTS, OUTBOX, SKELETON_POINTS, SOM1_CAPACITY, TRACK_CAPACITY};
use crate::math::geom::Rigid;
use crate::registration::local_rigid::{Lookup, TransformCache};
use crate::registration::pipeline::{Registering, Registration, Template};
use crate::registration::reach::{check_edges, cut_sides, edge_clearance, least_clearance};

use crate::acquisition::track::TrackedPose;
use crate::wire::{
    error_code, Command, Configure, CostW, FrameError, FromController, NackCode, PoseW,
    RegistrationW, State, StatusW, TemplateShape, ToController, WaypointW, MAX_WAYPOINTS,
    PIXEL_SUBDIVISIONS,
};
use crate::Vec3;
use nalgebra::Matrix3;

/// Finest voxel edge the robot PC configures for the controller, mm: the finest at which
/// a whole-chest sweep fits the controller's [`crate::limits::CONTROLLER_VOXELS`] without
/// coarsening (`ribreg hil --in-process --seed 0..9` fill 1,914–2,777 voxels at 3.5 mm;
/// at 3 mm six of the ten overflow, and one coarsening doubles the edge to 6 mm).
pub const CONTROLLER_VOXEL_MM: f32 = 3.5;

/// Units of work per registration step ([`Registering::step`]'s budget: SOM iterations,
/// node-set scans or rigid fits). One iteration of SOM 1 costs about 8,000 instructions
/// on the Cortex-M4F (BMU search over 400 nodes and the neighbourhood update), so 8 keep
/// a step near 0.1 M instructions (README, "Controller and firmware").
pub const SOM_ITERATIONS_PER_POLL: u32 = 8;
/// Voxels turned into centroids per [`Controller::poll`] before the registration starts:
/// ~1,800 instructions each on the emulated Cortex-M4F (2,255 voxels: 37 calls of 64,
/// 4.07 M in all, the worst 116 k; the registration's set-up is a call of its own).
pub const VOXELS_FINISHED_PER_POLL: usize = 64;
/// Work ([`crate::acquisition::compound::VoxelCloud::work`], ~20 instructions a unit) spent per
/// [`Controller::poll`] moving queued sweep points into the voxel cloud (a frame message
/// only places its points, see [`Compounder`]): 16 plain points, fewer when they start
/// voxels that shift the sorted cloud; plus at most one more insert, which with a
/// coarsening of the full cloud is ~5,000 units.
pub const SWEEP_WORK_PER_POLL: u64 = 2048;
/// Transform cache of the waypoint mapping (waypoints rarely share a neighbourhood).
const WAYPOINT_CACHE: usize = 4;

/// Sweep, calibration and motion settings (from [`Configure`]).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Settings {
    calibration: Calibration,
    lag_s: f64,
    voxel_mm: f32,
    max_speed: f32,
    max_accel: f32,
    standoff: f32,
    target_up: Option<Vec3>,
    partial: bool,
}

/// The controller (see the module docs). `VOXELS` is the compounding cloud's capacity.
///
/// `Clone` lets a test or fuzz target snapshot a controller mid-procedure (a copy of
/// about 100 KiB; the firmware never clones one).
#[derive(Clone)]
pub struct Controller<const VOXELS: usize> {
    state: State,
    connected: bool,
    expected: u16,
    out_seq: u16,
    outbox: heapless::Deque<(u16, FromController), OUTBOX>,
    recent: heapless::Deque<(u16, FromController), RECENT>,
    /// Replies dropped because the outbox was full.
    pub dropped_replies: u32,
    settings: Option<Settings>,
    nodes: heapless::Vec<Vec3, SOM1_CAPACITY>,
    labels: heapless::Vec<u8, SOM1_CAPACITY>,
    nodes_total: u16,
    template: Option<Template>,
    waypoints: heapless::Vec<Vec3, MAX_WAYPOINTS>,
    waypoints_total: u8,
    sweep: Compounder<TRACK_CAPACITY, VOXELS>,
    swept: bool,
    cloud_ready: bool,
    probe_sum: Vec3,
    probe_count: u32,
    registering: Option<Registering>,
    targets: heapless::Vec<ProbeTarget, MAX_WAYPOINTS>,
    /// The last registration's confidence, sent with its result.
    confidence: Option<RegistrationW>,
    /// The last registration's rib ends against the sweep's imaged region
    /// ([`edge_clearance`], one rib a call) and how many ribs are done.
    edges: ([[f32; 2]; 4], usize),
    /// The next waypoint's transform being found (bounded steps), then found.
    lookup: Option<Lookup>,
    mapped: Option<(Rigid, u32)>,
    waypoint_cache: TransformCache<WAYPOINT_CACHE>,
    last_pose: Option<(u64, Rigid)>,
    poses: u32,
    segment: Option<Segment>,
    next_setpoint_us: u64,
    paused_since: Option<u64>,
    waypoint: u8,
    cost: CostW,
}

impl<const VOXELS: usize> Default for Controller<VOXELS> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const VOXELS: usize> Controller<VOXELS> {
    /// A controller waiting for the handshake.
    pub const fn new() -> Self {
        Controller {
            state: State::Idle,
            connected: false,
            expected: 0,
            out_seq: 0,
            outbox: heapless::Deque::new(),
            recent: heapless::Deque::new(),
            dropped_replies: 0,
            settings: None,
            nodes: heapless::Vec::new(),
            labels: heapless::Vec::new(),
            nodes_total: 0,
            template: None,
            waypoints: heapless::Vec::new(),
            waypoints_total: 0,
            sweep: Compounder::empty(),
            swept: false,
            cloud_ready: false,
            probe_sum: Vec3::new(0.0, 0.0, 0.0),
            probe_count: 0,
            registering: None,
            targets: heapless::Vec::new(),
            confidence: None,
            edges: ([[f32::NAN; 2]; 4], 0),
            lookup: None,
            mapped: None,
            waypoint_cache: TransformCache::new(),
            last_pose: None,
            poses: 0,
            segment: None,
            next_setpoint_us: 0,
            paused_since: None,
            waypoint: 0,
            cost: CostW {
                registration_instructions: 0,
                registration_calls: 0,
                worst_call_instructions: 0,
                worst_step_instructions: 0,
                worst_receive_instructions: 0,
                peak_stack_bytes: 0,
                serial_overruns: 0,
                serial_framing_errors: 0,
                serial_dropped_bytes: 0,
            },
        }
    }

    /// Records the platform's measured costs, reported on [`Command::Cost`].
    pub fn set_cost(&mut self, cost: CostW) {
        self.cost = cost;
    }

    /// The current state.
    pub fn state(&self) -> State {
        self.state
    }

    /// The probe targets of the last registration.
    pub fn targets(&self) -> &[ProbeTarget] {
        &self.targets
    }

    /// The compounded cloud once the sweep has ended (robot base frame).
    pub fn cloud(&mut self) -> Option<&[Vec3]> {
        if !self.cloud_ready {
            return None;
        }
        while !self.sweep.insert_queued(u64::MAX) {}
        Some(self.sweep.cloud.finish())
    }

    /// Handles one frame from the link: its bytes (without the delimiter, decoded in
    /// place) or the receiver's error.
    pub fn receive(&mut self, frame: core::result::Result<&mut [u8], FrameError>, now_us: u64) {
        let Some((seq, msg)) = self.accept(frame) else {
            return;
        };
        let reply = match self.apply(msg, now_us) {
            Ok(()) => FromController::Ack { seq },
            Err(code) => FromController::Nack { seq, code },
        };
        self.reply(seq, reply);
    }

    fn require(&self, allowed: &[State]) -> core::result::Result<(), NackCode> {
        if allowed.contains(&self.state) {
            Ok(())
        } else {
            Err(NackCode::BadState)
        }
    }

    #[inline(never)]
    fn apply(&mut self, msg: ToController, now_us: u64) -> core::result::Result<(), NackCode> {
        use State::*;
        let invalid = |e: Error| NackCode::Invalid(error_code(&e));
        let setup = [Idle, TemplateLoaded, Ready, Done];
        match msg {
            ToController::Hello { .. } => Ok(()),
            ToController::Configure(c) => {
                self.require(&setup)?;
                self.settings = Some(settings(&c).map_err(invalid)?);
                self.update_loaded();
                Ok(())
            }
            ToController::TemplateNodes {
                offset,
                total,
                nodes,
            } => {
                self.require(&setup)?;
                if offset == 0 {
                    self.nodes.clear();
                    self.labels.clear();
                    self.template = None;
                    self.update_loaded();
                }
                let fits = usize::from(total) <= SOM1_CAPACITY
                    && usize::from(offset) == self.nodes.len()
                    && usize::from(offset) + nodes.len() <= usize::from(total)
                    && (offset == 0 || total == self.nodes_total);
                if !fits {
                    return Err(invalid(Error::Capacity {
                        capacity: SOM1_CAPACITY as u32,
                    }));
                }
                self.nodes_total = total;
                for n in &nodes {
                    // Note: `fits` bounded the count by SOM1_CAPACITY.
                    let _ = self.nodes.push(Vec3::from(n.p));
                    let _ = self.labels.push(n.label);
                }
                Ok(())
            }
            ToController::TemplateShape(shape) => {
                self.require(&setup)?;
                if self.nodes.len() != usize::from(self.nodes_total) || self.nodes.is_empty() {
                    return Err(invalid(Error::TooFewPoints {
                        cloud: crate::error::Cloud::Template,
                        found: self.nodes.len() as u32,
                        min: u32::from(self.nodes_total.max(1)),
                    }));
                }
                self.template = Some(template(&self.nodes, &self.labels, &shape).map_err(invalid)?);
                self.update_loaded();
                Ok(())
            }
            ToController::Waypoints {
                offset,
                total,
                points,
            } => {
                self.require(&setup)?;
                if offset == 0 {
                    self.waypoints.clear();
                }
                let fits = usize::from(total) <= MAX_WAYPOINTS
                    && usize::from(offset) == self.waypoints.len()
                    && usize::from(offset) + points.len() <= usize::from(total)
                    && (offset == 0 || total == self.waypoints_total);
                if !fits {
                    return Err(invalid(Error::Capacity {
                        capacity: MAX_WAYPOINTS as u32,
                    }));
                }
                if let Some(i) = points.iter().position(|p| !finite(p)) {
                    return Err(invalid(Error::NonFinite {
                        cloud: crate::error::Cloud::Query,
                        index: u32::from(offset) + i as u32,
                    }));
                }
                self.waypoints_total = total;
                for p in &points {
                    let _ = self.waypoints.push(Vec3::from(*p));
                }
                self.update_loaded();
                Ok(())
            }
            ToController::Pose(p) => self.pose(&p, now_us).map_err(invalid),
            ToController::Frame(f) => {
                self.require(&[Sweeping])?;
                let mut pixels = [[0.0f32; 2]; crate::limits::MAX_FRAME_PIXELS];
                for (o, p) in pixels.iter_mut().zip(&f.pixels) {
                    *o = [
                        f32::from(p[0]) / PIXEL_SUBDIVISIONS,
                        f32::from(p[1]) / PIXEL_SUBDIVISIONS,
                    ];
                }
                self.sweep
                    .queue_frame(f.t_us as f64 * 1e-6, &pixels[..f.pixels.len()])
                    .map(|_| ())
                    .map_err(invalid)
            }
            ToController::Command(c) => self.command(c, now_us),
        }
    }

    /// TemplateLoaded once configuration, template and all waypoints are in.
    fn update_loaded(&mut self) {
        let loaded = self.settings.is_some()
            && self.template.is_some()
            && !self.waypoints.is_empty()
            && self.waypoints.len() == usize::from(self.waypoints_total);
        match (self.state, loaded) {
            (State::Idle, true) => self.state = State::TemplateLoaded,
            (State::TemplateLoaded | State::Ready | State::Done, false) => self.state = State::Idle,
            _ => {}
        }
    }

    fn pose(&mut self, p: &PoseW, now_us: u64) -> Result<()> {
        let pose = TrackedPose::new(p.t_us as f64 * 1e-6, Vec3::from(p.position), p.quat)?;
        {
            if self.state == State::Sweeping {
                self.sweep.add_pose(pose)?;
                if let Some(s) = &self.settings {
                    let tcp = pose.to_rigid().after(&s.calibration.ee_t_tcp);
                    self.probe_sum += tcp.translation;
                    self.probe_count += 1;
                }
            }
        }
        self.last_pose = Some((now_us, pose.to_rigid()));
        self.poses = self.poses.saturating_add(1);
        Ok(())
    }

    #[inline(never)]
    fn command(&mut self, c: Command, now_us: u64) -> core::result::Result<(), NackCode> {
        use State::*;
        let invalid = |e: Error| NackCode::Invalid(error_code(&e));
        match c {
            Command::StartSweep => {
                self.require(&[TemplateLoaded, Ready, Done])?;
                // Note(unwrap-free): TemplateLoaded implies settings.
                let s = self.settings.ok_or(NackCode::BadState)?;
                self.sweep
                    .reset(s.calibration, s.lag_s, s.voxel_mm, DEFAULT_MAX_COARSENINGS)
                    .map_err(invalid)?;
                self.swept = true;
                self.cloud_ready = false;
                self.probe_sum = Vec3::zeros();
                self.probe_count = 0;
                self.targets.clear();
                self.confidence = None;
                self.state = Sweeping;
                Ok(())
            }
            Command::EndSweep => {
                self.require(&[Sweeping])?;
                // No more frames; the queued points go into the cloud and the voxels
                // become centroids in bounded steps in `poll`, before the registration.
                self.sweep.close();
                self.cloud_ready = true;
                self.state = TemplateLoaded;
                Ok(())
            }
            Command::Register => {
                self.require(&[TemplateLoaded])?;
                if !self.cloud_ready {
                    return Err(NackCode::BadState);
                }
                // At most this many voxels once the queued points are in (the
                // registration checks the final count again).
                let points = self.sweep.cloud.len() + self.sweep.queued();
                if points < MIN_CLOUD_POINTS {
                    return Err(invalid(Error::TooFewPoints {
                        cloud: crate::error::Cloud::Target,
                        found: points as u32,
                        min: MIN_CLOUD_POINTS as u32,
                    }));
                }
                // The registration starts in the next poll (its set-up is a bounded step
                // of its own, and keeps this handler's stack frame small).
                self.registering = None;
                self.state = Registering;
                Ok(())
            }
            Command::Execute => {
                self.require(&[Ready, Done])?;
                let (_, flange) = self.last_pose.ok_or(NackCode::BadState)?;
                let s = self.settings.ok_or(NackCode::BadState)?;
                // The first waypoint the sweep reaches (a partial plan skips the rest).
                let (first, to) = (self.targets.iter().enumerate())
                    .find(|(_, t)| t.supported)
                    .map(|(i, t)| (i, t.tcp))
                    .ok_or(NackCode::BadState)?;
                self.segment = Some(Segment {
                    from: flange.after(&s.calibration.ee_t_tcp),
                    to,
                    start_us: now_us,
                    target: first as u8,
                });
                self.waypoint = first as u8;
                self.next_setpoint_us = now_us;
                self.paused_since = None;
                self.state = Executing;
                Ok(())
            }
            Command::Abort => {
                self.registering = None;
                self.segment = None;
                self.paused_since = None;
                self.state = Idle;
                self.update_loaded();
                Ok(())
            }
            Command::Status => {
                self.send(FromController::Status(self.status()));
                Ok(())
            }
            Command::Cost => {
                self.send(FromController::Cost(self.cost));
                Ok(())
            }
            Command::Result => {
                self.require(&[Ready, Executing, Done])?;
                if let Some(c) = self.confidence {
                    self.send(FromController::Registration(c));
                }
                for i in 0..self.targets.len() {
                    let t = self.targets[i];
                    self.send(FromController::Waypoint(WaypointW {
                        index: i as u8,
                        total: self.targets.len() as u8,
                        position: t.waypoint.into(),
                        quality_mm: t.quality_mm,
                        supported: t.supported,
                    }));
                }
                Ok(())
            }
        }
    }

    /// Current status.
    pub fn status(&self) -> StatusW {
        let s = &self.sweep;
        let (placed, refused, points) = if self.swept {
            (
                s.frames.placed,
                s.frames.outside_track.saturating_add(s.frames.invalid),
                s.cloud.len().min(usize::from(u16::MAX)) as u16,
            )
        } else {
            (0, 0, 0)
        };
        let progress = match (&self.registering, self.state) {
            (Some(r), State::Registering) => {
                let (done, total) = r.progress(&Config::improved());
                (u64::from(done) * 100 / u64::from(total.max(1))) as u8
            }
            (_, State::Ready | State::Executing | State::Done) => 100,
            _ => 0,
        };
        StatusW {
            state: self.state,
            expected_seq: self.expected,
            poses: self.poses,
            frames_placed: placed,
            frames_refused: refused,
            points,
            progress,
            waypoint: self.waypoint,
        }
    }

    /// True while `poll` has work regardless of the time: registering, or sweep points
    /// queued for the cloud (a caller may sleep until the next message otherwise).
    pub fn busy(&self) -> bool {
        self.state == State::Registering || self.sweep.queued() > 0
    }

    /// The periodic work: one bounded registration step, setpoints, the pose watchdog.
    /// Call it at least every [`SETPOINT_PERIOD_US`].
    pub fn poll(&mut self, now_us: u64) {
        match self.state {
            State::Registering => self.register_step(),
            State::Executing => self.execute(now_us),
            _ => {
                self.sweep.insert_queued(SWEEP_WORK_PER_POLL);
            }
        }
    }

    #[inline(never)]
    fn register_step(&mut self) {
        // The same at every step: a configuration is accepted only before registering.
        let cfg = Config {
            target_up: self.settings.as_ref().and_then(|s| s.target_up),
            ..Config::improved()
        };
        if self.registering.is_none() {
            // First the queued sweep points, then the voxel centroids, then the
            // registration's set-up, each in calls of their own.
            if !self.sweep.insert_queued(0) {
                self.sweep.insert_queued(SWEEP_WORK_PER_POLL);
            } else if self.sweep.cloud.finish_some(0) {
                self.targets.clear();
                self.confidence = None;
                self.edges = ([[f32::NAN; 2]; 4], 0);
                self.start_registration(&cfg);
            } else {
                self.sweep.cloud.finish_some(VOXELS_FINISHED_PER_POLL);
            }
            return;
        }
        let (Some(r), Some(template)) = (&mut self.registering, &self.template) else {
            self.state = State::TemplateLoaded;
            return;
        };
        let cloud = self.sweep.cloud.finish();
        let finished_before = r.registration().is_some();
        let outcome = match r.step(template, cloud, &cfg, SOM_ITERATIONS_PER_POLL) {
            Ok(false) => return,
            // The registration's last step is a call of its own, and so is the check of
            // each rib's ends against where the sweep imaged: a partial plan drives to
            // neither side with a rib end at the sweep's edge.
            Ok(true) if !finished_before => return,
            Ok(true) if self.edges.1 < RIBS.len() => {
                let Some(reg) = r.registration() else { return };
                let area = &self.sweep.imaged;
                let (edges, done) = &mut self.edges;
                edges[*done] = edge_clearance(reg, *done, |p, u, max| area.reach(p, u, max));
                *done += 1;
                let partial = self.settings.as_ref().is_some_and(|s| s.partial);
                match check_edges(edges) {
                    Err(e) if *done == RIBS.len() && !partial => Err(e),
                    _ => return,
                }
            }
            // Then each waypoint in calls of its own: its transform (widening, fit),
            // then its probe pose.
            Ok(true) => match (r.registration(), self.waypoints.get(self.targets.len())) {
                (Some(reg), Some(w)) => match self.mapped.take() {
                    None => match reg.map.transform_step(
                        w,
                        &mut self.lookup,
                        &mut self.waypoint_cache,
                        SOM_ITERATIONS_PER_POLL,
                    ) {
                        Ok(found) => {
                            self.mapped = found;
                            return;
                        }
                        Err(e) => Err(e),
                    },
                    Some((t, mask)) => {
                        let s = self.settings.as_ref();
                        let partial = s.is_some_and(|s| s.partial);
                        let index = self.targets.len();
                        let t = target(
                            reg,
                            template,
                            w,
                            t,
                            mask,
                            cloud,
                            s,
                            self.probe_sum,
                            self.probe_count,
                        )
                        .and_then(|t| match t.reach {
                            // A waypoint the sweep does not reach refuses the whole
                            // plan, unless the plan is partial.
                            Some(r) if !partial => r.check(index).map(|()| t),
                            _ => Ok(t),
                        });
                        // Note: a push cannot fail, waypoints and targets share MAX_WAYPOINTS.
                        match t.map(|t| self.targets.push(t)) {
                            Ok(_) if self.targets.len() < self.waypoints.len() => return,
                            Ok(_) => mark_supported(&mut self.targets, self.edges.0),
                            Err(e) => Err(e),
                        }
                    }
                },
                (Some(_), None) => Ok(()),
                (None, _) => Err(Error::Config("the registration did not finish")),
            },
            Err(e) => Err(e),
        };
        if outcome.is_ok() {
            if let Some(reg) = r.registration() {
                self.confidence = Some(confidence(reg, self.edges.0, self.targets.len()));
            }
        }
        self.registering = None;
        match outcome {
            Ok(()) => {
                self.state = State::Ready;
                let _ = self.command(Command::Result, 0);
            }
            Err(e) => self.fail(e),
        }
    }

    #[inline(never)]
    fn start_registration(&mut self, cfg: &Config) {
        self.lookup = None;
        self.mapped = None;
        self.waypoint_cache = TransformCache::new();
        match crate::registration::pipeline::Registering::start(self.sweep.cloud.finish(), cfg) {
            Ok(r) => self.registering = Some(r),
            Err(e) => self.fail(e),
        }
    }

    /// What the registration works on (see [`Registering::stage`]), for cost reports:
    /// `"centroids"` before it starts, `None` when not registering.
    pub fn registration_stage(&self) -> Option<&'static str> {
        match (&self.registering, self.state) {
            (Some(r), State::Registering) => Some(r.stage()),
            (None, State::Registering) => Some("centroids"),
            _ => None,
        }
    }

    fn fail(&mut self, e: Error) {
        self.state = State::TemplateLoaded;
        self.send(FromController::Fault(crate::wire::Fault::Registration(
            error_code(&e),
        )));
    }
}

/// Marks the targets of a partial plan that are not driven to
/// ([`crate::registration::reach::WaypointReach::supported`], and every target on a side
/// with a rib end at the sweep's edge, [`cut_sides`] of `edges`, NaN where not
/// measured); a plan that keeps none is refused
/// ([`crate::registration::reach::check_plan`], or the edge's [`Error::SweepEdge`]).
/// (Without a partial plan every target is reached already: an unreached one, or a rib
/// end at the edge, refused the plan before.)
fn mark_supported(targets: &mut [ProbeTarget], edges: [[f32; 2]; 4]) -> Result<()> {
    let cut = cut_sides(&edges);
    let mut keep = [true; MAX_WAYPOINTS];
    for (k, t) in keep.iter_mut().zip(targets.iter()) {
        let plan = targets.iter().filter_map(|t| t.reach.as_ref());
        *k = t.reach.is_none_or(|r| {
            r.supported(plan) && !cut[usize::from(r.side == crate::error::Side::Left)]
        });
    }
    for (t, k) in targets.iter_mut().zip(keep) {
        t.supported = k;
    }
    crate::registration::reach::check_plan(targets.iter().map(|t| t.reach.as_ref()), true)?;
    if targets.iter().any(|t| t.supported) {
        Ok(())
    } else {
        check_edges(&edges)
    }
}

/// The wire summary of how clearly `reg` found the patient.
fn confidence(reg: &Registration, edges: [[f32; 2]; 4], waypoints: usize) -> RegistrationW {
    let spans = reg.coverage.unwrap_or([[f32::NAN; 2]; 4]);
    // NaN (no evidence, or the graph model) counts as 0 %.
    let least = spans.iter().flatten().fold(
        f32::INFINITY,
        |a, &b| if b.is_nan() { 0.0 } else { a.min(b) },
    );
    let c = reg.confidence;
    RegistrationW {
        hypotheses: c.map_or(0, |c| c.hypotheses),
        residual_mm: c.map_or(f32::NAN, |c| c.residual_mm),
        runner_up_mm: c.map_or(f32::NAN, |c| c.runner_up_mm),
        support_mm: c.map_or(f32::NAN, |c| c.support_mm),
        // `as` saturates: 0..=255 %.
        min_side_span_percent: (least * 100.0 + 0.5) as u8,
        min_edge_clearance_mm: least_clearance(&edges),
        waypoints: waypoints as u8,
    }
}

fn finite(p: &[f32; 3]) -> bool {
    p.iter()
        .all(|v| v.is_finite() && v.abs() <= crate::limits::MAX_COORD_MM)
}

fn rigid(w: &[f32; 12]) -> Rigid {
    Rigid {
        rotation: Matrix3::from_row_slice(&w[..9]),
        translation: Vec3::new(w[9], w[10], w[11]),
    }
}

fn settings(c: &Configure) -> Result<Settings> {
    let calibration = Calibration {
        probe: c.probe,
        tcp_t_us: rigid(&c.tcp_t_us),
        ee_t_tcp: rigid(&c.ee_t_tcp),
    };
    calibration.validate()?;
    let positive = |v: f32| v.is_finite() && v > 0.0 && v <= 1e4;
    if !positive(c.max_speed_mm_s) || !positive(c.max_accel_mm_s2) {
        return Err(Error::Config(
            "speed and acceleration limits must be positive",
        ));
    }
    if !(c.standoff_mm.is_finite() && (0.0..=200.0).contains(&c.standoff_mm)) {
        return Err(Error::Config("standoff must be within 0..=200 mm"));
    }
    if !(crate::acquisition::compound::MIN_VOXEL_MM..=100.0).contains(&c.voxel_mm) {
        return Err(Error::Config("voxel size must be between 0.1 and 100 mm"));
    }
    if c.lag_us.unsigned_abs() > 10_000_000 {
        return Err(Error::Config("lag must be within ±10 s"));
    }
    let up = Vec3::from(c.target_up);
    if !up.iter().all(|v| v.is_finite() && v.abs() <= 1e6) {
        return Err(Error::Config("the patient's up direction must be finite"));
    }
    Ok(Settings {
        calibration,
        lag_s: f64::from(c.lag_us) * 1e-6,
        voxel_mm: c.voxel_mm,
        max_speed: c.max_speed_mm_s,
        max_accel: c.max_accel_mm_s2,
        standoff: c.standoff_mm,
        // Zero: no prior (a direction too short to normalise is none, too).
        target_up: up.try_normalize(1e-6),
        partial: c.partial,
    })
}

fn template(nodes: &[Vec3], labels: &[u8], shape: &TemplateShape) -> Result<Template> {
    let mut skeleton = [Vec3::zeros(); SKELETON_POINTS];
    for (o, p) in skeleton.iter_mut().zip(&shape.skeleton) {
        *o = Vec3::from(*p);
    }
    let frame = crate::math::geom::Frame {
        origin: Vec3::from(shape.origin),
        axes: Matrix3::from_row_slice(&shape.axes),
        spread: Vec3::from(shape.spread),
    };
    Template::from_parts(nodes, labels, frame, skeleton, shape.midline_fraction)
}

/// Random messages with random (often hostile) content, random sequence numbers and
/// random corruption never make the controller panic, and it keeps its invariants.
#[cfg(test)]
mod fuzz_tests {
    use super::*;
    use crate::limits::MAX_FRAME_PIXELS;
    use crate::math::rng::Rng;
    use crate::wire::{encode, FrameW, Node, PoseW, ProbeW, MAGIC, MAX_FRAME, VERSION};

    fn f(rng: &mut Rng) -> f32 {
        match rng.below(8) {
            0 => f32::NAN,
            1 => f32::INFINITY,
            2 => -1e30,
            3 => 0.0,
            _ => (rng.next_f32() - 0.5) * 400.0,
        }
    }

    fn message(rng: &mut Rng) -> ToController {
        let p = |rng: &mut Rng| [f(rng), f(rng), f(rng)];
        match rng.below(10) {
            0 => ToController::Hello {
                magic: if rng.below(2) == 0 {
                    MAGIC
                } else {
                    rng.next_u32()
                },
                version: VERSION,
            },
            1 => ToController::Configure(Configure {
                probe: ProbeW {
                    width_px: rng.below(1000) as u16,
                    height_px: rng.below(1000) as u16,
                    footprint_mm: f(rng),
                    depth_mm: f(rng),
                },
                tcp_t_us: core::array::from_fn(|_| f(rng)),
                ee_t_tcp: [
                    1.0,
                    0.0,
                    0.0,
                    0.0,
                    1.0,
                    0.0,
                    0.0,
                    0.0,
                    1.0,
                    0.0,
                    0.0,
                    f(rng),
                ],
                lag_us: rng.next_u32() as i32,
                voxel_mm: f(rng),
                max_speed_mm_s: f(rng),
                max_accel_mm_s2: f(rng),
                standoff_mm: f(rng),
                target_up: p(rng),
                partial: rng.below(2) == 1,
            }),
            2 => {
                let mut nodes = heapless::Vec::new();
                for _ in 0..rng.below(33) {
                    let _ = nodes.push(Node {
                        p: p(rng),
                        label: rng.below(8) as u8,
                    });
                }
                ToController::TemplateNodes {
                    offset: rng.below(500) as u16,
                    total: rng.below(500) as u16,
                    nodes,
                }
            }
            3 => ToController::TemplateShape(TemplateShape {
                origin: p(rng),
                axes: core::array::from_fn(|_| f(rng)),
                spread: p(rng),
                skeleton: core::array::from_fn(|_| p(rng)),
                midline_fraction: core::array::from_fn(|_| f(rng)),
            }),
            4 => {
                let mut points = heapless::Vec::new();
                for _ in 0..rng.below(9) {
                    let _ = points.push(p(rng));
                }
                ToController::Waypoints {
                    offset: rng.below(40) as u8,
                    total: rng.below(40) as u8,
                    points,
                }
            }
            5 | 6 => ToController::Pose(PoseW {
                t_us: u64::from(rng.next_u32()),
                position: p(rng),
                quat: [f(rng), f(rng), f(rng), f(rng)],
            }),
            7 => {
                let mut pixels = heapless::Vec::new();
                for _ in 0..rng.below(MAX_FRAME_PIXELS as u32 + 1) {
                    let _ = pixels.push([rng.next_u32() as u16, rng.next_u32() as u16]);
                }
                ToController::Frame(FrameW {
                    t_us: u64::from(rng.next_u32()),
                    frame: rng.next_u32(),
                    pixels,
                })
            }
            _ => ToController::Command(
                [
                    Command::StartSweep,
                    Command::EndSweep,
                    Command::Register,
                    Command::Execute,
                    Command::Abort,
                    Command::Status,
                    Command::Result,
                    Command::Cost,
                ][rng.below(8) as usize],
            ),
        }
    }

    #[test]
    fn hostile_streams_never_panic() {
        let mut rng = Rng::new(2024);
        let mut c: Controller<256> = Controller::new();
        let mut buf = [0u8; MAX_FRAME];
        let mut seq = 0u16;
        let mut now = 0u64;
        for _ in 0..20_000 {
            let msg = message(&mut rng);
            // Mostly the expected number, sometimes a duplicate or a jump.
            let s = match rng.below(10) {
                0 => seq.wrapping_sub(rng.below(5) as u16),
                1 => seq.wrapping_add(rng.below(5) as u16),
                _ => seq,
            };
            let n = encode(s, &msg, &mut buf).unwrap();
            if rng.below(10) == 0 {
                let i = rng.below(n as u32 - 1) as usize;
                buf[i] = rng.next_u32() as u8 | 1;
            }
            let before = c.status().expected_seq;
            c.receive(Ok(&mut buf[..n - 1]), now);
            let after = c.status().expected_seq;
            assert!(after == before || after == before.wrapping_add(1) || s == 0);
            seq = after;
            now += u64::from(rng.below(20_000));
            c.poll(now);
            while c.next_reply().is_some() {}
        }
    }
}
