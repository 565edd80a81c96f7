//! The NRRD labelmap reader (module docs of [`super`]).
//!
//! Reads attached-header files as Slicer, ITK and pynrrd write them (NRRD format
//! `NRRD0001`..`NRRD0005`): the magic line, then `field: value` lines and `key:=value`
//! pairs (`#` lines are comments) up to a blank line, then the data.

use std::collections::{BTreeMap, HashMap};
use std::io::Read;

use flate2::bufread::GzDecoder;

use super::{label, labels_from, to_patient, voxel_count, Affine, LabelVolume, Sample};
use crate::io::{excerpt, text, FormatError, IoError, Location, Space};

/// Parse an attached-header NRRD labelmap (`.nrrd`, or a Slicer `.seg.nrrd` with its
/// `SegmentN_Name`, `SegmentN_LabelValue` and `SegmentN_Layer` pairs into
/// [`LabelVolume::segments`]).
///
/// Fields read: `type` (`uchar`, `char`, `short`, `ushort`, `int`, `uint`, `longlong`,
/// `ulonglong`, `float`, `double` and their aliases `uint8`, `unsigned char`, `int16`...),
/// `dimension` (3), `sizes`, `endian`, `encoding` (`raw`, `gzip`/`gz`, `ascii`/`text`/`txt`),
/// `space` (`left-posterior-superior`/`LPS` or `right-anterior-superior`/`RAS`),
/// `space directions` and `space origin`; others are ignored.
///
/// # Errors
///
/// [`IoError::Format`] (without a path; with the header line where one is at fault):
/// [`FormatError::NotNrrd`]; [`FormatError::NrrdField`] for a missing or malformed field,
/// a detached `data file`, a multi-layer segment or an unsupported encoding;
/// [`FormatError::VolumeDimension`] for anything but 3-D (a 4-D multi-layer segmentation
/// must be exported as a labelmap); [`FormatError::NoSpace`] without a `space`, [`FormatError::UnknownSpace`] for one not RAS or
/// LPS; [`FormatError::VolumeDatatype`], [`FormatError::EmptyVolume`],
/// [`FormatError::VolumeTooLarge`] (before allocating), [`FormatError::VolumeTruncated`],
/// [`FormatError::TrailingData`], [`FormatError::Gzip`],
/// [`FormatError::NotIntegralLabel`], [`FormatError::VolumeAffine`].
pub fn parse_nrrd(bytes: &[u8]) -> Result<LabelVolume, IoError> {
    let (header, data) = split(bytes)?;
    let header = Header::parse(text(header, 1)?)?;
    header.volume(data)
}

/// The refusal of a detached header (`data file:` or a `.nhdr`).
pub(super) fn detached() -> FormatError {
    FormatError::NrrdField {
        field: "data file".into(),
        problem: "detached data files are not read; save the volume as one .nrrd file".into(),
    }
}

/// The header bytes (magic line included) and the data after the blank line ending it.
fn split(bytes: &[u8]) -> Result<(&[u8], &[u8]), IoError> {
    let magic = bytes.get(..8).ok_or(FormatError::NotNrrd)?;
    if !(magic.starts_with(b"NRRD000") && (b'1'..=b'5').contains(&magic[7])) {
        return Err(FormatError::NotNrrd.into());
    }
    let mut start = 0;
    while let Some(len) = bytes[start..].iter().position(|&b| b == b'\n') {
        let line = &bytes[start..start + len];
        if line.is_empty() || line == b"\r" {
            return Ok((&bytes[..start], &bytes[start + len + 1..]));
        }
        start += len + 1;
    }
    // No blank line: a detached header ends without one.
    let header = text(bytes, 1)?;
    if header
        .lines()
        .any(|l| l.starts_with("data file:") || l.starts_with("datafile:"))
    {
        return Err(detached().into());
    }
    Err(FormatError::NrrdField {
        field: "header".into(),
        problem: "no blank line ends the header (and no data follows it)".into(),
    }
    .into())
}

/// The fields and key/value pairs of a header, each with its line number.
struct Header<'a> {
    fields: HashMap<String, (usize, &'a str)>,
    pairs: Vec<(usize, &'a str, &'a str)>,
}

