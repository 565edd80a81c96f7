//! `ribreg demo`: the default phantom pair registered and compared with its ground
//! truth; `--sweep`: the robotic chain (sweep, lag, compounding) end to end.

use super::{Context, PhantomArgs};
use ribreg_core::acquisition::compound::DEFAULT_VOXEL_MM;
use ribreg_sim::demo;
use ribreg_sim::error::CliError;
use ribreg_sim::phantom::PhantomConfig;
use ribreg_sim::register::Method;
use ribreg_sim::sweep::{self, SweepConfig};
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct Args {
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
    /// With `--sweep`: how far the sweep's lines run past the cartilages' lateral extent,
    /// mm (default 20); negative, they stop that far inside it, and the registration is
    /// refused as the controller's is ("rib N runs to the edge of the sweep", down to
    /// -60).
    #[arg(
        long,
        value_name = "MM",
        allow_negative_numbers = true,
        requires = "sweep"
    )]
    sweep_margin_mm: Option<f64>,
}

pub fn run(args: &Args, ctx: &Context) -> Result<(), CliError> {
    if args.sweep {
        let mut cfg = SweepConfig::default();
        if let Some(margin) = args.sweep_margin_mm {
            cfg.margin_mm = margin;
        }
        return run_sweep(
            &args.phantom.config(),
            &cfg,
            &args.out_dir.join("sweep"),
            ctx,
        );
    }
    let out_dir = &args.out_dir;
    let r = demo::run_demo(&args.phantom.config(), args.method, out_dir, &mut |l| {
        ctx.progress(l)
    })?;
    let g = &r["ground_truth"];
    println!(
        "demo: waypoint error {:.2} ± {:.2} mm (max {:.2}; across the gap max {:.2}, \
         least clearance to a cartilage {:.1}), dense error {:.2} mm, \
         ED {:.2} mm, HD {:.2} mm, registration {:.0} ms; outputs in {}",
        g["waypoint_error_mm"]["mean"].as_f64().unwrap_or(f64::NAN),
        g["waypoint_error_mm"]["sd"].as_f64().unwrap_or(f64::NAN),
        g["waypoint_error_mm"]["max"].as_f64().unwrap_or(f64::NAN),
        g["across_gap_mm"]["max"].as_f64().unwrap_or(f64::NAN),
        g["across_gap_mm"]["least_clearance"]
            .as_f64()
            .unwrap_or(f64::NAN),
        g["dense_error_mm"]["mean"].as_f64().unwrap_or(f64::NAN),
        r["metrics"]["ed_mean_mm"].as_f64().unwrap_or(f64::NAN),
        r["metrics"]["hausdorff_mm"].as_f64().unwrap_or(f64::NAN),
        r["timings_ms"]["total"].as_f64().unwrap_or(f64::NAN),
        out_dir.display()
    );
    Ok(())
}

fn run_sweep(
    phantom: &PhantomConfig,
    cfg: &SweepConfig,
    out_dir: &Path,
    ctx: &Context,
) -> Result<(), CliError> {
    super::phantom::run_sweep(phantom, cfg, out_dir, ctx)?;
    let r = sweep::end_to_end(out_dir, DEFAULT_VOXEL_MM, &mut |l| ctx.progress(l))?;
    let json = r.json(cfg.lag_ms);
    let text = serde_json::to_string_pretty(&json).map_err(|e| CliError::Output(e.to_string()))?;
    ribreg_sim::io::write_text(&out_dir.join("end_to_end.json"), &text)?;
    println!(
        "sweep demo: lag {:.1} ms (true {:.0}); compounded {} points; waypoint error {:.2} ± {:.2} mm \
         (max {:.2}) vs {:.2} ± {:.2} mm (max {:.2}) on the ideal cloud: difference {:+.2} mm; \
         every rib end imaged {:.1} mm past or more; outputs in {}",
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
        r.min_edge_clearance_mm,
        out_dir.display()
    );
    Ok(())
}
