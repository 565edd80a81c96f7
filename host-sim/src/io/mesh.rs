//! Surface meshes: reading PLY, OBJ and STL by extension; writing OBJ (PLY
//! writing lives with the PLY code).

use std::collections::HashMap;
use std::path::Path;

use super::ply::{parse_ply_mesh, Bytes, Scalar};
use super::{
    check_mesh, content_lines, excerpt, parse_point, push_fan, read_bytes, text, write_atomic,
};
use super::{FormatError, IoError, Location, Mesh, PlyFormat, Space};

/// Read a triangle mesh from `path`, choosing the format by extension
/// (case-insensitive):
///
/// - `.ply`: ASCII or binary little-endian, `vertex` (x, y, z) and `face`
///   (`vertex_indices`) elements; polygons are fan-triangulated.
/// - `.obj`: `v` and `f` statements (`i`, `i/j`, `i/j/k`, `i//k`, negative indices
///   relative to the vertices so far); polygons are fan-triangulated; other
///   statements (`vn`, `vt`, `o`, `g`, `s`, `usemtl`, `mtllib`...) are ignored.
/// - `.stl`: binary when the size is exactly `84 + 50 × count`, else ASCII when it
///   starts with `solid`; identical vertices are merged into an indexed mesh.
///
/// # Errors
///
/// All with the path attached: [`IoError::Io`] if the file cannot be read;
/// [`IoError::Format`] for an unknown extension, malformed content (see
/// [`parse_ply`](super::parse_ply) for PLY), a non-finite coordinate, a face index out of
/// range, a face with fewer than three corners, no vertices or no triangles.
pub fn read_mesh(path: &Path) -> Result<Mesh, IoError> {
    let extension = extension_of(path);
    check_extension(&extension).map_err(|e| e.with_path(path))?;
    parse_mesh(&extension, &read_bytes(path)?).map_err(|e| e.with_path(path))
}

