//! The sequence metafile reader and writer (module docs of [`super`]).

use std::fmt;
use std::fs::{self, File};
use std::io::{self, BufRead, BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use flate2::bufread::ZlibDecoder;
use flate2::write::ZlibEncoder;
use flate2::Compression;

use super::super::{create_temp, excerpt, write_atomic};

/// A 4 × 4 homogeneous transform, row-major (`m[row][column]`), as PLUS writes it.
pub type Matrix4 = [[f64; 4]; 4];

/// Longest header line accepted, bytes. PLUS reads its headers with `fgets` into a
/// 1,000-byte buffer, so every file PLUS can read has shorter lines; the longest a PLUS
/// header holds is a transform: 16 numbers of at most ~24 characters plus a key of ~50,
/// under 500 bytes. 4 KiB leaves room for other writers' precision.
pub const MAX_LINE_BYTES: usize = 4096;
/// Most frames accepted: 1,000,000 frames are 9.3 h at 30 fps (a sweep is minutes). The
/// reader's memory does not grow with it (frames are streamed); it bounds the arithmetic
/// and the time spent on a header that claims more.
pub const MAX_FRAMES: u64 = 1_000_000;
/// Widest and tallest image accepted, pixels: B-mode images are at most ~1,024 pixels a
/// side and screen grabs 3,840 × 2,160; 4,096 fits ribreg's `u16` probe model.
pub const MAX_SIDE_PX: u64 = 4096;
/// Most pixels in one frame: 4,096 × 4,096 = 16 Mi, i.e. the one frame buffer the reader
/// holds is at most 16 MiB of `MET_UCHAR`.
pub const MAX_FRAME_PIXELS: u64 = MAX_SIDE_PX * MAX_SIDE_PX;
/// Largest header read before `ElementDataFile`, bytes: PLUS writes ~400 bytes of fields
/// per frame (one transform, its status, two time stamps, the frame number, the image
/// status), so 512 MiB holds [`MAX_FRAMES`] frames with a few transforms each. The header
/// is read line by line, never held: the limit bounds the time spent on a file that never
/// says where its data starts.
pub const MAX_HEADER_BYTES: u64 = 512 << 20;
/// Transform names listed in a "missing transform" message (those of the first frame).
const MAX_LISTED_TRANSFORMS: usize = 16;
/// Largest deviation of a transform's last row from `0 0 0 1`.
const LAST_ROW_TOLERANCE: f64 = 1e-6;

/// Where the stored image's `+x` (columns) and `+y` (rows) point (PLUS
/// "UltrasoundImageOrientation": M/U marked/unmarked side, F/N far from/near the probe).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Orientation {
    /// Columns towards the marked side, rows away from the probe (PLUS's own).
    Mf,
    /// Columns towards the marked side, rows towards the probe.
    Mn,
    /// Columns towards the unmarked side, rows away from the probe.
    Uf,
    /// Columns towards the unmarked side, rows towards the probe.
    Un,
}

impl Orientation {
    /// `MF`, `MN`, `UF`, `UN`, or a 3-D code of those plus `A`/`D` (the third letter is
    /// the elevation axis, meaningless for 2-D frames). Case-insensitive.
    pub fn parse(s: &str) -> Option<Orientation> {
        let s = s.to_ascii_uppercase();
        let two = match s.len() {
            2 => s.as_str(),
            3 if s.ends_with('A') || s.ends_with('D') => &s[..2],
            _ => return None,
        };
        match two {
            "MF" => Some(Orientation::Mf),
            "MN" => Some(Orientation::Mn),
            "UF" => Some(Orientation::Uf),
            "UN" => Some(Orientation::Un),
            _ => None,
        }
    }

    /// The two-letter code.
    pub fn name(self) -> &'static str {
        match self {
            Orientation::Mf => "MF",
            Orientation::Mn => "MN",
            Orientation::Uf => "UF",
            Orientation::Un => "UN",
        }
    }

    /// `(reverse columns, reverse rows)` between this orientation and `MF`.
    fn flips(self) -> (bool, bool) {
        match self {
            Orientation::Mf => (false, false),
            Orientation::Mn => (false, true),
            Orientation::Uf => (true, false),
            Orientation::Un => (true, true),
        }
    }

    /// Re-orients a row-major `width`-wide image in place between this orientation and
    /// `MF` (either way: each flip is its own inverse).
    pub fn reorient(self, pixels: &mut [u8], width: usize) {
        let (cols, rows) = self.flips();
        if width == 0 {
            return;
        }
        if cols {
            pixels.chunks_exact_mut(width).for_each(<[u8]>::reverse);
        }
        if rows {
            let height = pixels.len() / width;
            for r in 0..height / 2 {
                let (top, bottom) = pixels.split_at_mut((height - 1 - r) * width);
                top[r * width..(r + 1) * width].swap_with_slice(&mut bottom[..width]);
            }
        }
    }
}

/// A transform or image status.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Status {
    /// `OK` (or no status field).
    Ok,
    /// `INVALID`.
    Invalid,
    /// `MISSING` (the tool was not seen).
    Missing,
    /// `OUT_OF_VIEW`.
    OutOfView,
    /// `OUT_OF_VOLUME`.
    OutOfVolume,
    /// Any other word.
    Other,
}

impl Status {
    fn parse(s: &str) -> Status {
        match s.to_ascii_uppercase().as_str() {
            "OK" => Status::Ok,
            "INVALID" => Status::Invalid,
            "MISSING" => Status::Missing,
            "OUT_OF_VIEW" => Status::OutOfView,
            "OUT_OF_VOLUME" => Status::OutOfVolume,
            _ => Status::Other,
        }
    }

    /// The word PLUS writes (`other` for unrecognised words).
    pub fn name(self) -> &'static str {
        match self {
            Status::Ok => "OK",
            Status::Invalid => "INVALID",
            Status::Missing => "MISSING",
            Status::OutOfView => "OUT_OF_VIEW",
            Status::OutOfVolume => "OUT_OF_VOLUME",
            Status::Other => "other",
        }
    }
}

