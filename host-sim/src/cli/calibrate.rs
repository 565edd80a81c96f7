//! `ribreg calibrate temporal`: the lag between the US video and the robot tracking.

use super::Context;
use ribreg_sim::error::CliError;
use ribreg_sim::sweep;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    kind: CalibrateCommand,
}

#[derive(clap::Subcommand)]
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
        #[arg(long, default_value = sweep::plus::DEFAULT_TRANSFORM)]
        transform: String,
        /// Print `{"lag_ms": .., "rmse": .., "pairs": ..}` instead of text.
        #[arg(long)]
        json: bool,
    },
}

pub fn run(args: &Args, ctx: &Context) -> Result<(), CliError> {
    let CalibrateCommand::Temporal {
        tracker,
        video,
        sequence,
        transform,
        json,
    } = &args.kind;
    let est = match (sequence, tracker, video) {
        (Some(seq), ..) => {
            let (est, n) = sweep::plus::calibrate_temporal_sequence(seq, transform)?;
            ctx.progress(&format!("{}: {}", seq.display(), n.summary()));
            est
        }
        (None, Some(tracker), Some(video)) => sweep::calibrate_temporal(tracker, video)?,
        _ => {
            return Err(CliError::Usage(
                "give --tracker and --video, or --sequence".into(),
            ))
        }
    };
    let lag_ms = est.lag_s * 1e3;
    if *json {
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
    Ok(())
}
