//! `ribreg`: command line of the ribreg toolkit. See `ribreg --help`.

use clap::{Parser, Subcommand};
use ribreg_sim::demo;
use ribreg_sim::eval::{self, EvalConfig, EvalMethod};
use ribreg_sim::phantom::{PhantomConfig, PhantomPair, Variant};
use ribreg_sim::register::{self, CliError, Method, RegisterJob};
use ribreg_sim::sweep::{self, SweepConfig};
use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "ribreg",
    version,
    about = "Skeleton-graph US-CT rib-cartilage registration"
)]
struct Cli {
    /// No progress lines on stderr.
    #[arg(long, short, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Register a CT template cloud onto a US target cloud and map waypoints.
    Register(RegisterJob),
    /// Poisson-disc sample a surface mesh (PLY, OBJ or STL) into a point cloud (PLY).
    Sample {
        /// The mesh.
        mesh: PathBuf,
        /// Minimum distance between samples, mm.
        #[arg(long, default_value_t = 2.5)]
        spacing: f64,
        /// Seed of the sampling.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Output point cloud (PLY, binary little-endian).
        #[arg(short, long)]
        out: PathBuf,
    },
    /// Write a phantom pair (CT template, US target, waypoints, ground truth) to a folder,
    /// or (`phantom sweep`) the logs of a simulated robotic sweep over it.
    #[command(args_conflicts_with_subcommands = true)]
    Phantom {
        /// Output folder (created if missing).
        #[arg(long, default_value = "out/phantom")]
        out_dir: PathBuf,
        #[command(flatten)]
        phantom: PhantomArgs,
        #[command(subcommand)]
        sweep: Option<PhantomCommand>,
    },
    /// Play the robot PC in a whole procedure against the controller (upload, sweep,
    /// register, execute) and report where the probe ended up at each waypoint.
    Hil {
        /// Run the controller in this process instead of the emulator (the default builds
        /// the firmware and runs it under qemu-system-arm, then compares with in-process).
        #[arg(long, conflicts_with = "port")]
        in_process: bool,
        /// A controller board on a serial device (`/dev/ttyUSB0`, `COM3`), or at HOST:PORT
        /// (a serial port exposed over TCP, such as the emulator's), instead of starting
        /// the emulator.
        #[arg(long)]
        port: Option<String>,
        /// Baud rate of a serial device.
        #[arg(long, default_value_t = 115_200)]
        baud: u32,
        /// Inject link faults (corrupted, dropped, duplicated, reordered frames, garbage).
        #[arg(long)]
        faults: bool,
        /// Seed of the fault injection.
        #[arg(long, default_value_t = 1)]
        fault_seed: u64,
        /// A lighter sweep (lines 15 mm apart, 30 mm/s, every 8th column): a third of the
        /// bytes on the emulator's slow link.
        #[arg(long)]
        quick: bool,
        /// Write the firmware's defmt log (QEMU's semihosting output) here.
        #[arg(long)]
        defmt_log: Option<PathBuf>,
        #[command(flatten)]
        phantom: PhantomArgs,
        /// Also write the report as JSON.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Calibrate the robotic US system.
    Calibrate {
        #[command(subcommand)]
        kind: CalibrateCommand,
    },
    /// Compound a tracked sweep (poses + annotated frames, or a PLUS sequence of bone
    /// masks) into a US cloud (PLY).
    Compound {
        /// Flange poses: CSV `t,x,y,z,qw,qx,qy,qz` (s, mm, unit quaternion), ~100 Hz.
        #[arg(
            long,
            required_unless_present = "sequence",
            conflicts_with = "sequence"
        )]
        poses: Option<PathBuf>,
        /// Bone pixels: CSV `frame,t,u,v` (frame number, video time s, column, row).
        #[arg(
            long,
            required_unless_present = "sequence",
            conflicts_with = "sequence"
        )]
        frames: Option<PathBuf>,
        /// Spatial calibration (JSON: probe, tcp_T_us, ee_T_tcp; see the README). With
        /// --sequence, the sequence's transform is then the flange pose b_T_ee.
        #[arg(long, required_unless_present = "plus_config")]
        probe: Option<PathBuf>,
        /// Instead of the CSV logs: a PLUS sequence file (.seq.mha) whose images are bone
        /// masks (MET_UCHAR, non-zero = bone). Per column, the first mask pixel from the
        /// probe side (near field) is the bone pixel, as `phantom sweep` annotates; frames
        /// whose transform or image status is not OK are skipped and counted.
        #[arg(long)]
        sequence: Option<PathBuf>,
        /// The sequence's per-frame transform (`Seq_FrameNNNN_<NAME>Transform`).
        #[arg(long, default_value = ribreg_sim::sweep::plus::DEFAULT_TRANSFORM)]
        transform: String,
        /// With --sequence: the PLUS device-set configuration holding `Image` → `Probe`
        /// (the `From` of --transform), the calibration with the pixel scale in it.
        #[arg(long, conflicts_with = "probe", requires = "sequence")]
        plus_config: Option<PathBuf>,
        /// Video lag behind the tracker, ms.
        #[arg(
            long,
            required_unless_present = "lag_file",
            conflicts_with = "lag_file",
            allow_negative_numbers = true
        )]
        lag_ms: Option<f64>,
        /// The lag as written by `ribreg calibrate temporal --json`.
        #[arg(long)]
        lag_file: Option<PathBuf>,
        /// Finest voxel edge of the down-sampling, mm (the grid coarsens if it fills up).
        #[arg(long, default_value_t = ribreg_core::compound::DEFAULT_VOXEL_MM)]
        voxel_mm: f32,
        /// Output cloud (PLY, binary little-endian), robot base frame.
        #[arg(short, long)]
        out: PathBuf,
    },
    /// Build the default phantom pair, register it and compare with the ground truth.
    Demo {
        /// Output folder (created if missing).
        #[arg(long, default_value = "out")]
        out_dir: PathBuf,
        #[command(flatten)]
        phantom: PhantomArgs,
        /// `paper`: as published; `improved`: guided ribs + anterior template.
        #[arg(long, value_enum, default_value_t = Method::Improved)]
        method: Method,
        /// Instead: simulate a robotic sweep, calibrate its lag, compound it and register
        /// onto the compounded and onto the ideal US cloud (writes to OUT_DIR/sweep).
        #[arg(long)]
        sweep: bool,
    },
    /// Run ours (paper and improved) and the baselines on phantom pairs; write tables and figures.
    Eval {
        /// Phantom pairs per variant (seeds 0..N).
        #[arg(long, default_value_t = 20)]
        pairs: u64,
        /// Which pose variants.
        #[arg(long, value_enum, default_value_t = Variants::Both)]
        variants: Variants,
        /// Worker threads (default: all cores).
        #[arg(long)]
        jobs: Option<usize>,
        /// Only our two methods (skip the slower baselines).
        #[arg(long)]
        ours_only: bool,
        /// Output folder (created if missing).
        #[arg(long, default_value = "out/eval")]
        out_dir: PathBuf,
    },
}

