//! Host file I/O: point clouds (PLY, PCD, XYZ, CSV), surface meshes (PLY, OBJ, STL) and
//! waypoints (CSV, 3D Slicer markups).
//!
//! Coordinates are millimetres. Every reader returns a typed [`IoError`] for bad
//! input and never panics, whatever the bytes. Every writer is atomic: it writes a
//! temporary file in the target's directory and renames it into place, so a failed
//! write never leaves a partial output file behind. Writers refuse data that their
//! own reader would reject (non-finite coordinates, empty clouds, bad indices), so
//! everything written can be read back.
//!
//! Error messages are one line: `PATH: LOCATION: PROBLEM`, for example
//! `CT.ply: line 14: expected 3 numbers, found 2` or
//! `US.ply: binary body ends after 1203 of 3000 vertices`. Line numbers count from 1;
//! element indices (`vertex 17`, `triangle 3`) count from 0, like the arrays they
//! index.

use std::fmt;
use std::fs::{self, File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

mod cloud;
mod csv;
#[cfg(test)]
mod fixtures;
mod lzf;
mod markups;
mod mesh;
mod pcd;
pub mod plus;
mod ply;
pub mod prepared;
pub mod space;
pub mod volume;
mod waypoints;
mod xyz;

pub use cloud::{parse_cloud_csv, read_cloud};
pub use csv::{
    parse_points_csv, parse_table_csv, read_points_csv, read_table_csv, write_points_csv,
    write_table_csv,
};
pub use markups::{parse_fcsv, parse_markups_json};
pub use mesh::{mesh_space, parse_mesh, read_mesh, read_mesh_in, write_mesh_obj, write_mesh_stl};
pub use pcd::{parse_pcd, read_pcd};
pub use ply::{parse_ply, parse_ply_elements, read_ply, write_mesh_ply, write_ply, PlyElement};
pub use space::Space;
pub use waypoints::{parse_waypoints_csv, read_waypoints, write_waypoints, Waypoints};
pub use xyz::{parse_xyz, read_xyz};

/// A point cloud read from or written to disk, coordinates in mm.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Cloud {
    /// The points, in file order.
    pub points: Vec<[f64; 3]>,
    /// One label per point (rib number 2..5, 1 = sternum) when the file has a
    /// `label` property; `None` otherwise.
    pub labels: Option<Vec<i32>>,
}

/// An indexed triangle mesh, coordinates in mm.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mesh {
    /// The vertex positions.
    pub vertices: Vec<[f64; 3]>,
    /// Triangles as indices into `vertices` (0-based).
    pub triangles: Vec<[u32; 3]>,
}

/// Body encoding of a PLY file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PlyFormat {
    /// `format ascii 1.0`: one element per text line.
    Ascii,
    /// `format binary_little_endian 1.0`: packed little-endian values.
    BinaryLittleEndian,
}

impl PlyFormat {
    /// How error messages name a body in this format.
    fn body_name(self) -> &'static str {
        match self {
            PlyFormat::Ascii => "ASCII",
            PlyFormat::BinaryLittleEndian => "binary",
        }
    }
}

/// Where in a file (or in the data being written) a problem was found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Location {
    /// A text line, counted from 1.
    Line(usize),
    /// An element instance, counted from 0: `vertex 17`, `face 3`, `triangle 0`.
    Item {
        /// Element name (`vertex`, `face`, `triangle`, `point`...).
        element: String,
        /// 0-based index of the instance.
        index: usize,
    },
}

impl Location {
    fn item(element: &str, index: usize) -> Self {
        Location::Item {
            element: element.to_owned(),
            index,
        }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Line(n) => write!(f, "line {n}"),
            Location::Item { element, index } => write!(f, "{element} {index}"),
        }
    }
}