/// What is wrong with a sequence file (see [`SequenceError`]).
#[derive(Debug)]
pub enum SequenceErrorKind {
    /// The operating system failed.
    Io {
        /// What was being done.
        op: &'static str,
        /// The error.
        source: io::Error,
    },
    /// The file does not start with `ObjectType = Image` (holds the start found).
    NotMetaImage {
        /// The first line (elided), or a description of the bytes.
        found: String,
    },
    /// A header line is longer than [`MAX_LINE_BYTES`].
    LineTooLong {
        /// Line number (from 1).
        line: usize,
    },
    /// A header line is not text (UTF-8).
    NotText {
        /// Line number.
        line: usize,
    },
    /// A header line is not `Key = Value`.
    NotKeyValue {
        /// Line number.
        line: usize,
        /// The line (elided).
        found: String,
    },
    /// No `ElementDataFile` line within [`MAX_HEADER_BYTES`].
    HeaderTooLarge,
    /// The file ends before `ElementDataFile`.
    NoElementDataFile,
    /// A required header key is missing.
    MissingKey {
        /// The key.
        key: &'static str,
    },
    /// A value cannot be read.
    BadValue {
        /// Line number.
        line: usize,
        /// The key.
        key: String,
        /// The value (elided).
        found: String,
        /// What was expected.
        expected: &'static str,
    },
    /// A key appears twice (globally, or twice for one frame).
    DuplicateKey {
        /// Line number of the second.
        line: usize,
        /// The key.
        key: String,
    },
    /// A valid MetaIO setting this reader does not handle.
    Unsupported {
        /// The key.
        key: &'static str,
        /// The value found.
        found: String,
        /// What is read.
        expected: &'static str,
    },
    /// `ElementType` is not `MET_UCHAR`.
    ElementType {
        /// The type found.
        found: String,
    },
    /// A size in the header is over a cap.
    OverCap {
        /// What (`image width`, `frames`, ...).
        what: &'static str,
        /// The value claimed.
        found: u64,
        /// The cap.
        cap: u64,
    },
    /// The transform name asked for is not a name (empty or with spaces).
    BadTransformName(String),
    /// Frame fields out of order (frame `frame` after frame `after`).
    FrameOrder {
        /// Line number.
        line: usize,
        /// The frame of the line.
        frame: u64,
        /// The frame whose fields came before.
        after: u64,
    },
    /// `DimSize` declares a different number of frames than the header has fields for.
    FrameCount {
        /// Frames `DimSize` declares.
        declared: u64,
        /// Frames with fields in the header.
        in_header: u64,
    },
    /// A frame whose status is OK has no transform of the name asked for.
    MissingTransform {
        /// The frame.
        frame: u64,
        /// The transform asked for (without the `Transform` suffix).
        name: String,
        /// Transforms the first frame has.
        available: Vec<String>,
    },
    /// A frame has no `Timestamp`.
    MissingTimestamp {
        /// The frame.
        frame: u64,
    },
    /// The raw pixel data is not the size `DimSize` says.
    DataSize {
        /// `[width, height, frames]`.
        dims: [u64; 3],
        /// Bytes `DimSize` needs.
        expected: u64,
        /// Bytes after the header.
        found: u64,
    },
    /// The compressed data is not the size `CompressedDataSize` says.
    CompressedSize {
        /// `CompressedDataSize`.
        declared: u64,
        /// Bytes after the header.
        found: u64,
    },
    /// The pixel data ends inside a frame.
    Truncated {
        /// The frame being read.
        frame: u64,
        /// Frames `DimSize` declares.
        frames: u64,
        /// Whether the data is compressed.
        compressed: bool,
    },
    /// The compressed data is not a valid zlib stream.
    Corrupt {
        /// The frame being read.
        frame: u64,
        /// What zlib said.
        detail: String,
    },
    /// The zlib stream does not end where `DimSize` and `CompressedDataSize` say.
    ExtraData(String),
    /// A writer was given data it cannot write.
    Unwritable(String),
}

/// Error of [`SequenceReader`] and [`SequenceWriter`]: the file and what is wrong. Its
/// message is one line, `FILE: [line N: | frame K: ]PROBLEM`, saying what was found and
/// what was expected.
#[derive(Debug)]
pub struct SequenceError {
    /// The file.
    pub path: PathBuf,
    /// What is wrong.
    pub kind: SequenceErrorKind,
}