/// The lower-case extension of `path` (empty if none).
fn extension_of(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

fn check_extension(extension: &str) -> Result<(), IoError> {
    match extension {
        "ply" | "obj" | "stl" => Ok(()),
        _ => Err(IoError::from(FormatError::UnknownExtension(
            extension.to_string(),
        ))),
    }
}

/// Parses the bytes of a mesh file whose (lower-case) extension is `extension` (`ply`,
/// `obj` or `stl`), in the file's coordinates: what [`read_mesh`] does after reading
/// the file, and the entry point for untrusted bytes (fuzzed in `tests/fuzz`).
///
/// # Errors
/// Those of [`read_mesh`], without a path.
pub fn parse_mesh(extension: &str, bytes: &[u8]) -> Result<Mesh, IoError> {
    check_extension(extension)?;
    match extension {
        "ply" => parse_ply_mesh(bytes),
        "obj" => parse_obj(text(bytes, 1)?),
        _ => parse_stl(bytes),
    }
}

/// Read a triangle mesh as [`read_mesh`] does and bring its vertices into ribreg's
/// patient frame, from the coordinate system the file declares or else `default`.
/// Returns the mesh (patient frame) and the space that was converted from.
///
/// The declaration is a `SPACE=LPS` or `SPACE=RAS` token (as 3D Slicer writes it, any
/// case of the value) in:
///
/// - an STL file's header: the 80-byte header of a binary STL, the `solid` line of an
///   ASCII one;
/// - a PLY header `comment` (or `obj_info`) line, e.g. `comment SPACE=LPS`;
/// - an OBJ comment line, e.g. `# SPACE=LPS`.
///
/// The first declaration found counts. Pass `default` = [`Space::Patient`] for files
/// known to be in ribreg's frame already (ribreg's own output). The conversion is a
/// proper rotation, so triangle orientation is kept.
///
/// # Errors
///
/// Those of [`read_mesh`], and [`FormatError::UnknownSpace`] (with the path) for a
/// `SPACE=` value other than RAS or LPS.
pub fn read_mesh_in(path: &Path, default: Space) -> Result<(Mesh, Space), IoError> {
    let extension = extension_of(path);
    check_extension(&extension).map_err(|e| e.with_path(path))?;
    let bytes = read_bytes(path)?;
    let mut mesh = parse_mesh(&extension, &bytes).map_err(|e| e.with_path(path))?;
    let space = mesh_space(&extension, &bytes)
        .map_err(|kind| IoError::from(kind).with_path(path))?
        .unwrap_or(default);
    for v in &mut mesh.vertices {
        *v = space.to_patient(*v);
    }
    Ok((mesh, space))
}

/// The space a mesh file of this (lower-case) extension declares (see [`read_mesh_in`]),
/// if any; meant for bytes [`parse_mesh`] accepted.
///
/// # Errors
/// [`FormatError::UnknownSpace`] for a `SPACE=` value other than RAS or LPS.
pub fn mesh_space(extension: &str, bytes: &[u8]) -> Result<Option<Space>, FormatError> {
    let lines = || bytes.split(|&b| b == b'\n').map(<[u8]>::trim_ascii);
    match extension {
        "stl" => {
            let binary = bytes
                .get(80..84)
                .and_then(|b| b.try_into().ok())
                .map(u32::from_le_bytes)
                .is_some_and(|n| 84 + 50 * u64::from(n) == bytes.len() as u64);
            if binary {
                find_space(bytes.get(..80).unwrap_or_default())
            } else {
                find_space(lines().find(|l| !l.is_empty()).unwrap_or_default())
            }
        }
        "ply" => {
            for line in lines().take_while(|l| *l != b"end_header") {
                if line.starts_with(b"comment") || line.starts_with(b"obj_info") {
                    if let Some(space) = find_space(line)? {
                        return Ok(Some(space));
                    }
                }
            }
            Ok(None)
        }
        _ => {
            for line in lines().filter(|l| l.starts_with(b"#")) {
                if let Some(space) = find_space(line)? {
                    return Ok(Some(space));
                }
            }
            Ok(None)
        }
    }
}

/// [`mesh_space`] of every kind, for the fixture tests' garbage runs.
#[cfg(test)]
pub(super) fn tests_declared_space(bytes: &[u8]) -> Vec<Result<Option<Space>, FormatError>> {
    ["stl", "ply", "obj"]
        .iter()
        .map(|e| mesh_space(e, bytes))
        .collect()
}

/// The value of the first `SPACE=` token in `text` (not preceded by a letter or digit):
/// RAS or LPS, any case.
fn find_space(text: &[u8]) -> Result<Option<Space>, FormatError> {
    const KEY: &[u8] = b"SPACE=";
    let mut from = 0;
    while let Some(i) = text
        .get(from..)
        .and_then(|rest| rest.windows(KEY.len()).position(|w| w == KEY))
    {
        let start = from + i;
        from = start + KEY.len();
        if start > 0 && text[start - 1].is_ascii_alphanumeric() {
            continue;
        }
        let value: Vec<u8> = text[from..]
            .iter()
            .copied()
            .take_while(|b| b.is_ascii_alphanumeric() || *b == b'-' || *b == b'_')
            .take(40)
            .collect();
        let value = String::from_utf8_lossy(&value).into_owned();
        return match value.to_ascii_uppercase().as_str() {
            "RAS" => Ok(Some(Space::Ras)),
            "LPS" => Ok(Some(Space::Lps)),
            _ => Err(FormatError::UnknownSpace(value)),
        };
    }
    Ok(None)
}

/// Write `mesh` to `path` as Wavefront OBJ (`v x y z` lines, then 1-based
/// `f a b c` lines), atomically.
///
/// # Errors
///
/// With `path` left untouched: [`IoError::Format`] for no vertices or no
/// triangles, a non-finite coordinate, or an index out of range; [`IoError::Io`]
/// if the file cannot be written.
pub fn write_mesh_obj(path: &Path, mesh: &Mesh) -> Result<(), IoError> {
    check_mesh(mesh).map_err(|e| e.with_path(path))?;
    write_atomic(path, |out| {
        writeln!(out, "# ribreg mesh, units mm")?;
        for v in &mesh.vertices {
            writeln!(out, "v {} {} {}", v[0], v[1], v[2])?;
        }
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| u64::from(i) + 1);
            writeln!(out, "f {a} {b} {c}")?;
        }
        Ok(())
    })
}

