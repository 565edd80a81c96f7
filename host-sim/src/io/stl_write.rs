//! Writing a mesh as binary STL the way 3D Slicer exports a segment: the vertices in
//! LPS or RAS and `SPACE=LPS` / `SPACE=RAS` in the 80-byte header, so a reader that
//! honours the header ([`super::read_mesh_in`]) gets the patient frame back.

use std::path::Path;

use super::{check_mesh, write_atomic, FormatError, IoError, Mesh, Space};

/// Write `mesh` (patient frame) to `path` as binary STL in `space`, atomically.
///
/// # Errors
/// With `path` left untouched: [`IoError::Format`] for an empty mesh, a non-finite
/// vertex or an index out of range, or more triangles than STL's `u32` count;
/// [`IoError::Io`] if the file cannot be written.
pub fn write_mesh_stl(path: &Path, mesh: &Mesh, space: Space) -> Result<(), IoError> {
    check_mesh(mesh).map_err(|e| e.with_path(path))?;
    let count = u32::try_from(mesh.triangles.len()).map_err(|_| {
        IoError::from(FormatError::TooManyVertices(mesh.triangles.len())).with_path(path)
    })?;
    write_atomic(path, |out| {
        let mut header = [b' '; 80];
        let text = format!("ribreg SPACE={}", space.name());
        header[..text.len()].copy_from_slice(text.as_bytes());
        out.write_all(&header)?;
        out.write_all(&count.to_le_bytes())?;
        for t in &mesh.triangles {
            let v = t.map(|i| space.from_patient(mesh.vertices[i as usize]));
            let e1 = [0, 1, 2].map(|a| v[1][a] - v[0][a]);
            let e2 = [0, 1, 2].map(|a| v[2][a] - v[0][a]);
            let n = [
                e1[1] * e2[2] - e1[2] * e2[1],
                e1[2] * e2[0] - e1[0] * e2[2],
                e1[0] * e2[1] - e1[1] * e2[0],
            ];
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt().max(1e-30);
            for c in n {
                out.write_all(&((c / len) as f32).to_le_bytes())?;
            }
            for p in v {
                for c in p {
                    out.write_all(&(c as f32).to_le_bytes())?;
                }
            }
            out.write_all(&[0, 0])?;
        }
        Ok(())
    })
}