impl fmt::Display for SequenceErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use SequenceErrorKind as K;
        match self {
            K::Io { op, source } => write!(f, "{op}: {source}"),
            K::NotMetaImage { found } => write!(
                f,
                "not a MetaIO sequence file: it starts with {found}, expected the line \
                 \"ObjectType = Image\""
            ),
            K::LineTooLong { line } => write!(
                f,
                "line {line}: header line longer than {MAX_LINE_BYTES} bytes (binary data \
                 before \"ElementDataFile = LOCAL\"?)"
            ),
            K::NotText { line } => write!(
                f,
                "line {line}: header line is not text (binary data before \
                 \"ElementDataFile = LOCAL\"?)"
            ),
            K::NotKeyValue { line, found } => {
                write!(
                    f,
                    "line {line}: expected \"Key = Value\", found \"{found}\""
                )
            }
            K::HeaderTooLarge => write!(
                f,
                "no \"ElementDataFile\" line in the first {} MiB: not a sequence header",
                MAX_HEADER_BYTES >> 20
            ),
            K::NoElementDataFile => write!(
                f,
                "the header ends without \"ElementDataFile = LOCAL\" (no pixel data)"
            ),
            K::MissingKey { key } => write!(f, "the header has no \"{key}\""),
            K::BadValue {
                line,
                key,
                found,
                expected,
            } => write!(f, "line {line}: {key} = \"{found}\": expected {expected}"),
            K::DuplicateKey { line, key } => write!(f, "line {line}: {key} is given twice"),
            K::Unsupported {
                key,
                found,
                expected,
            } => write!(f, "{key} = {found} is not supported (expected {expected})"),
            K::ElementType { found } => {
                let known = [
                    "MET_CHAR",
                    "MET_SHORT",
                    "MET_USHORT",
                    "MET_INT",
                    "MET_UINT",
                    "MET_LONG",
                    "MET_ULONG",
                    "MET_LONG_LONG",
                    "MET_ULONG_LONG",
                    "MET_FLOAT",
                    "MET_DOUBLE",
                ]
                .contains(&found.as_str());
                let what = if known { "not supported" } else { "unknown" };
                write!(
                    f,
                    "ElementType {found} is {what}: expected MET_UCHAR (a bone mask, 0 = \
                     background, anything else = bone)"
                )
            }
            K::OverCap { what, found, cap } => write!(
                f,
                "DimSize claims {found} for the {what}, more than the {cap} this reader \
                 accepts (nothing was allocated for it)"
            ),
            K::BadTransformName(name) => write!(
                f,
                "\"{name}\" is not a transform name (expected e.g. ProbeToTracker)"
            ),
            K::FrameOrder { line, frame, after } => write!(
                f,
                "line {line}: a field of frame {frame} after the fields of frame {after}: \
                 expected the frames' fields grouped, in frame order"
            ),
            K::FrameCount {
                declared,
                in_header,
            } => write!(
                f,
                "DimSize declares {declared} frames, the header has fields for {in_header}"
            ),
            K::MissingTransform {
                frame,
                name,
                available,
            } => {
                write!(
                    f,
                    "frame {frame}: no {name}Transform (Seq_Frame{frame:04}_{name}Transform); \
                     transforms of frame 0: "
                )?;
                if available.is_empty() {
                    write!(f, "none")
                } else {
                    write!(f, "{}", available.join(", "))
                }
            }
            K::MissingTimestamp { frame } => write!(
                f,
                "frame {frame}: no Timestamp (Seq_Frame{frame:04}_Timestamp)"
            ),
            K::DataSize {
                dims,
                expected,
                found,
            } => {
                let [w, h, n] = dims;
                write!(
                    f,
                    "DimSize {w} {h} {n} needs {expected} bytes of pixel data, the file holds \
                     {found} after the header ("
                )?;
                if found < expected {
                    write!(f, "truncated, or DimSize is wrong)")
                } else {
                    write!(f, "DimSize is wrong, or data follows the frames)")
                }
            }
            K::CompressedSize { declared, found } => write!(
                f,
                "CompressedDataSize = {declared}, but the file holds {found} bytes after the \
                 header ({})",
                if found < declared {
                    "truncated"
                } else {
                    "data follows the compressed stream"
                }
            ),
            K::Truncated {
                frame,
                frames,
                compressed,
            } => write!(
                f,
                "frame {frame}: the {} pixel data ends inside frame {frame} of the {frames} \
                 DimSize declares",
                if *compressed { "decompressed" } else { "raw" }
            ),
            K::Corrupt { frame, detail } => write!(
                f,
                "frame {frame}: the compressed pixel data is not a valid zlib stream ({detail})"
            ),
            K::ExtraData(s) => f.write_str(s),
            K::Unwritable(s) => f.write_str(s),
        }
    }
}

impl fmt::Display for SequenceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.path.display(), self.kind)
    }
}

impl std::error::Error for SequenceError {}

/// What the header says about the sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct SequenceInfo {
    /// Image width, pixels.
    pub width: u16,
    /// Image height, pixels.
    pub height: u16,
    /// Frames.
    pub frames: u32,
    /// The stored orientation (frames are handed out as `MF`).
    pub orientation: Orientation,
    /// Whether the file states its orientation (otherwise `MF` is assumed).
    pub orientation_given: bool,
    /// Whether the pixel data is zlib-compressed.
    pub compressed: bool,
    /// The transform read per frame, without its `Transform` suffix (`ProbeToTracker`).
    pub transform: String,
    /// Transforms the first frame has (without the suffix), at most 16.
    pub transforms_available: Vec<String>,
}

/// One frame: its fields and its mask (re-oriented to `MF`: row-major, row 0 at the
/// probe face, `width × height` bytes).
#[derive(Clone, Debug, PartialEq)]
pub struct SequenceFrame<'a> {
    /// Frame index in the file (0-based).
    pub index: u32,
    /// `Timestamp`, s.
    pub timestamp: f64,
    /// `UnfilteredTimestamp`, s, if given.
    pub unfiltered_timestamp: Option<f64>,
    /// `FrameNumber`, if given.
    pub frame_number: Option<i64>,
    /// The transform's status (`Ok` when the file has no status field).
    pub status: Status,
    /// The transform, if the status is `OK` (a valid affine matrix, last row `0 0 0 1`).
    pub transform: Option<Matrix4>,
    /// `ImageStatus` (`Ok` when absent).
    pub image_status: Status,
    /// The mask, `MF`.
    pub mask: &'a [u8],
}

/// A transform field as parsed: the matrix, or the value found and what was expected.
type ParsedMatrix = Result<Matrix4, (String, &'static str)>;

/// Parsed fields of one frame.
#[derive(Default)]
struct FrameFields {
    index: u64,
    /// Line and parse result (a malformed transform matters only if the status is OK).
    transform: Option<(usize, ParsedMatrix)>,
    status: Option<Status>,
    timestamp: Option<f64>,
    unfiltered: Option<f64>,
    frame_number: Option<i64>,
    image: Option<Status>,
}

/// The keys of the transform asked for.
struct Names {
    transform: String,
    status: String,
    name: String,
}

impl Names {
    fn new(name: &str) -> Result<Names, SequenceErrorKind> {
        let ok = !name.is_empty()
            && name.len() <= 200
            && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
        if !ok {
            return Err(SequenceErrorKind::BadTransformName(excerpt(name)));
        }
        Ok(Names {
            transform: format!("{name}Transform"),
            status: format!("{name}TransformStatus"),
            name: name.to_owned(),
        })
    }
}

/// `Seq_Frame<digits>_<field>` → `(index, field)`; `None` for any other key.
fn split_frame_key(key: &str) -> Option<Option<(u64, &str)>> {
    let rest = key.strip_prefix("Seq_Frame")?;
    let Some((digits, field)) = rest.split_once('_') else {
        return Some(None);
    };
    if digits.is_empty() || digits.len() > 10 || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return Some(None);
    }
    Some(digits.parse().ok().map(|i| (i, field)))
}

