//! 3D Slicer's markups readers (`.mrk.json`, `.fcsv`) on arbitrary text; the first byte
//! picks the reader.
#![no_main]
use libfuzzer_sys::fuzz_target;
use ribreg_sim::io as markups;

fuzz_target!(|data: &[u8]| {
    let Some((which, text)) = ribreg_fuzz::tagged_text(data, 2) else {
        return;
    };
    let parsed = if which == 0 {
        markups::parse_markups_json(text)
    } else {
        markups::parse_fcsv(text)
    };
    if let Ok(w) = parsed {
        assert!(w.points.iter().flatten().all(|v| v.is_finite()));
    }
});
