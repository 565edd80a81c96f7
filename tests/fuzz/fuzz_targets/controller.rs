//! The controller fed arbitrary traffic in every state: a fresh one or a snapshot along
//! a recorded whole procedure (chosen by the first byte), then messages with the
//! expected or any sequence number, raw garbage and time passing. No panic, every frame
//! answered, nothing applied out of order or twice, and it still answers at the end.
#![no_main]
use libfuzzer_sys::fuzz_target;
use ribreg_fuzz::{parse_ops, start};

fuzz_target!(|data: &[u8]| {
    let Some((&k, rest)) = data.split_first() else {
        return;
    };
    let mut run = start(k);
    for op in parse_ops(rest).iter().take(512) {
        run.step(op);
    }
    run.check_answers();
});
