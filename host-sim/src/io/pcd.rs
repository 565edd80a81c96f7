//! PCD (Point Cloud Library's format, also written by Open3D): header versions 0.5 to
//! 0.7, `DATA ascii`, `binary` and `binary_compressed` (LZF) bodies.

use std::path::Path;

use super::cloud::label_value;
use super::{content_lines, excerpt, lzf, read_bytes, text};
use super::{Cloud, FormatError, IoError, Location, PlyFormat};

/// The value type of a PCD field (`TYPE` letter).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// `F`: IEEE float, 4 or 8 bytes.
    Float,
    /// `I`: signed integer, 1, 2, 4 or 8 bytes.
    Signed,
    /// `U`: unsigned integer, 1, 2, 4 or 8 bytes.
    Unsigned,
}

/// A declared field: `COUNT` values of `SIZE` bytes each per point.
#[derive(Debug)]
struct Field {
    name: String,
    size: usize,
    kind: Kind,
    count: usize,
}

impl Field {
    /// Decode one little-endian value of this field from exactly `size` bytes.
    fn decode(&self, bytes: &[u8]) -> f64 {
        let mut raw = [0u8; 8];
        for (r, b) in raw.iter_mut().zip(bytes) {
            *r = *b;
        }
        let [a, b, c, d, ..] = raw;
        let wide = u64::from_le_bytes(raw);
        match self.kind {
            Kind::Float if self.size == 4 => f32::from_le_bytes([a, b, c, d]).into(),
            Kind::Float => f64::from_le_bytes(raw),
            Kind::Unsigned => wide as f64,
            Kind::Signed => {
                // Sign-extend from `size` bytes (1..=8, checked by the header parser).
                let shift = 64 - 8 * self.size as u32;
                ((wide << shift) as i64 >> shift) as f64
            }
        }
    }

    /// Bytes per point.
    fn width(&self) -> usize {
        self.size * self.count
    }
}

/// Body encoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Data {
    Ascii,
    Binary,
    Compressed,
}

/// A parsed header.
#[derive(Debug)]
struct Header {
    fields: Vec<Field>,
    points: usize,
    data: Data,
    /// Field index of x, y, z and the optional label.
    xyz: [usize; 3],
    label: Option<usize>,
    /// Byte offset and line number of the body.
    body_start: usize,
    body_line: usize,
}

impl Header {
    /// Bytes per point in a binary body (at most 8 × COUNT per field, checked).
    fn row_len(&self) -> usize {
        self.fields.iter().map(Field::width).sum()
    }

    /// Values per point in an ASCII body.
    fn values(&self) -> usize {
        self.fields.iter().map(|f| f.count).sum()
    }
}

/// Parse the whitespace-separated values after a header keyword.
fn numbers(keyword: &str, words: &[&str]) -> Result<Vec<usize>, FormatError> {
    words
        .iter()
        .map(|w| {
            w.parse().map_err(|_| {
                FormatError::PcdHeader(format!("{keyword} value \"{}\" is not a count", excerpt(w)))
            })
        })
        .collect()
}

/// The single count after `WIDTH`, `HEIGHT` or `POINTS`.
fn single(keyword: &str, words: &[&str]) -> Result<usize, FormatError> {
    match numbers(keyword, words)?.as_slice() {
        [n] => Ok(*n),
        v => Err(FormatError::PcdHeader(format!(
            "{keyword} needs one value, found {}",
            v.len()
        ))),
    }
}

