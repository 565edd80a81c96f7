//! The labelmap readers (NIfTI-1, NRRD incl. `.seg.nrrd`) on arbitrary bytes; the first
//! byte picks the reader. Sizes are checked before allocating, so a header that declares
//! a huge volume is an error, not an out-of-memory.
#![no_main]
use libfuzzer_sys::fuzz_target;
use ribreg_sim::io::volume;

fuzz_target!(|data: &[u8]| {
    let Some((which, bytes)) = ribreg_fuzz::tagged(data, 2) else {
        return;
    };
    let parsed = if which == 0 {
        volume::parse_nifti(bytes)
    } else {
        volume::parse_nrrd(bytes)
    };
    if let Ok(v) = parsed {
        assert_eq!(v.labels.len(), v.dims.iter().product::<usize>());
    }
});
