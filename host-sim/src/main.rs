//! `ribreg`: command line of the ribreg toolkit. See `ribreg --help`.

use clap::{Parser, Subcommand};
use ribreg_sim::demo;
use ribreg_sim::eval::{self, EvalConfig, EvalMethod};
use ribreg_sim::phantom::{PhantomConfig, PhantomPair, Variant};
use ribreg_sim::register::{self, Method, RegisterJob};
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
        #[arg(long, value_enum, default_value_t = Method::Improved)]
        method: Method,
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
