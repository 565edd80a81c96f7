//! PLY: header parsing, ASCII and binary little-endian bodies, point clouds and
//! meshes, reading and writing.
//!
//! One decoder serves both point clouds and meshes: it walks every element the
//! header declares (so binary bodies with lists can be skipped correctly) and hands
//! each decoded row to the caller, which keeps the vertex and face rows it wants.

use std::io::Write;
use std::path::Path;

use super::{
    check_mesh, check_points, content_lines, excerpt, push_fan, read_bytes, text, write_atomic,
    Cloud, FormatError, IoError, Location, Mesh, PlyFormat,
};

/// A PLY scalar type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    /// The type named in a header, with the sized aliases (`int8`, `float32`...).
    fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    /// Canonical name, for messages.
    fn name(self) -> &'static str {
        match self {
            Scalar::I8 => "char",
            Scalar::U8 => "uchar",
            Scalar::I16 => "short",
            Scalar::U16 => "ushort",
            Scalar::I32 => "int",
            Scalar::U32 => "uint",
            Scalar::F32 => "float",
            Scalar::F64 => "double",
        }
    }

    /// Size in a binary body, in bytes.
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    /// Value range of an integer type; `None` for floating-point types.
    fn integer_range(self) -> Option<(f64, f64)> {
        Some(match self {
            Scalar::I8 => (i8::MIN.into(), i8::MAX.into()),
            Scalar::U8 => (0.0, u8::MAX.into()),
            Scalar::I16 => (i16::MIN.into(), i16::MAX.into()),
            Scalar::U16 => (0.0, u16::MAX.into()),
            Scalar::I32 => (i32::MIN.into(), i32::MAX.into()),
            Scalar::U32 => (0.0, u32::MAX.into()),
            Scalar::F32 | Scalar::F64 => return None,
        })
    }

    /// Read one little-endian value (every PLY scalar is exact in `f64`);
    /// `None` when the bytes run out.
    pub(super) fn read_le(self, bytes: &mut Bytes<'_>) -> Option<f64> {
        Some(match self {
            Scalar::I8 => i8::from_le_bytes(bytes.take()?).into(),
            Scalar::U8 => u8::from_le_bytes(bytes.take()?).into(),
            Scalar::I16 => i16::from_le_bytes(bytes.take()?).into(),
            Scalar::U16 => u16::from_le_bytes(bytes.take()?).into(),
            Scalar::I32 => i32::from_le_bytes(bytes.take()?).into(),
            Scalar::U32 => u32::from_le_bytes(bytes.take()?).into(),
            Scalar::F32 => f32::from_le_bytes(bytes.take()?).into(),
            Scalar::F64 => f64::from_le_bytes(bytes.take()?),
        })
    }

    /// Parse one ASCII token: any number for a floating-point type (NaN and
    /// infinities included; callers judge those), an integral in-range number for
    /// an integer type.
    fn parse_text(self, token: &str) -> Result<f64, FormatError> {
        let value: f64 = token
            .parse()
            .map_err(|_| FormatError::NotANumber(excerpt(token)))?;
        match self.integer_range() {
            Some((lo, hi)) if !(value.fract() == 0.0 && lo <= value && value <= hi) => {
                Err(FormatError::OutOfRange {
                    value,
                    ty: self.name(),
                })
            }
            _ => Ok(value),
        }
    }
}

/// A cursor over a binary body.
pub(super) struct Bytes<'a> {
    rest: &'a [u8],
}

impl<'a> Bytes<'a> {
    /// A cursor at the start of `data`.
    pub(super) fn new(data: &'a [u8]) -> Self {
        Bytes { rest: data }
    }

    /// The next `N` bytes, or `None` (consuming nothing) if fewer remain.
    pub(super) fn take<const N: usize>(&mut self) -> Option<[u8; N]> {
        let (head, rest) = self.rest.split_first_chunk::<N>()?;
        self.rest = rest;
        Some(*head)
    }

    /// The bytes not consumed yet.
    pub(super) fn remaining(&self) -> &'a [u8] {
        self.rest
    }
}

/// The type of a declared property.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PropertyType {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

/// A declared property.
#[derive(Debug)]
struct Property {
    name: String,
    ty: PropertyType,
}

/// A declared element: name, instance count, properties in body order.
#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

impl Element {
    /// Index and type of the property called `name`.
    fn property(&self, name: &str) -> Option<(usize, PropertyType)> {
        self.properties
            .iter()
            .position(|p| p.name == name)
            .map(|i| (i, self.properties[i].ty))
    }

    /// How many rows to reserve room for: the declared count, capped by what a
    /// body of `body_len` bytes could hold, so a lying header cannot make us
    /// allocate more than the file justifies.
    fn reserve_hint(&self, format: PlyFormat, body_len: usize) -> usize {
        let min_row_len = match format {
            // Each value is at least one character plus a separator.
            PlyFormat::Ascii => 2 * self.properties.len(),
            PlyFormat::BinaryLittleEndian => self
                .properties
                .iter()
                .map(|p| match p.ty {
                    PropertyType::Scalar(s) => s.size(),
                    PropertyType::List { count, .. } => count.size(),
                })
                .sum(),
        };
        self.count.min(body_len / min_row_len.max(1) + 1)
    }
}

/// A parsed PLY header.
#[derive(Debug)]
struct Header {
    format: PlyFormat,
    elements: Vec<Element>,
    /// Byte offset of the body.
    body_start: usize,
    /// Line number of the first body line (for ASCII messages).
    body_line: usize,
}

impl Header {
    /// Index of the element called `name`.
    fn element(&self, name: &str) -> Option<usize> {
        self.elements.iter().position(|e| e.name == name)
    }
}

/// Locate the `end_header` line: the number of header lines (counting `ply` and
/// `end_header`) and the byte offset of the body.
fn find_end_header(bytes: &[u8]) -> Option<(usize, usize)> {
    let mut offset = 0;
    for (i, line) in bytes.split(|&b| b == b'\n').enumerate() {
        offset += line.len() + 1;
        if line.trim_ascii() == b"end_header" {
            return Some((i + 1, offset.min(bytes.len())));
        }
    }
    None
}

/// Parse the words of a `property` line after `property`.
fn parse_property(words: &[&str]) -> Result<Property, String> {
    let scalar = |name: &str| {
        Scalar::from_name(name)
            .ok_or_else(|| format!("unknown property type \"{}\"", excerpt(name)))
    };
    let (name, ty) = match *words {
        ["list", count, item, name] => {
            let count = scalar(count)?;
            if count.integer_range().is_none() {
                return Err(format!(
                    "list length type of {name} must be an integer type"
                ));
            }
            (
                name,
                PropertyType::List {
                    count,
                    item: scalar(item)?,
                },
            )
        }
        [ty, name] => (name, PropertyType::Scalar(scalar(ty)?)),
        _ => {
            return Err("expected \"property <type> <name>\" or \
                        \"property list <type> <type> <name>\""
                .to_owned())
        }
    };
    Ok(Property {
        name: name.to_owned(),
        ty,
    })
}

