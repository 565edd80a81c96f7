//! `ribreg hil`: the robot PC against the controller — in this process, on a serial
//! device or TCP port, or (default) the firmware under QEMU, then compared in-process
//! and held to its instruction and stack budgets.

use super::{Context, PhantomArgs, RobotArgs};
use ribreg_sim::error::CliError;
use ribreg_sim::hil::emulator::Board;
use ribreg_sim::hil::{
    self, Budgets, FaultInjector, Faults, HilReport, InProcess, Port, RunOptions, Session,
};
use ribreg_sim::phantom::PhantomConfig;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Run the controller in this process instead of the emulator (the default builds
    /// the firmware and runs it under qemu-system-arm, then compares with in-process).
    #[arg(long, conflicts_with = "port")]
    in_process: bool,
    /// A controller board on a serial device (`/dev/ttyUSB0`, `COM3`), or at HOST:PORT
    /// (a serial port exposed over TCP, such as the emulator's), instead of starting
    /// the emulator.
    #[arg(long)]
    port: Option<String>,
    /// Baud rate of a serial device: 921,600 by default, the rate the link budget
    /// recommends (the F405 build's USART1 runs at it; 115,200 does not carry the full
    /// sweep).
    #[arg(long, default_value_t = 921_600)]
    baud: u32,
    /// Inject link faults (corrupted, dropped, duplicated, reordered frames, garbage).
    #[arg(long)]
    faults: bool,
    /// Seed of the fault injection.
    #[arg(long, default_value_t = 1)]
    fault_seed: u64,
    /// A lighter sweep (lines 15 mm apart, 30 mm/s, every 8th column): a third of the
    /// bytes on the emulator's slow link.
    #[arg(long)]
    quick: bool,
    /// Configure a partial plan: the controller maps every waypoint, marks those the
    /// sweep does not reach and never drives there (by default it refuses the plan).
    #[arg(long)]
    partial: bool,
    /// How far each line of the simulated sweep runs past the cartilages' lateral
    /// extent, mm (default 20); negative, the lines stop that far inside it: a sweep
    /// band too narrow, which the controller should refuse (down to -60).
    #[arg(long, value_name = "MM", allow_negative_numbers = true)]
    sweep_margin_mm: Option<f64>,
    #[command(flatten)]
    robot: RobotArgs,
    /// The emulated board: `mps2-an386` (QEMU's MPS2, the default) or `f405` (the
    /// STM32F405 under QEMU's netduinoplus2).
    #[arg(long, default_value = "mps2-an386", value_parser = parse_board, conflicts_with_all = ["in_process", "port"])]
    board: Board,
    /// Write the firmware's defmt log (QEMU's semihosting output) here.
    #[arg(long)]
    defmt_log: Option<PathBuf>,
    #[command(flatten)]
    phantom: PhantomArgs,
    /// Also write the report as JSON.
    #[arg(long)]
    json: Option<PathBuf>,
}

pub fn run(args: &Args, ctx: &Context) -> Result<(), CliError> {
    let mut options = RunOptions {
        partial: args.partial,
        ..if args.quick {
            RunOptions::quick()
        } else {
            RunOptions::default()
        }
    };
    if let Some(margin) = args.sweep_margin_mm {
        options.sweep.margin_mm = margin;
    }
    options.sweep.base_yaw_deg = args.robot.base_yaw;
    let faults = args.faults.then_some((Faults::DEFAULT, args.fault_seed));
    let phantom = &args.phantom.config();
    let progress = &mut |l: &str| ctx.progress(l);
    // A serial device unless it looks like HOST:PORT (COM ports are devices).
    let serial = args
        .port
        .as_deref()
        .filter(|p| !p.contains(':') || p.starts_with("COM"));
    let (report, budgets) = if args.in_process {
        let r = run_on(InProcess::new(), faults, phantom, &options, progress)?;
        (r, None)
    } else if let Some(path) = serial {
        let port = hil::open_serial(path, args.baud)?;
        (run_on(port, faults, phantom, &options, progress)?, None)
    } else if let Some(addr) = &args.port {
        let port = hil::connect_tcp(addr)?;
        (run_on(port, faults, phantom, &options, progress)?, None)
    } else {
        let e = hil::run_emulated(
            args.board,
            faults,
            &options,
            args.defmt_log.clone(),
            phantom,
            progress,
        )?;
        let diff = e.mapped_difference();
        println!(
            "emulated vs in-process: mapped waypoints differ by at most {diff:.2e} mm; points {} vs {}",
            e.report.points, e.reference.points
        );
        if diff > 1e-2 || e.report.points != e.reference.points {
            return Err(CliError::Tolerance(format!(
                "the emulated controller disagrees with the in-process one by {diff} mm"
            )));
        }
        (e.report, Some((e.board, e.budgets)))
    };
    print_report(&report, budgets.as_ref());
    if let Some(path) = &args.json {
        let text =
            serde_json::to_string_pretty(&report).map_err(|e| CliError::Output(e.to_string()))?;
        ribreg_sim::io::write_text(path, &text)?;
    }
    let worst = report.max_error();
    let consistent =
        report.applied[0] == report.applied[2] && report.applied[1] == report.applied[3];
    if worst > hil::TOLERANCE_MM || !consistent {
        let message = format!(
            "procedure out of tolerance or inconsistent: worst waypoint {worst:.2} mm (tolerance {} mm), \
             applied poses {}/{} frames {}/{}",
            hil::TOLERANCE_MM,
            report.applied[0],
            report.applied[2],
            report.applied[1],
            report.applied[3]
        );
        // A message lost or applied twice is the link's failure, before any figure.
        return Err(if consistent {
            CliError::Tolerance(message)
        } else {
            CliError::Link(message)
        });
    }
    // The costs exist only where the firmware measured them (the emulator).
    if let Some((_, b)) = budgets {
        b.check()?;
    }
    Ok(())
}

