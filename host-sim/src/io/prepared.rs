//! Prepared templates: everything `Template::build` computes for the improved method,
//! with the template cloud it was computed from, in one binary PLY file.
//!
//! A template is prepared once (`ribreg template --prepared FILE`), then registered onto
//! every patient (`ribreg register --template FILE`) and uploaded to the controller,
//! without the template's SOMs being trained again. The file is an ordinary binary
//! little-endian PLY, so any viewer shows its `vertex` element (the template cloud); the
//! other elements hold the prepared parts as `float`, the core's own `f32`, so a
//! write → read round trip is exact and a registration from the file equals, bit for
//! bit, one from the cloud:
//!
//! ```text
//! element ribreg_prepared 1   property uint version                 (= 1)
//! element vertex N            property double x, y, z; int label    (the template cloud)
//! element node M              property float x, y, z; uchar label   (SOM-1 nodes, M ≤ 400)
//! element skeleton 30         property float x, y, z                (ribs 2..5: 6, 6, 8, 10)
//! element frame 1             property float ox oy oz, a00..a22 (row-major), sx sy sz
//! element midline 4           property float fraction               (sternum split per rib)
//! ```
//!
//! Coordinates are mm in ribreg's patient frame. The reader checks the layout and that
//! every value is finite; the core (`Template::from_parts`) checks the rest (a proper
//! frame, label ranges, fractions in [0, 1]).

use std::path::Path;

use super::{
    parse_ply, parse_ply_elements, read_bytes, write_atomic, Cloud, FormatError, IoError, Location,
    PlyElement,
};

/// The version this module writes and reads.
pub const PREPARED_VERSION: u32 = 3;
/// Skeleton points in a prepared template (ribs 2..5 with 6, 6, 8, 10 points).
pub const PREPARED_SKELETON: usize = 30;
/// Most SOM-1 nodes a prepared template may hold (the core's SOM-1 capacity).
pub const PREPARED_MAX_NODES: usize = 400;

/// The parts of a prepared template (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct PreparedTemplate {
    /// The template cloud, with its labels.
    pub cloud: Cloud,
    /// SOM-1 node positions.
    pub nodes: Vec<[f32; 3]>,
    /// One rib label per node (0 none, 1 sternum, 2..=5 rib).
    pub node_labels: Vec<u8>,
    /// The 30 rib skeleton points.
    pub skeleton: [[f32; 3]; PREPARED_SKELETON],
    /// Origin of the key points' frame.
    pub frame_origin: [f32; 3],
    /// Axes of that frame (columns), row-major.
    pub frame_axes: [f32; 9],
    /// Spread along each axis.
    pub frame_spread: [f32; 3],
    /// Per rib, the fraction of its stations on side 0.
    pub midline_fraction: [f32; 4],
}

/// What a `--template` file holds.
#[derive(Clone, Debug, PartialEq)]
pub enum TemplateFile {
    /// A point cloud, to be prepared.
    Cloud(Cloud),
    /// A prepared template.
    Prepared(Box<PreparedTemplate>),
}

fn element<'a>(
    elements: &'a [PlyElement],
    name: &'static str,
    properties: &[&str],
    rows: Option<usize>,
) -> Result<&'a PlyElement, FormatError> {
    let e = elements
        .iter()
        .find(|e| e.name == name)
        .ok_or(FormatError::MissingElement(name))?;
    for p in properties {
        if e.property(p).is_none() {
            return Err(FormatError::PreparedLayout(format!(
                "element {name} has no property {p}"
            )));
        }
    }
    if let Some(n) = rows {
        if e.rows.len() != n {
            return Err(FormatError::PreparedLayout(format!(
                "element {name} has {} rows, {n} expected",
                e.rows.len()
            )));
        }
    }
    Ok(e)
}