/// What is wrong with the content of a file, or with data handed to a writer.
#[derive(Debug, Clone, PartialEq)]
pub enum FormatError {
    /// The data does not start with the line `ply`.
    NotPly,
    /// The PLY header has no `end_header` line.
    MissingEndHeader,
    /// The PLY body is `binary_big_endian`, which is not supported.
    BigEndian,
    /// The PLY `format` line names an unknown encoding or version (the text after `format`).
    UnsupportedFormat(String),
    /// A PLY header line is malformed; the text says how.
    Header(String),
    /// A required element is not declared in the PLY header.
    MissingElement(&'static str),
    /// A required property is not declared for an element.
    MissingProperty {
        /// The element that lacks it.
        element: &'static str,
        /// The missing property.
        property: &'static str,
    },
    /// The file holds no points (vertex count 0), or a writer was given none.
    NoPoints,
    /// A mesh file holds no triangles, or a mesh writer was given none.
    NoTriangles,
    /// The body ends before the number of elements the header declares.
    Truncated {
        /// Encoding of the body.
        format: PlyFormat,
        /// Element being read (`vertex`, `face`...).
        element: String,
        /// Complete instances read.
        read: usize,
        /// Instances declared by the header.
        expected: usize,
    },
    /// A line holds the wrong number of values.
    TokenCount {
        /// Values the line must hold.
        expected: usize,
        /// Values found.
        found: usize,
    },
    /// A token is not a number.
    NotANumber(String),
    /// A number does not fit the declared integer property type (non-integral or out of range).
    OutOfRange {
        /// The value found.
        value: f64,
        /// The declared PLY type.
        ty: &'static str,
    },
    /// A coordinate is NaN or infinite.
    NotFinite,
    /// A `label` value is not an integer in the `i32` range.
    BadLabel(f64),
    /// A PLY list length is negative.
    BadListLength(f64),
    /// A face refers to a vertex that does not exist (the index as written in the file).
    IndexOutOfRange {
        /// The index as written (0-based for PLY, 1-based or negative for OBJ).
        index: i64,
        /// Number of vertices available.
        vertices: usize,
    },
    /// A face has fewer than three corners.
    TooFewCorners(usize),
    /// More vertices than a `u32` (or a PLY `int` index) can address.
    TooManyVertices(usize),
    /// Non-blank data follows the last element the header declares.
    TrailingData,
    /// Text that must be UTF-8 is not.
    NotUtf8,
    /// A CSV file does not start with the header `x,y,z`; holds the line found
    /// (empty at end of file).
    CsvHeader {
        /// The header expected, e.g. `x,y,z`.
        expected: String,
        /// What the first line held (empty at end of file).
        found: String,
    },
    /// A structural error in an OBJ or ASCII STL file; the text says what was expected.
    Syntax(String),
    /// Neither a binary STL of the right size nor an ASCII STL.
    NotStl {
        /// File size in bytes.
        len: u64,
        /// Triangle count from the binary header, if the file is long enough to have one.
        declared: Option<u32>,
    },
    /// `read_mesh` does not know the file extension (the extension found, possibly empty).
    UnknownExtension(String),
    /// A cloud's `labels` and `points` differ in length.
    LabelCountMismatch {
        /// Number of labels.
        labels: usize,
        /// Number of points.
        points: usize,
    },
    // Prepared templates (io::prepared)
    /// A prepared template of a version this build does not read.
    PreparedVersion(f64),
    /// A prepared template's elements or properties are not as written by ribreg.
    PreparedLayout(String),

    // Clouds and waypoints (io::pcd, io::xyz, io::markups)
    /// The data does not start with a PCD header (`VERSION`, `FIELDS`... lines).
    NotPcd,
    /// A PCD header line is malformed, missing or inconsistent; the text says how.
    PcdHeader(String),
    /// A PCD field cannot be read as declared (bad `SIZE`/`TYPE`/`COUNT`, or a required
    /// field missing or of the wrong type).
    PcdField {
        /// The field name (`x`, `label`...).
        field: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The PCD `DATA` line names an encoding other than `ascii`, `binary` or
    /// `binary_compressed` (the text found).
    PcdData(String),
    /// The PCD `POINTS` count differs from `WIDTH × HEIGHT`.
    PcdPoints {
        /// `POINTS` as declared.
        points: usize,
        /// `WIDTH` as declared.
        width: usize,
        /// `HEIGHT` as declared.
        height: usize,
    },
    /// A PCD `binary_compressed` body is not valid LZF data of the declared size; the
    /// text says how.
    Lzf(String),
    /// A 3D Slicer markups file is malformed; the text says how.
    Markups(String),
    /// A file declares a coordinate system other than RAS or LPS (the value found).
    UnknownSpace(String),
    /// A markups file declares coordinate units other than millimetres (the value found).
    UnknownUnits(String),
    /// A waypoint file holds no (defined) waypoints, or a waypoint writer was given none.
    NoWaypoints,
    /// A CSV header lacks the columns a reader needs.
    CsvColumns {
        /// The columns needed, e.g. `x, y and z`.
        expected: &'static str,
        /// The header found.
        found: String,
    },
    /// A reader or writer choosing the format by extension does not know this one.
    UnknownFileExtension {
        /// What is read or written (`point cloud`, `waypoint`).
        what: &'static str,
        /// The extension found (possibly empty).
        extension: String,
        /// The extensions accepted, for the message.
        expected: &'static str,
    },
    /// A label cannot be written so that its reader gives it back (it holds a line break).
    UnwritableLabel(String),

    // Volumes (io::volume)
    /// Not a NIfTI-1 single file; the text says why (too short, no `n+1` magic).
    NotNifti(String),
    /// A NIfTI flavour that is not read: NIfTI-2 or a `.hdr`/`.img` pair (the text says which).
    NiftiVersion(String),
    /// A NIfTI-1 header field is unusable (`vox_offset`, `pixdim`, `dim`...).
    NiftiField {
        /// The field, as the NIfTI-1 standard names it.
        field: &'static str,
        /// What is wrong with it.
        problem: String,
    },
    /// Not a NRRD file (no `NRRD000N` magic line).
    NotNrrd,
    /// A NRRD header field is missing or malformed.
    NrrdField {
        /// The field or key, as written in the header (`sizes`, `Segment2_LabelValue`...).
        field: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The voxel type cannot hold labels (the file's name for it, e.g. `NIfTI datatype 32`).
    VolumeDatatype(String),
    /// Not a 3-D volume; the text says what the file holds and what to do.
    VolumeDimension(String),
    /// The volume holds no voxels (a size is 0).
    EmptyVolume,
    /// More voxels than [`volume::MAX_VOXELS`].
    VolumeTooLarge {
        /// Voxels the header declares (saturated at `u64::MAX`).
        voxels: u64,
        /// The most accepted.
        max: usize,
    },
    /// The voxel data ends early.
    VolumeTruncated {
        /// Data bytes the header declares.
        expected: u64,
        /// Data bytes present.
        found: u64,
    },
    /// The compressed voxel data is not a valid gzip stream (the decoder's message).
    Gzip(String),
    /// A voxel value (after any NIfTI scaling) is not an integer in `0..=65535`.
    NotIntegralLabel {
        /// Index of the voxel in file order (`i + ni * (j + nj * k)`).
        index: usize,
        /// The value found.
        value: f64,
    },
    /// The file declares no world coordinate system (a NRRD without `space`); an unknown
    /// one is [`FormatError::UnknownSpace`].
    NoSpace,
    /// The voxel-to-world transform is not finite or not invertible; the text says which.
    VolumeAffine(String),
    /// `read_labelmap` does not know the file extension (the name found).
    VolumeExtension(String),
    /// A TotalSegmentator directory holds none of the class files ribreg reads.
    NoClassFiles,
    /// A TotalSegmentator class file does not match the first one read.
    VolumeMismatch {
        /// What differs (`dims 12x10x8 vs 12x10x9`, `affine`...).
        what: String,
        /// The file compared against.
        reference: String,
    },
    /// Two TotalSegmentator class files claim the same voxel.
    LabelOverlap {
        /// Index of the voxel (`i + ni * (j + nj * k)`).
        index: usize,
        /// Class already there.
        first: &'static str,
        /// Class claiming it again.
        second: &'static str,
    },
}

/// English plural of an element name for messages.
fn plural(element: &str) -> String {
    match element {
        "vertex" => "vertices".to_owned(),
        _ => format!("{element}s"),
    }
}

impl fmt::Display for FormatError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use FormatError as E;
        match self {
            E::NotPly => write!(f, "not a PLY file (the first line is not \"ply\")"),
            E::MissingEndHeader => write!(f, "PLY header has no end_header line"),
            E::BigEndian => write!(
                f,
                "binary_big_endian PLY is not supported; \
                 convert it to binary_little_endian or ascii"
            ),
            E::UnsupportedFormat(s) => write!(
                f,
                "unsupported PLY format \"{s}\" (expected ascii 1.0 or binary_little_endian 1.0)"
            ),
            E::Header(s) => write!(f, "bad PLY header: {s}"),
            E::MissingElement(e) => write!(f, "PLY header declares no \"{e}\" element"),
            E::MissingProperty { element, property } => {
                write!(f, "element {element} has no property {property}")
            }
            E::NoPoints => write!(f, "no points"),
            E::NoTriangles => write!(f, "no triangles"),
            E::Truncated {
                format,
                element,
                read,
                expected,
            } => write!(
                f,
                "{} body ends after {read} of {expected} {}",
                format.body_name(),
                plural(element)
            ),
            E::TokenCount { expected, found } => {
                let s = if *expected == 1 { "" } else { "s" };
                write!(f, "expected {expected} number{s}, found {found}")
            }
            E::NotANumber(t) if t.is_empty() => {
                write!(f, "empty value where a number was expected")
            }
            E::NotANumber(t) => write!(f, "\"{t}\" is not a number"),
            E::OutOfRange { value, ty } => write!(f, "value {value} does not fit type {ty}"),
            E::NotFinite => write!(f, "coordinate is not finite"),
            E::BadLabel(v) => write!(f, "label {v} is not an integer"),
            E::BadListLength(v) => write!(f, "list length {v} is negative"),
            E::IndexOutOfRange { index, vertices } => {
                write!(
                    f,
                    "vertex index {index} is out of range for {vertices} vertices"
                )
            }
            E::TooFewCorners(n) => write!(f, "face has {n} corners, at least 3 are needed"),
            E::TooManyVertices(n) => write!(f, "{n} vertices are more than can be indexed"),
            E::TrailingData => write!(f, "unexpected data after the last element"),
            E::NotUtf8 => write!(f, "text is not valid UTF-8"),
            E::CsvHeader { expected, found } if found.is_empty() => {
                write!(f, "expected header \"{expected}\", found end of file")
            }
            E::CsvHeader { expected, found } => {
                write!(f, "expected header \"{expected}\", found \"{found}\"")
            }
            E::Syntax(s) => write!(f, "{s}"),
            E::NotStl { len, declared } => {
                write!(f, "not an STL file: neither binary (")?;
                match declared {
                    Some(n) => {
                        let need = 84 + 50 * u64::from(*n);
                        write!(f, "{n} triangles need {need} bytes, the file has {len}")?;
                    }
                    None => write!(f, "{len} bytes is too short")?,
                }
                write!(f, ") nor ASCII (text starting with \"solid\")")
            }
            E::UnknownExtension(ext) => write!(
                f,
                "unknown mesh file extension \"{ext}\" (expected .ply, .obj or .stl)"
            ),
            E::LabelCountMismatch { labels, points } => {
                write!(f, "{labels} labels for {points} points")
            }
            E::PreparedVersion(v) => write!(
                f,
                "prepared template version {v}, this ribreg reads version {}; \
                 prepare the template again with `ribreg template`",
                prepared::PREPARED_VERSION
            ),
            E::PreparedLayout(s) => write!(f, "not a prepared template as ribreg writes it: {s}"),

            // Clouds and waypoints (io::pcd, io::xyz, io::markups)
            E::NotPcd => write!(f, "not a PCD file (no VERSION or FIELDS header line)"),
            E::PcdHeader(s) => write!(f, "bad PCD header: {s}"),
            E::PcdField { field, problem } => write!(f, "PCD field {field}: {problem}"),
            E::PcdData(s) => write!(
                f,
                "unsupported PCD DATA \"{s}\" (expected ascii, binary or binary_compressed)"
            ),
            E::PcdPoints {
                points,
                width,
                height,
            } => write!(f, "POINTS {points} is not WIDTH {width} x HEIGHT {height}"),
            E::Lzf(s) => write!(f, "bad binary_compressed body: {s}"),
            E::Markups(s) => write!(f, "bad markups file: {s}"),
            E::UnknownSpace(s) => {
                write!(f, "unknown coordinate system \"{s}\" (expected RAS or LPS)")
            }
            E::UnknownUnits(s) => write!(f, "unsupported coordinate units \"{s}\" (expected mm)"),
            E::NoWaypoints => write!(f, "no waypoints"),
            E::CsvColumns { expected, found } => {
                write!(f, "CSV header needs columns {expected}, found \"{found}\"")
            }
            E::UnknownFileExtension {
                what,
                extension,
                expected,
            } => write!(
                f,
                "unknown {what} file extension \"{extension}\" (expected {expected})"
            ),
            E::UnwritableLabel(s) => {
                write!(f, "label \"{s}\" holds a line break and cannot be written")
            }
            // Volumes (io::volume)
            E::NotNifti(why) => write!(f, "not a NIfTI-1 file: {why}"),
            E::NiftiVersion(what) => write!(f, "{what} is not supported; save as a NIfTI-1 .nii or .nii.gz"),
            E::NiftiField { field, problem } => write!(f, "NIfTI header field {field}: {problem}"),
            E::NotNrrd => write!(f, "not a NRRD file (the first line is not NRRD0001..NRRD0005)"),
            E::NrrdField { field, problem } => write!(f, "NRRD field \"{field}\": {problem}"),
            E::VolumeDatatype(t) => write!(f, "voxel type {t} cannot hold labels (expected integers or floats)"),
            E::VolumeDimension(s) => write!(f, "{s}"),
            E::EmptyVolume => write!(f, "the volume holds no voxels"),
            E::VolumeTooLarge { voxels, max } => write!(f, "volume too large: {voxels} voxels, at most {max} are read"),
            E::VolumeTruncated { expected, found } => write!(f, "voxel data ends after {found} of {expected} bytes"),
            E::Gzip(e) => write!(f, "bad gzip data: {e}"),
            E::NotIntegralLabel { index, value } => write!(f, "voxel {index} holds {value}, not a label (an integer in 0..=65535)"),
            E::NoSpace => write!(
                f,
                "no world coordinate system declared (expected RAS or LPS); refusing to guess"
            ),
            E::VolumeAffine(s) => write!(f, "bad voxel-to-world transform: {s}"),
            E::VolumeExtension(name) => write!(f, "unknown labelmap file \"{name}\" (expected .nii, .nii.gz, .nrrd, .seg.nrrd or a TotalSegmentator directory)"),
            E::NoClassFiles => write!(f, "no TotalSegmentator class files (sternum.nii.gz, costal_cartilages.nii.gz, rib_left_1.nii.gz .. rib_right_12.nii.gz)"),
            E::VolumeMismatch { what, reference } => write!(f, "does not match {reference}: {what}"),
            E::LabelOverlap { index, first, second } => write!(f, "voxel {index} is in both {first} and {second}"),
        }
    }
}

/// Error of every reader and writer in this module.
#[derive(Debug)]
pub enum IoError {
    /// The operating system failed to read, write or rename a file.
    Io {
        /// The file the caller named.
        path: PathBuf,
        /// What was being done, e.g. `cannot read`.
        op: &'static str,
        /// The underlying error.
        source: io::Error,
    },
    /// The content is malformed, or the data handed to a writer cannot be written.
    Format {
        /// The file, when known (`parse_*` functions have none; `read_*` and `write_*` add it).
        path: Option<PathBuf>,
        /// Where the problem is, when it is local.
        at: Option<Location>,
        /// What is wrong.
        kind: FormatError,
    },
}

impl IoError {
    /// A content error without a path.
    fn format(kind: FormatError, at: Option<Location>) -> Self {
        IoError::Format {
            path: None,
            at,
            kind,
        }
    }

    /// Attach `path` to a content error that has none yet.
    fn with_path(self, file: &Path) -> Self {
        match self {
            IoError::Format {
                path: None,
                at,
                kind,
            } => IoError::Format {
                path: Some(file.to_path_buf()),
                at,
                kind,
            },
            other => other,
        }
    }

    /// The file the error is about, when known.
    pub fn path(&self) -> Option<&Path> {
        match self {
            IoError::Io { path, .. } => Some(path),
            IoError::Format { path, .. } => path.as_deref(),
        }
    }

    /// The content problem, or `None` for an operating-system error.
    pub fn kind(&self) -> Option<&FormatError> {
        match self {
            IoError::Io { .. } => None,
            IoError::Format { kind, .. } => Some(kind),
        }
    }
}

impl From<FormatError> for IoError {
    fn from(kind: FormatError) -> Self {
        IoError::format(kind, None)
    }
}

impl fmt::Display for IoError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            IoError::Io { path, op, source } => write!(f, "{}: {op}: {source}", path.display()),
            IoError::Format { path, at, kind } => {
                if let Some(path) = path {
                    write!(f, "{}: ", path.display())?;
                }
                if let Some(at) = at {
                    write!(f, "{at}: ")?;
                }
                write!(f, "{kind}")
            }
        }
    }
}

