//! The `ribreg` command line: the top-level parser, the arguments several subcommands
//! share, and the dispatch to one module per subcommand. Each subcommand's clap
//! definitions live in its own module, next to the code they configure; adding one is a
//! variant here and a module with its `Args` and `run`.

use clap::{Parser, Subcommand};
use ribreg_sim::error::CliError;
use ribreg_sim::phantom::{HardPart, PhantomConfig, Preset, Variant};
use ribreg_sim::register::RegisterJob;

mod calibrate;
mod compound;
mod demo;
mod eval;
mod hil;
mod phantom;
mod register;
mod sample;
mod template;

#[derive(Parser)]
#[command(
    name = "ribreg",
    version,
    about = "Skeleton-graph US-CT rib-cartilage registration"
)]
pub struct Cli {
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
    /// Make a labelled template cloud (and its prepared parts) from a CT labelmap, one
    /// mesh per part, or a point cloud.
    Template(ribreg_sim::template::TemplateJob),
    /// Poisson-disc sample a surface mesh (PLY, OBJ or STL) into a point cloud (PLY).
    Sample(sample::Args),
    /// Write a phantom pair (CT template, US target, waypoints, ground truth) to a folder,
    /// or (`phantom sweep`) the logs of a simulated robotic sweep over it.
    #[command(args_conflicts_with_subcommands = true)]
    Phantom(phantom::Args),
    /// Play the robot PC in a whole procedure against the controller (upload, sweep,
    /// register, execute) and report where the probe ended up at each waypoint.
    Hil(hil::Args),
    /// Calibrate the robotic US system.
    Calibrate(calibrate::Args),
    /// Compound a tracked sweep (poses + annotated frames) into a US cloud (PLY).
    Compound(compound::Args),
    /// Build the default phantom pair, register it and compare with the ground truth.
    Demo(demo::Args),
    /// Run ours (paper and improved) and the baselines on phantom pairs; write tables and figures.
    Eval(eval::Args),
}

/// What every subcommand gets besides its arguments.
pub struct Context {
    /// `--quiet`: no progress lines.
    pub quiet: bool,
}

impl Context {
    /// A progress line on stderr (`ribreg: ...`), unless quiet.
    pub fn progress(&self, line: &str) {
        if !self.quiet {
            eprintln!("ribreg: {line}");
        }
    }
}

impl Cli {
    /// Runs the subcommand.
    pub fn run(self) -> Result<(), CliError> {
        let ctx = Context { quiet: self.quiet };
        match self.command {
            Command::Register(job) => register::run(&job, &ctx),
            Command::Template(job) => template::run(&job, &ctx),
            Command::Sample(args) => sample::run(&args),
            Command::Phantom(args) => phantom::run(&args, &ctx),
            Command::Hil(args) => hil::run(&args, &ctx),
            Command::Calibrate(args) => calibrate::run(&args, &ctx),
            Command::Compound(args) => compound::run(&args, &ctx),
            Command::Demo(args) => demo::run(&args, &ctx),
            Command::Eval(args) => eval::run(&args, &ctx),
        }
    }
}

/// Where the simulated robot stands (`phantom sweep`, `hil`).
#[derive(clap::Args)]
pub struct RobotArgs {
    /// Where the robot stands: its base turned by this many degrees about the patient's
    /// anterior axis (90: beside the bed, 180: at its other end). Nothing tells the
    /// registration where it stands.
    #[arg(
        long,
        value_name = "DEG",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    pub base_yaw: f64,
}

/// The phantom a subcommand builds (`phantom`, `phantom sweep`, `demo`, `hil`).
#[derive(clap::Args)]
pub struct PhantomArgs {
    /// Seed of the patient, noise and pose.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Pose of the US target: a few degrees/mm, or up to ~20° and ~40 mm.
    #[arg(long, value_enum, default_value_t = Variant::Aligned)]
    variant: Variant,
    /// Family of phantoms: `standard` (every figure before the hard ones), or `hard`
    /// (wider patients, a longer sternum, tip holes, partly seen junctions, breathing).
    #[arg(long, value_enum, default_value_t = Preset::Standard)]
    preset: Preset,
    /// With `--preset hard`: difficulties to leave out, comma-separated (an ablation of
    /// the phantom).
    #[arg(long, value_enum, value_delimiter = ',')]
    hard_without: Vec<HardPart>,
}

impl PhantomArgs {
    /// The phantom's configuration.
    pub fn config(&self) -> PhantomConfig {
        PhantomConfig {
            seed: self.seed,
            variant: self.variant,
            preset: self.preset,
            hard_without: self.hard_without.clone(),
            ..PhantomConfig::default()
        }
    }
}