/// Parse the header up to and including the `DATA` line.
fn parse_header(bytes: &[u8]) -> Result<Header, IoError> {
    let mut names: Option<Vec<String>> = None;
    let mut sizes: Option<Vec<usize>> = None;
    let mut types: Option<Vec<String>> = None;
    let mut counts: Option<Vec<usize>> = None;
    let (mut width, mut height, mut points) = (None, None, None);
    let mut seen_keyword = false;
    let mut offset = 0;
    let mut line_no = 0;
    let data = loop {
        if offset >= bytes.len() {
            return Err(if seen_keyword {
                FormatError::PcdHeader("no DATA line".to_owned()).into()
            } else {
                FormatError::NotPcd.into()
            });
        }
        line_no += 1;
        let rest = &bytes[offset..];
        let end = rest.iter().position(|&b| b == b'\n');
        let raw = &rest[..end.unwrap_or(rest.len())];
        offset += end.map_or(rest.len(), |e| e + 1);
        let at = |kind| IoError::format(kind, Some(Location::Line(line_no)));
        let line = std::str::from_utf8(raw)
            .map_err(|_| {
                at(if seen_keyword {
                    FormatError::NotUtf8
                } else {
                    FormatError::NotPcd
                })
            })?
            .trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let words: Vec<&str> = line.split_whitespace().collect();
        let (keyword, values) = match words.split_first() {
            Some((k, v)) => (*k, v),
            None => continue,
        };
        let known = matches!(
            keyword,
            "VERSION"
                | "FIELDS"
                | "COLUMNS"
                | "SIZE"
                | "TYPE"
                | "COUNT"
                | "WIDTH"
                | "HEIGHT"
                | "VIEWPOINT"
                | "POINTS"
                | "DATA"
        );
        if !known {
            return Err(at(if seen_keyword {
                FormatError::PcdHeader(format!("unknown header line \"{}\"", excerpt(line)))
            } else {
                FormatError::NotPcd
            }));
        }
        seen_keyword = true;
        let twice = |what: &str| at(FormatError::PcdHeader(format!("{what} is declared twice")));
        match keyword {
            "VERSION" => {
                let v = values.first().copied().unwrap_or_default();
                let v = v.strip_prefix('0').unwrap_or(v);
                if !matches!(v, ".5" | ".6" | ".7") || values.len() != 1 {
                    return Err(at(FormatError::PcdHeader(format!(
                        "unsupported \"{}\" (expected VERSION 0.5, 0.6 or 0.7)",
                        excerpt(line)
                    ))));
                }
            }
            "FIELDS" | "COLUMNS" if names.is_some() => return Err(twice("FIELDS")),
            "FIELDS" | "COLUMNS" => {
                names = Some(values.iter().map(|s| (*s).to_owned()).collect());
            }
            "SIZE" if sizes.is_some() => return Err(twice(keyword)),
            "SIZE" => sizes = Some(numbers(keyword, values).map_err(at)?),
            "TYPE" if types.is_some() => return Err(twice(keyword)),
            "TYPE" => types = Some(values.iter().map(|s| (*s).to_owned()).collect()),
            "COUNT" if counts.is_some() => return Err(twice(keyword)),
            "COUNT" => counts = Some(numbers(keyword, values).map_err(at)?),
            "WIDTH" => width = Some(single(keyword, values).map_err(at)?),
            "HEIGHT" => height = Some(single(keyword, values).map_err(at)?),
            "POINTS" => points = Some(single(keyword, values).map_err(at)?),
            "DATA" => {
                break match values {
                    ["ascii"] => Data::Ascii,
                    ["binary"] => Data::Binary,
                    ["binary_compressed"] => Data::Compressed,
                    _ => return Err(at(FormatError::PcdData(excerpt(&values.join(" "))))),
                }
            }
            // VIEWPOINT (a sensor pose) does not move the points.
            _ => {}
        }
    };
    let data_line = line_no;
    let at = |kind| IoError::format(kind, Some(Location::Line(data_line)));
    let names = names.ok_or_else(|| at(FormatError::PcdHeader("no FIELDS line".to_owned())))?;
    let sizes = sizes.ok_or_else(|| at(FormatError::PcdHeader("no SIZE line".to_owned())))?;
    let types = types.ok_or_else(|| at(FormatError::PcdHeader("no TYPE line".to_owned())))?;
    let counts = counts.unwrap_or_else(|| vec![1; names.len()]);
    for (what, len) in [
        ("SIZE", sizes.len()),
        ("TYPE", types.len()),
        ("COUNT", counts.len()),
    ] {
        if len != names.len() {
            return Err(at(FormatError::PcdHeader(format!(
                "{what} has {len} values for {} fields",
                names.len()
            ))));
        }
    }
    let mut fields = Vec::with_capacity(names.len());
    for (((name, size), ty), count) in names.into_iter().zip(sizes).zip(types).zip(counts) {
        let problem = |p: String| {
            at(FormatError::PcdField {
                field: excerpt(&name),
                problem: p,
            })
        };
        let kind = match (ty.as_str(), size) {
            ("F", 4 | 8) => Kind::Float,
            ("I", 1 | 2 | 4 | 8) => Kind::Signed,
            ("U", 1 | 2 | 4 | 8) => Kind::Unsigned,
            _ => {
                return Err(problem(format!(
                    "TYPE {} with SIZE {size} is not a PCD type",
                    excerpt(&ty)
                )))
            }
        };
        if count == 0 || count > 1 << 16 {
            return Err(problem(format!(
                "COUNT {count} is out of range (1 to 65536)"
            )));
        }
        fields.push(Field {
            name,
            size,
            kind,
            count,
        });
    }
    let find = |name: &str| fields.iter().position(|f| f.name == name);
    let mut xyz = [0; 3];
    for (slot, name) in xyz.iter_mut().zip(["x", "y", "z"]) {
        let i = find(name).ok_or_else(|| {
            at(FormatError::PcdField {
                field: name.to_owned(),
                problem: "missing from FIELDS".to_owned(),
            })
        })?;
        let f = &fields[i];
        if f.kind != Kind::Float || f.count != 1 {
            return Err(at(FormatError::PcdField {
                field: name.to_owned(),
                problem: format!(
                    "must be TYPE F, SIZE 4 or 8, COUNT 1 (found {}{} x {})",
                    match f.kind {
                        Kind::Float => "F",
                        Kind::Signed => "I",
                        Kind::Unsigned => "U",
                    },
                    f.size,
                    f.count
                ),
            }));
        }
        *slot = i;
    }
    let label = find("label");
    if let Some(f) = label.map(|i| &fields[i]).filter(|f| f.count != 1) {
        return Err(at(FormatError::PcdField {
            field: "label".to_owned(),
            problem: format!("COUNT {} (expected 1)", f.count),
        }));
    }
    let points = match (points, width) {
        (Some(points), Some(width)) => {
            let height = height.unwrap_or(1);
            if width.checked_mul(height) != Some(points) {
                return Err(at(FormatError::PcdPoints {
                    points,
                    width,
                    height,
                }));
            }
            points
        }
        (Some(points), None) => points,
        (None, Some(width)) => width.checked_mul(height.unwrap_or(1)).ok_or_else(|| {
            at(FormatError::PcdHeader(
                "WIDTH x HEIGHT is too large".to_owned(),
            ))
        })?,
        (None, None) => {
            return Err(at(FormatError::PcdHeader(
                "neither POINTS nor WIDTH is declared".to_owned(),
            )))
        }
    };
    if points == 0 {
        return Err(FormatError::NoPoints.into());
    }
    Ok(Header {
        fields,
        points,
        data,
        xyz,
        label,
        body_start: offset,
        body_line: line_no + 1,
    })
}