/// Parse Wavefront OBJ text (see [`read_mesh`]).
fn parse_obj(text: &str) -> Result<Mesh, IoError> {
    let mut mesh = Mesh::default();
    let mut corners = Vec::new();
    for (n, line) in content_lines(text, 1) {
        let at = |kind| IoError::format(kind, Some(Location::Line(n)));
        // `#` starts a comment, also after a statement.
        let statement = line.split('#').next().unwrap_or_default();
        let mut words = statement.split_whitespace();
        match words.next() {
            Some("v") => {
                let coords: Vec<&str> = words.take(3).collect();
                mesh.vertices.push(parse_point(&coords).map_err(at)?);
            }
            Some("f") => {
                corners.clear();
                for word in words {
                    corners.push(obj_index(word, mesh.vertices.len()).map_err(at)?);
                }
                push_fan(&mut mesh.triangles, &corners).map_err(at)?;
            }
            _ => {}
        }
    }
    finish(mesh)
}

/// Resolve one `f` corner (`i`, `i/j`, `i/j/k`, `i//k`) to a 0-based vertex
/// index, given the number of vertices defined so far.
fn obj_index(word: &str, vertices: usize) -> Result<u32, FormatError> {
    let bad = || FormatError::Syntax(format!("bad face corner \"{}\"", excerpt(word)));
    let mut parts = word.split('/');
    let first = parts.next().unwrap_or_default();
    if parts.count() > 2 {
        return Err(bad());
    }
    let index: i64 = first.parse().map_err(|_| bad())?;
    let count = i64::try_from(vertices).unwrap_or(i64::MAX);
    let resolved = if index < 0 { count + index } else { index - 1 };
    if index == 0 || resolved < 0 || resolved >= count {
        return Err(FormatError::IndexOutOfRange { index, vertices });
    }
    u32::try_from(resolved).map_err(|_| FormatError::TooManyVertices(vertices))
}

/// Parse an STL file, binary or ASCII (see [`read_mesh`]).
fn parse_stl(bytes: &[u8]) -> Result<Mesh, IoError> {
    let len = bytes.len() as u64;
    let declared = bytes
        .get(80..84)
        .and_then(|b| b.try_into().ok())
        .map(u32::from_le_bytes);
    if let Some(count) = declared {
        if 84 + 50 * u64::from(count) == len {
            return parse_binary_stl(&bytes[84..], count);
        }
    }
    // ASCII only if it says so and is text; a binary file of the wrong size whose
    // header happens to start with "solid" gets the size error.
    let is_text = !bytes.contains(&0) && std::str::from_utf8(bytes).is_ok();
    if bytes.trim_ascii_start().starts_with(b"solid") && is_text {
        parse_ascii_stl(text(bytes, 1)?)
    } else {
        Err(FormatError::NotStl { len, declared }.into())
    }
}

/// Merges vertices with bitwise-identical coordinates (`-0.0` counted as `0.0`).
#[derive(Default)]
struct VertexMerger {
    mesh: Mesh,
    index: HashMap<[u64; 3], u32>,
}

impl VertexMerger {
    /// Index of `p`, adding it if new.
    fn insert(&mut self, p: [f64; 3]) -> Result<u32, FormatError> {
        if !p.iter().all(|c| c.is_finite()) {
            return Err(FormatError::NotFinite);
        }
        let key = p.map(|c| (c + 0.0).to_bits());
        if let Some(&i) = self.index.get(&key) {
            return Ok(i);
        }
        let i = u32::try_from(self.mesh.vertices.len())
            .map_err(|_| FormatError::TooManyVertices(self.mesh.vertices.len()))?;
        self.mesh.vertices.push(p);
        self.index.insert(key, i);
        Ok(i)
    }
}

/// Binary STL body: per triangle a normal (ignored), three vertices (f32 x, y, z)
/// and a 2-byte attribute.
fn parse_binary_stl(body: &[u8], count: u32) -> Result<Mesh, IoError> {
    let mut bytes = Bytes::new(body);
    let mut merger = VertexMerger::default();
    // The file size matches the count exactly, so the count is safe to reserve.
    let expected = count as usize;
    merger.mesh.triangles.reserve(expected);
    for t in 0..expected {
        let at = |kind| IoError::format(kind, Some(Location::item("triangle", t)));
        let truncated = || FormatError::Truncated {
            format: PlyFormat::BinaryLittleEndian,
            element: "triangle".to_owned(),
            read: t,
            expected,
        };
        let mut values = [0.0; 12];
        for v in &mut values {
            *v = Scalar::F32.read_le(&mut bytes).ok_or_else(truncated)?;
        }
        bytes.take::<2>().ok_or_else(truncated)?;
        let mut corners = [0; 3];
        for (corner, p) in corners.iter_mut().zip(values[3..].chunks_exact(3)) {
            *corner = merger.insert([p[0], p[1], p[2]]).map_err(at)?;
        }
        merger.mesh.triangles.push(corners);
    }
    finish(merger.mesh)
}

