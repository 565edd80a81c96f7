//! The serial link's budget, computed from the protocol's real encoded frames
//! (`ribreg_core::wire::encode`) at the baud rate the README recommends
//! ([`RECOMMENDED_BAUD`]):
//!
//! * bandwidth: the sweep's poses (100 Hz) and frames (30 fps) one way and their acks the
//!   other, then the executing phase's 100 Hz poses and setpoints with their acks, each
//!   within [`MARGIN`] of the link's capacity;
//! * no byte lost: the firmware's RX queue (`RX_QUEUE` in `firmware/src/serial.rs`, read
//!   from the source so the two cannot drift) against
//!   the procedure's real byte stream arriving back to back, with the loop's receive step
//!   draining it only every other turn and every turn as long as the budget allows
//!   (168,000 instructions at 168 MHz, the most `ribreg hil` accepts; measured worst:
//!   140,595 on the F405, 141,360 on MPS2), and the RX interrupt's latency, from the
//!   instructions its handler and the longest masked section take, within one byte time.
//!
//! Ten bits a byte on the wire (8N1). Instructions are taken as cycles at 168 MHz (one
//! per cycle), as in the firmware's budgets.

use ribreg_core::wire::{self, FromController, SetpointW, ToController, MAX_FRAME};
use ribreg_sim::hil::{prepare, robot, RunOptions};
use ribreg_sim::phantom::PhantomConfig;

/// The baud rate the README recommends for a board (and the F405 build's USART1 rate):
/// from APB2's 84 MHz, 16× oversampled, its divider is 0.02 % off. 115,200 baud
/// (11.5 kB/s) does not carry the default sweep's busiest second (16.6 kB).
const RECOMMENDED_BAUD: u32 = 921_600;
/// Bits on the wire per byte (start, 8 data, stop).
const BITS_PER_BYTE: u32 = 10;
/// Each direction must stay below this fraction of the link's capacity.
const MARGIN: f64 = 0.5;
/// Core clock of the F405, Hz; one instruction per cycle.
const CORE_HZ: f64 = 168e6;
/// The longest loop turn `ribreg hil` accepts, instructions.
const TURN_BUDGET: u64 = 168_000;
/// Usable slots of the firmware's RX queue: `RX_QUEUE` of `firmware/src/serial.rs`
/// (a `heapless::spsc::Queue`, capacity one less).
fn rx_capacity() -> usize {
    let source = include_str!("../../firmware/src/serial.rs");
    let line = source
        .lines()
        .find_map(|l| l.strip_prefix("pub const RX_QUEUE: usize = "))
        .expect("firmware/src/serial.rs defines RX_QUEUE");
    let slots: usize = line.trim_end_matches(';').parse().expect("a number");
    slots - 1
}
/// Instructions from a byte's arrival to its read, at most: the RX handler's entry and
/// its work per byte (critical section, queue push, register reads: under 150
/// instructions) behind the longest section with interrupts masked (the SysTick reading,
/// a WFI check, or one handler run that also refills TX: a few hundred). Taken as 1,000.
const IRQ_LATENCY: u64 = 1_000;

fn encoded_len_to(m: &ToController) -> usize {
    let mut buf = [0u8; MAX_FRAME];
    wire::encode(0x7FFF, m, &mut buf).expect("every message encodes")
}

fn encoded_len_from(m: &FromController) -> usize {
    let mut buf = [0u8; MAX_FRAME];
    wire::encode(0x7FFF, m, &mut buf).expect("every message encodes")
}

fn bytes_per_s(baud: u32) -> f64 {
    f64::from(baud) / f64::from(BITS_PER_BYTE)
}

/// The sweep's messages as the robot PC sends them, with their times (s): poses at their
/// timestamps, frames at theirs.
fn sweep(options: &RunOptions) -> Vec<(f64, usize)> {
    let prepared = prepare(&PhantomConfig::default(), &options.sweep).expect("sweep");
    robot::sweep_messages(&prepared.logs)
        .iter()
        .map(|m| {
            let t_us = match m {
                ToController::Pose(p) => p.t_us,
                ToController::Frame(f) => f.t_us,
                _ => 0,
            };
            (t_us as f64 * 1e-6, encoded_len_to(m))
        })
        .collect()
}

/// The largest acknowledgement (seq near u16::MAX: the longest varint).
fn ack_len() -> usize {
    encoded_len_from(&FromController::Ack { seq: u16::MAX })
}