/// Collects points and labels, checking each.
struct Sink {
    cloud: Cloud,
}

impl Sink {
    fn new(header: &Header, reserve: usize) -> Self {
        Sink {
            cloud: Cloud {
                points: Vec::with_capacity(reserve),
                labels: header.label.map(|_| Vec::with_capacity(reserve)),
            },
        }
    }

    /// Add a point from its values (`value(field index)` gives the first value of a field).
    fn push(&mut self, header: &Header, value: impl Fn(usize) -> f64) -> Result<(), FormatError> {
        let p = header.xyz.map(&value);
        if !p.iter().all(|c| c.is_finite()) {
            return Err(FormatError::NotFinite);
        }
        self.cloud.points.push(p);
        if let (Some(labels), Some(i)) = (self.cloud.labels.as_mut(), header.label) {
            labels.push(label_value(value(i))?);
        }
        Ok(())
    }
}

/// Decode a PCD point cloud from the bytes of a whole file.
///
/// The header (versions 0.5 to 0.7; `#` comments; `FIELDS` or the old `COLUMNS`;
/// `COUNT` optional, default 1; `WIDTH`/`HEIGHT`/`POINTS`, any two determining the
/// third, all three having to agree; `VIEWPOINT` ignored) must declare fields `x`, `y`,
/// `z` of type `F` (float or double), count 1. Other fields (`rgb`, `normal_x`...,
/// `curvature`) are skipped; an optional `label` field (any type, count 1, integral
/// values) fills [`Cloud::labels`]. Organised clouds (`HEIGHT` > 1) are read row by
/// row. The body is `DATA ascii` (one point per line), `binary` (packed little-endian
/// points) or `binary_compressed` (two little-endian `u32` sizes, compressed then
/// uncompressed, then LZF data holding each field's values for all points in turn).
///
/// Strict like [`parse_ply`](super::parse_ply): a non-finite coordinate is an error
/// naming the point, even though PCL writes NaN for the invalid points of organised
/// clouds (remove them first, e.g. with PCL's `removeNaNFromPointCloud`). Header counts
/// never drive allocation beyond what the body can hold.
///
/// # Errors
///
/// [`IoError::Format`] (without a path): not a PCD ([`FormatError::NotPcd`]); a
/// malformed header ([`FormatError::PcdHeader`], [`FormatError::PcdField`],
/// [`FormatError::PcdData`], [`FormatError::PcdPoints`]); zero points; a body shorter
/// than declared ([`FormatError::Truncated`]) or longer ([`FormatError::TrailingData`]);
/// bad LZF data ([`FormatError::Lzf`]); an ASCII line with the wrong number of values or
/// a token that is not a number; a non-finite coordinate; a non-integral label.
pub fn parse_pcd(bytes: &[u8]) -> Result<Cloud, IoError> {
    let header = parse_header(bytes)?;
    let body = bytes.get(header.body_start..).unwrap_or_default();
    match header.data {
        Data::Ascii => decode_ascii(&header, text(body, header.body_line)?),
        Data::Binary => decode_binary(&header, body),
        Data::Compressed => decode_compressed(&header, body),
    }
}