#[derive(Subcommand)]
enum PhantomCommand {
    /// Simulate a multi-line robotic sweep over the phantom: probe calibration, pose and
    /// frame logs, a temporal-calibration sweep, plus the phantom files; the scan and the
    /// calibration sweep also as PLUS sequences of bone masks (sweep.seq.mha,
    /// calib.seq.mha) with plus_config.xml.
    Sweep {
        /// Output folder (created if missing).
        #[arg(long, default_value = "out/sweep")]
        out_dir: PathBuf,
        #[command(flatten)]
        phantom: PhantomArgs,
        #[command(flatten)]
        sweep: SweepArgs,
    },
}

#[derive(Subcommand)]
enum CalibrateCommand {
    /// Lag between the US video and the robot tracking from a calibration sweep.
    Temporal {
        /// CSV `t,x,y,z`: TCP positions (s, mm, base frame), ~100 Hz.
        #[arg(
            long,
            required_unless_present = "sequence",
            conflicts_with = "sequence"
        )]
        tracker: Option<PathBuf>,
        /// CSV `t,row`: the landmark's row (s, pixels) per frame, ~30 fps.
        #[arg(
            long,
            required_unless_present = "sequence",
            conflicts_with = "sequence"
        )]
        video: Option<PathBuf>,
        /// Instead: a PLUS sequence of the calibration sweep recorded without a time
        /// offset, its images bone masks of the landmark; the tracker stream is the
        /// per-frame transform's translation, the video stream each mask's landmark row.
        #[arg(long)]
        sequence: Option<PathBuf>,
        /// The sequence's per-frame transform.
        #[arg(long, default_value = ribreg_sim::sweep::plus::DEFAULT_TRANSFORM)]
        transform: String,
        /// Print `{"lag_ms": .., "rmse": .., "pairs": ..}` instead of text.
        #[arg(long)]
        json: bool,
    },
}