impl std::error::Error for IoError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            IoError::Io { source, .. } => Some(source),
            IoError::Format { .. } => None,
        }
    }
}

/// `text` for quoting in a one-line message: at most 40 characters, the rest elided.
fn excerpt(text: &str) -> String {
    const MAX: usize = 40;
    match text.char_indices().nth(MAX) {
        Some((cut, _)) => format!("{}...", &text[..cut]),
        None => text.to_owned(),
    }
}

/// Write `text` to `path` atomically, as the other writers do (for reports and
/// other small text outputs).
///
/// # Errors
///
/// [`IoError::Io`] if the file cannot be written; `path` is then left untouched.
pub fn write_text(path: &Path, text: &str) -> Result<(), IoError> {
    write_atomic(path, |out| out.write_all(text.as_bytes()))
}

/// Read a whole file.
pub(crate) fn read_bytes(path: &Path) -> Result<Vec<u8>, IoError> {
    fs::read(path).map_err(|source| IoError::Io {
        path: path.to_path_buf(),
        op: "cannot read",
        source,
    })
}

/// View `bytes` as UTF-8 text whose first line is line `first_line` of the file.
fn text(bytes: &[u8], first_line: usize) -> Result<&str, IoError> {
    std::str::from_utf8(bytes).map_err(|e| {
        let good = bytes.get(..e.valid_up_to()).unwrap_or_default();
        let line = first_line + good.iter().filter(|&&b| b == b'\n').count();
        IoError::format(FormatError::NotUtf8, Some(Location::Line(line)))
    })
}