/// Parse the header: magic line, then lines up to `end_header`.
fn parse_header(bytes: &[u8]) -> Result<Header, IoError> {
    let mut lines = bytes.split(|&b| b == b'\n');
    if lines.next().map(<[u8]>::trim_ascii) != Some(&b"ply"[..]) {
        return Err(FormatError::NotPly.into());
    }
    // Find `end_header` first, so a file lacking it gets that error rather than a
    // complaint about the first body line.
    let (header_lines, body_start) = find_end_header(bytes).ok_or(FormatError::MissingEndHeader)?;

    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    for (i, raw) in lines.take(header_lines.saturating_sub(2)).enumerate() {
        let n = i + 2;
        let at = |kind| IoError::format(kind, Some(Location::Line(n)));
        let bad = |message: String| at(FormatError::Header(message));
        let line = std::str::from_utf8(raw).map_err(|_| at(FormatError::NotUtf8))?;
        let words: Vec<&str> = line.split_whitespace().collect();
        match words[..] {
            [] | ["comment" | "obj_info", ..] => {}
            ["format", encoding, version] => {
                if format.is_some() {
                    return Err(bad("second format line".to_owned()));
                }
                format = Some(match (encoding, version) {
                    ("ascii", "1.0") => PlyFormat::Ascii,
                    ("binary_little_endian", "1.0") => PlyFormat::BinaryLittleEndian,
                    ("binary_big_endian", _) => return Err(at(FormatError::BigEndian)),
                    _ => {
                        return Err(at(FormatError::UnsupportedFormat(format!(
                            "{encoding} {version}"
                        ))))
                    }
                });
            }
            ["element", name, count] => {
                let count = count.parse().map_err(|_| {
                    bad(format!(
                        "element count \"{count}\" is not a non-negative integer"
                    ))
                })?;
                if elements.iter().any(|e| e.name == name) {
                    return Err(bad(format!("element {name} declared twice")));
                }
                elements.push(Element {
                    name: name.to_owned(),
                    count,
                    properties: Vec::new(),
                });
            }
            ["property", ref rest @ ..] => {
                let element = elements
                    .last_mut()
                    .ok_or_else(|| bad("property before any element".to_owned()))?;
                let property = parse_property(rest).map_err(bad)?;
                if element.properties.iter().any(|p| p.name == property.name) {
                    return Err(bad(format!("property {} declared twice", property.name)));
                }
                element.properties.push(property);
            }
            ["format" | "element", ..] => {
                return Err(bad(format!("malformed {} line", words[0])));
            }
            [keyword, ..] => return Err(bad(format!("unknown keyword \"{}\"", excerpt(keyword)))),
        }
    }
    let format = format.ok_or_else(|| FormatError::Header("no format line".to_owned()))?;
    // A row without properties takes no room, so its count would be unbounded work.
    if let Some(e) = elements
        .iter()
        .find(|e| e.count > 0 && e.properties.is_empty())
    {
        return Err(FormatError::Header(format!("element {} has no properties", e.name)).into());
    }
    Ok(Header {
        format,
        elements,
        body_start,
        body_line: header_lines + 1,
    })
}

/// The values of one element instance, flattened, with each property's span.
#[derive(Debug, Default)]
struct Row {
    values: Vec<f64>,
    /// `(start, len)` in `values` for each property, in declaration order.
    spans: Vec<(usize, usize)>,
}

impl Row {
    fn clear(&mut self) {
        self.values.clear();
        self.spans.clear();
    }

    /// Value of scalar property `property`.
    fn scalar(&self, property: usize) -> f64 {
        self.values[self.spans[property].0]
    }

    /// Items of list property `property`.
    fn list(&self, property: usize) -> &[f64] {
        let (start, len) = self.spans[property];
        &self.values[start..start + len]
    }
}

/// A list length read from a list's count property (always integral).
fn list_len(value: f64) -> Result<usize, FormatError> {
    if value < 0.0 {
        Err(FormatError::BadListLength(value))
    } else {
        // Integral and at most u32::MAX: exact.
        Ok(value as usize)
    }
}

/// Something that consumes decoded rows: `(element index, row)`.
type Visit<'v> = dyn FnMut(usize, &Row) -> Result<(), FormatError> + 'v;

/// Decode every row of every element, in file order, handing each to `visit`.
/// Errors from `visit` get the row's location.
fn decode_body(header: &Header, bytes: &[u8], visit: &mut Visit<'_>) -> Result<(), IoError> {
    let body = bytes.get(header.body_start..).unwrap_or_default();
    match header.format {
        PlyFormat::Ascii => decode_ascii(header, body, visit),
        PlyFormat::BinaryLittleEndian => decode_binary(header, body, visit),
    }
}

/// ASCII body: one element instance per non-blank line.
fn decode_ascii(header: &Header, body: &[u8], visit: &mut Visit<'_>) -> Result<(), IoError> {
    let mut lines = content_lines(text(body, header.body_line)?, header.body_line);
    let mut row = Row::default();
    for (e, element) in header.elements.iter().enumerate() {
        for index in 0..element.count {
            let Some((n, line)) = lines.next() else {
                return Err(truncated(PlyFormat::Ascii, element, index));
            };
            let at = |kind| IoError::format(kind, Some(Location::Line(n)));
            row.clear();
            parse_ascii_row(element, line, &mut row).map_err(at)?;
            visit(e, &row).map_err(at)?;
        }
    }
    match lines.next() {
        Some((n, _)) => Err(IoError::format(
            FormatError::TrailingData,
            Some(Location::Line(n)),
        )),
        None => Ok(()),
    }
}

/// Parse one ASCII row; the line must hold exactly the values the header declares.
fn parse_ascii_row(element: &Element, line: &str, row: &mut Row) -> Result<(), FormatError> {
    let mut tokens = line.split_whitespace();
    let wrong_count = || token_count_error(element, line);
    for property in &element.properties {
        let start = row.values.len();
        let len = match property.ty {
            PropertyType::Scalar(ty) => {
                let token = tokens.next().ok_or_else(wrong_count)?;
                row.values.push(ty.parse_text(token)?);
                1
            }
            PropertyType::List { count, item } => {
                let token = tokens.next().ok_or_else(wrong_count)?;
                let len = list_len(count.parse_text(token)?)?;
                for _ in 0..len {
                    let token = tokens.next().ok_or_else(wrong_count)?;
                    row.values.push(item.parse_text(token)?);
                }
                len
            }
        };
        row.spans.push((start, len));
    }
    match tokens.next() {
        Some(_) => Err(wrong_count()),
        None => Ok(()),
    }
}