/// Read a PCD point cloud from `path`; see [`parse_pcd`].
///
/// # Errors
///
/// [`IoError::Io`] if the file cannot be read; otherwise the errors of [`parse_pcd`],
/// with the path attached.
pub fn read_pcd(path: &Path) -> Result<Cloud, IoError> {
    parse_pcd(&read_bytes(path)?).map_err(|e| e.with_path(path))
}

fn decode_ascii(header: &Header, body: &str) -> Result<Cloud, IoError> {
    let values = header.values();
    // The first value of each field among a line's tokens.
    let mut first = Vec::with_capacity(header.fields.len());
    let mut next = 0;
    for f in &header.fields {
        first.push(next);
        next += f.count;
    }
    let reserve = header.points.min(body.len() / (2 * values) + 1);
    let mut sink = Sink::new(header, reserve);
    let mut tokens = Vec::with_capacity(values);
    let mut parsed = Vec::with_capacity(values);
    for (n, line) in content_lines(body, header.body_line) {
        let at = |kind| IoError::format(kind, Some(Location::Line(n)));
        if sink.cloud.points.len() == header.points {
            return Err(at(FormatError::TrailingData));
        }
        tokens.clear();
        tokens.extend(line.split_whitespace());
        if tokens.len() != values {
            return Err(at(FormatError::TokenCount {
                expected: values,
                found: tokens.len(),
            }));
        }
        parsed.clear();
        for t in &tokens {
            let v: f64 = t
                .parse()
                .map_err(|_| at(FormatError::NotANumber(excerpt(t))))?;
            parsed.push(v);
        }
        sink.push(header, |f| parsed[first[f]]).map_err(at)?;
    }
    let read = sink.cloud.points.len();
    if read < header.points {
        return Err(truncated(PlyFormat::Ascii, read, header.points));
    }
    Ok(sink.cloud)
}

fn truncated(format: PlyFormat, read: usize, expected: usize) -> IoError {
    FormatError::Truncated {
        format,
        element: "point".to_owned(),
        read,
        expected,
    }
    .into()
}

