//! `ribreg`: command line of the ribreg toolkit. See `ribreg --help`.

use clap::{Parser, Subcommand};
use ribreg_sim::register::{self, RegisterJob};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "ribreg", version, about = "Skeleton-graph US-CT rib-cartilage registration")]
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
    },
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
        Command::Register { template, target, waypoints, out, out_waypoints, report, ascii } => {
            let job = RegisterJob { template, target, waypoints, out, out_waypoints, report, ascii };
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
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("ribreg: error: {e}");
            ExitCode::from(2)
        }
    }
}
