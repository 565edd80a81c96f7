//! `ribreg`: command line of the ribreg toolkit. See `ribreg --help`.

use clap::{Parser, Subcommand};
use ribreg_sim::demo;
use ribreg_sim::phantom::{PhantomConfig, PhantomPair, Variant};
use ribreg_sim::register::{self, Method, RegisterJob};
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
    Register {
        /// CT template point cloud (PLY; optional integer `label`: rib 2..5, 1 = sternum).
        #[arg(long)]
        template: PathBuf,
        /// US target point cloud (PLY).
        #[arg(long)]
        target: PathBuf,
        /// Planned waypoints on the template (CSV with header `x,y,z`, mm).
        #[arg(long)]
        waypoints: Option<PathBuf>,
        /// Output: the template's points, same order, registered (PLY).
        #[arg(long)]
        out: PathBuf,
        /// Output: mapped waypoints (CSV `x,y,z`).
        #[arg(long)]
        out_waypoints: Option<PathBuf>,
        /// Output: JSON report (skeletons, endpoint match, ED/HD, timings).
        #[arg(long)]
        report: Option<PathBuf>,
        /// Write the output PLY as ASCII (default: binary little-endian).
        #[arg(long)]
        ascii: bool,
        #[arg(long, value_enum, default_value_t = MethodArg::Improved)]
        /// `paper`: as published; `improved`: guided ribs + anterior template (needs labels).
        method: MethodArg,
    },
    /// Write a phantom pair (CT template, US target, waypoints, ground truth) to a folder.
    Phantom {
        /// Output folder (created if missing).
        #[arg(long, default_value = "out/phantom")]
        out_dir: PathBuf,
        #[command(flatten)]
        phantom: PhantomArgs,
    },
    /// Build the default phantom pair, register it and compare with the ground truth.
    Demo {
        /// Output folder (created if missing).
        #[arg(long, default_value = "out")]
        out_dir: PathBuf,
        #[command(flatten)]
        phantom: PhantomArgs,
        /// `paper`: as published; `improved`: guided ribs + anterior template.
        #[arg(long, value_enum, default_value_t = MethodArg::Improved)]
        method: MethodArg,
    },
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum MethodArg {
    Paper,
    Improved,
}

impl From<MethodArg> for Method {
    fn from(m: MethodArg) -> Method {
        match m {
            MethodArg::Paper => Method::Paper,
            MethodArg::Improved => Method::Improved,
        }
    }
}

#[derive(clap::Args)]
struct PhantomArgs {
    /// Seed of the patient, noise and pose.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Pose of the US target: a few degrees/mm, or up to ~20° and ~40 mm.
    #[arg(long, value_enum, default_value_t = VariantArg::Aligned)]
    variant: VariantArg,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum VariantArg {
    Aligned,
    Misaligned,
}

impl PhantomArgs {
    fn config(&self) -> PhantomConfig {
        let variant = match self.variant {
            VariantArg::Aligned => Variant::Aligned,
            VariantArg::Misaligned => Variant::Misaligned,
        };
        PhantomConfig {
            seed: self.seed,
            variant,
            ..PhantomConfig::default()
        }
    }
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
        Command::Register {
            template,
            target,
            waypoints,
            out,
            out_waypoints,
            report,
            ascii,
            method,
        } => {
            let job = RegisterJob {
                template,
                target,
                waypoints,
                out,
                out_waypoints,
                report,
                ascii,
                method: method.into(),
            };
            register::run(&job, &mut progress).map(|o| {
                println!(
                    "registered {} points: ED {:.2} ± {:.2} mm (max {:.2}), HD {:.2} mm",
                    o.registered.len(),
                    o.metrics.ed.mean,
                    o.metrics.ed.sd,
                    o.metrics.ed.max,
                    o.metrics.hausdorff
                );
            })
        }
        Command::Phantom { out_dir, phantom } => {
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
            method,
        } => demo::run_demo(&phantom.config(), method.into(), &out_dir, &mut progress).map(|r| {
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
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("ribreg: error: {e}");
            ExitCode::from(2)
        }
    }
}
