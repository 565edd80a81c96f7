//! `ribreg calibrate temporal`: the lag between the US video and the robot tracking.

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
        #[arg(long)]
        tracker: PathBuf,
        /// CSV `t,row`: the landmark's row (s, pixels) per frame, ~30 fps.
        #[arg(long)]
        video: PathBuf,
        /// Print `{"lag_ms": .., "rmse": .., "pairs": ..}` instead of text.
        #[arg(long)]
        json: bool,
    },
}

pub fn run(args: &Args) -> Result<(), CliError> {
    let CalibrateCommand::Temporal {
        tracker,
        video,
        json,
    } = &args.kind;
    let est = sweep::calibrate_temporal(tracker, video)?;
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