/// The error for an ASCII row with the wrong number of values: how many the
/// header (and the row's own list lengths) call for, and how many there are.
fn token_count_error(element: &Element, line: &str) -> FormatError {
    let tokens: Vec<&str> = line.split_whitespace().collect();
    let mut expected = 0usize;
    for property in &element.properties {
        let items = match property.ty {
            PropertyType::Scalar(_) => 0,
            PropertyType::List { count, .. } => tokens
                .get(expected)
                .and_then(|t| count.parse_text(t).ok())
                .and_then(|v| list_len(v).ok())
                .unwrap_or(0),
        };
        expected = expected.saturating_add(1).saturating_add(items);
    }
    FormatError::TokenCount {
        expected,
        found: tokens.len(),
    }
}

/// Binary little-endian body: packed rows.
fn decode_binary(header: &Header, body: &[u8], visit: &mut Visit<'_>) -> Result<(), IoError> {
    let mut bytes = Bytes::new(body);
    let mut row = Row::default();
    for (e, element) in header.elements.iter().enumerate() {
        for index in 0..element.count {
            let at = |kind| IoError::format(kind, Some(Location::item(&element.name, index)));
            row.clear();
            if !read_binary_row(element, &mut bytes, &mut row).map_err(at)? {
                return Err(truncated(PlyFormat::BinaryLittleEndian, element, index));
            }
            visit(e, &row).map_err(at)?;
        }
    }
    // Tolerate a stray line ending after the body, nothing else.
    if bytes.remaining().iter().all(u8::is_ascii_whitespace) {
        Ok(())
    } else {
        Err(FormatError::TrailingData.into())
    }
}

/// Read one binary row; `Ok(false)` if the body ends first.
fn read_binary_row(
    element: &Element,
    bytes: &mut Bytes<'_>,
    row: &mut Row,
) -> Result<bool, FormatError> {
    for property in &element.properties {
        let start = row.values.len();
        let len = match property.ty {
            PropertyType::Scalar(ty) => {
                let Some(value) = ty.read_le(bytes) else {
                    return Ok(false);
                };
                row.values.push(value);
                1
            }
            PropertyType::List { count, item } => {
                let Some(len) = count.read_le(bytes) else {
                    return Ok(false);
                };
                let len = list_len(len)?;
                // No reservation from `len`: it is only as good as the bytes behind it.
                for _ in 0..len {
                    let Some(value) = item.read_le(bytes) else {
                        return Ok(false);
                    };
                    row.values.push(value);
                }
                len
            }
        };
        row.spans.push((start, len));
    }
    Ok(true)
}

fn truncated(format: PlyFormat, element: &Element, read: usize) -> IoError {
    FormatError::Truncated {
        format,
        element: element.name.clone(),
        read,
        expected: element.count,
    }
    .into()
}

/// Where the coordinates (and the optional label) sit in a vertex row.
struct VertexLayout {
    xyz: [usize; 3],
    label: Option<usize>,
}

impl VertexLayout {
    fn new(element: &Element) -> Result<Self, FormatError> {
        let scalar = |name: &'static str| match element.property(name) {
            Some((i, PropertyType::Scalar(_))) => Ok(Some(i)),
            Some(_) => Err(FormatError::Header(format!(
                "property {name} of element vertex is a list"
            ))),
            None => Ok(None),
        };
        let coordinate = |name: &'static str| {
            scalar(name)?.ok_or(FormatError::MissingProperty {
                element: "vertex",
                property: name,
            })
        };
        Ok(VertexLayout {
            xyz: [coordinate("x")?, coordinate("y")?, coordinate("z")?],
            label: scalar("label")?,
        })
    }

    fn point(&self, row: &Row) -> Result<[f64; 3], FormatError> {
        let p = self.xyz.map(|i| row.scalar(i));
        if p.iter().all(|c| c.is_finite()) {
            Ok(p)
        } else {
            Err(FormatError::NotFinite)
        }
    }

    /// The row's label: integer-typed, or float-typed with an integral value.
    fn label(&self, row: &Row) -> Option<Result<i32, FormatError>> {
        let value = row.scalar(self.label?);
        let fits =
            value.fract() == 0.0 && f64::from(i32::MIN) <= value && value <= f64::from(i32::MAX);
        // In range and integral: the cast is exact.
        Some(if fits {
            Ok(value as i32)
        } else {
            Err(FormatError::BadLabel(value))
        })
    }
}

/// What a PLY file holds, decoded: the vertices (and labels) and, for meshes, the
/// fan-triangulated faces.
struct Contents {
    cloud: Cloud,
    triangles: Vec<[u32; 3]>,
}

/// Decode a PLY file. With `faces`, the `face` element is required and its
/// `vertex_indices` (or `vertex_index`) lists are triangulated, and labels are not
/// read; without, every element but `vertex` is skipped.
fn decode(bytes: &[u8], faces: bool) -> Result<Contents, IoError> {
    let header = parse_header(bytes)?;
    let body_len = bytes.len().saturating_sub(header.body_start);
    let vertex = header
        .element("vertex")
        .ok_or(FormatError::MissingElement("vertex"))?;
    let vertices = &header.elements[vertex];
    let mut layout = VertexLayout::new(vertices)?;
    if vertices.count == 0 {
        return Err(FormatError::NoPoints.into());
    }
    let face = if faces {
        layout.label = None;
        Some(face_layout(&header)?)
    } else {
        None
    };

    let reserve = vertices.reserve_hint(header.format, body_len);
    let mut points = Vec::with_capacity(reserve);
    let mut labels = layout.label.map(|_| Vec::with_capacity(reserve));
    let mut triangles = Vec::new();
    if let Some((f, _)) = face {
        triangles.reserve(header.elements[f].reserve_hint(header.format, body_len));
    }
    let mut corners = Vec::new();
    let vertex_count = vertices.count;
    decode_body(&header, bytes, &mut |e, row| {
        if e == vertex {
            points.push(layout.point(row)?);
            if let (Some(labels), Some(label)) = (labels.as_mut(), layout.label(row)) {
                labels.push(label?);
            }
        } else if let Some((_, indices)) = face.filter(|&(f, _)| f == e) {
            corners.clear();
            for &index in row.list(indices) {
                corners.push(vertex_index(index, vertex_count)?);
            }
            push_fan(&mut triangles, &corners)?;
        }
        Ok(())
    })?;
    Ok(Contents {
        cloud: Cloud { points, labels },
        triangles,
    })
}