fn parse_board(name: &str) -> Result<Board, String> {
    Board::from_name(name).ok_or_else(|| {
        let names: Vec<&str> = Board::ALL.iter().map(|b| b.name()).collect();
        format!("unknown board `{name}` (one of: {})", names.join(", "))
    })
}

/// The procedure over `port`, through a fault injector if `faults` is set.
fn run_on<P: Port>(
    port: P,
    faults: Option<(Faults, u64)>,
    phantom: &PhantomConfig,
    options: &RunOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<HilReport, CliError> {
    match faults {
        Some((f, seed)) => {
            let mut session = Session::new(FaultInjector::new(port, f, seed));
            hil::run_with(&mut session, phantom, options.clone(), progress)
        }
        None => hil::run_with(&mut Session::new(port), phantom, options.clone(), progress),
    }
}

fn print_report(r: &HilReport, budgets: Option<&(Board, Budgets)>) {
    println!("waypoint  mapped (x, y, z) mm               quality  probe error  across the gap  clearance");
    for (i, w) in r.waypoints.iter().enumerate() {
        if !w.supported {
            println!(
                "{i:>8}  ({:8.2}, {:8.2}, {:8.2})  {:6.2} mm  not driven: not reached by the sweep",
                w.mapped[0], w.mapped[1], w.mapped[2], w.quality_mm,
            );
            continue;
        }
        println!(
            "{i:>8}  ({:8.2}, {:8.2}, {:8.2})  {:6.2} mm  {:6.2} mm    {:+6.2} mm    {:6.2} mm",
            w.mapped[0],
            w.mapped[1],
            w.mapped[2],
            w.quality_mm,
            w.error_mm,
            w.across_gap_mm,
            w.clearance_mm
        );
    }
    let driven = r.driven().count();
    let mean = r.driven().map(|w| w.error_mm).sum::<f64>() / driven.max(1) as f64;
    let c = &r.cost;
    if c.registration_calls > 0 {
        let board = budgets.map_or(String::new(), |(b, _)| format!(" on {b}"));
        println!(
            "controller cost{board} (instructions, QEMU -icount): registration {} in {} steps (worst step {}), \
             worst control-loop turn {}, worst frame handling {}; peak stack {} B; serial: {} overruns, \
             {} framing errors, {} bytes dropped",
            c.registration_instructions,
            c.registration_calls,
            c.worst_step_instructions,
            c.worst_call_instructions,
            c.worst_receive_instructions,
            c.peak_stack_bytes,
            c.serial_overruns,
            c.serial_framing_errors,
            c.serial_dropped_bytes
        );
    }
    if let Some((_, b)) = budgets {
        println!("{}", b.summary());
    }
    println!(
        "hil: {} waypoints ({driven} driven to), probe error mean {mean:.2} mm, max {:.2} mm (tolerance {} mm), across \
         the gap max {:.2} mm (least clearance to a cartilage {:.1} mm); lag {:.1} ms; \
         {} points compounded; applied poses {}/{}, frames {}/{}; link: {} frames sent, {} re-sent, \
         {} NACKs, {} timeouts, faults injected {:?}; {:.1} s",
        r.waypoints.len(),
        r.max_error(),
        hil::TOLERANCE_MM,
        r.max_across_gap(),
        r.least_clearance(),
        r.lag_ms,
        r.points,
        r.applied[0],
        r.applied[2],
        r.applied[1],
        r.applied[3],
        r.link.sent,
        r.link.resent,
        r.link.nacks,
        r.link.timeouts,
        r.link.injected,
        r.wall_s
    );
}