fn parse_matrix(value: &str) -> ParsedMatrix {
    const EXPECTED: &str = "16 finite numbers, last row 0 0 0 1";
    let bad = || Err((excerpt(value), EXPECTED));
    let mut m = [[0.0; 4]; 4];
    let mut n = 0;
    for tok in value.split_ascii_whitespace() {
        let Ok(v) = tok.parse::<f64>() else {
            return bad();
        };
        if n >= 16 || !v.is_finite() {
            return bad();
        }
        m[n / 4][n % 4] = v;
        n += 1;
    }
    let last = [0.0, 0.0, 0.0, 1.0];
    if n != 16 || (0..4).any(|j| (m[3][j] - last[j]).abs() > LAST_ROW_TOLERANCE) {
        return bad();
    }
    Ok(m)
}

fn bad_value(line: usize, key: &str, value: &str, expected: &'static str) -> SequenceErrorKind {
    SequenceErrorKind::BadValue {
        line,
        key: key.to_owned(),
        found: excerpt(value),
        expected,
    }
}

fn parse_time(line: usize, key: &str, value: &str) -> Result<f64, SequenceErrorKind> {
    value
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| bad_value(line, key, value, "a finite number of seconds"))
}

/// Adds field `field` (of key `key`, line `line`) to `f`.
fn add_field(
    f: &mut FrameFields,
    names: &Names,
    field: &str,
    key: &str,
    value: &str,
    line: usize,
) -> Result<(), SequenceErrorKind> {
    fn set<T>(slot: &mut Option<T>, v: T, line: usize, key: &str) -> Result<(), SequenceErrorKind> {
        if slot.is_some() {
            return Err(SequenceErrorKind::DuplicateKey {
                line,
                key: key.to_owned(),
            });
        }
        *slot = Some(v);
        Ok(())
    }
    if field == names.transform {
        set(&mut f.transform, (line, parse_matrix(value)), line, key)
    } else if field == names.status {
        set(&mut f.status, Status::parse(value), line, key)
    } else {
        match field {
            "Timestamp" => set(&mut f.timestamp, parse_time(line, key, value)?, line, key),
            "UnfilteredTimestamp" => {
                set(&mut f.unfiltered, parse_time(line, key, value)?, line, key)
            }
            "FrameNumber" => {
                let n = value
                    .parse::<i64>()
                    .map_err(|_| bad_value(line, key, value, "a whole number"))?;
                set(&mut f.frame_number, n, line, key)
            }
            "ImageStatus" => set(&mut f.image, Status::parse(value), line, key),
            _ => Ok(()),
        }
    }
}

/// Checks a frame's fields are complete: a time stamp, and the transform (valid) unless
/// its status says it is not OK.
fn complete(
    f: &FrameFields,
    names: &Names,
    available: &[String],
) -> Result<Option<Matrix4>, SequenceErrorKind> {
    if f.timestamp.is_none() {
        return Err(SequenceErrorKind::MissingTimestamp { frame: f.index });
    }
    if f.status.unwrap_or(Status::Ok) != Status::Ok {
        return Ok(None);
    }
    match &f.transform {
        None => Err(SequenceErrorKind::MissingTransform {
            frame: f.index,
            name: names.name.clone(),
            available: available.to_vec(),
        }),
        Some((line, Err((found, expected)))) => Err(SequenceErrorKind::BadValue {
            line: *line,
            key: format!("Seq_Frame{:04}_{}", f.index, names.transform),
            found: found.clone(),
            expected,
        }),
        Some((_, Ok(m))) => Ok(Some(*m)),
    }
}

/// Header lines, one at a time, with line numbers and the bytes consumed.
struct HeaderLines<R> {
    r: R,
    line: usize,
    consumed: u64,
    buf: Vec<u8>,
}

impl<R: BufRead> HeaderLines<R> {
    fn new(r: R, line: usize, consumed: u64) -> Self {
        HeaderLines {
            r,
            line,
            consumed,
            buf: Vec::with_capacity(256),
        }
    }

    /// The next line, trimmed (`""` for a blank one); `None` at the end of the file.
    fn next_line(&mut self) -> Result<Option<&str>, SequenceErrorKind> {
        self.buf.clear();
        let n = (&mut self.r)
            .take(MAX_LINE_BYTES as u64 + 1)
            .read_until(b'\n', &mut self.buf)
            .map_err(|source| SequenceErrorKind::Io {
                op: "cannot read",
                source,
            })?;
        if n == 0 {
            return Ok(None);
        }
        self.line += 1;
        self.consumed += n as u64;
        if self.consumed > MAX_HEADER_BYTES {
            return Err(SequenceErrorKind::HeaderTooLarge);
        }
        if n > MAX_LINE_BYTES && self.buf.last() != Some(&b'\n') {
            return Err(SequenceErrorKind::LineTooLong { line: self.line });
        }
        let text = std::str::from_utf8(&self.buf)
            .map_err(|_| SequenceErrorKind::NotText { line: self.line })?;
        Ok(Some(text.trim()))
    }
}

fn split_key_value(line: usize, text: &str) -> Result<(&str, &str), SequenceErrorKind> {
    match text.split_once('=') {
        Some((k, v)) if !k.trim().is_empty() => Ok((k.trim(), v.trim())),
        _ => Err(SequenceErrorKind::NotKeyValue {
            line,
            found: excerpt(text),
        }),
    }
}

/// The global fields the reader uses.
#[derive(Default)]
struct Globals {
    ndims: Option<(usize, String)>,
    dim_size: Option<(usize, String)>,
    element_type: Option<String>,
    channels: Option<(usize, String)>,
    binary: Option<String>,
    compressed: Option<(usize, String)>,
    compressed_size: Option<(usize, String)>,
    orientation: Option<String>,
    image_type: Option<String>,
    data_file: Option<String>,
}

impl Globals {
    /// Records `key = value` if the reader uses the key.
    fn add(&mut self, line: usize, key: &str, value: &str) -> Result<(), SequenceErrorKind> {
        let slot = match key {
            "NDims" => return put(&mut self.ndims, (line, value.to_owned()), line, key),
            "DimSize" => return put(&mut self.dim_size, (line, value.to_owned()), line, key),
            "ElementNumberOfChannels" => {
                return put(&mut self.channels, (line, value.to_owned()), line, key)
            }
            "CompressedData" => {
                return put(&mut self.compressed, (line, value.to_owned()), line, key)
            }
            "CompressedDataSize" => {
                return put(
                    &mut self.compressed_size,
                    (line, value.to_owned()),
                    line,
                    key,
                )
            }
            "ElementType" => &mut self.element_type,
            "BinaryData" => &mut self.binary,
            "UltrasoundImageOrientation" => &mut self.orientation,
            "UltrasoundImageType" => &mut self.image_type,
            "ElementDataFile" => &mut self.data_file,
            _ => return Ok(()),
        };
        return put(slot, value.to_owned(), line, key);

        fn put<T>(
            slot: &mut Option<T>,
            v: T,
            line: usize,
            key: &str,
        ) -> Result<(), SequenceErrorKind> {
            if slot.is_some() {
                return Err(SequenceErrorKind::DuplicateKey {
                    line,
                    key: key.to_owned(),
                });
            }
            *slot = Some(v);
            Ok(())
        }
    }
}