/// The face element and its index-list property.
fn face_layout(header: &Header) -> Result<(usize, usize), FormatError> {
    let face = header
        .element("face")
        .ok_or(FormatError::MissingElement("face"))?;
    let element = &header.elements[face];
    let (property, ty) = element
        .property("vertex_indices")
        .or_else(|| element.property("vertex_index"))
        .ok_or(FormatError::MissingProperty {
            element: "face",
            property: "vertex_indices",
        })?;
    match ty {
        PropertyType::List { item, .. } if item.integer_range().is_some() => Ok((face, property)),
        _ => Err(FormatError::Header(
            "face vertex_indices must be a list of an integer type".to_owned(),
        )),
    }
}

/// A 0-based face index (an integral value of an integer type) checked against the vertex count.
fn vertex_index(value: f64, vertices: usize) -> Result<u32, FormatError> {
    // Integer-typed, so integral and within u32/i32 range: the casts are exact.
    let index = value as i64;
    usize::try_from(index)
        .ok()
        .filter(|&i| i < vertices)
        .and_then(|i| u32::try_from(i).ok())
        .ok_or(FormatError::IndexOutOfRange { index, vertices })
}

/// Decode a PLY point cloud from the bytes of a whole file.
///
/// Reads `format ascii 1.0` and `format binary_little_endian 1.0`. The `vertex`
/// element must have scalar `x`, `y`, `z` properties (any numeric type, float or
/// double in practice) and may have any others, which are skipped; an optional
/// `label` property (integer type, or float type holding integral values) fills
/// [`Cloud::labels`]. Other elements (faces, edges...) are checked and skipped.
/// Header comments are ignored and CRLF line endings tolerated. Trailing blank
/// space after the body is tolerated; any other trailing data is an error, as it
/// means the header's counts are wrong.
///
/// Header counts never drive allocation beyond what the body could hold.
///
/// # Errors
///
/// [`IoError::Format`] (without a path) for: not a PLY, no `end_header`,
/// big-endian or unknown format, a malformed header line, no `vertex` element or
/// no x/y/z, zero vertices, a truncated body (the number of complete rows is
/// reported), a non-numeric or out-of-range value, an ASCII line with the wrong
/// number of values, a non-finite coordinate, a non-integral label, trailing data.
pub fn parse_ply(bytes: &[u8]) -> Result<Cloud, IoError> {
    decode(bytes, false).map(|contents| contents.cloud)
}

/// Read a PLY point cloud from `path`; see [`parse_ply`].
///
/// # Errors
///
/// [`IoError::Io`] if the file cannot be read; otherwise the errors of
/// [`parse_ply`], with the path attached.
pub fn read_ply(path: &Path) -> Result<Cloud, IoError> {
    parse_ply(&read_bytes(path)?).map_err(|e| e.with_path(path))
}

/// One element of a PLY file with its scalar properties, decoded (see [`parse_ply_elements`]).
#[derive(Debug, Clone, PartialEq)]
pub struct PlyElement {
    /// The element's name (`vertex`, `face`, `node`...).
    pub name: String,
    /// The names of its scalar properties, in declaration order (list properties are
    /// left out).
    pub properties: Vec<String>,
    /// Each instance's scalar values, in the order of `properties`. Every PLY scalar
    /// type is exact in an f64.
    pub rows: Vec<Vec<f64>>,
}

impl PlyElement {
    /// The index of scalar property `name` in `properties`.
    pub fn property(&self, name: &str) -> Option<usize> {
        self.properties.iter().position(|p| p == name)
    }
}

/// Whether the PLY header of `bytes` declares an element called `name` (the body is
/// not read). `false` for anything that is not a PLY header.
pub(super) fn declares_element(bytes: &[u8], name: &str) -> bool {
    parse_header(bytes).is_ok_and(|h| h.element(name).is_some())
}

/// Decode every element of a PLY file (any element names), for files that carry more
/// than a cloud or a mesh (ribreg's prepared templates). List properties are checked and
/// skipped, and so are the rows of the elements named in `skip` (a caller that decodes
/// the vertices with [`parse_ply`] skips `vertex`: one allocation a row is most of the
/// decoding). Non-finite values are kept: the caller decides what a value means. Header
/// counts never drive allocation beyond what the body could hold.
///
/// # Errors
///
/// The errors of [`parse_ply`] about the header and the body, except that no `vertex`
/// element or property is required.
pub fn parse_ply_elements(bytes: &[u8], skip: &[&str]) -> Result<Vec<PlyElement>, IoError> {
    let header = parse_header(bytes)?;
    let body_len = bytes.len().saturating_sub(header.body_start);
    let mut out: Vec<PlyElement> = header
        .elements
        .iter()
        .map(|e| PlyElement {
            name: e.name.clone(),
            properties: e
                .properties
                .iter()
                .filter(|p| matches!(p.ty, PropertyType::Scalar(_)))
                .map(|p| p.name.clone())
                .collect(),
            rows: Vec::new(),
        })
        .collect();
    // Rows to keep, per element: the indices of its scalar properties (`None`: skipped).
    let scalars: Vec<Option<Vec<usize>>> = header
        .elements
        .iter()
        .zip(&mut out)
        .map(|(e, element)| {
            if skip.contains(&e.name.as_str()) {
                return None;
            }
            element.rows = Vec::with_capacity(e.reserve_hint(header.format, body_len));
            Some(
                e.properties
                    .iter()
                    .enumerate()
                    .filter(|(_, p)| matches!(p.ty, PropertyType::Scalar(_)))
                    .map(|(i, _)| i)
                    .collect(),
            )
        })
        .collect();
    decode_body(&header, bytes, &mut |e, row| {
        if let (Some(element), Some(Some(scalars))) = (out.get_mut(e), scalars.get(e)) {
            element
                .rows
                .push(scalars.iter().map(|&i| row.scalar(i)).collect());
        }
        Ok(())
    })?;
    Ok(out)
}

/// Decode a PLY mesh: `vertex` (x, y, z) and `face` (`vertex_indices` lists,
/// polygons fan-triangulated) elements; other elements and properties are skipped.
pub(super) fn parse_ply_mesh(bytes: &[u8]) -> Result<Mesh, IoError> {
    let contents = decode(bytes, true)?;
    if contents.triangles.is_empty() {
        return Err(FormatError::NoTriangles.into());
    }
    Ok(Mesh {
        vertices: contents.cloud.points,
        triangles: contents.triangles,
    })
}

/// Write the header: vertex element with double x, y, z (and int label), then an
/// optional face element.
fn write_header(
    out: &mut dyn Write,
    format: PlyFormat,
    vertices: usize,
    labels: bool,
    faces: Option<usize>,
) -> std::io::Result<()> {
    let encoding = match format {
        PlyFormat::Ascii => "ascii",
        PlyFormat::BinaryLittleEndian => "binary_little_endian",
    };
    write!(
        out,
        "ply\nformat {encoding} 1.0\ncomment ribreg, units mm\nelement vertex {vertices}\n\
         property double x\nproperty double y\nproperty double z\n"
    )?;
    if labels {
        writeln!(out, "property int label")?;
    }
    if let Some(faces) = faces {
        write!(
            out,
            "element face {faces}\nproperty list uchar int vertex_indices\n"
        )?;
    }
    writeln!(out, "end_header")
}