#[derive(clap::Args)]
struct SweepArgs {
    /// Video lag behind the tracker, ms.
    #[arg(long, default_value_t = 268.0, allow_negative_numbers = true)]
    lag_ms: f64,
    /// Probe speed, mm/s.
    #[arg(long, default_value_t = 20.0)]
    speed_mm_s: f64,
    /// Distance between scan lines, mm.
    #[arg(long, default_value_t = 10.0)]
    line_spacing_mm: f64,
    /// Annotation noise of the bone rows (SD), pixels.
    #[arg(long, default_value_t = 2.0)]
    pixel_noise_px: f64,
    /// Fraction of frames lost.
    #[arg(long, default_value_t = 0.05)]
    miss_rate: f64,
}

impl SweepArgs {
    fn config(&self) -> SweepConfig {
        SweepConfig {
            lag_ms: self.lag_ms,
            speed_mm_s: self.speed_mm_s,
            line_spacing_mm: self.line_spacing_mm,
            pixel_noise_px: self.pixel_noise_px,
            frame_miss_rate: self.miss_rate,
            ..SweepConfig::default()
        }
    }
}

/// Which pose variants `eval` runs.
#[derive(Clone, Copy, clap::ValueEnum)]
enum Variants {
    Both,
    Aligned,
    Misaligned,
}

#[derive(clap::Args)]
struct PhantomArgs {
    /// Seed of the patient, noise and pose.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Pose of the US target: a few degrees/mm, or up to ~20° and ~40 mm.
    #[arg(long, value_enum, default_value_t = Variant::Aligned)]
    variant: Variant,
}

impl PhantomArgs {
    fn config(&self) -> PhantomConfig {
        PhantomConfig {
            seed: self.seed,
            variant: self.variant,
            ..PhantomConfig::default()
        }
    }
}

/// `lag_ms` from the JSON `ribreg calibrate temporal --json` prints.
fn read_lag_ms(path: &std::path::Path) -> Result<f64, CliError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| CliError::Usage(format!("{}: cannot read: {e}", path.display())))?;
    let v: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| CliError::Usage(format!("{}: {e}", path.display())))?;
    v["lag_ms"]
        .as_f64()
        .filter(|v| v.is_finite())
        .ok_or_else(|| CliError::Usage(format!("{}: no number \"lag_ms\"", path.display())))
}

#[allow(clippy::too_many_arguments)]
fn run_hil(
    in_process: bool,
    port: Option<(String, u32)>,
    faults: Option<u64>,
    options: &ribreg_sim::hil::RunOptions,
    defmt_log: Option<PathBuf>,
    phantom: &PhantomConfig,
    json: Option<PathBuf>,
    progress: &mut dyn FnMut(&str),
) -> Result<(), CliError> {
    use ribreg_sim::hil::{self, Faults, Session};
    let faults = faults.map(|seed| (Faults::DEFAULT, seed));
    let report = if in_process {
        let mut session = Session::new(hil::InProcess::new(), faults);
        hil::run_with(&mut session, phantom, options.clone(), progress)?
    } else if let Some((path, baud)) = port
        .as_ref()
        .filter(|(p, _)| !p.contains(':') || p.starts_with("COM"))
    {
        let mut session = Session::new(hil::open_serial(path, *baud)?, faults);
        hil::run_with(&mut session, phantom, options.clone(), progress)?
    } else if let Some((addr, _)) = port {
        let stream = std::net::TcpStream::connect(&addr)
            .map_err(|e| CliError::Usage(format!("{addr}: cannot connect: {e}")))?;
        let _ = stream.set_nodelay(true);
        let mut session = Session::new(hil::Stream::new(stream), faults);
        hil::run_with(&mut session, phantom, options.clone(), progress)?
    } else {
        run_emulated(faults, options, defmt_log, phantom, progress)?
    };
    print_hil(&report);
    if let Some(path) = json {
        let text =
            serde_json::to_string_pretty(&report).map_err(|e| CliError::Usage(e.to_string()))?;
        ribreg_sim::io::write_text(&path, &text)?;
    }
    let worst = report.max_error();
    if worst > hil::TOLERANCE_MM
        || report.applied[0] != report.applied[2]
        || report.applied[1] != report.applied[3]
    {
        return Err(CliError::Usage(format!(
            "procedure out of tolerance or inconsistent: worst waypoint {worst:.2} mm (tolerance {} mm), \
             applied poses {}/{} frames {}/{}",
            hil::TOLERANCE_MM,
            report.applied[0],
            report.applied[2],
            report.applied[1],
            report.applied[3]
        )));
    }
    Ok(())
}