/// The values of `names` in every row of `e`, as f32, finite.
fn columns<const N: usize>(e: &PlyElement, names: [&str; N]) -> Result<Vec<[f32; N]>, IoError> {
    let idx: Vec<usize> = names.iter().filter_map(|n| e.property(n)).collect();
    e.rows
        .iter()
        .enumerate()
        .map(|(r, row)| {
            let mut out = [0.0f32; N];
            for (o, &i) in out.iter_mut().zip(&idx) {
                let v = row.get(i).copied().unwrap_or(f64::NAN);
                // Written as `float`: exact. A double-typed file may hold more digits;
                // the nearest f32 is what the core computes with anyway.
                *o = v as f32;
                if !o.is_finite() {
                    return Err(IoError::format(
                        FormatError::NotFinite,
                        Some(Location::item(&e.name, r)),
                    ));
                }
            }
            Ok(out)
        })
        .collect()
}

/// Decode a `--template` file: a prepared template when the PLY has a `ribreg_prepared`
/// element, otherwise the PLY's point cloud ([`parse_ply`]).
///
/// # Errors
///
/// The PLY errors of [`parse_ply`]; for a prepared file [`FormatError::PreparedVersion`]
/// for another version, [`FormatError::PreparedLayout`] or `MissingElement` for a
/// missing element, property or row, `NotFinite` for a non-finite value and `BadLabel`
/// for a node label outside 0..=5.
pub fn parse_template_file(bytes: &[u8]) -> Result<TemplateFile, IoError> {
    // A plain cloud is decoded once, by the cloud reader alone.
    if !super::ply::declares_element(bytes, "ribreg_prepared") {
        return parse_ply(bytes).map(TemplateFile::Cloud);
    }
    // The vertices are the cloud, which `parse_ply` decodes below.
    let elements = parse_ply_elements(bytes, &["vertex"])?;
    let marker = element(&elements, "ribreg_prepared", &["version"], Some(1))?;
    let version = marker
        .property("version")
        .and_then(|i| marker.rows.first().and_then(|r| r.get(i)))
        .copied()
        .ok_or_else(|| FormatError::PreparedLayout("no version".to_owned()))?;
    if version != f64::from(PREPARED_VERSION) {
        return Err(FormatError::PreparedVersion(version).into());
    }
    let cloud = parse_ply(bytes)?;
    if cloud.labels.is_none() {
        return Err(FormatError::PreparedLayout("the template cloud has no labels".into()).into());
    }
    let node = element(&elements, "node", &["x", "y", "z", "label"], None)?;
    if node.rows.is_empty() || node.rows.len() > PREPARED_MAX_NODES {
        return Err(FormatError::PreparedLayout(format!(
            "{} nodes, 1..={PREPARED_MAX_NODES} expected",
            node.rows.len()
        ))
        .into());
    }
    let nodes = columns(node, ["x", "y", "z"])?;
    let li = node.property("label").unwrap_or(0);
    let node_labels = node
        .rows
        .iter()
        .enumerate()
        .map(|(r, row)| {
            let v = row.get(li).copied().unwrap_or(f64::NAN);
            if (0.0..=5.0).contains(&v) && v.fract() == 0.0 {
                // In 0..=5 and integral: exact.
                Ok(v as u8)
            } else {
                Err(IoError::format(
                    FormatError::BadLabel(v),
                    Some(Location::item("node", r)),
                ))
            }
        })
        .collect::<Result<Vec<u8>, IoError>>()?;
    let sk = columns(
        element(
            &elements,
            "skeleton",
            &["x", "y", "z"],
            Some(PREPARED_SKELETON),
        )?,
        ["x", "y", "z"],
    )?;
    let mut skeleton = [[0.0f32; 3]; PREPARED_SKELETON];
    skeleton.copy_from_slice(&sk);
    const FRAME: [&str; 15] = [
        "ox", "oy", "oz", "a00", "a01", "a02", "a10", "a11", "a12", "a20", "a21", "a22", "sx",
        "sy", "sz",
    ];
    let frame = columns(element(&elements, "frame", &FRAME, Some(1))?, FRAME)?;
    let f = frame.first().copied().unwrap_or([0.0; 15]);
    let mid = columns(
        element(&elements, "midline", &["fraction"], Some(4))?,
        ["fraction"],
    )?;
    Ok(TemplateFile::Prepared(Box::new(PreparedTemplate {
        cloud,
        nodes,
        node_labels,
        skeleton,
        frame_origin: [f[0], f[1], f[2]],
        frame_axes: std::array::from_fn(|i| f[3 + i]),
        frame_spread: [f[12], f[13], f[14]],
        midline_fraction: std::array::from_fn(|i| mid.get(i).map_or(f32::NAN, |m| m[0])),
    })))
}

