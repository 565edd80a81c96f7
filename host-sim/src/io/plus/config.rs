//! The PLUS device-set configuration: reading a transform of `<CoordinateDefinitions>`,
//! writing a minimal configuration that holds a calibration.

use std::fmt;
use std::io::Read;
use std::path::{Path, PathBuf};

use super::super::{excerpt, write_text};
use super::Matrix4;

/// Largest configuration file read, bytes: PLUS device sets are a few KiB (the largest
/// examples PLUS ships, with volume reconstruction and many tools, are under 20 KiB);
/// 16 MiB bounds the memory roxmltree's document takes (a few times the text).
pub const MAX_CONFIG_BYTES: u64 = 16 << 20;

/// Error of [`read_plus_transform`] and [`write_plus_config`]: the file and what is wrong,
/// as one line.
#[derive(Debug)]
pub struct PlusConfigError {
    /// The file.
    pub path: PathBuf,
    /// What is wrong.
    pub problem: PlusConfigProblem,
}

/// What is wrong with a PLUS configuration file.
#[derive(Debug)]
pub enum PlusConfigProblem {
    /// The operating system failed to read the file.
    Io(std::io::Error),
    /// Writing the file failed (the writer's message).
    Write(String),
    /// Larger than [`MAX_CONFIG_BYTES`].
    TooLarge(u64),
    /// Not well-formed XML (the parser's message, with its position).
    Xml(String),
    /// No `<CoordinateDefinitions><Transform>` from `from` to `to` (nor the inverse).
    NoTransform {
        /// Wanted `From`.
        from: String,
        /// Wanted `To`.
        to: String,
        /// The transforms the file defines, `From→To`.
        found: Vec<String>,
    },
    /// The `Matrix` attribute is not 16 finite numbers with last row `0 0 0 1`, or the
    /// inverse was needed and the matrix is singular.
    Matrix {
        /// `From→To` of the element.
        which: String,
        /// The attribute (elided).
        found: String,
    },
}

impl fmt::Display for PlusConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: ", self.path.display())?;
        match &self.problem {
            PlusConfigProblem::Io(e) => write!(f, "cannot read: {e}"),
            PlusConfigProblem::Write(e) => write!(f, "cannot write: {e}"),
            PlusConfigProblem::TooLarge(n) => write!(
                f,
                "{n} bytes: larger than the {} MiB a PLUS configuration can be",
                MAX_CONFIG_BYTES >> 20
            ),
            PlusConfigProblem::Xml(e) => write!(f, "not a PLUS configuration (XML): {e}"),
            PlusConfigProblem::NoTransform { from, to, found } => {
                write!(
                    f,
                    "no <Transform From=\"{from}\" To=\"{to}\"> (nor its inverse) in \
                     <CoordinateDefinitions>; it defines: "
                )?;
                if found.is_empty() {
                    write!(f, "nothing")
                } else {
                    write!(f, "{}", found.join(", "))
                }
            }
            PlusConfigProblem::Matrix { which, found } => write!(
                f,
                "the {which} Matrix \"{found}\" is not 16 finite numbers (row-major, last row \
                 0 0 0 1) of an invertible transform"
            ),
        }
    }
}

impl std::error::Error for PlusConfigError {}

fn parse_matrix(text: &str) -> Option<Matrix4> {
    let v: Vec<f64> = text
        .split_ascii_whitespace()
        .map(|t| t.parse::<f64>().ok().filter(|v| v.is_finite()))
        .collect::<Option<_>>()?;
    if v.len() != 16 {
        return None;
    }
    let m: Matrix4 = std::array::from_fn(|i| std::array::from_fn(|j| v[4 * i + j]));
    let last = [0.0, 0.0, 0.0, 1.0];
    (0..4)
        .all(|j| (m[3][j] - last[j]).abs() <= 1e-6)
        .then_some(m)
}

/// The inverse of an affine 4 × 4 matrix, `None` if singular.
fn invert_affine(m: &Matrix4) -> Option<Matrix4> {
    let a = nalgebra::Matrix3::from_fn(|i, j| m[i][j]);
    let t = nalgebra::Vector3::new(m[0][3], m[1][3], m[2][3]);
    let inv = a.try_inverse()?;
    let ti = -(inv * t);
    let mut out = [[0.0; 4]; 4];
    for i in 0..3 {
        for j in 0..3 {
            out[i][j] = inv[(i, j)];
        }
        out[i][3] = ti[i];
    }
    out[3][3] = 1.0;
    out.iter().flatten().all(|v| v.is_finite()).then_some(out)
}