/// Bytes a body of `points` points needs, checked.
fn body_len(header: &Header) -> Result<usize, IoError> {
    header
        .row_len()
        .checked_mul(header.points)
        .ok_or_else(|| FormatError::PcdHeader("POINTS is too large".to_owned()).into())
}

fn decode_binary(header: &Header, body: &[u8]) -> Result<Cloud, IoError> {
    let row_len = header.row_len();
    let need = body_len(header)?;
    if body.len() < need {
        return Err(truncated(
            PlyFormat::BinaryLittleEndian,
            body.len() / row_len,
            header.points,
        ));
    }
    if body.len() > need {
        return Err(FormatError::TrailingData.into());
    }
    let mut offsets = Vec::with_capacity(header.fields.len());
    let mut next = 0;
    for f in &header.fields {
        offsets.push(next);
        next += f.width();
    }
    let mut sink = Sink::new(header, header.points);
    for (i, row) in body.chunks_exact(row_len).enumerate() {
        let value = |f: usize| {
            let field = &header.fields[f];
            field.decode(
                row.get(offsets[f]..offsets[f] + field.size)
                    .unwrap_or_default(),
            )
        };
        sink.push(header, value)
            .map_err(|kind| IoError::format(kind, Some(Location::item("point", i))))?;
    }
    Ok(sink.cloud)
}

fn decode_compressed(header: &Header, body: &[u8]) -> Result<Cloud, IoError> {
    let size = |i: usize| {
        body.get(i..i + 4)
            .and_then(|b| b.try_into().ok())
            .map(u32::from_le_bytes)
            .ok_or_else(|| FormatError::Lzf("the body ends before the two sizes".to_owned()))
    };
    let compressed = size(0)? as usize;
    let uncompressed = size(4)? as usize;
    let need = body_len(header)?;
    if uncompressed != need {
        return Err(FormatError::Lzf(format!(
            "uncompressed size {uncompressed} differs from the {need} bytes of {} points",
            header.points
        ))
        .into());
    }
    let data = &body[8..];
    if data.len() < compressed {
        return Err(FormatError::Lzf(format!(
            "compressed size {compressed} but only {} bytes follow",
            data.len()
        ))
        .into());
    }
    if data.len() > compressed {
        return Err(FormatError::TrailingData.into());
    }
    let raw = lzf::decompress(data, uncompressed)?;
    // Field-major: all points' values of field 0, then of field 1...
    let mut starts = Vec::with_capacity(header.fields.len());
    let mut next = 0;
    for f in &header.fields {
        starts.push(next);
        next += f.width() * header.points;
    }
    let mut sink = Sink::new(header, header.points);
    for i in 0..header.points {
        let value = |f: usize| {
            let field = &header.fields[f];
            let at = starts[f] + i * field.width();
            field.decode(raw.get(at..at + field.size).unwrap_or_default())
        };
        sink.push(header, value)
            .map_err(|kind| IoError::format(kind, Some(Location::item("point", i))))?;
    }
    Ok(sink.cloud)
}

#[cfg(test)]
mod tests {
    use super::*;

    const ASCII: &str = "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n\
        FIELDS x y z rgb label\nSIZE 4 4 4 4 4\nTYPE F F F F U\nCOUNT 1 1 1 1 1\n\
        WIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA ascii\n\
        1 2 3 4.2108e+06 2\n-1.5 0 1e3 0 3\n\n0.25 0.5 0.75 0 5\n";

    fn err(bytes: &[u8]) -> String {
        parse_pcd(bytes).unwrap_err().to_string()
    }