/// Read a `--template` file from `path`; see [`parse_template_file`].
///
/// # Errors
///
/// [`IoError::Io`] if the file cannot be read; otherwise the errors of
/// [`parse_template_file`], with the path attached.
pub fn read_template_file(path: &Path) -> Result<TemplateFile, IoError> {
    parse_template_file(&read_bytes(path)?).map_err(|e| e.with_path(path))
}

/// Write `prepared` to `path` (binary PLY, see the module docs), atomically.
///
/// # Errors
///
/// With `path` left untouched: [`IoError::Format`] for an empty or unlabelled cloud, a
/// non-finite coordinate, labels and points of different lengths, no nodes or more than
/// [`PREPARED_MAX_NODES`], or node labels and nodes of different lengths;
/// [`IoError::Io`] if the file cannot be written.
pub fn write_prepared(path: &Path, prepared: &PreparedTemplate) -> Result<(), IoError> {
    let p = prepared;
    let fail = |kind: FormatError| IoError::from(kind).with_path(path);
    super::check_points(&p.cloud.points, "vertex").map_err(|e| e.with_path(path))?;
    let Some(labels) = p.cloud.labels.as_deref() else {
        return Err(fail(FormatError::PreparedLayout(
            "the template cloud has no labels".into(),
        )));
    };
    if labels.len() != p.cloud.points.len() {
        return Err(fail(FormatError::LabelCountMismatch {
            labels: labels.len(),
            points: p.cloud.points.len(),
        }));
    }
    if p.nodes.is_empty() || p.nodes.len() > PREPARED_MAX_NODES {
        return Err(fail(FormatError::PreparedLayout(format!(
            "{} nodes, 1..={PREPARED_MAX_NODES} expected",
            p.nodes.len()
        ))));
    }
    if p.node_labels.len() != p.nodes.len() {
        return Err(fail(FormatError::LabelCountMismatch {
            labels: p.node_labels.len(),
            points: p.nodes.len(),
        }));
    }
    write_atomic(path, |out| {
        write!(
            out,
            "ply\nformat binary_little_endian 1.0\n\
             comment ribreg prepared template (improved method), units mm, patient frame \
             (x left, y cranial, z anterior)\n\
             element ribreg_prepared 1\nproperty uint version\n\
             element vertex {}\nproperty double x\nproperty double y\nproperty double z\n\
             property int label\n\
             element node {}\nproperty float x\nproperty float y\nproperty float z\n\
             property uchar label\n\
             element skeleton {PREPARED_SKELETON}\nproperty float x\nproperty float y\n\
             property float z\n\
             element frame 1\n",
            p.cloud.points.len(),
            p.nodes.len()
        )?;
        for name in [
            "ox", "oy", "oz", "a00", "a01", "a02", "a10", "a11", "a12", "a20", "a21", "a22", "sx",
            "sy", "sz",
        ] {
            writeln!(out, "property float {name}")?;
        }
        write!(
            out,
            "element midline 4\nproperty float fraction\nend_header\n"
        )?;
        out.write_all(&PREPARED_VERSION.to_le_bytes())?;
        for (q, l) in p.cloud.points.iter().zip(labels) {
            for c in q {
                out.write_all(&c.to_le_bytes())?;
            }
            out.write_all(&l.to_le_bytes())?;
        }
        for (q, l) in p.nodes.iter().zip(&p.node_labels) {
            for c in q {
                out.write_all(&c.to_le_bytes())?;
            }
            out.write_all(&[*l])?;
        }
        let floats = p
            .skeleton
            .iter()
            .flatten()
            .chain(&p.frame_origin)
            .chain(&p.frame_axes)
            .chain(&p.frame_spread)
            .chain(&p.midline_fraction);
        for c in floats {
            out.write_all(&c.to_le_bytes())?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> PreparedTemplate {
        PreparedTemplate {
            cloud: Cloud {
                points: vec![[1.0, 2.0, 3.0], [0.1, -0.2, 1e-7]],
                labels: Some(vec![1, 5]),
            },
            nodes: vec![[0.1, 0.2, 0.3], [f32::MIN_POSITIVE, -7.25, 1e30]],
            node_labels: vec![0, 3],
            skeleton: std::array::from_fn(|i| [i as f32 * 0.1, 1.0 / (i as f32 + 1.0), -3.3]),
            frame_origin: [1.5, 2.5, 3.5],
            frame_axes: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            frame_spread: [30.0, 20.0, 0.1],
            midline_fraction: [0.5, 0.49, 0.51, 1.0 / 3.0],
        }
    }

    #[test]
    fn round_trip_is_exact() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.ply");
        let p = sample();
        write_prepared(&path, &p).unwrap();
        match read_template_file(&path).unwrap() {
            TemplateFile::Prepared(q) => assert_eq!(*q, p),
            other => panic!("not prepared: {other:?}"),
        }
        // It is also a plain PLY cloud for every other reader.
        assert_eq!(super::super::read_ply(&path).unwrap(), p.cloud);
    }

    #[test]
    fn a_plain_cloud_is_a_cloud() {
        let bytes = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n";
        assert!(matches!(
            parse_template_file(bytes).unwrap(),
            TemplateFile::Cloud(_)
        ));
    }

    #[test]
    fn bad_prepared_files_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.ply");
        write_prepared(&path, &sample()).unwrap();
        let good = std::fs::read(&path).unwrap();
        // Another version: the one before (its skeleton had no tip search) and the next.
        let header_end = good.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        for other in [PREPARED_VERSION - 1, PREPARED_VERSION + 1] {
            let mut bytes = good.clone();
            bytes[header_end..header_end + 4].copy_from_slice(&other.to_le_bytes());
            let e = parse_template_file(&bytes).unwrap_err().to_string();
            assert!(e.contains(&format!("version {other}")), "{e}");
        }
        // A truncated body.
        let e = parse_template_file(&good[..good.len() - 3])
            .unwrap_err()
            .to_string();
        assert!(e.contains("ends after"), "{e}");
        // A missing element.
        let at = good.windows(9).position(|w| w == b"midline 4").unwrap();
        let mut renamed = good.clone();
        renamed[at..at + 7].copy_from_slice(b"midlinx");
        let e = parse_template_file(&renamed).unwrap_err().to_string();
        assert!(e.contains("midline"), "{e}");
        // A node label out of range.
        let mut bad = sample();
        bad.node_labels[1] = 9;
        write_prepared(&path, &bad).unwrap();
        let e = read_template_file(&path).unwrap_err().to_string();
        assert!(e.contains("node 1") && e.contains("label 9"), "{e}");
        // A non-finite part.
        let mut bad = sample();
        bad.skeleton[4][1] = f32::NAN;
        write_prepared(&path, &bad).unwrap();
        let e = read_template_file(&path).unwrap_err().to_string();
        assert!(e.contains("skeleton 4") && e.contains("not finite"), "{e}");
        // Writers refuse what cannot be read back, leaving nothing behind.
        let mut bad = sample();
        bad.cloud.labels = None;
        let fresh = dir.path().join("u.ply");
        assert!(write_prepared(&fresh, &bad).is_err());
        assert!(!fresh.exists());
    }
}
