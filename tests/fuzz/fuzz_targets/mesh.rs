//! The mesh readers (OBJ, ascii and binary STL, PLY faces) and their `SPACE=`
//! declarations on arbitrary bytes; the first byte picks the format.
#![no_main]
use libfuzzer_sys::fuzz_target;
use ribreg_sim::io;

fuzz_target!(|data: &[u8]| {
    let Some((which, bytes)) = ribreg_fuzz::tagged(data, 3) else {
        return;
    };
    let ext = ["obj", "stl", "ply"][usize::from(which)];
    if let Ok(mesh) = io::parse_mesh(ext, bytes) {
        assert!(mesh.vertices.iter().flatten().all(|c| c.is_finite()));
        let n = mesh.vertices.len();
        assert!(mesh.triangles.iter().flatten().all(|&i| (i as usize) < n));
        let _ = io::mesh_space(ext, bytes);
    }
});