/// The `From = from`, `To = to` transform of a PLUS device-set configuration
/// (`<CoordinateDefinitions><Transform From=".." To=".." Matrix=".."/>`), inverted if
/// only `to` → `from` is defined.
pub fn read_plus_transform(path: &Path, from: &str, to: &str) -> Result<Matrix4, PlusConfigError> {
    let err = |problem| PlusConfigError {
        path: path.to_path_buf(),
        problem,
    };
    let file = std::fs::File::open(path).map_err(|e| err(PlusConfigProblem::Io(e)))?;
    let mut text = String::new();
    file.take(MAX_CONFIG_BYTES + 1)
        .read_to_string(&mut text)
        .map_err(|e| err(PlusConfigProblem::Io(e)))?;
    if text.len() as u64 > MAX_CONFIG_BYTES {
        return Err(err(PlusConfigProblem::TooLarge(text.len() as u64)));
    }
    let doc = roxmltree::Document::parse(&text)
        .map_err(|e| err(PlusConfigProblem::Xml(e.to_string())))?;
    let mut found = Vec::new();
    let mut inverse = None;
    for node in doc.descendants().filter(|n| {
        n.has_tag_name("Transform")
            && n.parent_element()
                .is_some_and(|p| p.has_tag_name("CoordinateDefinitions"))
    }) {
        let (f, t) = (
            node.attribute("From").unwrap_or(""),
            node.attribute("To").unwrap_or(""),
        );
        let which = format!("{f}→{t}");
        let matrix = || {
            let m = node.attribute("Matrix").unwrap_or("");
            parse_matrix(m).ok_or_else(|| {
                err(PlusConfigProblem::Matrix {
                    which: which.clone(),
                    found: excerpt(&m.split_ascii_whitespace().collect::<Vec<_>>().join(" ")),
                })
            })
        };
        if f == from && t == to {
            return matrix();
        }
        if f == to && t == from && inverse.is_none() {
            let m = matrix()?;
            inverse = Some(invert_affine(&m).ok_or_else(|| {
                err(PlusConfigProblem::Matrix {
                    which: which.clone(),
                    found: "a singular matrix".into(),
                })
            })?);
        }
        if found.len() < 32 {
            found.push(which);
        }
    }
    inverse.ok_or_else(|| {
        err(PlusConfigProblem::NoTransform {
            from: from.into(),
            to: to.into(),
            found,
        })
    })
}

/// `text` escaped for an XML attribute value.
fn attr(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Writes a minimal PLUS device-set configuration: a `SavedDataSource` replaying
/// `sequence_file` (a file name beside it) and `<CoordinateDefinitions>` holding the
/// `Image` → `probe_frame` transform `image_to_probe`. `description` goes into the
/// `DeviceSet`.
pub fn write_plus_config(
    path: &Path,
    image_to_probe: &Matrix4,
    probe_frame: &str,
    sequence_file: &str,
    description: &str,
) -> Result<(), PlusConfigError> {
    let err = |problem| PlusConfigError {
        path: path.to_path_buf(),
        problem,
    };
    if parse_matrix(
        &image_to_probe
            .iter()
            .flatten()
            .map(|v| format!("{v:e}"))
            .collect::<Vec<_>>()
            .join(" "),
    )
    .is_none()
    {
        return Err(err(PlusConfigProblem::Matrix {
            which: format!("Image→{probe_frame}"),
            found: "not finite, or last row not 0 0 0 1".into(),
        }));
    }
    let rows: Vec<String> = image_to_probe
        .iter()
        .map(|r| {
            r.iter()
                .map(|v| format!("{v}"))
                .collect::<Vec<_>>()
                .join(" ")
        })
        .collect();
    let text = format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<PlusConfiguration version="2.1">
  <DataCollection StartupDelaySec="1.0">
    <DeviceSet Name="ribreg: {name}" Description="{description}" />
    <Device Id="TrackedVideoDevice" Type="SavedDataSource" SequenceFile="{seq}"
      UseData="IMAGE_AND_TRANSFORM" UseOriginalTimestamps="TRUE" RepeatEnabled="FALSE">
      <DataSources>
        <DataSource Type="Video" Id="Video" PortUsImageOrientation="MF" />
      </DataSources>
      <OutputChannels>
        <OutputChannel Id="TrackedVideoStream" VideoDataSourceId="Video" />
      </OutputChannels>
    </Device>
  </DataCollection>
  <CoordinateDefinitions>
    <Transform From="Image" To="{probe}"
      Matrix="
        {r0}
        {r1}
        {r2}
        {r3}" />
  </CoordinateDefinitions>
</PlusConfiguration>
"#,
        name = attr(sequence_file),
        description = attr(description),
        seq = attr(sequence_file),
        probe = attr(probe_frame),
        r0 = rows[0],
        r1 = rows[1],
        r2 = rows[2],
        r3 = rows[3],
    );
    write_text(path, &text)
        .map_err(|e| err(PlusConfigProblem::Io(std::io::Error::other(e.to_string()))))
}