fn is_true(v: &str) -> Option<bool> {
    match v.to_ascii_lowercase().as_str() {
        "true" => Some(true),
        "false" => Some(false),
        _ => None,
    }
}

/// Where the pixel data comes from.
enum Pixels {
    Raw(BufReader<File>),
    Zlib(Box<ZlibDecoder<BufReader<io::Take<File>>>>),
}

/// Streams a sequence file frame by frame (module docs of [`super`]).
pub struct SequenceReader {
    path: PathBuf,
    info: SequenceInfo,
    names: Names,
    header: HeaderLines<BufReader<File>>,
    /// A frame field read ahead: (line, frame, key, value).
    lookahead: Option<(usize, u64, String, String)>,
    pixels: Pixels,
    compressed_size: u64,
    buf: Vec<u8>,
    next: u32,
    done: bool,
    /// The fields of the frame last read, and its transform if OK.
    current: FrameFields,
    transform: Option<Matrix4>,
}

impl SequenceReader {
    /// Opens `path` and checks its header (every line, the sizes against the caps and
    /// the file) for the per-frame transform `transform` (e.g. `ProbeToTracker`: the
    /// fields `Seq_FrameNNNN_ProbeToTrackerTransform[Status]`).
    pub fn open(path: &Path, transform: &str) -> Result<SequenceReader, SequenceError> {
        let err = |kind| SequenceError {
            path: path.to_path_buf(),
            kind,
        };
        Self::open_inner(path, transform).map_err(err)
    }

