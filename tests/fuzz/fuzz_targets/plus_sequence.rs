//! The PLUS sequence reader (`.mha`/`.mhd` header, raw or zlib pixel data, per-frame
//! transforms) on arbitrary bytes: written to a file (the reader streams from one), then
//! opened and read to the end.
#![no_main]
use libfuzzer_sys::fuzz_target;
use ribreg_sim::io::plus::SequenceReader;
use std::path::PathBuf;

fn scratch() -> PathBuf {
    let dir = if std::path::Path::new("/dev/shm").is_dir() {
        PathBuf::from("/dev/shm")
    } else {
        std::env::temp_dir()
    };
    dir.join(format!("ribreg-fuzz-plus-{}.mha", std::process::id()))
}

fuzz_target!(|bytes: &[u8]| {
    let path = scratch();
    std::fs::write(&path, bytes).expect("scratch file");
    if let Ok(mut reader) = SequenceReader::open(&path, "ProbeToTracker") {
        for _ in 0..10_000 {
            match reader.next_frame() {
                Ok(Some(_)) => {}
                _ => break,
            }
        }
    }
});