/// The procedure against the firmware under QEMU (`-icount shift=0,sleep=on`: SysTick
/// counts instructions while the firmware works), then the same in-process for comparison.
fn run_emulated(
    faults: Option<(ribreg_sim::hil::Faults, u64)>,
    options: &ribreg_sim::hil::RunOptions,
    defmt_log: Option<PathBuf>,
    phantom: &PhantomConfig,
    progress: &mut dyn FnMut(&str),
) -> Result<ribreg_sim::hil::HilReport, CliError> {
    use ribreg_sim::hil::{self, Port, Session};
    use ribreg_sim::qemu;
    let q = |e: qemu::QemuError| CliError::Usage(e.to_string());
    progress("building the firmware");
    let elf = qemu::firmware_elf().map_err(q)?;
    let opts = qemu::Options {
        icount: Some(qemu::Icount {
            shift: 0,
            sleep: true,
        }),
        semihosting_log: defmt_log,
        ..qemu::Options::default()
    };
    let mut emu = qemu::Emulator::start(&elf, &opts).map_err(q)?;
    progress(&format!("emulator up ({})", emu.args().join(" ")));
    let stream = emu
        .serial()
        .try_clone()
        .map_err(|e| CliError::Usage(format!("emulator serial port: {e}")))?;
    let mut session = Session::new(hil::Stream::new(stream), faults);
    let report = match hil::run_with(&mut session, phantom, options.clone(), progress) {
        Ok(r) => r,
        Err(e) => {
            let status = emu.wait(std::time::Duration::from_secs(2));
            return Err(CliError::Usage(format!(
                "{e}; the emulator: {status:?}, {}",
                emu.stderr_output().trim()
            )));
        }
    };
    session.port.write_all(b"QUIT\0")?;
    let status = emu.wait(std::time::Duration::from_secs(30)).map_err(q)?;
    if !status.success() {
        return Err(CliError::Usage(format!(
            "the firmware did not exit cleanly ({status}); QEMU said: {}",
            emu.stderr_output().trim()
        )));
    }
    progress("the same procedure in-process, for comparison");
    let mut local = Session::new(hil::InProcess::new(), None);
    let reference = hil::run_with(&mut local, phantom, options.clone(), &mut |_| {})?;
    let diff = report
        .waypoints
        .iter()
        .zip(&reference.waypoints)
        .flat_map(|(a, b)| (0..3).map(move |i| (a.mapped[i] - b.mapped[i]).abs()))
        .fold(0.0f32, f32::max);
    println!(
        "emulated vs in-process: mapped waypoints differ by at most {diff:.2e} mm; points {} vs {}",
        report.points, reference.points
    );
    if diff > 1e-2 || report.points != reference.points {
        return Err(CliError::Usage(format!(
            "the emulated controller disagrees with the in-process one by {diff} mm"
        )));
    }
    Ok(report)
}