    fn open_inner(path: &Path, transform: &str) -> Result<SequenceReader, SequenceErrorKind> {
        use SequenceErrorKind as K;
        let names = Names::new(transform)?;
        let io_err = |op| move |source| K::Io { op, source };
        let file = File::open(path).map_err(io_err("cannot open"))?;
        let file_len = file.metadata().map_err(io_err("cannot read"))?.len();
        let mut lines = HeaderLines::new(BufReader::new(file), 0, 0);

        // Line 1: ObjectType = Image. Any problem there means "not a sequence file".
        let first = match lines.next_line() {
            Ok(Some(t)) => t.to_owned(),
            Ok(None) => {
                return Err(K::NotMetaImage {
                    found: "nothing (an empty file)".into(),
                })
            }
            Err(K::Io { op, source }) => return Err(K::Io { op, source }),
            Err(_) => {
                return Err(K::NotMetaImage {
                    found: "binary data".into(),
                })
            }
        };
        let object_type = first
            .split_once('=')
            .map(|(k, v)| (k.trim(), v.trim()))
            .filter(|(k, _)| *k == "ObjectType");
        if object_type.map(|(_, v)| v) != Some("Image") {
            return Err(K::NotMetaImage {
                found: format!("\"{}\"", excerpt(&first)),
            });
        }

        let mut g = Globals::default();
        let mut current: Option<FrameFields> = None;
        let mut frames_in_header = 0u64;
        let mut available: Vec<String> = Vec::new();
        let mut first_frame_at: Option<(usize, u64)> = None;
        let data_offset;
        loop {
            let before = (lines.line, lines.consumed);
            let line = lines.line + 1;
            let Some(text) = lines.next_line()? else {
                return Err(K::NoElementDataFile);
            };
            if text.is_empty() {
                continue;
            }
            let (key, value) = split_key_value(line, text)?;
            match split_frame_key(key) {
                None => {
                    g.add(line, key, value)?;
                    if key == "ElementDataFile" {
                        data_offset = lines.consumed;
                        break;
                    }
                }
                Some(None) => {
                    return Err(bad_value(
                        line,
                        key,
                        value,
                        "a frame field named Seq_Frame<number>_<field>",
                    ))
                }
                Some(Some((index, field))) => {
                    let same = current.as_ref().map(|c| c.index);
                    if same != Some(index) {
                        let expected = match current.take() {
                            None => 0,
                            Some(done) => {
                                if index < done.index {
                                    return Err(K::FrameOrder {
                                        line,
                                        frame: index,
                                        after: done.index,
                                    });
                                }
                                complete(&done, &names, &available)?;
                                done.index + 1
                            }
                        };
                        if index != expected {
                            // Frame `expected` has no fields at all.
                            return Err(K::MissingTimestamp { frame: expected });
                        }
                        frames_in_header = index + 1;
                        first_frame_at.get_or_insert(before);
                        current = Some(FrameFields {
                            index,
                            ..FrameFields::default()
                        });
                    }
                    if index == 0 && available.len() < MAX_LISTED_TRANSFORMS {
                        if let Some(name) = field.strip_suffix("Transform") {
                            available.push(name.to_owned());
                        }
                    }
                    if let Some(c) = current.as_mut() {
                        add_field(c, &names, field, key, value, line)?;
                    }
                }
            }
        }
        if let Some(done) = &current {
            complete(done, &names, &available)?;
        }

        // Global fields.
        let data_file = g.data_file.unwrap_or_default();
        if data_file != "LOCAL" {
            return Err(K::Unsupported {
                key: "ElementDataFile",
                found: excerpt(&data_file),
                expected: "LOCAL: the pixel data in the same file (.mha); a .mhd header with \
                           a separate data file is not read",
            });
        }
        let (dims_line, dims_text) = g.dim_size.ok_or(K::MissingKey { key: "DimSize" })?;
        let dims: Vec<u64> = dims_text
            .split_ascii_whitespace()
            .map(|t| t.parse::<u64>())
            .collect::<Result<_, _>>()
            .map_err(|_| bad_value(dims_line, "DimSize", &dims_text, "whole numbers"))?;
        let ndims = match &g.ndims {
            Some((line, v)) => v
                .parse::<usize>()
                .map_err(|_| bad_value(*line, "NDims", v, "3 (width height frames)"))?,
            None => dims.len(),
        };
        let [w, h, n] = match (ndims, dims.as_slice()) {
            (3, &[w, h, n]) => [w, h, n],
            (4, &[w, h, 1, n]) => [w, h, n],
            (4, &[_, _, d, _]) => {
                return Err(K::Unsupported {
                    key: "DimSize",
                    found: format!("{dims_text} (3-D frames {d} deep)"),
                    expected: "2-D frames: width height frames, or width height 1 frames",
                })
            }
            (3 | 4, _) => {
                return Err(bad_value(
                    dims_line,
                    "DimSize",
                    &dims_text,
                    "as many numbers as NDims says",
                ))
            }
            (other, _) => {
                return Err(K::Unsupported {
                    key: "NDims",
                    found: other.to_string(),
                    expected: "3 (a sequence of 2-D frames: width height frames)",
                })
            }
        };
        if w == 0 || h == 0 || n == 0 {
            return Err(bad_value(
                dims_line,
                "DimSize",
                &dims_text,
                "at least one pixel and one frame",
            ));
        }
        for (what, found, cap) in [
            ("image width", w, MAX_SIDE_PX),
            ("image height", h, MAX_SIDE_PX),
            ("pixels of a frame", w * h, MAX_FRAME_PIXELS),
            ("frames", n, MAX_FRAMES),
        ] {
            if found > cap {
                return Err(K::OverCap { what, found, cap });
            }
        }
        match g.element_type.as_deref() {
            Some("MET_UCHAR") => {}
            Some(other) => {
                return Err(K::ElementType {
                    found: excerpt(other),
                })
            }
            None => return Err(K::MissingKey { key: "ElementType" }),
        }
        if let Some((_, c)) = &g.channels {
            if c != "1" {
                return Err(K::Unsupported {
                    key: "ElementNumberOfChannels",
                    found: excerpt(c),
                    expected: "1 (a mask)",
                });
            }
        }
        if let Some(b) = &g.binary {
            if is_true(b) != Some(true) {
                return Err(K::Unsupported {
                    key: "BinaryData",
                    found: excerpt(b),
                    expected: "True",
                });
            }
        }
        if let Some(t) = &g.image_type {
            if !t.eq_ignore_ascii_case("BRIGHTNESS") {
                return Err(K::Unsupported {
                    key: "UltrasoundImageType",
                    found: excerpt(t),
                    expected: "BRIGHTNESS (B-mode frames; here bone masks)",
                });
            }
        }
        let orientation = match &g.orientation {
            None => Orientation::Mf,
            Some(o) => Orientation::parse(o).ok_or_else(|| K::Unsupported {
                key: "UltrasoundImageOrientation",
                found: excerpt(o),
                expected: "a B-mode orientation: MF, MN, UF or UN",
            })?,
        };
        let compressed = match &g.compressed {
            None => false,
            Some((line, v)) => {
                is_true(v).ok_or_else(|| bad_value(*line, "CompressedData", v, "True or False"))?
            }
        };
        if frames_in_header != n {
            return Err(K::FrameCount {
                declared: n,
                in_header: frames_in_header,
            });
        }

        // The data against the file.
        let found = file_len.saturating_sub(data_offset);
        let compressed_size = if compressed {
            let (line, v) = g.compressed_size.ok_or(K::MissingKey {
                key: "CompressedDataSize",
            })?;
            let declared = v.parse::<u64>().map_err(|_| {
                bad_value(line, "CompressedDataSize", &v, "a whole number of bytes")
            })?;
            if declared != found {
                return Err(K::CompressedSize { declared, found });
            }
            declared
        } else {
            let expected = w * h * n;
            if expected != found {
                return Err(K::DataSize {
                    dims: [w, h, n],
                    expected,
                    found,
                });
            }
            0
        };

        // Second cursor over the header, at the first frame field; pixel cursor.
        let (first_line, first_offset) = first_frame_at.unwrap_or((0, 0));
        let mut hf = File::open(path).map_err(io_err("cannot open"))?;
        hf.seek(SeekFrom::Start(first_offset))
            .map_err(io_err("cannot read"))?;
        let header = HeaderLines::new(BufReader::new(hf), first_line, first_offset);
        let mut pf = File::open(path).map_err(io_err("cannot open"))?;
        pf.seek(SeekFrom::Start(data_offset))
            .map_err(io_err("cannot read"))?;
        let pixels = if compressed {
            Pixels::Zlib(Box::new(ZlibDecoder::new(BufReader::new(
                pf.take(compressed_size),
            ))))
        } else {
            Pixels::Raw(BufReader::new(pf))
        };
        // Note: w, h and n are within the caps checked above, so these fit.
        let (width, height, frames) = (w as u16, h as u16, n as u32);
        Ok(SequenceReader {
            path: path.to_path_buf(),
            info: SequenceInfo {
                width,
                height,
                frames,
                orientation,
                orientation_given: g.orientation.is_some(),
                compressed,
                transform: names.name.clone(),
                transforms_available: available,
            },
            names,
            header,
            lookahead: None,
            pixels,
            compressed_size,
            buf: vec![0; (w * h) as usize],
            next: 0,
            done: false,
            current: FrameFields::default(),
            transform: None,
        })
    }

    /// What the header says.
    pub fn info(&self) -> &SequenceInfo {
        &self.info
    }

    /// The next frame, `None` after the last (then the end of the data is checked: a zlib
    /// stream must end exactly with the last frame and the `CompressedDataSize` bytes).
    pub fn next_frame(&mut self) -> Result<Option<SequenceFrame<'_>>, SequenceError> {
        match self.next_inner() {
            Ok(true) => {}
            Ok(false) => return Ok(None),
            Err(kind) => {
                return Err(SequenceError {
                    path: self.path.clone(),
                    kind,
                })
            }
        }
        let f = &self.current;
        Ok(Some(SequenceFrame {
            index: self.next - 1,
            timestamp: f.timestamp.unwrap_or(f64::NAN),
            unfiltered_timestamp: f.unfiltered,
            frame_number: f.frame_number,
            status: f.status.unwrap_or(Status::Ok),
            transform: self.transform,
            image_status: f.image.unwrap_or(Status::Ok),
            mask: &self.buf,
        }))
    }
}

