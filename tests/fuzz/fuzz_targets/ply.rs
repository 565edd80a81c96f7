//! The PLY reader (ascii, binary little and big endian; clouds and every element) on
//! arbitrary bytes: an error or a cloud whose points are all finite, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
use ribreg_sim::io;

fuzz_target!(|bytes: &[u8]| {
    if let Ok(cloud) = io::parse_ply(bytes) {
        assert!(cloud.points.iter().flatten().all(|c| c.is_finite()));
        if let Some(l) = &cloud.labels {
            assert_eq!(l.len(), cloud.points.len());
        }
    }
    let _ = io::parse_ply_elements(bytes, &[]);
    let _ = io::parse_ply_elements(bytes, &["vertex"]);
});