/// The non-blank lines of `text`, trimmed, with their line numbers (the first
/// line of `text` being `first_line`). Handles `\n` and `\r\n` endings.
fn content_lines(text: &str, first_line: usize) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .map(move |(i, line)| (first_line + i, line.trim()))
        .filter(|(_, line)| !line.is_empty())
}

/// Parse one coordinate token of a text format: a finite number.
fn parse_coordinate(token: &str) -> Result<f64, FormatError> {
    let value: f64 = token
        .parse()
        .map_err(|_| FormatError::NotANumber(excerpt(token)))?;
    if value.is_finite() {
        Ok(value)
    } else {
        Err(FormatError::NotFinite)
    }
}

/// Parse exactly `N` tokens of a text format into finite numbers.
fn parse_numbers<const N: usize>(tokens: &[&str]) -> Result<[f64; N], FormatError> {
    if tokens.len() != N {
        return Err(FormatError::TokenCount {
            expected: N,
            found: tokens.len(),
        });
    }
    let mut out = [0.0; N];
    for (o, t) in out.iter_mut().zip(tokens) {
        *o = parse_coordinate(t)?;
    }
    Ok(out)
}

/// Parse exactly three coordinate tokens of a text format into a finite point.
fn parse_point(tokens: &[&str]) -> Result<[f64; 3], FormatError> {
    parse_numbers(tokens)
}