/// What an ASCII STL parser expects next.
#[derive(Clone, Copy, PartialEq, Eq)]
enum StlState {
    /// Before `solid`, or after `endsolid`.
    Outside,
    /// Inside a solid: `facet` or `endsolid`.
    Solid,
    /// After `facet normal ...`: `outer loop`.
    Facet,
    /// Inside the loop: `vertex` or `endloop`.
    Loop,
    /// After `endloop`: `endfacet`.
    EndLoop,
}

/// ASCII STL: `solid` … `facet normal` / `outer loop` / `vertex x y z` … /
/// `endloop` / `endfacet` … `endsolid`. Loops with more than three vertices are
/// fan-triangulated; several solids are merged; a missing final `endsolid` is
/// tolerated.
fn parse_ascii_stl(text: &str) -> Result<Mesh, IoError> {
    use StlState as S;
    let mut merger = VertexMerger::default();
    let mut corners = Vec::new();
    let mut state = S::Outside;
    for (n, line) in content_lines(text, 1) {
        let at = |kind| IoError::format(kind, Some(Location::Line(n)));
        let mut words = line.split_whitespace();
        let keyword = words.next().unwrap_or_default();
        state = match (state, keyword) {
            (S::Outside, "solid") => S::Solid,
            (S::Solid, "facet") => S::Facet,
            (S::Solid, "endsolid") => S::Outside,
            (S::Facet, "outer") if words.next() == Some("loop") => {
                corners.clear();
                S::Loop
            }
            (S::Loop, "vertex") => {
                let coords: Vec<&str> = words.collect();
                let p = parse_point(&coords).map_err(at)?;
                corners.push(merger.insert(p).map_err(at)?);
                S::Loop
            }
            (S::Loop, "endloop") => {
                push_fan(&mut merger.mesh.triangles, &corners).map_err(at)?;
                S::EndLoop
            }
            (S::EndLoop, "endfacet") => S::Solid,
            (state, _) => {
                let expected = match state {
                    S::Outside => "\"solid\"",
                    S::Solid => "\"facet\" or \"endsolid\"",
                    S::Facet => "\"outer loop\"",
                    S::Loop => "\"vertex\" or \"endloop\"",
                    S::EndLoop => "\"endfacet\"",
                };
                return Err(at(FormatError::Syntax(format!(
                    "expected {expected}, found \"{}\"",
                    excerpt(line)
                ))));
            }
        };
    }
    if !matches!(state, S::Outside | S::Solid) {
        return Err(FormatError::Syntax("file ends inside a facet".to_owned()).into());
    }
    finish(merger.mesh)
}

/// A parsed mesh must have vertices and triangles.
fn finish(mesh: Mesh) -> Result<Mesh, IoError> {
    if mesh.vertices.is_empty() {
        Err(FormatError::NoPoints.into())
    } else if mesh.triangles.is_empty() {
        Err(FormatError::NoTriangles.into())
    } else {
        Ok(mesh)
    }
}

/// Write `mesh` as binary STL the way 3D Slicer exports a segment: the vertices in
/// `space` and `SPACE=LPS` / `SPACE=RAS` in the 80-byte header, so that
/// [`read_mesh_in`] gets the patient frame back.
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

#[cfg(test)]
mod tests {
    use super::*;

    fn obj_err(text: &str) -> String {
        parse_obj(text).unwrap_err().to_string()
    }

    const OBJ: &str = "# a square and friends\nmtllib x.mtl\no thing\n\
        v 0 0 0\nv 1 0 0 1.0\nv 1 1 0 0.5 0.5 0.5\nv 0 1 0\nvt 0 0\nvn 0 0 1\n\
        g group\ns off\nusemtl mat\n\
        f 1 2 3\nf 1/1 3/1 4/1\nf 1/1/1 2/1/1 3/1/1\nf 1//1 2//1 4//1\n\
        f -4 -3 -2 -1\nv 5 5 -5.5\r\nf -1 1 2 # inline comment\r\n";