#[test]
fn the_sweep_and_the_executing_phase_fit_the_recommended_baud() {
    let capacity = bytes_per_s(RECOMMENDED_BAUD);
    for (name, options) in [
        ("default", RunOptions::default()),
        ("quick", RunOptions::quick()),
    ] {
        let msgs = sweep(&options);
        let duration = msgs.last().map_or(0.0, |m| m.0) - msgs.first().map_or(0.0, |m| m.0);
        let to_controller: usize = msgs.iter().map(|m| m.1).sum();
        let acks = msgs.len() * ack_len();
        // The busiest second, not only the mean: frames cluster on the sweep's lines.
        let busiest = busiest_second(&msgs);
        let (mean_in, mean_out) = (to_controller as f64 / duration, acks as f64 / duration);
        eprintln!(
            "{name} sweep: {} messages over {duration:.1} s, {to_controller} B to the controller \
             ({mean_in:.0} B/s mean, {busiest} B in the busiest second), {acks} B of acks \
             ({mean_out:.0} B/s); link {capacity:.0} B/s at {RECOMMENDED_BAUD} baud: \
             {:.0} % and {:.0} % used at the busiest",
            msgs.len(),
            100.0 * busiest as f64 / capacity,
            100.0 * (busiest_count(&msgs) * ack_len()) as f64 / capacity,
        );
        assert!(busiest as f64 <= MARGIN * capacity, "{name}: {busiest} B/s");
        assert!(mean_out <= MARGIN * capacity);
    }

    // Executing: a 100 Hz pose stream in, 100 Hz setpoints out, each acked the other way.
    let pose = encoded_len_to(&ToController::Pose(wire::PoseW {
        t_us: u64::MAX,
        position: [f32::MAX; 3],
        quat: [f32::MAX; 4],
    }));
    let setpoint = encoded_len_from(&FromController::Setpoint(SetpointW {
        t_us: u64::MAX,
        position: [f32::MAX; 3],
        quat: [f32::MAX; 4],
        waypoint: u8::MAX,
    }));
    let (inward, outward) = (100 * (pose + ack_len()), 100 * (setpoint + ack_len()));
    eprintln!(
        "executing: {inward} B/s in ({pose}-byte poses), {outward} B/s out ({setpoint}-byte \
         setpoints): {:.1} % and {:.1} % of the link",
        100.0 * inward as f64 / capacity,
        100.0 * outward as f64 / capacity
    );
    assert!(inward as f64 <= MARGIN * capacity && outward as f64 <= MARGIN * capacity);
}

/// Bytes of the busiest one-second window of `msgs` (time, bytes).
fn busiest_second(msgs: &[(f64, usize)]) -> usize {
    window_max(msgs, |m| m.1)
}

/// Messages in the busiest one-second window.
fn busiest_count(msgs: &[(f64, usize)]) -> usize {
    window_max(msgs, |_| 1)
}

fn window_max(msgs: &[(f64, usize)], weight: impl Fn(&(f64, usize)) -> usize) -> usize {
    let (mut start, mut sum, mut best) = (0, 0, 0);
    for (end, m) in msgs.iter().enumerate() {
        sum += weight(m);
        while msgs[end].0 - msgs[start].0 >= 1.0 {
            sum -= weight(&msgs[start]);
            start += 1;
        }
        best = best.max(sum);
    }
    best
}

/// The loop's worst case replayed byte by byte: bytes arrive back to back at `baud`
/// (a message is sent at its time or when the previous one has left, whichever is
/// later); the queue is drained only at the start of every other turn of `turn`
/// instructions, up to the end of the first complete frame. Returns the fullest the
/// queue got.
fn replay(msgs: &[(f64, usize)], baud: u32, turn: u64) -> usize {
    let byte_s = 1.0 / bytes_per_s(baud);
    let turn_s = turn as f64 / CORE_HZ;
    // Arrival time of every byte, and where each frame ends.
    let mut arrivals = Vec::new();
    let mut frame_ends = Vec::new();
    let mut line_free = 0.0f64;
    for &(t, len) in msgs {
        let mut at = t.max(line_free);
        for _ in 0..len {
            at += byte_s;
            arrivals.push(at);
        }
        line_free = at;
        frame_ends.push(arrivals.len());
    }
    let (mut read, mut next_end, mut fullest) = (0usize, 0usize, 0usize);
    let mut arrived = 0usize;
    // Drains two turns apart: the receive turn and the polling turn after it.
    let mut now = arrivals.first().copied().unwrap_or(0.0);
    while read < arrivals.len() {
        now += 2.0 * turn_s;
        while arrived < arrivals.len() && arrivals[arrived] <= now {
            arrived += 1;
        }
        fullest = fullest.max(arrived - read);
        // Up to the end of the first complete frame (or all that arrived).
        while next_end < frame_ends.len() && frame_ends[next_end] <= read {
            next_end += 1;
        }
        read = match frame_ends.get(next_end) {
            Some(&end) if end <= arrived => end,
            _ => arrived,
        };
    }
    fullest
}

#[test]
fn no_byte_is_lost_while_the_longest_call_runs() {
    let byte_instructions =
        (f64::from(BITS_PER_BYTE) / f64::from(RECOMMENDED_BAUD) * CORE_HZ) as u64;
    eprintln!(
        "a byte lasts {byte_instructions} instructions at {RECOMMENDED_BAUD} baud; the RX \
         interrupt answers within {IRQ_LATENCY}"
    );
    // The handler reads each byte before the next one completes (else ORE).
    assert!(IRQ_LATENCY < byte_instructions);

    // Back to back for the whole of the longest gap between two drains.
    let capacity = rx_capacity();
    let gap_bytes = (2.0 * TURN_BUDGET as f64 / CORE_HZ * bytes_per_s(RECOMMENDED_BAUD)).ceil();
    eprintln!("two turns of {TURN_BUDGET} instructions: {gap_bytes} bytes, queue {capacity}");
    assert!(gap_bytes as usize <= capacity);

    // The procedure's real stream, as fast as the link carries it.
    for (name, options) in [
        ("default", RunOptions::default()),
        ("quick", RunOptions::quick()),
    ] {
        let fullest = replay(&sweep(&options), RECOMMENDED_BAUD, TURN_BUDGET);
        eprintln!(
            "{name} sweep at {RECOMMENDED_BAUD} baud, every turn {TURN_BUDGET} instructions: \
             the RX queue holds at most {fullest} of {capacity} bytes"
        );
        assert!(fullest <= capacity, "{name}: {fullest}");
    }
}