    /// A binary PCD body (x y z as F4, normal_x as F8 count 2, label I2) and its header.
    fn binary(points: &[([f32; 3], i16)], data: &str) -> Vec<u8> {
        let mut out = format!(
            "VERSION .7\nFIELDS x y z normal label\nSIZE 4 4 4 8 2\nTYPE F F F F I\n\
             COUNT 1 1 1 2 1\nWIDTH {}\nHEIGHT 1\nPOINTS {}\nDATA {data}\n",
            points.len(),
            points.len()
        )
        .into_bytes();
        let mut body = Vec::new();
        if data == "binary" {
            for (p, l) in points {
                for c in p {
                    body.extend(c.to_le_bytes());
                }
                body.extend([0u8; 16]);
                body.extend(l.to_le_bytes());
            }
            out.extend(body);
        } else {
            for k in 0..3 {
                for (p, _) in points {
                    body.extend(p[k].to_le_bytes());
                }
            }
            for _ in points {
                body.extend([0x3fu8; 16]);
            }
            for (_, l) in points {
                body.extend(l.to_le_bytes());
            }
            let packed = lzf::tests::compress(&body);
            out.extend((packed.len() as u32).to_le_bytes());
            out.extend((body.len() as u32).to_le_bytes());
            out.extend(packed);
        }
        out
    }

    const POINTS: [([f32; 3], i16); 4] = [
        ([1.0, 2.0, 3.0], 2),
        ([-1.5, 0.0, 1e3], -3),
        ([0.25, 0.5, 0.75], 5),
        ([0.25, 0.5, 0.75], 5),
    ];

    #[test]
    fn ascii_with_labels_and_skipped_fields() {
        let cloud = parse_pcd(ASCII.as_bytes()).unwrap();
        assert_eq!(
            cloud.points,
            vec![[1.0, 2.0, 3.0], [-1.5, 0.0, 1000.0], [0.25, 0.5, 0.75]]
        );
        assert_eq!(cloud.labels, Some(vec![2, 3, 5]));
        // Version 0.5 style: COLUMNS, no COUNT, no WIDTH/HEIGHT, CRLF.
        let old = "VERSION 0.5\r\nCOLUMNS x y z\r\nSIZE 8 8 8\r\nTYPE F F F\r\nPOINTS 1\r\n\
                   DATA ascii\r\n1 2 3\r\n";
        assert_eq!(
            parse_pcd(old.as_bytes()).unwrap().points,
            vec![[1.0, 2.0, 3.0]]
        );
    }

    #[test]
    fn binary_and_compressed_agree() {
        for data in ["binary", "binary_compressed"] {
            let cloud = parse_pcd(&binary(&POINTS, data)).unwrap();
            let expected: Vec<[f64; 3]> = POINTS.iter().map(|(p, _)| p.map(f64::from)).collect();
            assert_eq!(cloud.points, expected, "{data}");
            assert_eq!(cloud.labels, Some(vec![2, -3, 5, 5]), "{data}");
        }
    }

    #[test]
    fn organised_cloud() {
        let text = "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nHEIGHT 2\nDATA ascii\n\
                    0 0 0\n1 0 0\n0 1 0\n1 1 0\n";
        assert_eq!(parse_pcd(text.as_bytes()).unwrap().points.len(), 4);
    }