/// Write `cloud` to `path` as PLY in `format`, atomically.
///
/// The header declares `element vertex N` with `property double x/y/z` (nothing
/// lost) and, when `labels` is `Some`, `property int label`. ASCII values use the
/// shortest round-trip formatting, so reading the file back gives identical
/// values.
///
/// # Errors
///
/// With `path` left untouched: [`IoError::Format`] for no points, a non-finite
/// coordinate, or labels and points of different lengths; [`IoError::Io`] if the
/// file cannot be written (e.g. the directory does not exist).
pub fn write_ply(path: &Path, cloud: &Cloud, format: PlyFormat) -> Result<(), IoError> {
    check_points(&cloud.points, "vertex").map_err(|e| e.with_path(path))?;
    if let Some(labels) = &cloud.labels {
        if labels.len() != cloud.points.len() {
            let kind = FormatError::LabelCountMismatch {
                labels: labels.len(),
                points: cloud.points.len(),
            };
            return Err(IoError::from(kind).with_path(path));
        }
    }
    let labels = cloud.labels.as_deref();
    write_atomic(path, |out| {
        write_header(out, format, cloud.points.len(), labels.is_some(), None)?;
        for (i, p) in cloud.points.iter().enumerate() {
            let label = labels.and_then(|l| l.get(i));
            match format {
                PlyFormat::Ascii => {
                    write!(out, "{} {} {}", p[0], p[1], p[2])?;
                    if let Some(label) = label {
                        write!(out, " {label}")?;
                    }
                    writeln!(out)?;
                }
                PlyFormat::BinaryLittleEndian => {
                    for c in p {
                        out.write_all(&c.to_le_bytes())?;
                    }
                    if let Some(label) = label {
                        out.write_all(&label.to_le_bytes())?;
                    }
                }
            }
        }
        Ok(())
    })
}

