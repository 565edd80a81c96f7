//! `ribreg sample`: Poisson-disc sampling of a surface mesh.

use ribreg_sim::error::CliError;
use ribreg_sim::io::{self, Cloud, PlyFormat};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
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
}

pub fn run(args: &Args) -> Result<(), CliError> {
    let m = io::read_mesh(&args.mesh)?;
    let points = ribreg_sim::sample::poisson_disc(&m, args.spacing, args.seed)
        .map_err(|e| CliError::input(&args.mesh, e.to_string()))?;
    let n = points.len();
    let cloud = Cloud {
        points,
        labels: None,
    };
    io::write_ply(&args.out, &cloud, PlyFormat::BinaryLittleEndian)?;
    println!(
        "wrote {}: {n} points, spacing {} mm",
        args.out.display(),
        args.spacing
    );
    Ok(())
}