/// A field error at `line`.
fn at(line: usize, field: &str, problem: impl Into<String>) -> IoError {
    IoError::format(
        FormatError::NrrdField {
            field: field.to_owned(),
            problem: problem.into(),
        },
        Some(Location::Line(line)),
    )
}

/// A missing required field.
fn missing(field: &str) -> IoError {
    FormatError::NrrdField {
        field: field.to_owned(),
        problem: "missing".into(),
    }
    .into()
}

impl<'a> Header<'a> {
    fn parse(text: &'a str) -> Result<Self, IoError> {
        let mut fields = HashMap::new();
        let mut pairs = Vec::new();
        for (i, line) in text.lines().enumerate().skip(1) {
            let n = i + 1;
            let line = line.trim_end_matches('\r');
            if line.starts_with('#') {
                continue;
            }
            let field = line
                .find(": ")
                .or_else(|| line.strip_suffix(':').map(str::len));
            let pair = line.find(":=");
            match (field, pair) {
                (Some(f), p) if p.is_none_or(|p| f < p) => {
                    let name = line[..f].trim().to_ascii_lowercase();
                    let value = line.get(f + 2..).unwrap_or("").trim();
                    if fields.insert(name.clone(), (n, value)).is_some() {
                        return Err(at(n, &name, "given twice"));
                    }
                }
                (_, Some(p)) => pairs.push((n, &line[..p], &line[p + 2..])),
                _ => {
                    return Err(IoError::format(
                        FormatError::Syntax(format!(
                            "expected \"field: value\" or \"key:=value\", found \"{}\"",
                            excerpt(line)
                        )),
                        Some(Location::Line(n)),
                    ))
                }
            }
        }
        Ok(Header { fields, pairs })
    }

    /// A field's line and value, if present.
    fn get(&self, field: &str) -> Option<(usize, &'a str)> {
        self.fields.get(field).copied()
    }

    /// A required field's line and value.
    fn require(&self, field: &str) -> Result<(usize, &'a str), IoError> {
        self.get(field).ok_or_else(|| missing(field))
    }

    /// The volume the header describes, with `data` its body.
    fn volume(&self, data: &[u8]) -> Result<LabelVolume, IoError> {
        if self.get("data file").or(self.get("datafile")).is_some() {
            return Err(detached().into());
        }
        for field in ["byte skip", "line skip"] {
            if let Some((n, v)) = self.get(field) {
                if v != "0" {
                    return Err(at(n, field, "skipping into the data is not supported"));
                }
            }
        }
        let (n, dimension) = self.require("dimension")?;
        match dimension.parse::<usize>() {
            Ok(3) => {}
            Ok(4) => {
                return Err(IoError::format(
                    FormatError::VolumeDimension(
                        "4-D NRRD (a segmentation with overlapping layers?): export a \
                         labelmap, or save the segmentation as a single layer"
                            .into(),
                    ),
                    Some(Location::Line(n)),
                ))
            }
            Ok(d) => {
                return Err(IoError::format(
                    FormatError::VolumeDimension(format!("a {d}-D NRRD, not a 3-D volume")),
                    Some(Location::Line(n)),
                ))
            }
            Err(_) => {
                return Err(at(
                    n,
                    "dimension",
                    format!("\"{}\" is not a count", excerpt(dimension)),
                ))
            }
        }
        let (n, ty) = self.require("type")?;
        let sample = sample(ty).ok_or_else(|| {
            IoError::format(
                FormatError::VolumeDatatype(format!("NRRD type \"{}\"", excerpt(ty))),
                Some(Location::Line(n)),
            )
        })?;
        let (n, sizes) = self.require("sizes")?;
        let dims: Vec<u64> = sizes
            .split_whitespace()
            .map(str::parse)
            .collect::<Result<_, _>>()
            .map_err(|_| at(n, "sizes", format!("\"{}\" are not counts", excerpt(sizes))))?;
        let dims: [u64; 3] = dims
            .try_into()
            .map_err(|d: Vec<u64>| at(n, "sizes", format!("{} sizes for dimension 3", d.len())))?;
        let voxels = voxel_count(dims).map_err(|e| IoError::format(e, Some(Location::Line(n))))?;

        let ((linear, offset), space) = self.affine()?;
        let segments = self.segments()?;

        let encoding = match self.require("encoding")? {
            (_, "raw") => Encoding::Raw,
            (_, "gzip" | "gz") => Encoding::Gzip,
            (_, "ascii" | "text" | "txt") => Encoding::Ascii,
            (n, other) => {
                return Err(at(
                    n,
                    "encoding",
                    format!(
                        "\"{}\" is not supported (save as raw or gzip)",
                        excerpt(other)
                    ),
                ))
            }
        };
        let big_endian = match self.get("endian") {
            Some((_, "little")) => false,
            Some((_, "big")) => true,
            Some((n, other)) => {
                return Err(at(
                    n,
                    "endian",
                    format!("\"{}\" is neither little nor big", excerpt(other)),
                ))
            }
            None if sample.size() == 1 || encoding == Encoding::Ascii => false,
            None => return Err(missing("endian")),
        };
        let labels = match encoding {
            Encoding::Ascii => ascii_labels(data, voxels)?,
            Encoding::Raw | Encoding::Gzip => {
                let expected = voxels * sample.size();
                let body;
                let bytes = if encoding == Encoding::Gzip {
                    // Inflate at most one byte more than declared: enough to see trailing data.
                    let mut out = Vec::new();
                    GzDecoder::new(data)
                        .take(expected as u64 + 1)
                        .read_to_end(&mut out)
                        .map_err(|e| FormatError::Gzip(e.to_string()))?;
                    body = out;
                    &body[..]
                } else {
                    data
                };
                if bytes.len() < expected {
                    return Err(FormatError::VolumeTruncated {
                        expected: expected as u64,
                        found: bytes.len() as u64,
                    }
                    .into());
                }
                if bytes.len() > expected {
                    return Err(FormatError::TrailingData.into());
                }
                labels_from(bytes, sample, big_endian, None)?
            }
        };
        Ok(LabelVolume {
            dims: dims.map(|d| d as usize),
            labels,
            linear,
            offset,
            space,
            segments,
        })
    }