/// Fan-triangulate a polygon `corners` (`[a, b, c, d]` gives `abc`, `acd`) onto `out`.
fn push_fan(out: &mut Vec<[u32; 3]>, corners: &[u32]) -> Result<(), FormatError> {
    match corners {
        [first, rest @ ..] if rest.len() >= 2 => {
            out.extend(rest.windows(2).map(|w| [*first, w[0], w[1]]));
            Ok(())
        }
        _ => Err(FormatError::TooFewCorners(corners.len())),
    }
}

/// Check that `points` is non-empty and finite before writing; errors name the
/// offending `element` instance.
fn check_points(points: &[[f64; 3]], element: &str) -> Result<(), IoError> {
    if points.is_empty() {
        return Err(FormatError::NoPoints.into());
    }
    match points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        Some(i) => Err(IoError::format(
            FormatError::NotFinite,
            Some(Location::item(element, i)),
        )),
        None => Ok(()),
    }
}

/// Check a mesh before writing: vertices as for [`check_points`], at least one
/// triangle, every index in range.
fn check_mesh(mesh: &Mesh) -> Result<(), IoError> {
    check_points(&mesh.vertices, "vertex")?;
    if mesh.triangles.is_empty() {
        return Err(FormatError::NoTriangles.into());
    }
    let vertices = mesh.vertices.len();
    for (i, triangle) in mesh.triangles.iter().enumerate() {
        if let Some(&index) = triangle.iter().find(|&&v| v as usize >= vertices) {
            return Err(IoError::format(
                FormatError::IndexOutOfRange {
                    index: index.into(),
                    vertices,
                },
                Some(Location::item("triangle", i)),
            ));
        }
    }
    Ok(())
}