/// Write `mesh` to `path` as ASCII PLY with `vertex` (double x, y, z) and `face`
/// (`list uchar int vertex_indices`) elements, atomically.
///
/// # Errors
///
/// With `path` left untouched: [`IoError::Format`] for no vertices or no
/// triangles, a non-finite coordinate, an index out of range, or more vertices
/// than an `int` index can address; [`IoError::Io`] if the file cannot be written.
pub fn write_mesh_ply(path: &Path, mesh: &Mesh) -> Result<(), IoError> {
    check_mesh(mesh).map_err(|e| e.with_path(path))?;
    if i32::try_from(mesh.vertices.len()).is_err() {
        return Err(
            IoError::from(FormatError::TooManyVertices(mesh.vertices.len())).with_path(path),
        );
    }
    write_atomic(path, |out| {
        let faces = Some(mesh.triangles.len());
        write_header(out, PlyFormat::Ascii, mesh.vertices.len(), false, faces)?;
        for v in &mesh.vertices {
            writeln!(out, "{} {} {}", v[0], v[1], v[2])?;
        }
        for t in &mesh.triangles {
            writeln!(out, "3 {} {} {}", t[0], t[1], t[2])?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(bytes: &[u8]) -> IoError {
        parse_ply(bytes).unwrap_err()
    }

    fn kind(bytes: &[u8]) -> FormatError {
        err(bytes).kind().cloned().unwrap()
    }

    /// Awkward values that a lossy writer would change.
    fn awkward_points() -> Vec<[f64; 3]> {
        vec![
            [0.1, -0.2, 1.0 / 3.0],
            [std::f64::consts::PI, -0.0, 123456.789012345],
            [1e-300, -2.5e300, f64::MIN_POSITIVE],
            [f64::EPSILON, -7.0, 42.0],
        ]
    }

    fn ascii(header_and_body: &str) -> Vec<u8> {
        header_and_body.as_bytes().to_vec()
    }

    /// Every element is decoded, but for those named in `skip`: their header stays, their
    /// rows are left out, and the elements after them are still read where they are.
    #[test]
    fn elements_are_decoded_but_for_those_skipped() {
        let bytes = ascii(
            "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
             property float z\nelement node 1\nproperty int label\n\
             property list uchar int idx\nproperty double w\nend_header\n\
             1 2 3\n4 5 6\n7 2 8 9 0.5\n",
        );
        let all = parse_ply_elements(&bytes, &[]).unwrap();
        assert_eq!(all[0].rows, [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        assert_eq!(all[1].properties, ["label", "w"]);
        assert_eq!(all[1].rows, [[7.0, 0.5]]);
        let some = parse_ply_elements(&bytes, &["vertex"]).unwrap();
        assert_eq!(
            (some[0].name.as_str(), some[0].properties.len()),
            ("vertex", 3)
        );
        assert!(some[0].rows.is_empty());
        assert_eq!(some[1], all[1]);
    }

    #[test]
    fn round_trip_all_formats_with_and_without_labels() {
        let dir = tempfile::tempdir().unwrap();
        for format in [PlyFormat::Ascii, PlyFormat::BinaryLittleEndian] {
            for labels in [None, Some(vec![2, 3, -1, i32::MAX])] {
                let cloud = Cloud {
                    points: awkward_points(),
                    labels,
                };
                let path = dir.path().join("cloud.ply");
                write_ply(&path, &cloud, format).unwrap();
                let back = read_ply(&path).unwrap();
                assert_eq!(back.labels, cloud.labels);
                // Bitwise equality (covers -0.0).
                let bits = |c: &Cloud| -> Vec<u64> {
                    c.points.iter().flatten().map(|v| v.to_bits()).collect()
                };
                assert_eq!(bits(&back), bits(&cloud), "{format:?}");
            }
        }
        // Only the final file is left: no temporaries.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn written_ascii_header_is_as_documented() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.ply");
        let cloud = Cloud {
            points: vec![[1.5, -2.0, 0.1]],
            labels: Some(vec![4]),
        };
        write_ply(&path, &cloud, PlyFormat::Ascii).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(
            text,
            "ply\nformat ascii 1.0\ncomment ribreg, units mm\nelement vertex 1\n\
             property double x\nproperty double y\nproperty double z\nproperty int label\n\
             end_header\n1.5 -2 0.1 4\n"
        );
    }

    /// Binary file with float x y z interleaved with normals, colours, a uchar
    /// label, and a face element (triangle + quad) after the vertices.
    fn binary_with_extras() -> Vec<u8> {
        let mut b = b"ply\r\nformat binary_little_endian 1.0\r\ncomment made by hand\r\n\
            obj_info scanner 7\r\nelement vertex 4\r\nproperty float32 x\r\nproperty float nx\r\n\
            property float y\r\nproperty float z\r\nproperty float ny\r\nproperty float nz\r\n\
            property uchar red\r\nproperty uint8 green\r\nproperty uchar blue\r\n\
            property short s\r\nproperty uint u\r\nproperty double d\r\nproperty uchar label\r\n\
            element face 2\r\nproperty list uchar int vertex_indices\r\nproperty int8 flags\r\n\
            end_header\r\n"
            .to_vec();
        let verts: [[f32; 3]; 4] = [
            [0.0, 0.0, 0.0],
            [1.5, 0.0, 0.0],
            [1.5, 2.25, 0.0],
            [0.0, 2.0, -3.0],
        ];
        for (i, v) in verts.iter().enumerate() {
            b.extend(v[0].to_le_bytes());
            b.extend(9.0f32.to_le_bytes()); // nx
            b.extend(v[1].to_le_bytes());
            b.extend(v[2].to_le_bytes());
            b.extend(f32::NAN.to_le_bytes()); // ny: not a coordinate, not checked
            b.extend(1.0f32.to_le_bytes());
            b.extend([255, 128, 0]);
            b.extend((-5i16).to_le_bytes());
            b.extend(u32::MAX.to_le_bytes());
            b.extend(1e300f64.to_le_bytes());
            b.push(2 + i as u8);
        }
        b.push(3);
        for i in [0i32, 1, 2] {
            b.extend(i.to_le_bytes());
        }
        b.push(0xff); // flags = -1
        b.push(4);
        for i in [0i32, 1, 2, 3] {
            b.extend(i.to_le_bytes());
        }
        b.push(1);
        b
    }

    #[test]
    fn binary_with_extra_properties_and_faces() {
        let cloud = parse_ply(&binary_with_extras()).unwrap();
        assert_eq!(
            cloud.points,
            vec![
                [0.0, 0.0, 0.0],
                [1.5, 0.0, 0.0],
                [1.5, 2.25, 0.0],
                [0.0, 2.0, -3.0]
            ]
        );
        assert_eq!(cloud.labels, Some(vec![2, 3, 4, 5]));

        let mesh = parse_ply_mesh(&binary_with_extras()).unwrap();
        assert_eq!(mesh.vertices, cloud.points);
        assert_eq!(mesh.triangles, vec![[0, 1, 2], [0, 1, 2], [0, 2, 3]]);
    }

    #[test]
    fn ascii_with_crlf_comments_extras_and_faces() {
        let bytes = ascii(
            "ply\r\nformat ascii 1.0\r\ncomment hi\r\nelement vertex 3\r\nproperty uchar red\r\n\
             property double z\r\nproperty double y\r\nproperty double x\r\nproperty int label\r\n\
             element face 1\r\nproperty list uchar uint vertex_indices\r\nend_header\r\n\
             255 3.5 2 1 2\r\n0 -1e-3 0.25 7 3\r\n\r\n  1 0 0 0 -4  \r\n3 0 1 2\r\n\r\n",
        );
        let cloud = parse_ply(&bytes).unwrap();
        assert_eq!(
            cloud.points,
            vec![[1.0, 2.0, 3.5], [7.0, 0.25, -1e-3], [0.0, 0.0, 0.0]]
        );
        assert_eq!(cloud.labels, Some(vec![2, 3, -4]));
        let mesh = parse_ply_mesh(&bytes).unwrap();
        assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
    }

    #[test]
    fn float_and_double_coordinates() {
        let header = |ty: &str| {
            format!(
                "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty {ty} x\n\
                 property {ty} y\nproperty {ty} z\nend_header\n"
            )
        };
        let mut f = header("float").into_bytes();
        for v in [0.1f32, -0.2, 1e10] {
            f.extend(v.to_le_bytes());
        }
        assert_eq!(
            parse_ply(&f).unwrap().points,
            vec![[f64::from(0.1f32), f64::from(-0.2f32), 1e10]]
        );
        let mut d = header("float64").into_bytes();
        for v in [0.1f64, -0.2, 1e10] {
            d.extend(v.to_le_bytes());
        }
        assert_eq!(parse_ply(&d).unwrap().points, vec![[0.1, -0.2, 1e10]]);
    }

    #[test]
    fn float_label_must_be_integral() {
        let ply = |label: &str| {
            ascii(&format!(
                "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
                 property float z\nproperty float label\nend_header\n0 0 0 {label}\n"
            ))
        };
        assert_eq!(parse_ply(&ply("3.0")).unwrap().labels, Some(vec![3]));
        assert_eq!(
            err(&ply("2.5")).to_string(),
            "line 9: label 2.5 is not an integer"
        );
        assert_eq!(kind(&ply("1e10")), FormatError::BadLabel(1e10));
    }

    const XYZ_ASCII: &str = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n\
                             property float y\nproperty float z\nend_header\n";

    #[test]
    fn ascii_value_errors_name_the_line() {
        let cases = [
            ("1 2 3\n4 5\n7 8 9\n", "line 9: expected 3 numbers, found 2"),
            (
                "1 2 3\n4 5 6 7\n7 8 9\n",
                "line 9: expected 3 numbers, found 4",
            ),
            (
                "1 2 3\n4 five 6\n7 8 9\n",
                "line 9: \"five\" is not a number",
            ),
            (
                "1 2 3\n4 5 6\n7 nan 9\n",
                "line 10: coordinate is not finite",
            ),
            (
                "1 2 3\n4 5 inf\n7 8 9\n",
                "line 9: coordinate is not finite",
            ),
            ("1 2 3\n4 5 6\n", "ASCII body ends after 2 of 3 vertices"),
            (
                "1 2 3\n4 5 6\n7 8 9\n10 11 12\n",
                "line 11: unexpected data after the last element",
            ),
        ];
        for (body, message) in cases {
            let bytes = ascii(&format!("{XYZ_ASCII}{body}"));
            assert_eq!(err(&bytes).to_string(), message, "{body:?}");
        }
    }

    #[test]
    fn ascii_list_and_integer_errors() {
        let head = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
                    property float z\nproperty uchar red\nelement face 1\n\
                    property list uchar int vertex_indices\nend_header\n";
        let cases = [
            (
                "0 0 0 300\n3 0 0 0\n",
                "line 11: value 300 does not fit type uchar",
            ),
            (
                "0 0 0 1.5\n3 0 0 0\n",
                "line 11: value 1.5 does not fit type uchar",
            ),
            ("0 0 0 1\n3 0 0\n", "line 12: expected 4 numbers, found 3"),
            ("0 0 0 1\n2 0 0 0\n", "line 12: expected 3 numbers, found 4"),
        ];
        for (body, message) in cases {
            assert_eq!(err(&ascii(&format!("{head}{body}"))).to_string(), message);
        }
        // In a mesh, indices are checked and faces need three corners.
        let mesh_err = |body: &str| {
            parse_ply_mesh(&ascii(&format!("{head}{body}")))
                .unwrap_err()
                .to_string()
        };
        assert_eq!(
            mesh_err("0 0 0 1\n3 0 0 1\n"),
            "line 12: vertex index 1 is out of range for 1 vertices"
        );
        assert_eq!(
            mesh_err("0 0 0 1\n2 0 0\n"),
            "line 12: face has 2 corners, at least 3 are needed"
        );
    }

    fn binary_xyz(count: &str, points: &[[f32; 3]]) -> Vec<u8> {
        let mut b = format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex {count}\nproperty float x\n\
             property float y\nproperty float z\nend_header\n"
        )
        .into_bytes();
        for p in points {
            for c in p {
                b.extend(c.to_le_bytes());
            }
        }
        b
    }

    #[test]
    fn binary_truncation_and_absurd_counts() {
        let pts = [[1.0f32, 2.0, 3.0], [4.0, 5.0, 6.0]];
        let full = binary_xyz("2", &pts);
        assert_eq!(parse_ply(&full).unwrap().points.len(), 2);
        // Every cut inside the body is reported with the number of vertices read.
        let body_start = full.len() - 24;
        for cut in body_start..full.len() {
            let read = (cut - body_start) / 12;
            assert_eq!(
                kind(&full[..cut]),
                FormatError::Truncated {
                    format: PlyFormat::BinaryLittleEndian,
                    element: "vertex".to_owned(),
                    read,
                    expected: 2,
                }
            );
        }
        assert_eq!(
            err(&binary_xyz("3000", &pts)).to_string(),
            "binary body ends after 2 of 3000 vertices"
        );
        // A count far beyond the file (and memory) is a clean error, not an allocation.
        let huge = usize::MAX.to_string();
        assert_eq!(
            err(&binary_xyz(&huge, &pts)).to_string(),
            format!("binary body ends after 2 of {huge} vertices")
        );
        // Too many points for the count: trailing data.
        assert_eq!(kind(&binary_xyz("1", &pts)), FormatError::TrailingData);
        // A stray newline after the body is tolerated.
        let mut newline = full.clone();
        newline.extend(b"\r\n");
        assert_eq!(parse_ply(&newline).unwrap().points.len(), 2);
    }

    #[test]
    fn binary_truncated_inside_a_skipped_list() {
        let mut b = binary_xyz("1", &[[0.0, 0.0, 0.0]]);
        // Splice a face element into the header.
        let header_end = b.windows(11).position(|w| w == b"end_header\n").unwrap();
        b.splice(
            header_end..header_end,
            b"element face 2\nproperty list uint int vertex_indices\n"
                .iter()
                .copied(),
        );
        b.extend(3u32.to_le_bytes());
        b.extend([0u8; 12]);
        b.extend(u32::MAX.to_le_bytes()); // a huge list length with no data behind it
        b.extend([0u8; 8]);
        assert_eq!(err(&b).to_string(), "binary body ends after 1 of 2 faces");
    }

    #[test]
    fn binary_non_finite_names_the_vertex() {
        let b = binary_xyz(
            "3",
            &[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, f32::INFINITY, 2.0]],
        );
        assert_eq!(err(&b).to_string(), "vertex 2: coordinate is not finite");
        let b = binary_xyz("2", &[[f32::NAN, 0.0, 0.0], [1.0, 1.0, 1.0]]);
        assert_eq!(err(&b).to_string(), "vertex 0: coordinate is not finite");
    }

    #[test]
    fn header_errors() {
        assert_eq!(kind(b""), FormatError::NotPly);
        assert_eq!(kind(b"\x00\x01\x02garbage\xff\xfe"), FormatError::NotPly);
        assert_eq!(
            kind(b"solid cube\nfacet normal 0 0 1\n"),
            FormatError::NotPly
        );
        assert_eq!(
            kind(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n1 2 3\n"),
            FormatError::MissingEndHeader
        );
        assert_eq!(kind(b"ply"), FormatError::MissingEndHeader);
        assert_eq!(
            err(b"ply\nformat binary_big_endian 1.0\nelement vertex 1\nend_header\n").to_string(),
            "line 2: binary_big_endian PLY is not supported; \
             convert it to binary_little_endian or ascii"
        );
        assert_eq!(
            kind(b"ply\nformat ascii 2.0\nend_header\n"),
            FormatError::UnsupportedFormat("ascii 2.0".to_owned())
        );
        let no_y = XYZ_ASCII.replace("property float y\n", "");
        assert_eq!(
            err(no_y.as_bytes()).to_string(),
            "element vertex has no property y"
        );
        assert_eq!(
            kind(b"ply\nformat ascii 1.0\nelement face 0\nproperty float x\nend_header\n"),
            FormatError::MissingElement("vertex")
        );
        let zero = XYZ_ASCII.replace("vertex 3", "vertex 0");
        assert_eq!(err(zero.as_bytes()).to_string(), "no points");
        let cases: [(&[u8], &str); 8] = [
            (
                b"ply\nelement vertex 1\nend_header\n",
                "bad PLY header: no format line",
            ),
            (
                b"ply\nformat ascii 1.0\nproperty float x\nend_header\n",
                "line 3: bad PLY header: property before any element",
            ),
            (
                b"ply\nformat ascii 1.0\nelement vertex -1\nend_header\n",
                "line 3: bad PLY header: element count \"-1\" is not a non-negative integer",
            ),
            (
                b"ply\nformat ascii 1.0\nelement vertex 1\nproperty half x\nend_header\n",
                "line 4: bad PLY header: unknown property type \"half\"",
            ),
            (
                b"ply\nformat ascii 1.0\nelement vertex 1\nproperty list float int x\nend_header\n",
                "line 4: bad PLY header: list length type of x must be an integer type",
            ),
            (
                b"ply\nformat ascii 1.0\nbanana\nend_header\n",
                "line 3: bad PLY header: unknown keyword \"banana\"",
            ),
            (
                b"ply\nformat ascii 1.0\nelement vertex 5\nend_header\n",
                "bad PLY header: element vertex has no properties",
            ),
            (
                b"ply\nformat ascii 1.0\nelement vertex 1\nproperty \xff x\nend_header\n",
                "line 4: text is not valid UTF-8",
            ),
        ];
        for (bytes, message) in cases {
            assert_eq!(err(bytes).to_string(), message);
        }
    }

    #[test]
    fn mesh_needs_faces() {
        let cloud_only = ascii(&format!("{XYZ_ASCII}0 0 0\n1 0 0\n0 1 0\n"));
        assert_eq!(
            parse_ply_mesh(&cloud_only).unwrap_err().kind(),
            Some(&FormatError::MissingElement("face"))
        );
        let zero_faces = format!("{XYZ_ASCII}0 0 0\n1 0 0\n0 1 0\n").replace(
            "end_header",
            "element face 0\nproperty list uchar int vertex_indices\nend_header",
        );
        assert_eq!(
            parse_ply_mesh(zero_faces.as_bytes()).unwrap_err().kind(),
            Some(&FormatError::NoTriangles)
        );
    }

    #[test]
    fn read_ply_names_the_file() {
        use std::io::ErrorKind;
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("CT.ply");
        let e = read_ply(&missing).unwrap_err();
        assert!(matches!(&e, IoError::Io { source, .. } if source.kind() == ErrorKind::NotFound));
        assert!(e
            .to_string()
            .starts_with(&format!("{}: cannot read: ", missing.display())));

        let path = dir.path().join("US.ply");
        std::fs::write(&path, binary_xyz("3000", &[[0.0, 0.0, 0.0]])).unwrap();
        assert_eq!(
            read_ply(&path).unwrap_err().to_string(),
            format!(
                "{}: binary body ends after 1 of 3000 vertices",
                path.display()
            )
        );
    }

    #[test]
    fn writer_refuses_bad_clouds_and_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.ply");
        let bad = [
            (
                Cloud {
                    points: vec![],
                    labels: None,
                },
                "no points".to_owned(),
            ),
            (
                Cloud {
                    points: vec![[0.0; 3], [0.0, f64::NAN, 0.0]],
                    labels: None,
                },
                "vertex 1: coordinate is not finite".to_owned(),
            ),
            (
                Cloud {
                    points: vec![[0.0; 3]],
                    labels: Some(vec![1, 2]),
                },
                "2 labels for 1 points".to_owned(),
            ),
        ];
        for (cloud, message) in bad {
            let e = write_ply(&path, &cloud, PlyFormat::BinaryLittleEndian).unwrap_err();
            assert_eq!(e.to_string(), format!("{}: {message}", path.display()));
        }
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);

        let e = write_ply(
            &dir.path().join("missing/out.ply"),
            &Cloud {
                points: vec![[1.0; 3]],
                labels: None,
            },
            PlyFormat::Ascii,
        )
        .unwrap_err();
        assert!(matches!(e, IoError::Io { .. }));
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn mesh_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.ply");
        let mesh = Mesh {
            vertices: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.1],
                [0.0, 1.0, -0.3],
                [1.0, 1.0, 0.0],
            ],
            triangles: vec![[0, 1, 2], [2, 1, 3]],
        };
        write_mesh_ply(&path, &mesh).unwrap();
        assert_eq!(
            parse_ply_mesh(&std::fs::read(&path).unwrap()).unwrap(),
            mesh
        );
        // The same file read as a cloud skips the faces.
        assert_eq!(read_ply(&path).unwrap().points, mesh.vertices);

        let bad = Mesh {
            triangles: vec![[0, 1, 4]],
            ..mesh
        };
        assert_eq!(
            write_mesh_ply(&path, &bad).unwrap_err().to_string(),
            format!(
                "{}: triangle 0: vertex index 4 is out of range for 4 vertices",
                path.display()
            )
        );
    }

    #[test]
    fn reservation_is_capped_by_the_body() {
        let element = Element {
            name: "vertex".to_owned(),
            count: usize::MAX,
            properties: ["x", "y", "z"]
                .map(|name| Property {
                    name: name.to_owned(),
                    ty: PropertyType::Scalar(Scalar::F32),
                })
                .into(),
        };
        assert_eq!(element.reserve_hint(PlyFormat::BinaryLittleEndian, 120), 11);
        assert_eq!(element.reserve_hint(PlyFormat::Ascii, 120), 21);
        let small = Element {
            count: 5,
            ..element
        };
        assert_eq!(
            small.reserve_hint(PlyFormat::BinaryLittleEndian, 1 << 20),
            5
        );
    }

    #[test]
    fn element_before_vertices_is_skipped() {
        let mut b = b"ply\nformat binary_little_endian 1.0\nelement camera 2\n\
            property list ushort double params\nproperty int16 id\nelement vertex 2\n\
            property double z\nproperty double y\nproperty double x\nproperty uint label\n\
            end_header\n"
            .to_vec();
        for (n, id) in [(3u16, 7i16), (0, 8)] {
            b.extend(n.to_le_bytes());
            for k in 0..n {
                b.extend(f64::from(k).to_le_bytes());
            }
            b.extend(id.to_le_bytes());
        }
        for (p, label) in [([1.0f64, 2.0, 3.0], 5u32), ([-4.0, 0.5, 6.0], 1)] {
            for c in p {
                b.extend(c.to_le_bytes());
            }
            b.extend(label.to_le_bytes());
        }
        let cloud = parse_ply(&b).unwrap();
        assert_eq!(cloud.points, vec![[3.0, 2.0, 1.0], [6.0, 0.5, -4.0]]);
        assert_eq!(cloud.labels, Some(vec![5, 1]));

        // A uint label beyond i32 is refused, naming the vertex.
        let len = b.len();
        b[len - 4..].copy_from_slice(&u32::MAX.to_le_bytes());
        assert_eq!(
            err(&b).to_string(),
            "vertex 1: label 4294967295 is not an integer"
        );
    }

    #[test]
    fn long_garbage_is_quoted_briefly() {
        let long = "z".repeat(5000);
        let message = err(format!("{XYZ_ASCII}1 2 3\n4 {long} 6\n7 8 9\n").as_bytes()).to_string();
        assert_eq!(
            message,
            format!("line 9: \"{}...\" is not a number", "z".repeat(40))
        );
    }

    #[test]
    fn garbage_and_mutations_never_panic() {
        let mut s = 7;
        for len in 0..300 {
            let bytes: Vec<u8> = (0..len).map(|_| crate::io::lcg(&mut s) as u8).collect();
            assert!(parse_ply(&bytes).is_err());
            let mut with_magic = b"ply\nformat binary_little_endian 1.0\n".to_vec();
            with_magic.extend(&bytes);
            let _ = parse_ply(&with_magic);
            let _ = parse_ply_mesh(&with_magic);
        }
        let seeds = [
            binary_with_extras(),
            ascii(&format!("{XYZ_ASCII}1 2 3\n4 5 6\n7 8 9\n")),
        ];
        for seed in &seeds {
            for m in crate::io::mutants(seed, 3000, b"0123456789 \n-e.", &mut s) {
                let _ = parse_ply(&m);
                let _ = parse_ply_mesh(&m);
            }
        }
    }
}