    #[test]
    fn obj_index_forms_negative_indices_and_quads() {
        let mesh = parse_obj(OBJ).unwrap();
        assert_eq!(
            mesh.vertices,
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
                [5.0, 5.0, -5.5]
            ]
        );
        assert_eq!(
            mesh.triangles,
            vec![
                [0, 1, 2],
                [0, 2, 3],
                [0, 1, 2],
                [0, 1, 3],
                [0, 1, 2], // quad, first half
                [0, 2, 3], // quad, second half
                [4, 0, 1],
            ]
        );
    }

    #[test]
    fn obj_errors_name_the_line() {
        let v = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n";
        let cases = [
            (
                "f 1 2 9\n",
                "line 5: vertex index 9 is out of range for 4 vertices",
            ),
            (
                "f 0 1 2\n",
                "line 5: vertex index 0 is out of range for 4 vertices",
            ),
            (
                "f -5 1 2\n",
                "line 5: vertex index -5 is out of range for 4 vertices",
            ),
            ("f 1 2 3/1/1/1\n", "line 5: bad face corner \"3/1/1/1\""),
            ("f 1 b 3\n", "line 5: bad face corner \"b\""),
            (
                "f 1 2\n",
                "line 5: face has 2 corners, at least 3 are needed",
            ),
            ("v 1 2\n", "line 5: expected 3 numbers, found 2"),
            ("v 1 NaN 2\n", "line 5: coordinate is not finite"),
            ("v 1 x 2\n", "line 5: \"x\" is not a number"),
        ];
        for (tail, message) in cases {
            assert_eq!(obj_err(&format!("{v}{tail}")), message, "{tail:?}");
        }
        // A face may not use a vertex defined after it.
        assert_eq!(
            obj_err("v 0 0 0\nv 1 0 0\nf 1 2 3\nv 0 1 0\n"),
            "line 3: vertex index 3 is out of range for 2 vertices"
        );
        assert_eq!(obj_err("# nothing\n"), "no points");
        assert_eq!(obj_err(v), "no triangles");
    }

    fn binary_stl(header: &[u8], triangles: &[[[f32; 3]; 3]]) -> Vec<u8> {
        let mut b = header.to_vec();
        b.resize(80, b' ');
        b.extend((triangles.len() as u32).to_le_bytes());
        for t in triangles {
            b.extend([0u8; 12]); // normal
            for c in t.iter().flatten() {
                b.extend(c.to_le_bytes());
            }
            b.extend([0u8; 2]);
        }
        b
    }

    const SQUARE: [[[f32; 3]; 3]; 2] = [
        [[0.0, 0.0, 0.0], [1.5, 0.0, 0.0], [0.0, 1.0, 0.0]],
        [[1.5, 0.0, 0.0], [1.5, 1.0, 0.0], [0.0, 1.0, -0.0]],
    ];

    fn square_mesh() -> Mesh {
        Mesh {
            vertices: vec![
                [0.0, 0.0, 0.0],
                [1.5, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [1.5, 1.0, 0.0],
            ],
            triangles: vec![[0, 1, 2], [1, 3, 2]],
        }
    }

    #[test]
    fn binary_stl_merges_vertices() {
        // A header starting with "solid" must not fool the detection.
        let b = binary_stl(b"solid exported by a CAD tool", &SQUARE);
        assert_eq!(parse_stl(&b).unwrap(), square_mesh());
        let b = binary_stl(b"", &SQUARE);
        assert_eq!(parse_stl(&b).unwrap(), square_mesh());
    }

    #[test]
    fn binary_stl_errors() {
        let mut nan = SQUARE;
        nan[1][2][1] = f32::NAN;
        assert_eq!(
            parse_stl(&binary_stl(b"", &nan)).unwrap_err().to_string(),
            "triangle 1: coordinate is not finite"
        );
        let full = binary_stl(b"solid x", &SQUARE);
        assert_eq!(
            parse_stl(&full[..full.len() - 1]).unwrap_err().to_string(),
            "not an STL file: neither binary (2 triangles need 184 bytes, the file has 183) \
             nor ASCII (text starting with \"solid\")"
        );
        assert_eq!(
            parse_stl(b"\x00\x01").unwrap_err().kind(),
            Some(&FormatError::NotStl {
                len: 2,
                declared: None
            })
        );
        assert_eq!(
            parse_stl(&binary_stl(b"", &[])).unwrap_err().kind(),
            Some(&FormatError::NoPoints)
        );
    }

    const ASCII_STL: &str = "solid square\n  facet normal 0 0 1\n    outer loop\n\
        vertex 0 0 0\n      vertex 1.5 0 0\n      vertex 0 1 0\n    endloop\n  endfacet\n\
        facet normal 0 0 1\n outer loop\n vertex 1.5 0 0\n vertex 1.5 1 0\n vertex 0 1 -0\n\
        endloop\n endfacet\nendsolid square\n";

    #[test]
    fn ascii_stl_merges_vertices_and_tolerates_crlf() {
        assert_eq!(parse_stl(ASCII_STL.as_bytes()).unwrap(), square_mesh());
        let crlf = ASCII_STL.replace('\n', "\r\n");
        assert_eq!(parse_stl(crlf.as_bytes()).unwrap(), square_mesh());
        // Missing endsolid is tolerated.
        let open = ASCII_STL.replace("endsolid square\n", "");
        assert_eq!(parse_stl(open.as_bytes()).unwrap(), square_mesh());
    }

    #[test]
    fn ascii_stl_errors() {
        let err = |text: &str| parse_stl(text.as_bytes()).unwrap_err().to_string();
        assert_eq!(
            err(&ASCII_STL.replace("vertex 1.5 0 0\n    ", "vertx 1.5 0 0\n    ")),
            "line 5: expected \"vertex\" or \"endloop\", found \"vertx 1.5 0 0\""
        );
        assert_eq!(
            err(&ASCII_STL.replace(" vertex 0 1 -0", " vertex 0 1")),
            "line 13: expected 3 numbers, found 2"
        );
        assert_eq!(
            err(&ASCII_STL.replace(" vertex 0 1 -0", " vertex 0 1 inf")),
            "line 13: coordinate is not finite"
        );
        let cut = &ASCII_STL[..ASCII_STL.find(" vertex 1.5 1 0").unwrap()];
        assert_eq!(err(cut), "file ends inside a facet");
        assert_eq!(err("solid empty\nendsolid empty\n"), "no points");
    }

    #[test]
    fn read_mesh_by_extension_and_write_obj() {
        let dir = tempfile::tempdir().unwrap();
        let mesh = square_mesh();

        let obj = dir.path().join("square.OBJ");
        write_mesh_obj(&obj, &mesh).unwrap();
        assert_eq!(
            std::fs::read_to_string(&obj).unwrap(),
            "# ribreg mesh, units mm\nv 0 0 0\nv 1.5 0 0\nv 0 1 0\nv 1.5 1 0\nf 1 2 3\nf 2 4 3\n"
        );
        assert_eq!(read_mesh(&obj).unwrap(), mesh);

        let ply = dir.path().join("square.ply");
        super::super::write_mesh_ply(&ply, &mesh).unwrap();
        assert_eq!(read_mesh(&ply).unwrap(), mesh);

        let stl = dir.path().join("square.stl");
        std::fs::write(&stl, binary_stl(b"", &SQUARE)).unwrap();
        assert_eq!(read_mesh(&stl).unwrap(), mesh);
        std::fs::write(&stl, ASCII_STL).unwrap();
        assert_eq!(read_mesh(&stl).unwrap(), mesh);

        std::fs::write(&stl, "solid x\nfacet normal 0 0 1\nouter lop\n").unwrap();
        assert_eq!(
            read_mesh(&stl).unwrap_err().to_string(),
            format!(
                "{}: line 3: expected \"outer loop\", found \"outer lop\"",
                stl.display()
            )
        );

        let xyz = dir.path().join("square.xyz");
        assert_eq!(
            read_mesh(&xyz).unwrap_err().to_string(),
            format!(
                "{}: unknown mesh file extension \"xyz\" (expected .ply, .obj or .stl)",
                xyz.display()
            )
        );
        let missing = dir.path().join("missing.obj");
        assert!(matches!(read_mesh(&missing), Err(IoError::Io { .. })));
    }

    #[test]
    fn declared_spaces_convert_to_the_patient_frame() {
        let dir = tempfile::tempdir().unwrap();
        let mesh = square_mesh();
        let in_space = |s: Space| {
            mesh.vertices
                .iter()
                .map(|&v| s.to_patient(v))
                .collect::<Vec<_>>()
        };
        let read = |name: &str, bytes: &[u8], default: Space| {
            let path = dir.path().join(name);
            std::fs::write(&path, bytes).unwrap();
            read_mesh_in(&path, default)
        };
        let stl = binary_stl(b"3D Slicer output. SPACE=LPS", &SQUARE);
        let (m, s) = read("a.stl", &stl, Space::Patient).unwrap();
        assert_eq!((m.vertices, s), (in_space(Space::Lps), Space::Lps));
        assert_eq!(m.triangles, mesh.triangles);
        let ascii = ASCII_STL.replace("solid square\n", "solid ras SPACE=ras\n");
        let (m, s) = read("a.stl", ascii.as_bytes(), Space::Lps).unwrap();
        assert_eq!((m.vertices, s), (in_space(Space::Ras), Space::Ras));
        // Undeclared: the default; a SPACE= in a later line of ASCII STL does not count.
        let (m, s) = read("a.stl", ASCII_STL.as_bytes(), Space::Lps).unwrap();
        assert_eq!((m.vertices, s), (in_space(Space::Lps), Space::Lps));
        let (_, s) = read(
            "a.stl",
            &binary_stl(b"COLORSPACE=RAS", &SQUARE),
            Space::Patient,
        )
        .unwrap();
        assert_eq!(s, Space::Patient);
        let obj = format!("# SPACE=LPS\n{OBJ}");
        assert_eq!(
            read("a.obj", obj.as_bytes(), Space::Ras).unwrap().1,
            Space::Lps
        );
        let ply = dir.path().join("a.ply");
        super::super::write_mesh_ply(&ply, &mesh).unwrap();
        let text = std::fs::read(&ply).unwrap();
        let text = String::from_utf8_lossy(&text).replacen("ply\n", "ply\ncomment SPACE=RAS\n", 1);
        let (m, s) = read("a.ply", text.as_bytes(), Space::Lps).unwrap();
        assert_eq!((m.vertices, s), (in_space(Space::Ras), Space::Ras));

        let bad = binary_stl(b"SPACE=XYZ", &SQUARE);
        let e = read("bad.stl", &bad, Space::Patient).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!(
                "{}: unknown coordinate system \"XYZ\" (expected RAS or LPS)",
                dir.path().join("bad.stl").display()
            )
        );
        assert!(read("bad.obj", b"# SPACE=\nv 0 0 0\n", Space::Patient).is_err());
        // Content errors come first, with the path.
        assert!(read("bad.stl", b"SPACE=XYZ", Space::Patient)
            .unwrap_err()
            .to_string()
            .contains("not an STL file"));
        assert!(read("a.off", b"", Space::Patient).is_err());
    }

    #[test]
    fn obj_writer_refuses_bad_meshes_and_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.obj");
        let no_triangles = Mesh {
            triangles: vec![],
            ..square_mesh()
        };
        assert_eq!(
            write_mesh_obj(&path, &no_triangles).unwrap_err().kind(),
            Some(&FormatError::NoTriangles)
        );
        let mut nan = square_mesh();
        nan.vertices[3][0] = f64::NAN;
        assert_eq!(
            write_mesh_obj(&path, &nan).unwrap_err().to_string(),
            format!("{}: vertex 3: coordinate is not finite", path.display())
        );
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        let nowhere = dir.path().join("sub").join("m.obj");
        assert!(matches!(
            write_mesh_obj(&nowhere, &square_mesh()),
            Err(IoError::Io { .. })
        ));
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn garbage_never_panics() {
        let mut s: u64 = 11;
        let seeds = [
            OBJ.as_bytes().to_vec(),
            ASCII_STL.as_bytes().to_vec(),
            binary_stl(b"solid", &SQUARE),
        ];
        for seed in &seeds {
            for m in crate::io::mutants(seed, 2000, b"0123456789 \n-/f#v", &mut s) {
                let _ = parse_stl(&m);
                if let Ok(text) = std::str::from_utf8(&m) {
                    let _ = parse_obj(text);
                }
            }
        }
    }
}