fn print_hil(r: &ribreg_sim::hil::HilReport) {
    println!("waypoint  mapped (x, y, z) mm               quality  probe error");
    for (i, w) in r.waypoints.iter().enumerate() {
        println!(
            "{i:>8}  ({:8.2}, {:8.2}, {:8.2})  {:6.2} mm  {:6.2} mm",
            w.mapped[0], w.mapped[1], w.mapped[2], w.quality_mm, w.error_mm
        );
    }
    let mean =
        r.waypoints.iter().map(|w| w.error_mm).sum::<f64>() / r.waypoints.len().max(1) as f64;
    let c = &r.cost;
    if c.registration_calls > 0 {
        println!(
            "controller cost (instructions, QEMU -icount): registration {} in {} steps (worst step {}), \
             worst control-loop turn {}, worst frame handling {}; peak stack {} B",
            c.registration_instructions,
            c.registration_calls,
            c.worst_step_instructions,
            c.worst_call_instructions,
            c.worst_receive_instructions,
            c.peak_stack_bytes
        );
    }
    println!(
        "hil: {} waypoints, probe error mean {mean:.2} mm, max {:.2} mm (tolerance {} mm); lag {:.1} ms; \
         {} points compounded; applied poses {}/{}, frames {}/{}; link: {} frames sent, {} re-sent, \
         {} NACKs, {} timeouts, faults injected {:?}; {:.1} s",
        r.waypoints.len(),
        r.max_error(),
        ribreg_sim::hil::TOLERANCE_MM,
        r.lag_ms,
        r.points,
        r.applied[0],
        r.applied[2],
        r.applied[1],
        r.applied[3],
        r.link.sent,
        r.link.resent,
        r.link.nacks,
        r.link.timeouts,
        r.link.injected,
        r.wall_s
    );
}

fn run_phantom_sweep(
    phantom: &PhantomConfig,
    cfg: &SweepConfig,
    out_dir: &std::path::Path,
    progress: &mut dyn FnMut(&str),
) -> Result<(), CliError> {
    progress("simulating the sweep");
    let logs = sweep::simulate(phantom, cfg)?;
    logs.write(out_dir)?;
    let s = &logs.summary["scan"];
    println!(
        "wrote {}: {} scan lines in {:.0} s, {} poses, {} of {} frames with {} bone pixels; \
         calibration sweep {} poses / {} frames; lag {} ms",
        out_dir.display(),
        s["lines"],
        s["duration_s"].as_f64().unwrap_or(f64::NAN),
        s["poses"],
        s["frames_logged"],
        s["frames_captured"],
        s["pixels"],
        logs.calib_tracker.len(),
        logs.calib_video.len(),
        cfg.lag_ms
    );
    Ok(())
}