/// Distinguishes temporary files of concurrent writes from this process.
static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Create a fresh temporary file next to `path` (same directory, so a rename is atomic).
fn create_temp(path: &Path) -> io::Result<(PathBuf, File)> {
    let name = path
        .file_name()
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "the path has no file name"))?;
    let dir = match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir,
        _ => Path::new("."),
    };
    let mut attempts = 0;
    loop {
        let n = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
        let mut temp_name = std::ffi::OsString::from(".");
        temp_name.push(name);
        temp_name.push(format!(".{}.{n}.tmp", std::process::id()));
        let temp = dir.join(temp_name);
        match OpenOptions::new().write(true).create_new(true).open(&temp) {
            Ok(file) => return Ok((temp, file)),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists && attempts < 100 => attempts += 1,
            Err(e) => return Err(e),
        }
    }
}

/// Write `path` atomically: `body` fills a temporary file in the same directory,
/// which is flushed, synced and renamed onto `path`. On any failure the temporary
/// file is removed and `path` is left as it was.
pub(crate) fn write_atomic(
    path: &Path,
    body: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> Result<(), IoError> {
    let fail = |op, source| IoError::Io {
        path: path.to_path_buf(),
        op,
        source,
    };
    let (temp, file) = create_temp(path).map_err(|e| fail("cannot create a file", e))?;
    let written = (|| {
        let mut out = BufWriter::new(file);
        body(&mut out)?;
        let file = out.into_inner().map_err(io::IntoInnerError::into_error)?;
        file.sync_all()
    })();
    let result = match written {
        Ok(()) => {
            fs::rename(&temp, path).map_err(|e| fail("cannot move the written file into place", e))
        }
        Err(e) => Err(fail("cannot write", e)),
    };
    if result.is_err() {
        // Best effort: the temporary file is ours and must not linger.
        let _ = fs::remove_file(&temp);
    }
    result
}

/// One output file and what writes it, for [`write_all_or_none`].
pub type Output<'a> = (
    &'a Path,
    Box<dyn FnOnce() -> Result<(), IoError> + Send + 'a>,
);