impl SequenceReader {
    /// Reads the next frame's fields and pixels into `self`; `false` after the last.
    fn next_inner(&mut self) -> Result<bool, SequenceErrorKind> {
        use SequenceErrorKind as K;
        if self.next >= self.info.frames {
            self.finish_data()?;
            return Ok(false);
        }
        let k = u64::from(self.next);
        let mut f = FrameFields {
            index: k,
            ..FrameFields::default()
        };
        if let Some((line, frame, key, value)) = self.lookahead.take() {
            if frame != k {
                return Err(K::FrameOrder {
                    line,
                    frame,
                    after: k,
                });
            }
            let field = key
                .strip_prefix("Seq_Frame")
                .and_then(|r| r.split_once('_'))
                .map_or("", |(_, field)| field);
            add_field(&mut f, &self.names, field, &key, &value, line)?;
        }
        loop {
            let line = self.header.line + 1;
            let Some(text) = self.header.next_line()? else {
                break;
            };
            if text.is_empty() {
                continue;
            }
            let (key, value) = split_key_value(line, text)?;
            if key == "ElementDataFile" {
                break;
            }
            match split_frame_key(key) {
                None => continue,
                Some(None) => {
                    return Err(bad_value(
                        line,
                        key,
                        value,
                        "a frame field named Seq_Frame<number>_<field>",
                    ))
                }
                Some(Some((index, field))) if index == k => {
                    add_field(&mut f, &self.names, field, key, value, line)?;
                }
                Some(Some((index, _))) if index > k => {
                    self.lookahead = Some((line, index, key.to_owned(), value.to_owned()));
                    break;
                }
                Some(Some((index, _))) => {
                    return Err(K::FrameOrder {
                        line,
                        frame: index,
                        after: k,
                    })
                }
            }
        }
        self.transform = complete(&f, &self.names, &self.info.transforms_available)?;
        self.current = f;

        let frames = u64::from(self.info.frames);
        let compressed = self.info.compressed;
        let read = match &mut self.pixels {
            Pixels::Raw(r) => r.read_exact(&mut self.buf),
            Pixels::Zlib(z) => z.read_exact(&mut self.buf),
        };
        read.map_err(|e| match e.kind() {
            io::ErrorKind::UnexpectedEof => K::Truncated {
                frame: k,
                frames,
                compressed,
            },
            io::ErrorKind::InvalidInput | io::ErrorKind::InvalidData if compressed => K::Corrupt {
                frame: k,
                detail: e.to_string(),
            },
            _ => K::Io {
                op: "cannot read",
                source: e,
            },
        })?;
        self.info
            .orientation
            .reorient(&mut self.buf, usize::from(self.info.width));
        self.next += 1;
        Ok(true)
    }

    /// After the last frame: the zlib stream must end here, having used every byte of
    /// `CompressedDataSize`.
    fn finish_data(&mut self) -> Result<(), SequenceErrorKind> {
        if std::mem::replace(&mut self.done, true) {
            return Ok(());
        }
        let Pixels::Zlib(z) = &mut self.pixels else {
            return Ok(());
        };
        let mut one = [0u8; 1];
        match z.read(&mut one) {
            Ok(0) => {}
            Ok(_) => {
                return Err(SequenceErrorKind::ExtraData(format!(
                    "the compressed pixel data decompresses to more than the {} frames of {} × \
                     {} pixels DimSize declares",
                    self.info.frames, self.info.width, self.info.height
                )))
            }
            Err(e) => {
                return Err(SequenceErrorKind::Corrupt {
                    frame: u64::from(self.info.frames),
                    detail: e.to_string(),
                })
            }
        }
        let used = z.total_in();
        if used != self.compressed_size {
            return Err(SequenceErrorKind::ExtraData(format!(
                "the zlib stream ends after {used} of the CompressedDataSize = {} bytes",
                self.compressed_size
            )));
        }
        Ok(())
    }
}

/// What [`SequenceWriter`] writes.
#[derive(Clone, Debug, PartialEq)]
pub struct SequenceSpec {
    /// Image width, pixels.
    pub width: u16,
    /// Image height, pixels.
    pub height: u16,
    /// Orientation stated in the file (frames are given to the writer as `MF` and stored
    /// in this orientation).
    pub orientation: Orientation,
    /// zlib-compress the pixel data.
    pub compressed: bool,
    /// Name of the per-frame transform (`ProbeToTracker`).
    pub transform: String,
}

/// One frame for [`SequenceWriter::push`].
#[derive(Clone, Copy, Debug)]
pub struct FrameOut<'a> {
    /// `Timestamp`, s.
    pub timestamp: f64,
    /// `UnfilteredTimestamp`, s.
    pub unfiltered_timestamp: f64,
    /// `FrameNumber`.
    pub frame_number: u64,
    /// The transform with status `OK`, or `None`: status `INVALID` (identity written).
    pub transform: Option<&'a Matrix4>,
    /// The mask, `MF`, row-major, `width × height` bytes.
    pub mask: &'a [u8],
}

enum Sink {
    Raw(BufWriter<File>),
    Zlib(ZlibEncoder<BufWriter<File>>),
}

/// Writes a sequence file: frames are pushed one at a time, their pixels streamed to a
/// temporary file beside the output (raw or through zlib), their fields kept as text
/// (~500 bytes a frame); [`SequenceWriter::finish`] writes the header and the data to
/// the output atomically, as the other writers of [`crate::io`] do.
pub struct SequenceWriter {
    path: PathBuf,
    spec: SequenceSpec,
    names: Names,
    fields: String,
    frames: u64,
    temp: PathBuf,
    sink: Option<Sink>,
    scratch: Vec<u8>,
}