    /// The patient-frame affine and the declared space.
    fn affine(&self) -> Result<(Affine, Space), IoError> {
        let space = match self.get("space") {
            Some((n, name)) => match Space::parse(name) {
                Some(s @ (Space::Lps | Space::Ras)) => s,
                _ => {
                    return Err(IoError::format(
                        FormatError::UnknownSpace(excerpt(name)),
                        Some(Location::Line(n)),
                    ))
                }
            },
            None => return Err(FormatError::NoSpace.into()),
        };
        let (n, directions) = self.require("space directions")?;
        let columns = vectors(directions).map_err(|p| at(n, "space directions", p))?;
        let columns: [[f64; 3]; 3] = columns.try_into().map_err(|c: Vec<_>| {
            at(
                n,
                "space directions",
                format!("{} vectors for dimension 3", c.len()),
            )
        })?;
        let (n, origin) = self.require("space origin")?;
        let origin = vectors(origin).map_err(|p| at(n, "space origin", p))?;
        let [origin]: [[f64; 3]; 1] = origin
            .try_into()
            .map_err(|_| at(n, "space origin", "expected one vector (x,y,z)"))?;
        let linear = [0, 1, 2].map(|r| [0, 1, 2].map(|c| columns[c][r]));
        let (linear, offset) = to_patient(space, linear, origin)
            .map_err(|e| IoError::format(e, Some(Location::Line(n))))?;
        Ok(((linear, offset), space))
    }

