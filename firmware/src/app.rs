//! The application: set-up, then one loop that serves the robot PC over the board's
//! serial port ([`crate::board::Serial`]) and runs `ribreg_core::controller::Controller`.
//! The same on every board; the board layer supplies the port and the SysTick clock.
//!
//! ## What runs when
//!
//! * At boot (`main` before its loop): SysTick starts and is calibrated
//!   (`meter::Meter::start`), the board's serial port is set up
//!   (`board::take_serial`: clocks, pins, UART, interrupts), the controller (a static of
//!   about 85 KB, const-initialised in place, never on the stack) is taken.
//! * Every loop turn, in this order:
//!   1. **receive** (`link::Link::receive`): the bytes that have arrived, up to the
//!      first complete frame, which goes to `Controller::receive`; skipped in the turn
//!      right after one that took a frame, so under a burst receiving and polling
//!      alternate and the rest waits in the link. `QUIT` ends the run here
//!      (`exit::quit`).
//!   2. **poll** (`poll`): in a turn that took no frame, and in every turn while
//!      executing, one `Controller::poll`: one bounded registration step, queued sweep
//!      points, the setpoints and the pose watchdog.
//!   3. **flush** (`link::Link::flush`): every queued reply is encoded and sent.
//!   4. **account** (`meter::Meter::end_turn`): the turn's cost, handed to the
//!      controller for `Command::Cost`.
//!   5. **sleep** (`link::Link::sleep`): nothing to do (`Controller::busy` false, no
//!      byte waiting) sleeps in WFI until a byte arrives; while executing, until a byte
//!      or the next 1 ms SysTick wrap, so the setpoints and the watchdog keep time.
//!
//! ## Deadlines
//!
//! * Every controller call (one receive or one poll) stays within
//!   `meter::LONG_CALL` = 168,000 instructions, 1 ms at 168 MHz (assuming one
//!   instruction per cycle); so does a whole turn, which makes at most one receive and
//!   one poll (both only while executing). A call or turn above it is logged when it
//!   happens (`long receive`, `long poll`, `long turn`); the worst cases are reported on
//!   `Command::Cost` and at `QUIT`. Counted in instructions from SysTick under
//!   `qemu-system-arm -icount shift=0`, with the instructions per tick calibrated at
//!   boot (40 on MPS2's 25 MHz SysTick, about 5.95 on the F405's 168 MHz).
//! * Poses arrive at 100 Hz (10 ms period) and setpoints go out at 100 Hz
//!   (`SETPOINT_PERIOD_US`): with turns of at most 1 ms and receive and poll
//!   alternating, a pose frame waits at most about two turns, and the executing poll
//!   runs every turn, well inside the period and the 50 ms pose watchdog
//!   (`POSE_TIMEOUT_US`).
//!
//! ## Ending
//!
//! A frame whose bytes are exactly `QUIT` (never valid COBS) logs the measurements
//! through defmt and exits the emulator with success; a panic or HardFault logs and exits
//! with failure (`exit`).

use crate::board;
use crate::cost;
use crate::link::Link;
use crate::meter::Meter;
use cortex_m_rt::entry;
use defmt_semihosting as _;
use ribreg_core::controller::Controller;
use ribreg_core::limits::CONTROLLER_VOXELS;
use ribreg_core::wire::State;
use static_cell::ConstStaticCell;

defmt::timestamp!("{=u64}", cost::now_ticks());

/// The controller. `Controller::new` is `const`, so the cell's initial value is part of
/// `.data` (copied from flash by the reset handler): the controller is built in place and
/// never passes through the stack.
static CONTROLLER: ConstStaticCell<Controller<CONTROLLER_VOXELS>> =
    ConstStaticCell::new(Controller::new());

/// Set-up, then the loop (see the module documentation for what runs when); every call
/// and turn within 168,000 instructions.
#[entry]
fn main() -> ! {
    let Some(cp) = cortex_m::Peripherals::take() else {
        panic!("core peripherals taken twice");
    };
    let mut meter = Meter::start(cp.SYST);
    let mut link = Link::new(board::take_serial());
    let Some(controller) = CONTROLLER.try_take() else {
        panic!("controller taken twice");
    };

    let mut received = false;
    loop {
        meter.start_turn();
        let now = cost::now_us();
        received = !received && link.receive(controller, &mut meter, now);
        poll(controller, &mut meter, received);
        let replies = link.flush(controller);
        meter.end_turn(controller, replies);
        link.sleep(controller);
    }
}

/// One bounded step of the periodic work, unless this turn handed a frame over
/// (`received`); while executing, always.
fn poll(controller: &mut Controller<CONTROLLER_VOXELS>, meter: &mut Meter, received: bool) {
    meter.track_registration(controller.state());
    if !received || controller.state() == State::Executing {
        meter.poll(controller);
    }
}