/// A number as text that reads back to the same `f64`: plain decimals in the usual
/// range, exponent notation for very small or large magnitudes (keeps lines short).
fn num(v: f64) -> String {
    if v == 0.0 || (1e-4..1e15).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

impl SequenceWriter {
    /// Starts writing `path`.
    pub fn create(path: &Path, spec: SequenceSpec) -> Result<SequenceWriter, SequenceError> {
        let err = |kind| SequenceError {
            path: path.to_path_buf(),
            kind,
        };
        let names = Names::new(&spec.transform).map_err(err)?;
        if spec.width == 0 || spec.height == 0 {
            return Err(err(SequenceErrorKind::Unwritable(
                "the image must be at least 1 × 1 pixels".into(),
            )));
        }
        let (temp, file) = create_temp(path).map_err(|source| {
            err(SequenceErrorKind::Io {
                op: "cannot create a file",
                source,
            })
        })?;
        let out = BufWriter::new(file);
        let sink = if spec.compressed {
            Sink::Zlib(ZlibEncoder::new(out, Compression::default()))
        } else {
            Sink::Raw(out)
        };
        let pixels = usize::from(spec.width) * usize::from(spec.height);
        Ok(SequenceWriter {
            path: path.to_path_buf(),
            spec,
            names,
            fields: String::new(),
            frames: 0,
            temp,
            sink: Some(sink),
            scratch: vec![0; pixels],
        })
    }

    fn error(&self, kind: SequenceErrorKind) -> SequenceError {
        SequenceError {
            path: self.path.clone(),
            kind,
        }
    }

    /// Appends a frame.
    pub fn push(&mut self, frame: &FrameOut<'_>) -> Result<(), SequenceError> {
        use std::fmt::Write as _;
        let unwritable = |s: String| SequenceErrorKind::Unwritable(s);
        let k = self.frames;
        if frame.mask.len() != self.scratch.len() {
            return Err(self.error(unwritable(format!(
                "frame {k}: mask of {} bytes for a {} × {} image",
                frame.mask.len(),
                self.spec.width,
                self.spec.height
            ))));
        }
        let finite = frame.timestamp.is_finite()
            && frame.unfiltered_timestamp.is_finite()
            && frame
                .transform
                .is_none_or(|m| m.iter().flatten().all(|v| v.is_finite()));
        if !finite {
            return Err(self.error(unwritable(format!(
                "frame {k}: a time stamp or the transform is not finite"
            ))));
        }
        if k >= MAX_FRAMES {
            return Err(self.error(unwritable(format!("more than {MAX_FRAMES} frames"))));
        }
        let identity = [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        let (m, status) = match frame.transform {
            Some(m) => (m, "OK"),
            None => (&identity, "INVALID"),
        };
        let matrix: Vec<String> = m.iter().flatten().map(|&v| num(v)).collect();
        let p = format!("Seq_Frame{k:04}_");
        // Note: writing into a String cannot fail.
        let _ = write!(
            self.fields,
            "{p}FrameNumber = {}\n{p}{} = {}\n{p}{} = {status}\n{p}Timestamp = {}\n\
             {p}UnfilteredTimestamp = {}\n{p}ImageStatus = OK\n",
            frame.frame_number,
            self.names.transform,
            matrix.join(" "),
            self.names.status,
            num(frame.timestamp),
            num(frame.unfiltered_timestamp),
        );
        self.scratch.copy_from_slice(frame.mask);
        self.spec
            .orientation
            .reorient(&mut self.scratch, usize::from(self.spec.width));
        let written = match self.sink.as_mut() {
            Some(Sink::Raw(w)) => w.write_all(&self.scratch),
            Some(Sink::Zlib(z)) => z.write_all(&self.scratch),
            None => Ok(()),
        };
        written.map_err(|source| {
            self.error(SequenceErrorKind::Io {
                op: "cannot write",
                source,
            })
        })?;
        self.frames += 1;
        Ok(())
    }

    /// Writes the file (header, then the pixel data) and removes the temporary file.
    pub fn finish(mut self) -> Result<(), SequenceError> {
        let io_err = |op| move |source| SequenceErrorKind::Io { op, source };
        if self.frames == 0 {
            return Err(self.error(SequenceErrorKind::Unwritable("no frames to write".into())));
        }
        let flushed = match self.sink.take() {
            Some(Sink::Raw(w)) => w.into_inner().map_err(io::IntoInnerError::into_error),
            Some(Sink::Zlib(z)) => z
                .finish()
                .and_then(|w| w.into_inner().map_err(io::IntoInnerError::into_error)),
            None => Err(io::Error::other("the writer was finished")),
        };
        let data_len = flushed
            .and_then(|f| f.sync_all().and_then(|()| fs::metadata(&self.temp)))
            .map(|m| m.len())
            .map_err(|e| self.error(io_err("cannot write")(e)))?;
        let s = &self.spec;
        let mut header = format!(
            "ObjectType = Image\nNDims = 3\nAnatomicalOrientation = RAI\nBinaryData = True\n\
             BinaryDataByteOrderMSB = False\nCenterOfRotation = 0 0 0\nCompressedData = {}\n",
            if s.compressed { "True" } else { "False" }
        );
        if s.compressed {
            header.push_str(&format!("CompressedDataSize = {data_len}\n"));
        }
        header.push_str(&format!(
            "DimSize = {} {} {}\nElementNumberOfChannels = 1\nElementSpacing = 1 1 1\n\
             ElementType = MET_UCHAR\nKinds = domain domain list\nOffset = 0 0 0\n\
             TransformMatrix = 1 0 0 0 1 0 0 0 1\nUltrasoundImageOrientation = {}\n\
             UltrasoundImageType = BRIGHTNESS\n",
            s.width,
            s.height,
            self.frames,
            s.orientation.name()
        ));
        let temp = self.temp.clone();
        let fields = std::mem::take(&mut self.fields);
        let written = write_atomic(&self.path, |out| {
            out.write_all(header.as_bytes())?;
            out.write_all(fields.as_bytes())?;
            out.write_all(b"ElementDataFile = LOCAL\n")?;
            let mut data = File::open(&temp)?;
            io::copy(&mut data, out)?;
            Ok(())
        });
        let _ = fs::remove_file(&self.temp);
        written.map_err(|e| match e {
            super::super::IoError::Io { op, source, .. } => {
                self.error(SequenceErrorKind::Io { op, source })
            }
            other => self.error(SequenceErrorKind::Unwritable(other.to_string())),
        })
    }
}

impl Drop for SequenceWriter {
    fn drop(&mut self) {
        // Best effort: the temporary data file is ours (already gone after `finish`).
        let _ = fs::remove_file(&self.temp);
    }
}
