//! The PCD reader (ascii, binary, binary_compressed with LZF) on arbitrary bytes.
#![no_main]
use libfuzzer_sys::fuzz_target;
use ribreg_sim::io;

fuzz_target!(|bytes: &[u8]| {
    if let Ok(c) = io::parse_pcd(bytes) {
        assert!(c.points.iter().flatten().all(|v| v.is_finite()));
    }
});