/// Writes every output, each on a thread of its own so that their `fsync`s overlap (each
/// file is written atomically, by its own writer's `write_atomic`), while `meanwhile`
/// runs on this thread; the output it returns, if any, is written after it, here. If
/// any write fails, or `meanwhile` does, the outputs that were written are removed and
/// the first failure is returned (`meanwhile`'s, else the writes' in the given order): a
/// run leaves all of its outputs or none.
pub fn write_all_or_none<'a, T, E: From<IoError>>(
    outputs: Vec<Output<'a>>,
    meanwhile: impl FnOnce() -> Result<(T, Option<Output<'a>>), E>,
) -> Result<T, E> {
    let (late, results) = std::thread::scope(|s| {
        let handles: Vec<_> = outputs
            .into_iter()
            .map(|(path, write)| (path, s.spawn(write)))
            .collect();
        let late = meanwhile().map(|(value, output)| {
            let written = output.map(|(path, write)| (path, write()));
            (value, written)
        });
        let results: Vec<(&Path, Result<(), IoError>)> = handles
            .into_iter()
            .map(|(path, handle)| {
                // A writer that panicked goes on panicking here.
                let result = handle
                    .join()
                    .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
                (path, result)
            })
            .collect();
        (late, results)
    });
    let (mut outcome, late): (Result<T, E>, _) = match late {
        Ok((value, written)) => (Ok(value), written),
        Err(e) => (Err(e), None),
    };
    let mut written = Vec::new();
    for (path, result) in results.into_iter().chain(late) {
        match result {
            Ok(()) => written.push(path),
            Err(e) if outcome.is_ok() => outcome = Err(E::from(e)),
            Err(_) => {}
        }
    }
    if outcome.is_err() {
        for path in written {
            // Best effort: the file is ours, written by this run.
            let _ = fs::remove_file(path);
        }
    }
    outcome
}

/// Test support: the next value of a small deterministic generator (an LCG) for the
/// readers' garbage tests.
#[cfg(test)]
pub(crate) fn lcg(state: &mut u64) -> usize {
    *state = state
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (*state >> 33) as usize
}