fn run_sweep_demo(
    phantom: &PhantomConfig,
    out_dir: &std::path::Path,
    progress: &mut dyn FnMut(&str),
) -> Result<(), CliError> {
    let cfg = SweepConfig::default();
    run_phantom_sweep(phantom, &cfg, out_dir, progress)?;
    let r = sweep::end_to_end(out_dir, ribreg_core::compound::DEFAULT_VOXEL_MM, progress)?;
    let json = r.json(cfg.lag_ms);
    let text = serde_json::to_string_pretty(&json).map_err(|e| CliError::Usage(e.to_string()))?;
    ribreg_sim::io::write_text(&out_dir.join("end_to_end.json"), &text)?;
    println!(
        "sweep demo: lag {:.1} ms (true {:.0}); compounded {} points; waypoint error {:.2} ± {:.2} mm \
         (max {:.2}) vs {:.2} ± {:.2} mm (max {:.2}) on the ideal cloud: difference {:+.2} mm; outputs in {}",
        r.lag.lag_s * 1e3,
        cfg.lag_ms,
        r.compound.points.len(),
        r.sweep_waypoints.0,
        r.sweep_waypoints.1,
        r.sweep_waypoints.2,
        r.ideal_waypoints.0,
        r.ideal_waypoints.1,
        r.ideal_waypoints.2,
        r.sweep_waypoints.0 - r.ideal_waypoints.0,
        out_dir.display()
    );
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let quiet = cli.quiet;
    let mut progress = |line: &str| {
        if !quiet {
            eprintln!("ribreg: {line}");
        }
    };
    let result = match cli.command {
        Command::Register(job) => register::run(&job, &mut progress).map(|o| {
            println!(
                "registered {} points: ED {:.2} ± {:.2} mm (max {:.2}), HD {:.2} mm",
                o.registered.len(),
                o.metrics.ed.mean,
                o.metrics.ed.sd,
                o.metrics.ed.max,
                o.metrics.hausdorff
            );
        }),
        Command::Sample {
            mesh,
            spacing,
            seed,
            out,
        } => (|| {
            let m = ribreg_sim::io::read_mesh(&mesh)?;
            let points = ribreg_sim::sample::poisson_disc(&m, spacing, seed)
                .map_err(|e| register::CliError::Usage(format!("{}: {e}", mesh.display())))?;
            let n = points.len();
            let cloud = ribreg_sim::io::Cloud {
                points,
                labels: None,
            };
            ribreg_sim::io::write_ply(&out, &cloud, ribreg_sim::io::PlyFormat::BinaryLittleEndian)?;
            println!("wrote {}: {n} points, spacing {spacing} mm", out.display());
            Ok(())
        })(),
        Command::Phantom {
            sweep: Some(PhantomCommand::Sweep {
                out_dir,
                phantom,
                sweep,
            }),
            ..
        } => run_phantom_sweep(&phantom.config(), &sweep.config(), &out_dir, &mut progress),
        Command::Hil {
            in_process,
            port,
            faults,
            fault_seed,
            quick,
            defmt_log,
            baud,
            phantom,
            json,
        } => {
            let options = if quick {
                ribreg_sim::hil::RunOptions::quick()
            } else {
                ribreg_sim::hil::RunOptions::default()
            };
            let faults = faults.then_some(fault_seed);
            let port = port.map(|p| (p, baud));
            run_hil(in_process, port, faults, &options, defmt_log, &phantom.config(), json, &mut progress)
        }
        Command::Calibrate {
            kind:
                CalibrateCommand::Temporal {
                    tracker,
                    video,
                    sequence,
                    transform,
                    json,
                },
        } => match (sequence, tracker, video) {
            (Some(seq), ..) => sweep::plus::calibrate_temporal_sequence(&seq, &transform).map(|(est, n)| {
                progress(&format!("{}: {}", seq.display(), n.summary()));
                est
            }),
            (None, Some(tracker), Some(video)) => sweep::calibrate_temporal(&tracker, &video),
            _ => Err(CliError::Usage("give --tracker and --video, or --sequence".into())),
        }
        .map(|est| {
            let lag_ms = est.lag_s * 1e3;
            if json {
                println!(
                    "{}",
                    serde_json::json!({ "lag_ms": lag_ms, "rmse": est.rmse_px, "pairs": est.pairs })
                );
            } else {
                println!(
                    "lag {lag_ms:.1} ms (positive: the video lags the tracker); residual RMSE {:.2} px \
                     over {} frame/position pairs; NCC {:.4}; swing {:.1} mm / {:.0} px",
                    est.rmse_px, est.pairs, est.ncc, est.swing_mm, est.swing_px
                );
            }
        }),
        Command::Compound {
            poses,
            frames,
            probe,
            sequence,
            transform,
            plus_config,
            lag_ms,
            lag_file,
            voxel_mm,
            out,
        } => (|| {
            let lag_ms = match (lag_ms, lag_file) {
                (Some(ms), _) => ms,
                (None, Some(path)) => read_lag_ms(&path)?,
                (None, None) => return Err(CliError::Usage("give --lag-ms or --lag-file".into())),
            };
            let o = match (&sequence, poses, frames, &probe) {
                (Some(seq), ..) => {
                    use sweep::plus::Spatial;
                    let spatial = match (&plus_config, &probe) {
                        (Some(c), _) => Spatial::PlusConfig(c),
                        (None, Some(p)) => Spatial::Probe(p),
                        (None, None) => return Err(CliError::Usage("give --plus-config or --probe".into())),
                    };
                    let (o, s) = sweep::plus::compound_sequence(seq, &transform, spatial, lag_ms * 1e-3, voxel_mm)?;
                    println!("{}: {}; lag {lag_ms} ms; refused by reason: {:?}", seq.display(), s.counts.summary(), o.refusals);
                    o
                }
                (None, Some(poses), Some(frames), Some(probe)) => {
                    let cal = sweep::ProbeFile::read(probe)?;
                    let poses = sweep::read_poses(&poses)?;
                    let frames = sweep::read_frames(&frames)?;
                    progress(&format!("{} poses, {} pixel rows; lag {lag_ms} ms", poses.len(), frames.len()));
                    sweep::compound(&cal, lag_ms * 1e-3, voxel_mm, &poses, &frames)?
                }
                _ => return Err(CliError::Usage("give --poses, --frames and --probe, or --sequence".into())),
            };
            if o.points.is_empty() {
                return Err(CliError::Usage(format!(
                    "no bone point was placed: {} frames outside the tracked time range, {} invalid \
                     (is the lag right, do the logs overlap in time?)",
                    o.frames.outside_track, o.frames.invalid
                )));
            }
            sweep::write_cloud(&out, &o.points)?;
            println!(
                "wrote {}: {} points ({} mm voxels); frames placed {}, refused {} outside the tracked \
                 range, {} invalid; points accepted {} (merged {}), refused {} (cloud full); poses refused {}",
                out.display(),
                o.points.len(),
                o.voxel_mm,
                o.frames.placed,
                o.frames.outside_track,
                o.frames.invalid,
                o.voxels.accepted,
                o.voxels.merged,
                o.voxels.refused_full,
                o.poses_refused
            );
            Ok(())
        })(),
        Command::Phantom {
            out_dir, phantom, ..
        } => {
            let pair = PhantomPair::generate(&phantom.config());
            demo::write_phantom(&pair, &out_dir).map(|()| {
                println!(
                    "wrote {}: template {} points, target {} points, 10 waypoints",
                    out_dir.display(),
                    pair.template.points.len(),
                    pair.target.len()
                );
            })
        }
        Command::Demo {
            out_dir,
            phantom,
            sweep: true,
            ..
        } => run_sweep_demo(&phantom.config(), &out_dir.join("sweep"), &mut progress),
        Command::Demo {
            out_dir,
            phantom,
            method,
            ..
        } => demo::run_demo(&phantom.config(), method, &out_dir, &mut progress).map(|r| {
            let g = &r["ground_truth"];
            println!(
                "demo: waypoint error {:.2} ± {:.2} mm (max {:.2}), dense error {:.2} mm, \
                 ED {:.2} mm, HD {:.2} mm, registration {:.0} ms; outputs in {}",
                g["waypoint_error_mm"]["mean"].as_f64().unwrap_or(f64::NAN),
                g["waypoint_error_mm"]["sd"].as_f64().unwrap_or(f64::NAN),
                g["waypoint_error_mm"]["max"].as_f64().unwrap_or(f64::NAN),
                g["dense_error_mm"]["mean"].as_f64().unwrap_or(f64::NAN),
                r["metrics"]["ed_mean_mm"].as_f64().unwrap_or(f64::NAN),
                r["metrics"]["hausdorff_mm"].as_f64().unwrap_or(f64::NAN),
                r["timings_ms"]["total"].as_f64().unwrap_or(f64::NAN),
                out_dir.display()
            );
        }),
        Command::Eval {
            pairs,
            variants,
            jobs,
            ours_only,
            out_dir,
        } => {
            let variants = match variants {
                Variants::Both => vec![Variant::Aligned, Variant::Misaligned],
                Variants::Aligned => vec![Variant::Aligned],
                Variants::Misaligned => vec![Variant::Misaligned],
            };
            let mut methods = EvalMethod::all();
            if ours_only {
                methods.retain(|m| matches!(m, EvalMethod::Ours(..)));
            }
            let jobs =
                jobs.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
            let cfg = EvalConfig {
                pairs,
                variants,
                methods,
                jobs,
            };
            let tty = std::io::stderr().is_terminal();
            let mut line = |l: &str| match (quiet, tty) {
                (true, _) => {}
                (false, true) => eprint!("\r{l}   "),
                (false, false) => eprintln!("{l}"),
            };
            let r = eval::run_eval(&cfg, &out_dir, &mut line);
            if tty && !quiet {
                eprintln!();
            }
            r.map(|table| println!("{table}\nwrote {}", out_dir.display()))
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("ribreg: error: {e}");
            ExitCode::from(2)
        }
    }
}
