//! `ribreg phantom`: a phantom pair with its ground truth; `ribreg phantom sweep`: the
//! logs of a simulated robotic sweep over it.

use super::{Context, PhantomArgs, RobotArgs};
use ribreg_sim::demo;
use ribreg_sim::error::CliError;
use ribreg_sim::phantom::{PhantomConfig, PhantomPair};
use ribreg_sim::sweep::{self, SweepConfig};
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct Args {
    /// Output folder (created if missing).
    #[arg(long, default_value = "out/phantom")]
    out_dir: PathBuf,
    #[command(flatten)]
    phantom: PhantomArgs,
    /// Also write the template's CT as a segmentation hands it over, into `OUT_DIR/ct`:
    /// a TotalSegmentator-style labelmap, per-part STL meshes and the plan as Slicer
    /// markups (for trying `ribreg template`).
    #[arg(long)]
    ct: bool,
    #[command(subcommand)]
    sweep: Option<PhantomCommand>,
}

#[derive(clap::Subcommand)]
enum PhantomCommand {
    /// Simulate a multi-line robotic sweep over the phantom: probe calibration, pose and
    /// frame logs, a temporal-calibration sweep, plus the phantom files.
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
    /// How far each line runs past the cartilages' lateral extent, mm (the default 20:
    /// on a curved chest the image at the cartilage's depth reaches about 10 mm less
    /// than the probe on the skin); negative, the lines stop that far inside it (a sweep
    /// band too narrow; down to -60).
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
    margin_mm: f64,
    #[command(flatten)]
    robot: RobotArgs,
}

impl SweepArgs {
    fn config(&self) -> SweepConfig {
        SweepConfig {
            lag_ms: self.lag_ms,
            speed_mm_s: self.speed_mm_s,
            line_spacing_mm: self.line_spacing_mm,
            pixel_noise_px: self.pixel_noise_px,
            frame_miss_rate: self.miss_rate,
            margin_mm: self.margin_mm,
            base_yaw_deg: self.robot.base_yaw,
            ..SweepConfig::default()
        }
    }
}

pub fn run(args: &Args, ctx: &Context) -> Result<(), CliError> {
    if let Some(PhantomCommand::Sweep {
        out_dir,
        phantom,
        sweep,
    }) = &args.sweep
    {
        return run_sweep(&phantom.config(), &sweep.config(), out_dir, ctx);
    }
    let pair = PhantomPair::generate(&args.phantom.config());
    demo::write_phantom(&pair, &args.out_dir)?;
    if args.ct {
        ctx.progress("painting the template's CT labelmap");
        demo::write_ct(&pair, &args.out_dir.join("ct"))?;
    }
    println!(
        "wrote {}: template {} points, target {} points, 10 waypoints",
        args.out_dir.display(),
        pair.template.points.len(),
        pair.target.len()
    );
    Ok(())
}

/// Simulates a sweep over `phantom` and writes its logs to `out_dir` (also `demo --sweep`).
pub fn run_sweep(
    phantom: &PhantomConfig,
    cfg: &SweepConfig,
    out_dir: &Path,
    ctx: &Context,
) -> Result<(), CliError> {
    ctx.progress("simulating the sweep");
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