    /// Slicer's `SegmentN_Name` / `SegmentN_LabelValue` pairs, in segment order.
    fn segments(&self) -> Result<Vec<(String, u16)>, IoError> {
        #[derive(Default)]
        struct Segment {
            name: Option<String>,
            label: Option<u16>,
            line: usize,
        }
        let mut by_number: BTreeMap<u32, Segment> = BTreeMap::new();
        for &(n, key, value) in &self.pairs {
            let Some((number, attribute)) = key
                .strip_prefix("Segment")
                .and_then(|rest| rest.split_once('_'))
            else {
                continue;
            };
            let Ok(number) = number.parse::<u32>() else {
                continue;
            };
            let parse_int = |what: &str| {
                value
                    .trim()
                    .parse::<u16>()
                    .map_err(|_| at(n, key, format!("\"{}\" is not a {what}", excerpt(value))))
            };
            match attribute {
                "Name" => {
                    let s = by_number.entry(number).or_default();
                    s.name = Some(unescape(value));
                    s.line = n;
                }
                "LabelValue" => {
                    let l = parse_int("label value in 0..=65535")?;
                    let s = by_number.entry(number).or_default();
                    s.label = Some(l);
                    s.line = n;
                }
                "Layer" => {
                    let layer = parse_int("layer number")?;
                    if layer != 0 {
                        return Err(at(
                            n,
                            key,
                            "a second layer in a 3-D file: export a labelmap",
                        ));
                    }
                }
                _ => {}
            }
        }
        by_number
            .into_iter()
            .map(|(number, s)| match (s.name, s.label) {
                (Some(name), Some(label)) => Ok((name, label)),
                (None, _) => Err(at(s.line, &format!("Segment{number}_Name"), "missing")),
                (_, None) => Err(at(
                    s.line,
                    &format!("Segment{number}_LabelValue"),
                    "missing",
                )),
            })
            .collect()
    }
}

/// A body encoding.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Encoding {
    Raw,
    Gzip,
    Ascii,
}

/// The voxel type of a NRRD `type` (its canonical names and every alias of the format).
fn sample(ty: &str) -> Option<Sample> {
    Some(match ty {
        "signed char" | "int8" | "int8_t" | "char" => Sample::I8,
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => Sample::U8,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => {
            Sample::I16
        }
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => Sample::U16,
        "int" | "signed int" | "int32" | "int32_t" => Sample::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => Sample::U32,
        "longlong"
        | "long long"
        | "long long int"
        | "signed long long"
        | "signed long long int"
        | "int64"
        | "int64_t" => Sample::I64,
        "ulonglong" | "unsigned long long" | "unsigned long long int" | "uint64" | "uint64_t" => {
            Sample::U64
        }
        "float" => Sample::F32,
        "double" => Sample::F64,
        _ => return None,
    })
}

/// The `(x,y,z)` vectors of a `space directions` or `space origin` value.
fn vectors(value: &str) -> Result<Vec<[f64; 3]>, String> {
    let mut out = Vec::new();
    let mut rest = value.trim();
    while !rest.is_empty() {
        if rest.starts_with("none") {
            return Err("an axis without a direction (\"none\"): not a spatial volume".into());
        }
        let inner = rest
            .strip_prefix('(')
            .and_then(|r| r.split_once(')'))
            .ok_or_else(|| format!("\"{}\" is not a vector (x,y,z)", excerpt(rest)))?;
        let tokens: Vec<&str> = inner.0.split(',').map(str::trim).collect();
        let v = crate::io::parse_numbers::<3>(&tokens)
            .map_err(|e| format!("({}): {e}", excerpt(inner.0)))?;
        out.push(v);
        rest = inner.1.trim_start();
    }
    Ok(out)
}

/// A key/value string with NRRD's escapes (`\n`, `\\`) undone.
fn unescape(value: &str) -> String {
    let mut out = String::with_capacity(value.len());
    let mut chars = value.chars();
    while let Some(c) = chars.next() {
        match (c, chars.clone().next()) {
            ('\\', Some('n')) => {
                out.push('\n');
                chars.next();
            }
            ('\\', Some('\\')) => {
                out.push('\\');
                chars.next();
            }
            _ => out.push(c),
        }
    }
    out
}

/// Labels from an `ascii` body: whitespace-separated numbers, exactly `voxels` of them.
fn ascii_labels(data: &[u8], voxels: usize) -> Result<Vec<u16>, IoError> {
    let body = std::str::from_utf8(data).map_err(|_| FormatError::NotUtf8)?;
    let mut labels = Vec::new();
    for (index, token) in body.split_whitespace().enumerate() {
        if index == voxels {
            return Err(FormatError::TrailingData.into());
        }
        let value: f64 = token
            .parse()
            .map_err(|_| FormatError::NotANumber(excerpt(token)))?;
        labels.push(label(index, value)?);
    }
    if labels.len() < voxels {
        return Err(FormatError::NrrdField {
            field: "sizes".into(),
            problem: format!(
                "the ascii data holds {} values, the sizes declare {voxels}",
                labels.len()
            ),
        }
        .into());
    }
    Ok(labels)
}
