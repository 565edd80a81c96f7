//! The text readers of clouds and waypoints: CSV clouds (with labels), waypoint CSV
//! (x,y,z or Slicer's label,l,p,s / label,r,a,s), bare point CSV and XYZ; the first byte
//! picks the reader.
#![no_main]
use libfuzzer_sys::fuzz_target;
use ribreg_sim::io;

fuzz_target!(|data: &[u8]| {
    let Some((which, text)) = ribreg_fuzz::tagged_text(data, 4) else {
        return;
    };
    match which {
        0 => {
            if let Ok(c) = io::parse_cloud_csv(text) {
                assert!(c.points.iter().flatten().all(|v| v.is_finite()));
            }
        }
        1 => {
            if let Ok(w) = io::parse_waypoints_csv(text) {
                assert!(w.labels.is_empty() || w.labels.len() == w.points.len());
            }
        }
        2 => {
            let _ = io::parse_points_csv(text);
        }
        _ => {
            let _ = io::parse_xyz(text);
        }
    }
});
