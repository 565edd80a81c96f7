//! `ribreg eval`: every method on phantom pairs; tables and figures.

use super::Context;
use ribreg_sim::error::CliError;
use ribreg_sim::eval::{self, EvalConfig, EvalMethod};
use ribreg_sim::phantom::{HardPart, Preset, Variant};
use ribreg_sim::register::Ablation;
use std::io::IsTerminal;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Phantom pairs per variant (seeds S..S+N, S from `--first-seed`).
    #[arg(long, default_value_t = 20)]
    pairs: u64,
    /// The first phantom seed S: e.g. `--first-seed 100` evaluates phantoms that no
    /// constant was set on (the README's figures come from seeds 0..100).
    #[arg(long, default_value_t = 0)]
    first_seed: u64,
    /// Which pose variants.
    #[arg(long, value_enum, default_value_t = Variants::Both)]
    variants: Variants,
    /// Which phantom families: `standard` (every figure before the hard phantoms),
    /// `hard`, or `both` (each gets its own tables).
    #[arg(long, value_enum, default_value_t = Presets::Standard)]
    preset: Presets,
    /// With the hard preset: difficulties to leave out, comma-separated (an ablation of
    /// the phantom: what each costs).
    #[arg(long, value_enum, value_delimiter = ',')]
    hard_without: Vec<HardPart>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    jobs: Option<usize>,
    /// Only our two methods (skip the slower baselines).
    #[arg(long)]
    ours_only: bool,
    /// Also ours (improved) with each of its steps left out in turn (an ablation of the
    /// method: what each step brings; rows "ours (improved), no ...").
    #[arg(long)]
    ablation: bool,
    /// Also ours (improved) mapping every waypoint and marking those the sweep does not
    /// reach (`register --partial`; rows "ours (improved, partial)"); marked waypoints
    /// are not judged.
    #[arg(long)]
    partial: bool,
    /// The robustness sweep instead of the accuracy table: every pair turned (a yaw grid,
    /// random rotations) and moved 0.5 m, sparse, missing a side or rib 5, or stopping
    /// short on one side; counts
    /// accepted runs, refusals and silent failures (writes robustness.md and .json).
    #[arg(long)]
    robustness: bool,
    /// With `--robustness`: give each case's sweep the lines its probe imaged (the
    /// default sweep's, 20 mm past the cartilages, stopping where a case cuts a side
    /// short), and check every rib end against them as `register --imaged` and the
    /// controller do.
    #[arg(long, requires = "robustness")]
    imaged: bool,
    /// Output folder (created if missing).
    #[arg(long, default_value = "out/eval")]
    out_dir: PathBuf,
}

/// Which phantom presets `eval` runs.
#[derive(Clone, Copy, clap::ValueEnum)]
enum Presets {
    Standard,
    Hard,
    Both,
}

/// Which pose variants `eval` runs.
#[derive(Clone, Copy, clap::ValueEnum)]
enum Variants {
    Both,
    Aligned,
    Misaligned,
}

pub fn run(args: &Args, ctx: &Context) -> Result<(), CliError> {
    let variants = match args.variants {
        Variants::Both => vec![Variant::Aligned, Variant::Misaligned],
        Variants::Aligned => vec![Variant::Aligned],
        Variants::Misaligned => vec![Variant::Misaligned],
    };
    let mut methods = EvalMethod::all();
    if args.ours_only {
        methods.retain(|m| matches!(m, EvalMethod::Ours(..)));
    }
    if args.ablation {
        methods.extend(Ablation::ALL.iter().map(|&a| EvalMethod::Without(a)));
    }
    if args.partial {
        methods.push(EvalMethod::Partial);
    }
    let jobs = args
        .jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let presets = match args.preset {
        Presets::Standard => vec![Preset::Standard],
        Presets::Hard => vec![Preset::Hard],
        Presets::Both => Preset::ALL.to_vec(),
    };
    let cfg = EvalConfig {
        pairs: args.pairs,
        first_seed: args.first_seed,
        presets,
        hard_without: args.hard_without.clone(),
        variants,
        methods,
        jobs,
        imaged: args.imaged,
    };
    // Progress rewrites one line on a terminal.
    let (quiet, tty) = (ctx.quiet, std::io::stderr().is_terminal());
    let mut line = |l: &str| match (quiet, tty) {
        (true, _) => {}
        (false, true) => eprint!("\r{l}   "),
        (false, false) => eprintln!("{l}"),
    };
    let r = if args.robustness {
        eval::robustness::run_robustness(&cfg, &args.out_dir, &mut line)
    } else {
        eval::run_eval(&cfg, &args.out_dir, &mut line)
    };
    if tty && !quiet {
        eprintln!();
    }
    let table = r?;
    println!("{table}\nwrote {}", args.out_dir.display());
    Ok(())
}
