//! The text readers of clouds and waypoints: CSV clouds (with labels), waypoint CSV
//! (x,y,z or Slicer's label,l,p,s / label,r,a,s), bare point CSV, XYZ, and a sweep's
//! imaged lines (`compound --imaged`); the first byte picks the reader.
#![no_main]
use libfuzzer_sys::fuzz_target;
use ribreg_sim::io;

fuzz_target!(|data: &[u8]| {
    let Some((which, text)) = ribreg_fuzz::tagged_text(data, 5) else {
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
        3 => {
            let _ = io::parse_xyz(text);
        }
        _ => {
            if let Ok(area) = ribreg_sim::sweep::parse_imaged(text) {
                assert!(area.line_count() <= ribreg_core::limits::IMAGED_LINES);
                let p = ribreg_core::Vec3::new(1.0, 2.0, 3.0);
                let r = area.reach(&p, &ribreg_core::Vec3::new(1.0, 0.0, 0.0), 20.0);
                assert!((0.0..=20.0).contains(&r), "{r}");
            }
        }
    }
});