    #[test]
    fn header_errors() {
        let cases: [(&str, &str); 14] = [
            ("", "not a PCD file (no VERSION or FIELDS header line)"),
            ("ply\nformat ascii 1.0\n", "line 1: not a PCD file (no VERSION or FIELDS header line)"),
            ("VERSION 0.7\nFIELDS x y z\n", "bad PCD header: no DATA line"),
            ("VERSION 0.8\n", "line 1: bad PCD header: unsupported \"VERSION 0.8\" (expected VERSION 0.5, 0.6 or 0.7)"),
            ("FIELDS x y z\nSIZE 4 4\nTYPE F F F\nPOINTS 1\nDATA ascii\n", "line 5: bad PCD header: SIZE has 2 values for 3 fields"),
            ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1\nPOINTS 1\nDATA ascii\n", "line 6: bad PCD header: COUNT has 2 values for 3 fields"),
            ("FIELDS x y z\nSIZE 4 4 2\nTYPE F F F\nPOINTS 1\nDATA ascii\n", "line 5: PCD field z: TYPE F with SIZE 2 is not a PCD type"),
            ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F I\nPOINTS 1\nDATA ascii\n", "line 5: PCD field z: must be TYPE F, SIZE 4 or 8, COUNT 1 (found I4 x 1)"),
            ("FIELDS x y\nSIZE 4 4\nTYPE F F\nPOINTS 1\nDATA ascii\n", "line 5: PCD field z: missing from FIELDS"),
            ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 3\nHEIGHT 2\nPOINTS 5\nDATA ascii\n", "line 7: POINTS 5 is not WIDTH 3 x HEIGHT 2"),
            ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\nDATA binary_lz4\n", "line 5: unsupported PCD DATA \"binary_lz4\" (expected ascii, binary or binary_compressed)"),
            ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 0\nDATA ascii\n", "no points"),
            ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS -1\nDATA ascii\n", "line 4: bad PCD header: POINTS value \"-1\" is not a count"),
            ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nFOO 2\n", "line 5: bad PCD header: unknown header line \"FOO 2\""),
        ];
        for (text, message) in cases {
            assert_eq!(err(text.as_bytes()), message, "{text:?}");
        }
        let big =
            "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 18446744073709551615\nDATA binary\n";
        assert!(err(big.as_bytes()).contains("POINTS is too large"));
    }

    #[test]
    fn body_errors() {
        let ascii = |tail: &str| {
            let head = "FIELDS x y z label\nSIZE 4 4 4 4\nTYPE F F F F\nPOINTS 2\nDATA ascii\n";
            err(format!("{head}{tail}").as_bytes())
        };
        assert_eq!(ascii("1 2 3 1\n"), "ASCII body ends after 1 of 2 points");
        assert_eq!(
            ascii("1 2 3 1\n1 2 3\n"),
            "line 7: expected 4 numbers, found 3"
        );
        assert_eq!(
            ascii("1 2 3 1\n1 2 nan 1\n"),
            "line 7: coordinate is not finite"
        );
        assert_eq!(ascii("1 2 3 1\n1 2 x 1\n"), "line 7: \"x\" is not a number");
        assert_eq!(
            ascii("1 2 3 1.5\n1 2 3 1\n"),
            "line 6: label 1.5 is not an integer"
        );
        assert_eq!(
            ascii("1 2 3 1\n1 2 3 1\n1 2 3 1\n"),
            "line 8: unexpected data after the last element"
        );

        let full = binary(&POINTS, "binary");
        assert_eq!(
            err(&full[..full.len() - 1]),
            "binary body ends after 3 of 4 points"
        );
        let mut long = full.clone();
        long.push(0);
        assert_eq!(err(&long), "unexpected data after the last element");
        let mut nan = POINTS;
        nan[2].0[1] = f32::NAN;
        assert_eq!(
            err(&binary(&nan, "binary")),
            "point 2: coordinate is not finite"
        );
        assert_eq!(
            err(&binary(&nan, "binary_compressed")),
            "point 2: coordinate is not finite"
        );

        let packed = binary(&POINTS, "binary_compressed");
        let header_len = String::from_utf8_lossy(&packed)
            .find("binary_compressed\n")
            .unwrap()
            + "binary_compressed\n".len();
        assert_eq!(
            err(&packed[..header_len + 6]),
            "bad binary_compressed body: the body ends before the two sizes"
        );
        assert!(err(&packed[..packed.len() - 1])
            .starts_with("bad binary_compressed body: compressed size"));
        let mut wrong_size = packed.clone();
        wrong_size[header_len + 4] ^= 1;
        assert!(err(&wrong_size).contains("differs from the 120 bytes of 4 points"));
        let mut bad = packed.clone();
        bad[header_len + 8] = 0xff; // a back reference at the very start
        assert!(err(&bad).starts_with("bad binary_compressed body: chunk at compressed byte 0"));
    }

    #[test]
    fn garbage_never_panics() {
        let mut s: u64 = 7;
        let seeds = [
            ASCII.as_bytes().to_vec(),
            binary(&POINTS, "binary"),
            binary(&POINTS, "binary_compressed"),
        ];
        for seed in &seeds {
            for m in crate::io::mutants(seed, 3000, b"0123456789 \n-FIU", &mut s) {
                let _ = parse_pcd(&m);
            }
        }
    }
}
