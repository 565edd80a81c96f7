//! `ribreg hil`: the robot PC's side of a whole procedure against the controller —
//! upload, sweep, register, execute — with a simulated robot and probe, over the real
//! wire protocol, to a controller in this process, in the emulator, or on a serial port.
//!
//! # What the procedure guarantees
//! [`run_with`] returns a [`HilReport`] only if every stage completed: the handshake and
//! upload acknowledged, every sweep message handled, all waypoints mapped, execution
//! ended with the controller `Done`, and a final status read. Then:
//! * Exactly once: every message the host sent was applied once or refused with an
//!   application NACK (listed in [`HilReport::refused`]); nothing is lost or applied
//!   twice whatever the link does — `applied` holds the controller's counters next to
//!   the host's, and the caller fails the run when they differ.
//! * Same order, same result: the controller sees the messages in the order sent, so a
//!   run over a faulty link (see [`faults`]) maps the same waypoints, bit for bit, as a
//!   fault-free one.
//! * The outcome per waypoint: the mapped waypoint, its quality figure, and the probe's
//!   aim point when the controller moved on, against the phantom's truth
//!   ([`WaypointOutcome`]); [`TOLERANCE_MM`] is the clinical bound the CLI holds it to.
//! * Against the emulator ([`run_emulated`]): the firmware's costs ([`HilReport::cost`])
//!   and, in [`Budgets`], their instruction and stack budgets; the same procedure
//!   in-process for comparison.
//!
//! Failures are [`CliError::Link`] (timeouts, a controller fault, a closed link),
//! [`CliError::Emulator`], or whatever the sweep simulation refused.
//!
//! # Layers
//! * [`port`]: the byte transport ([`Port`]): in-process, serial device, TCP.
//! * [`faults`]: [`FaultInjector`], a port wrapping a port with seeded link faults.
//! * [`session`]: the protocol engine ([`Session`]): sequence numbers, go-back-N.
//! * [`robot`]: the simulated robot and probe.
//! * [`procedure`]: the stages and the report.
//! * [`emulator`]: the firmware under QEMU.
//!
//! [`CliError::Link`]: crate::error::CliError::Link
//! [`CliError::Emulator`]: crate::error::CliError::Emulator

pub mod emulator;
pub mod faults;
pub mod port;
pub mod procedure;
pub mod robot;
pub mod session;

pub use faults::{FaultInjector, FaultStats, Faults};
pub use port::{connect_tcp, open_serial, InProcess, Port, Stream};
pub use procedure::{
    board_emulator_options, emulator_options, prepare, run, run_emulated, run_with, Budgets,
    Emulated, HilReport, Prepared, RunOptions, WaypointOutcome, MAX_ACCEL_MM_S2, MAX_SPEED_MM_S,
    REGISTRATION_BUDGET_INSTRUCTIONS, STACK_HEADROOM_BYTES, TOLERANCE_MM, TURN_BUDGET_INSTRUCTIONS,
};
pub use robot::{ROBOT_LAG_S, STANDOFF_MM};
pub use session::{LinkStats, Session, RESEND_AFTER, WINDOW};
