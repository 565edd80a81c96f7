//! The wire layer on arbitrary byte streams: the `Receiver` cuts frames (never longer
//! than `MAX_FRAME`), `decode` of each as either direction's message never panics, and a
//! frame that decodes re-encodes to a frame that decodes and re-encodes to the same
//! bytes (bytes, not messages: a NaN coordinate is kept but is not equal to itself; the
//! first fuzz finding, `regressions/wire-nan-node`, was this oracle's own mistake).
#![no_main]
use libfuzzer_sys::fuzz_target;
use ribreg_core::wire::{self, FromController, ToController, MAX_FRAME};

fuzz_target!(|bytes: &[u8]| {
    let mut rx = wire::Receiver::new();
    for &b in bytes {
        if let Some(Ok(frame)) = rx.push(b) {
            assert!(frame.len() < MAX_FRAME);
            let mut copy = frame.to_vec();
            if let Ok((seq, msg)) = wire::decode::<ToController>(frame) {
                let mut buf = [0u8; MAX_FRAME];
                let n = wire::encode(seq, &msg, &mut buf).expect("a decoded message re-encodes");
                let first = buf[..n].to_vec();
                let (seq2, back) =
                    wire::decode::<ToController>(&mut buf[..n - 1]).expect("and decodes");
                let mut again = [0u8; MAX_FRAME];
                let m = wire::encode(seq2, &back, &mut again).expect("and re-encodes");
                assert_eq!((seq2, &again[..m]), (seq, &first[..]));
            }
            let _ = wire::decode::<FromController>(&mut copy);
        }
    }
});