/// Test support: `count` mutants of `seed`, each with one to four edits (a byte
/// overwritten, the data cut, or a byte of `alphabet` inserted), for the readers' "never
/// panics" tests.
#[cfg(test)]
pub(crate) fn mutants(seed: &[u8], count: usize, alphabet: &[u8], state: &mut u64) -> Vec<Vec<u8>> {
    (0..count)
        .map(|_| {
            let mut m = seed.to_vec();
            for _ in 0..1 + lcg(state) % 4 {
                if m.is_empty() {
                    break;
                }
                let i = lcg(state) % m.len();
                match lcg(state) % 3 {
                    0 => m[i] = lcg(state) as u8,
                    1 => m.truncate(i),
                    _ => m.insert(i, alphabet[lcg(state) % alphabet.len()]),
                }
            }
            m
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fan_triangulation() {
        let mut out = Vec::new();
        push_fan(&mut out, &[4, 5, 6, 7, 8]).unwrap();
        assert_eq!(out, vec![[4, 5, 6], [4, 6, 7], [4, 7, 8]]);
        assert_eq!(
            push_fan(&mut out, &[1, 2]),
            Err(FormatError::TooFewCorners(2))
        );
    }

    #[test]
    fn utf8_error_names_the_line() {
        let err = text(b"a\nb\n\xff\n", 1).unwrap_err();
        assert_eq!(err.to_string(), "line 3: text is not valid UTF-8");
    }

    #[test]
    fn atomic_write_into_missing_directory_fails_and_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("no_such_dir");
        let target = missing.join("out.ply");
        let err = write_atomic(&target, |w| w.write_all(b"data")).unwrap_err();
        assert!(matches!(err, IoError::Io { .. }));
        assert_eq!(err.path(), Some(target.as_path()));
        assert!(err
            .to_string()
            .starts_with(&format!("{}: ", target.display())));
        assert!(!missing.exists());
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn atomic_write_failure_keeps_old_file_and_removes_temp() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.txt");
        fs::write(&target, b"old").unwrap();
        let err = write_atomic(&target, |w| {
            w.write_all(b"partial")?;
            Err(io::Error::other("disk full"))
        })
        .unwrap_err();
        assert!(err.to_string().contains("cannot write: disk full"));
        assert_eq!(fs::read(&target).unwrap(), b"old");
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);

        write_atomic(&target, |w| w.write_all(b"new")).unwrap();
        assert_eq!(fs::read(&target).unwrap(), b"new");
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn write_text_replaces_the_whole_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("report.json");
        write_text(&path, "{\"a\": 1, \"long\": \"...\"}\n").unwrap();
        write_text(&path, "{}\n").unwrap();
        assert_eq!(fs::read_to_string(&path).unwrap(), "{}\n");
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
        let nowhere = dir.path().join("none").join("report.json");
        assert!(matches!(
            write_text(&nowhere, "{}"),
            Err(IoError::Io { .. })
        ));
    }

    /// The outputs are written while `meanwhile` runs; a failure of `meanwhile`, of an
    /// output, or of the output `meanwhile` hands back leaves none of them behind.
    #[test]
    fn write_all_or_none_leaves_every_output_or_none() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b, c) = (
            dir.path().join("a.txt"),
            dir.path().join("b.txt"),
            dir.path().join("c.txt"),
        );
        let nowhere = dir.path().join("none").join("c.txt");
        let early = || -> Vec<Output<'_>> {
            vec![
                (&a, Box::new(|| write_text(&a, "a"))),
                (&b, Box::new(|| write_text(&b, "b"))),
            ]
        };
        fn late(path: &Path) -> Output<'_> {
            (path, Box::new(move || write_text(path, "c")))
        }
        let (c_path, nowhere) = (c.as_path(), nowhere.as_path());
        // Everything written, and `meanwhile`'s value returned.
        let value = write_all_or_none(early(), || Ok::<_, IoError>((7, Some(late(c_path)))));
        assert_eq!(value.unwrap(), 7);
        for (p, text) in [(&a, "a"), (&b, "b"), (&c, "c")] {
            assert_eq!(fs::read_to_string(p).unwrap(), text);
            fs::remove_file(p).unwrap();
        }
        // `meanwhile` fails: its error, and the outputs written meanwhile are removed.
        let failed = write_all_or_none(early(), || -> Result<((), _), IoError> {
            Err(FormatError::NoPoints.into())
        });
        assert!(matches!(failed, Err(IoError::Format { .. })), "{failed:?}");
        // The late output fails: the early ones are removed.
        let failed = write_all_or_none(early(), || Ok::<_, IoError>(((), Some(late(nowhere)))));
        assert!(matches!(failed, Err(IoError::Io { .. })), "{failed:?}");
        // An early output fails: the late one and the other early one are removed.
        let outputs: Vec<Output<'_>> = vec![
            (&a, Box::new(|| write_text(&a, "a"))),
            (nowhere, Box::new(|| write_text(nowhere, "x"))),
        ];
        let failed = write_all_or_none(outputs, || Ok::<_, IoError>(((), Some(late(c_path)))));
        assert!(matches!(failed, Err(IoError::Io { .. })), "{failed:?}");
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn temp_file_is_created_beside_the_target() {
        let dir = tempfile::tempdir().unwrap();
        let (temp, file) = create_temp(&dir.path().join("x.csv")).unwrap();
        drop(file);
        assert_eq!(temp.parent(), Some(dir.path()));
        let name = temp.file_name().unwrap().to_string_lossy().into_owned();
        assert!(
            name.starts_with(".x.csv.") && name.ends_with(".tmp"),
            "{name}"
        );
        assert!(create_temp(Path::new("/")).is_err());
    }
}
