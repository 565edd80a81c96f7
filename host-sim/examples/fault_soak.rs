//! The link-fault soak: the whole quick procedure in-process (`ribreg hil --in-process
//! --quick --faults`) over many fault seeds, fault mixes and patients. A run passes when
//! every message was applied exactly once (the controller's counters equal the host's)
//! and the controller mapped the same waypoints, bit for bit, as a fault-free run of the
//! same patient. Prints the figures per mix; exits 1 on any failure.
//!
//! ```sh
//! cargo run --release -p ribreg-sim --example fault_soak -- [RUNS]   # default 100
//! ```

use ribreg_sim::hil::{self, FaultInjector, Faults, InProcess, RunOptions, Session};
use ribreg_sim::phantom::PhantomConfig;

/// Patients the runs cycle through.
const PATIENTS: u64 = 10;

fn mixes() -> Vec<(&'static str, Faults)> {
    let none = Faults::NONE;
    vec![
        ("2 % each", Faults::DEFAULT),
        (
            "10 % each",
            Faults {
                corrupt: 0.1,
                drop: 0.1,
                duplicate: 0.1,
                reorder: 0.1,
                garbage: 0.1,
            },
        ),
        (
            "20 % corrupt",
            Faults {
                corrupt: 0.2,
                ..none
            },
        ),
        ("20 % drop", Faults { drop: 0.2, ..none }),
        (
            "20 % duplicate",
            Faults {
                duplicate: 0.2,
                ..none
            },
        ),
        (
            "20 % reorder",
            Faults {
                reorder: 0.2,
                ..none
            },
        ),
        (
            "20 % garbage",
            Faults {
                garbage: 0.2,
                ..none
            },
        ),
    ]
}

#[derive(Default)]
struct Tally {
    runs: u64,
    failed: u64,
    sent: u64,
    resent: u64,
    nacks: u64,
    timeouts: u64,
    injected: [u64; 5],
    poses: u64,
    frames: u64,
}

fn main() {
    let runs: u64 = std::env::args()
        .nth(1)
        .map(|a| a.parse().expect("RUNS is a number"))
        .unwrap_or(100);
    let phantom = |p: u64| PhantomConfig {
        seed: p,
        ..PhantomConfig::default()
    };
    let t0 = std::time::Instant::now();
    // The fault-free reference of each patient.
    let reference: Vec<Vec<[f32; 3]>> = (0..PATIENTS.min(runs))
        .map(|p| {
            let r = hil::run_with(
                &mut Session::new(InProcess::new()),
                &phantom(p),
                RunOptions::quick(),
                &mut |_| {},
            )
            .expect("fault-free run");
            r.waypoints.iter().map(|w| w.mapped).collect()
        })
        .collect();
    let mixes = mixes();
    let mut tally: Vec<Tally> = mixes.iter().map(|_| Tally::default()).collect();
    for i in 0..runs {
        let (m, patient) = ((i as usize) % mixes.len(), i % PATIENTS);
        let mut session = Session::new(FaultInjector::new(InProcess::new(), mixes[m].1, i));
        let t = &mut tally[m];
        t.runs += 1;
        let outcome = hil::run_with(
            &mut session,
            &phantom(patient),
            RunOptions::quick(),
            &mut |_| {},
        );
        let why = match &outcome {
            Err(e) => Some(format!("failed: {e}")),
            Ok(r) if r.applied[0] != r.applied[2] || r.applied[1] != r.applied[3] => Some(format!(
                "applied poses {}/{}, frames {}/{}",
                r.applied[0], r.applied[2], r.applied[1], r.applied[3]
            )),
            Ok(r) if !r.refused.is_empty() => Some(format!("refused: {:?}", r.refused)),
            Ok(r)
                if r.waypoints
                    .iter()
                    .map(|w| w.mapped)
                    .ne(reference[patient as usize].iter().copied()) =>
            {
                Some("mapped waypoints differ from the fault-free run".into())
            }
            Ok(_) => None,
        };
        if let Ok(r) = &outcome {
            t.sent += r.link.sent;
            t.resent += r.link.resent;
            t.nacks += r.link.nacks;
            t.timeouts += r.link.timeouts;
            for (a, b) in t.injected.iter_mut().zip(r.link.injected) {
                *a += b;
            }
            t.poses += r.applied[2];
            t.frames += r.applied[3];
        }
        if let Some(why) = why {
            t.failed += 1;
            eprintln!(
                "run {i} (mix {}, patient {patient}, fault seed {i}): {why}",
                mixes[m].0
            );
        }
    }
    println!(
        "{:<15} {:>4} {:>6} {:>9} {:>8} {:>8} {:>6} {:>9} {:>8} {:>8}  faults injected: corrupt, drop, duplicate, reorder, garbage",
        "mix", "runs", "failed", "sent", "re-sent", "NACKs", "t/outs", "poses", "frames", "applied"
    );
    let mut failed = 0;
    for ((name, _), t) in mixes.iter().zip(&tally) {
        failed += t.failed;
        println!(
            "{name:<15} {:>4} {:>6} {:>9} {:>8} {:>8} {:>6} {:>9} {:>8} {:>8}  {:?}",
            t.runs,
            t.failed,
            t.sent,
            t.resent,
            t.nacks,
            t.timeouts,
            t.poses,
            t.frames,
            if t.failed == 0 { "once" } else { "NO" },
            t.injected
        );
    }
    println!(
        "soak: {runs} runs over {} mixes and {} patients, {failed} failed; every message applied once \
         and the waypoints equal to the fault-free run's in the others; {:.0} s",
        mixes.len(),
        PATIENTS.min(runs),
        t0.elapsed().as_secs_f64()
    );
    if failed > 0 {
        std::process::exit(1);
    }
}
