//! `ribreg compound`: a tracked sweep (poses + annotated frames, or a PLUS sequence of
//! bone masks) compounded into a US cloud.

use super::Context;
use ribreg_sim::error::CliError;
use ribreg_sim::io::IoError;
use ribreg_sim::sweep;
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct Args {
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
    #[arg(long, default_value = sweep::plus::DEFAULT_TRANSFORM)]
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
    #[arg(long, default_value_t = ribreg_core::acquisition::compound::DEFAULT_VOXEL_MM)]
    voxel_mm: f32,
    /// Output cloud (PLY, binary little-endian), robot base frame.
    #[arg(short, long)]
    out: PathBuf,
    /// Also write the sweep's lines (CSV, `sweep::IMAGED_COLUMNS`): where its images
    /// passed, for `register --imaged` to check that the sweep imaged past every rib
    /// end it shows.
    #[arg(long, value_name = "LINES.csv")]
    imaged: Option<PathBuf>,
}

pub fn run(args: &Args, ctx: &Context) -> Result<(), CliError> {
    let lag_ms = match (args.lag_ms, &args.lag_file) {
        (Some(ms), _) => ms,
        (None, Some(path)) => read_lag_ms(path)?,
        (None, None) => return Err(CliError::Usage("give --lag-ms or --lag-file".into())),
    };
    let o = match (&args.sequence, &args.poses, &args.frames, &args.probe) {
        (Some(seq), ..) => {
            let spatial = match (&args.plus_config, &args.probe) {
                (Some(c), _) => sweep::plus::Spatial::PlusConfig(c),
                (None, Some(p)) => sweep::plus::Spatial::Probe(p),
                (None, None) => {
                    return Err(CliError::Usage("give --plus-config or --probe".into()))
                }
            };
            let (o, s) = sweep::plus::compound_sequence(
                seq,
                &args.transform,
                spatial,
                lag_ms * 1e-3,
                args.voxel_mm,
            )?;
            // On stdout with the result: what was used and skipped is part of it.
            println!(
                "{}: {}; lag {lag_ms} ms; refused by reason: {:?}",
                seq.display(),
                s.counts.summary(),
                o.refusals
            );
            o
        }
        (None, Some(poses), Some(frames), Some(probe)) => {
            let cal = sweep::ProbeFile::read(probe)?;
            let poses = sweep::read_poses(poses)?;
            let frames = sweep::read_frames(frames)?;
            ctx.progress(&format!(
                "{} poses, {} pixel rows; lag {lag_ms} ms",
                poses.len(),
                frames.len()
            ));
            sweep::compound(&cal, lag_ms * 1e-3, args.voxel_mm, &poses, &frames)?
        }
        _ => {
            return Err(CliError::Usage(
                "give --poses, --frames and --probe, or --sequence".into(),
            ))
        }
    };
    if o.points.is_empty() {
        return Err(CliError::value(format!(
            "no bone point was placed: {} frames outside the tracked time range, {} invalid \
             (is the lag right, do the logs overlap in time?)",
            o.frames.outside_track, o.frames.invalid
        )));
    }
    sweep::write_cloud(&args.out, &o.points)?;
    if let Some(path) = &args.imaged {
        sweep::write_imaged(path, &o.imaged)?;
        println!(
            "wrote {}: {} sweep lines ({} not kept: more than {})",
            path.display(),
            o.imaged.line_count(),
            o.imaged.dropped,
            ribreg_core::limits::IMAGED_LINES
        );
    }
    println!(
        "wrote {}: {} points ({} mm voxels); frames placed {}, refused {} outside the tracked \
         range, {} invalid; points accepted {} (merged {}), refused {} (cloud full); poses refused {}",
        args.out.display(),
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
}

/// `lag_ms` from the JSON `ribreg calibrate temporal --json` prints.
fn read_lag_ms(path: &Path) -> Result<f64, CliError> {
    let text = std::fs::read_to_string(path).map_err(|source| IoError::Io {
        path: path.to_owned(),
        op: "cannot read",
        source,
    })?;
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| CliError::input(path, e.to_string()))?;
    v["lag_ms"]
        .as_f64()
        .filter(|v| v.is_finite())
        .ok_or_else(|| CliError::input(path, "no number \"lag_ms\""))
}
